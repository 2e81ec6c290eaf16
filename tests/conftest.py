import fcntl
import functools
import hashlib
import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import cli_server
import pytest
from threadpoolctl import threadpool_limits

# Each test process has a core of its own (pytest-xdist, one per core): a command under test
# runs its work in its own process (analysis.base.executors.default_processes) unless the test asks for
# --workers; the parallel paths are tested with explicit --workers / --scheduler.
os.environ.setdefault("TWIN_WORKERS", "1")
# ... and one BLAS thread in the test process itself, as in the commands (twin.cli.main) and their
# workers: the other core is the other test process's, and OpenBLAS's idle threads spin.
threadpool_limits(1)
# The suite starts a few hundred Python processes (the commands under test, their workers); where
# the environment forbids bytecode files (PYTHONDONTWRITEBYTECODE, set on some CI images), each
# compiles twin/ and analysis/ from source again. Python's default instead: compiled once into
# __pycache__ (ignored by git), read back by the processes after.
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
sys.dont_write_bytecode = False
REPO = Path(__file__).resolve().parents[1]
TWIN = [sys.executable, "-m", "twin.cli"]
# A small but complete campaign: every kind of unit, a few seconds of simulation.
SMALL = ["--set", "phase1.capture_s=2.0", "--set", "phase1.sample_interval_hours=250",
         "--set", "phase2.runs_per_session=2", "--set", "phase2.dwell_s=0.5",
         "--set", "phase2.speeds_mm_s=[100.0, 500.0]", "--set", "phase2.session_hours=[50.0, 550.0]"]
# The reference data set, reduced: 5 samples per condition of 2 captures of 4 s (Fisher selection).
REFERENCE_SMALL = ["--set", "phase1.captures_per_sample=2", "--set", "phase1.capture_s=4.0",
                   "--set", "phase1.sample_interval_hours=20"]
# Tiny Phase I campaigns: one 3-s capture per sample; the reference set at one sample per 40 h.
TINY_PHASE1 = ["--set", "phase1.captures_per_sample=1", "--set", "phase1.capture_s=3.0"]
REFERENCE_TINY = [*TINY_PHASE1, "--set", "phase1.sample_interval_hours=40"]


def run_twin(*args, check=True, env=None, **kw):
    """``python -m twin.cli ARGS`` in the repository with this process's environment (PYTHONPATH
    the repository) or ``env``: the completed process, its output captured as text; with
    ``check``, CalledProcessError on a non-zero exit. Forked from the test process's warm server
    (:mod:`cli_server`); a new interpreter (:func:`subprocess.run`) with other keywords or when
    TWIN_TEST_SUBPROCESS is set."""
    env = dict(os.environ, PYTHONPATH=str(REPO)) if env is None else env
    if set(kw) <= {"timeout"} and not os.environ.get("TWIN_TEST_SUBPROCESS"):
        proc = cli_server.call([*map(str, args)], env, REPO, kw.get("timeout"))
        if check and proc.returncode:
            raise subprocess.CalledProcessError(proc.returncode, proc.args, proc.stdout, proc.stderr)
        return proc
    return subprocess.run([*TWIN, *map(str, args)], cwd=REPO, env=env, capture_output=True,
                          text=True, check=check, **kw)


def shared_dir(tmp_path_factory, name: str) -> Path:
    """A folder ``name`` that every test process of this run sees (beside pytest-xdist's per-process
    base temporary folders), created if missing."""
    base = tmp_path_factory.getbasetemp()
    folder = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / name
    folder.mkdir(exist_ok=True)
    return folder


def made_master(tmp_path_factory, key: list, make) -> Path:
    """``make(master)`` once per test run for this ``key`` (the first test process to ask holds a
    file lock while the others wait), into a store shared by the run's test processes: the
    ``master`` folder, which callers must not write into (they copy it: :func:`simulate_shared`)."""
    store = shared_dir(tmp_path_factory, "shared-campaigns")
    digest = hashlib.sha256(json.dumps([str(k) for k in key]).encode()).hexdigest()[:16]
    master = store / digest
    with open(store / f"{digest}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (store / f"{digest}.done").exists():
            shutil.rmtree(master, ignore_errors=True)
            make(master)
            master.mkdir(exist_ok=True)
            (store / f"{digest}.done").touch()
    return master


def simulated_master(tmp_path_factory, scenario, *args) -> Path:
    """The run's one ``twin simulate SCENARIO -o MASTER ARGS...`` (:func:`made_master`; callers
    must not write into it): simulated once per test run, or, for a campaign the run's
    ``twin demo`` simulates (:data:`DEMO_SIMULATES`), resumed from the demo's units
    (:func:`demo_master`)."""
    key = ["simulate", scenario, *args]
    part = DEMO_SIMULATES.get((str(Path(scenario).resolve()), *map(str, args)))
    if part is None:
        return made_master(tmp_path_factory, key, lambda master: run_twin("simulate", scenario, "-o", master, *args))

    def resume(master: Path) -> None:
        # the demo's units, then `twin simulate`, which checks that they are this scenario's
        # (it refuses a folder simulated from another) and assembles the files from them
        demo, said = demo_master(tmp_path_factory)
        assert said.returncode == 0, f"twin demo, whose units this campaign takes, failed:\n{said.stderr}"
        shutil.copytree(demo / part / ".parts", master / ".parts")
        proc = run_twin("simulate", scenario, "-o", master, *args)
        assert "0 units simulated" in " ".join(proc.stderr.split()), proc.stderr

    return made_master(tmp_path_factory, key, resume)


def simulate_shared(tmp_path_factory, scenario, out, *args) -> Path:
    """``twin simulate SCENARIO -o OUT ARGS...`` for a campaign several test files simulate alike:
    a copy of :func:`simulated_master` (what the caller's own run would give: the twin's
    campaigns are deterministic, tests/test_campaign.py)."""
    shutil.copytree(simulated_master(tmp_path_factory, scenario, *args), out)
    return Path(out)


DIAGNOSE_BENCH = REPO / "scenarios" / "diagnose-bench.toml"


def record_diagnose_bench(tmp_path, name, *sets):
    """A recording of the diagnosis benchmark's scenario (seed 777, ``sets`` as `--set`) in
    ``tmp_path / name``, its truth.h5 removed (the diagnosis must not need it)."""
    d = tmp_path / name
    proc = run_twin("simulate", str(DIAGNOSE_BENCH), "-o", str(d), "--workers", "1",
                    "--set", "seed=777", *[x for s in sets for x in ("--set", s)])
    assert proc.returncode == 0, proc.stderr
    (d / "truth.h5").unlink()
    return d


@functools.cache
def record_module():
    """benchmarks/record.py, loaded once (the benchmarks folder is not a package)."""
    spec = importlib.util.spec_from_file_location("record", REPO / "benchmarks" / "record.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def signed(x: float, digits: int = 2) -> str:
    """A figure as the docs write it: ``digits`` decimals, a real minus sign, never −0.00
    (benchmarks/record.py's ``text``, the benchmarks' formatter)."""
    return record_module().text(x, f"{{:.{digits}f}}")


class Quote:
    """What a test measures and the docs quote: ``quote(name, value, text)`` a figure,
    ``quote.table(name, markdown)`` a table. With the environment variable ``TWIN_RECORD`` set
    (`make validate`, which runs the tests marked ``quoted``) they go into docs/validation.json
    under ``test_<file stem>`` (benchmarks/record.py, merged with the file's other tests'
    figures), else nowhere: the test's assertions are what `make test` checks."""

    def __init__(self, node):
        self.bench = node.path.stem
        self.command = f"TWIN_RECORD=1 .venv/bin/python -m pytest -m quoted {node.path.relative_to(REPO)}"
        # the file's docstring: the same for every test of the file, whichever records last
        self.scale = " ".join((node.module.__doc__ or self.bench).split()).split(". ")[0]
        self.on = bool(os.environ.get("TWIN_RECORD"))

    def _record(self, figures, tables):
        if not self.on:
            return
        record_module().record(self.bench, command=self.command, scale=self.scale, figures=figures, tables=tables,
                      merge=True)

    def __call__(self, name: str, value: float | None, text: str) -> None:
        self._record({name: (value, text)}, {})

    def table(self, name: str, markdown: str) -> None:
        self._record({}, {name: markdown})


@pytest.fixture
def quote(request) -> Quote:
    return Quote(request.node)


def truncate_dataset(group, key: str, fraction: float) -> None:
    """Replace ``group[key]`` by its first ``fraction`` of rows, keeping its attributes (a
    recording cut short)."""
    data, attrs = group[key][...], dict(group[key].attrs)
    del group[key]
    ds = group.create_dataset(key, data=data[: int(fraction * len(data))])
    for k, v in attrs.items():
        ds.attrs[k] = v


@pytest.fixture(scope="session")
def small_campaign(tmp_path_factory):
    out = tmp_path_factory.mktemp("small")
    run_twin("simulate", REPO / "scenarios/quick.toml", "-o", out, *SMALL)
    return out


# `twin demo` at a smaller scale than `make demo`: 25 Phase I samples (15 baseline, onset at
# 172 h), three Phase II sessions of 3 runs (100, 150 h healthy; 250 h with ~2 µm of backlash).
DEMO_SMALL = ["--set", "campaign.total_hours=250", "--set", "phase2.session_hours=[100.0, 150.0, 250.0]",
              "--set", "phase2.runs_per_session=3"]


#: What `twin demo` at DEMO_SMALL simulates on its way, as `twin simulate` arguments (the
#: scenario's resolved path, then the arguments): the folder of the demo's output that holds it.
DEMO_SIMULATES = {(str(REPO / "scenarios" / "demo.toml"), *DEMO_SMALL): ".",
                  (str(REPO / "scenarios" / "paper-reference.toml"), *REFERENCE_SMALL): "reference"}


DEMO_PROCESS = "demo-process.json"


def demo_master(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    """``twin demo -o MASTER`` at DEMO_SMALL, run once per test run (:func:`made_master`: the test
    processes share it; the process's exit code and output kept in MASTER/:data:`DEMO_PROCESS`):
    (MASTER, the completed process). The units it simulates are those of `twin simulate` with
    the same arguments, which :func:`simulate_shared` resumes from them instead of simulating
    them again."""
    def demo(master: Path) -> None:
        proc = run_twin("demo", "-o", master, *DEMO_SMALL, check=False, timeout=900)
        master.mkdir(parents=True, exist_ok=True)
        (master / DEMO_PROCESS).write_text(json.dumps(
            {"returncode": proc.returncode, "stdout": proc.stdout, "stderr": proc.stderr}))

    master = made_master(tmp_path_factory, ["demo", *DEMO_SMALL], demo)
    said = json.loads((master / DEMO_PROCESS).read_text())
    return master, subprocess.CompletedProcess(["twin", "demo"], said["returncode"], said["stdout"],
                                               said["stderr"])


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory):
    """A copy of the run's ``twin demo`` (:func:`demo_master`) for this test process: (directory,
    completed process)."""
    master, proc = demo_master(tmp_path_factory)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    out = tmp_path_factory.mktemp("demo") / "demo"
    shutil.copytree(master, out, ignore=lambda d, names: [DEMO_PROCESS] if Path(d) == master else [])
    return out, proc


# The longest files (their total time in `make test`, longest first), run first: with two test
# processes (`make test`, pytest-xdist's loadfile) the other process works through the short files
# meanwhile, instead of one process finishing a long file alone at the end.
LONG_FILES = ("test_calibrate.py", "test_gate.py", "test_phase2_backlash.py", "test_executors.py",
              "test_sweep.py", "test_monitor.py", "test_plugin_kinds.py", "test_campaign.py",
              "test_fuzz_import.py", "test_phase2_cli.py", "test_import_watch.py", "test_view.py")


#: Module fixtures whose setup (counted in the timeout of the first test that takes them) takes
#: longest: on the 2-core machine where `make test` took 30 min, the gate's cold build 328 s and
#: the calibration round trip 179 s. Their tests get 30 min, more than 3x that, so a busy machine
#: does not fail them.
LONG_FIXTURES = ("round_trip", "cold")


def pytest_collection_modifyitems(config, items):
    """The long files first (:data:`LONG_FILES`, a stable sort: the order within and between
    the other files is kept); `slow` campaigns may take up to an hour each, the tests that set up
    a :data:`LONG_FIXTURES` 30 min, the others the default timeout (pyproject: 15 min)."""
    rank = {name: i for i, name in enumerate(LONG_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FILES)))
    for item in items:
        if item.get_closest_marker("timeout"):
            continue
        if item.get_closest_marker("slow"):
            item.add_marker(pytest.mark.timeout(3600))
        elif set(LONG_FIXTURES) & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.timeout(1800))


@pytest.fixture(autouse=True, scope="session")
def backlash_cache(tmp_path_factory):
    """Every `twin backlash` the suite runs keeps its sessions' error motions in one folder that
    the run's test processes share (TWIN_BACKLASH_CACHE, the --cache default): the files run it
    on the same recordings (copies of a campaign simulated once, :func:`simulate_shared`) with
    other estimators and options. Keyed by the recording's bytes and the error-motion options
    (analysis.phase2.error_motion_cache), so a changed recording misses; each entry is written
    atomically, so two processes computing the same session write the same file in turn;
    tests/test_phase2_cli.py proves the cached result equals the computed one."""
    os.environ["TWIN_BACKLASH_CACHE"] = str(shared_dir(tmp_path_factory, "backlash-cache"))
    yield
    os.environ.pop("TWIN_BACKLASH_CACHE", None)
