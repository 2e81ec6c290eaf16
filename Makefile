# Each target creates or updates .venv itself, so a fresh clone needs nothing else.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test test-slow lint bench bench-check validate validate-ci venv clean

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[all,test]'
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/twin demo

lint: $(STAMP)
	$(VENV)/bin/ruff check .

# Two test processes (pytest-xdist), a test file to each in turn: the suite's long campaigns run
# side by side. The slowest tests are listed at the end of every run.
test: lint
	$(PY) -m pytest -q -n 2 --dist loadfile --durations=25

test-slow: $(STAMP)
	$(PY) -m pytest -q -m slow

bench: $(STAMP)
	for b in benchmarks/bench_*.py; do $(PY) $$b || exit 1; done

# The regression guard of the simulation's speed (not part of `make test`; CI may run it): the
# ratios to MuJoCo's bare stepping measured in the same run against benchmarks/baseline.json,
# exit 1 if any is more than 20 % above it. A new baseline:
#   .venv/bin/python benchmarks/bench_simulation.py --no-quick --repeat 3 --write-baseline benchmarks/baseline.json
bench-check: $(STAMP)
	$(PY) benchmarks/bench_simulation.py --no-quick --check benchmarks/baseline.json

# Every figure the README and the docs quote, re-measured: each benchmark below stores its figures
# in docs/validation.json (--record), then benchmarks/record.py writes them into the docs' quoted
# spans (<!-- fig:... -->, <!-- table:... -->); tests/test_quoted_figures.py checks they agree.
# The `validate` tests (the diagnosis benchmark's targets, tests/test_diagnosis_benchmark.py) run
# on the cache bench_diagnose.py leaves in runs/validate/diagnose-benchmark; the `quoted` tests
# record the figures they measure (TWIN_RECORD=1, their `quote` fixture). Run by hand; CI runs
# the part of it that fits (make validate-ci, below: the benchmarks of VALIDATE_CI).
VALIDATE_CI := benchmarks/bench_demo.py benchmarks/table3_phase1.py benchmarks/bench_phase1.py \
               benchmarks/bench_phase2_backlash.py benchmarks/bench_rail_passes.py \
               benchmarks/bench_phase2_error_motions.py benchmarks/bench_prognosis.py
VALIDATE := benchmarks/bench_diagnose.py benchmarks/sweep_tables.py benchmarks/fig13_paper.py $(VALIDATE_CI)
validate: $(STAMP)
	for b in $(VALIDATE); do $(PY) $$b --record || exit 1; done
	TWIN_WORKERS=1 $(PY) benchmarks/bench_monitor.py --record
	TWIN_RECORD=1 TWIN_DIAGNOSE_BENCH_CACHE=runs/validate/diagnose-benchmark/cache \
	  $(PY) -m pytest -q -m "(validate or quoted) and not slow" --durations=10
	$(PY) benchmarks/record.py

# CI's second step (.ci/run, after `make test`): the part of `make validate` that fits CI's 90
# minutes on a slow 2-core machine (the run prints its slowest steps). It re-runs the
# benchmarks below with --record and the `validate` tests except the diagnosis benchmark's, then
# writes the figures into the docs and lists the pages whose figures moved. Left to
# `make validate` (run by hand, the figures committed): the gap diagnosis's blind benchmark
# (bench_diagnose.py and its `validate` tests), the shipped sweeps' tables (sweep_tables.py),
# Fig. 13 (fig13_paper.py), the monitor's soak (bench_monitor.py) and the `quoted` tests'
# recording (their assertions run in `make test`).
validate-ci: $(STAMP)
	for b in $(VALIDATE_CI); do $(PY) $$b --record || exit 1; done
	$(PY) -m pytest -q -n 2 --dist loadfile -m "validate and not slow" --ignore=tests/test_diagnosis_benchmark.py \
	  --durations=10
	$(PY) benchmarks/record.py
	git diff --stat -- README.md docs || true

clean:
	rm -rf $(VENV) build *.egg-info
