"""Reader fuzzing (issue 14, deliverable 7): mutated ``measurements.h5`` files (tests/fuzz_files.py)
given to ``twin detect``, ``twin backlash`` (and ``twin check`` where it exists): each exits 0, 1
or 2, with a message when not 0, and never with a traceback.

The default suite runs one mutation of each kind (fixed seed) in this process (typer's CliRunner);
the ``slow`` test runs 500 (``FUZZ_N``), each verb in a forked child whose wall time (≤ 30 s) and
peak resident memory (≤ 2 GB, from ``wait4``) are checked, and prints the figures."""

import os
import re
import resource
import signal
import sys
import time
import traceback

import numpy as np
import pytest
from typer.testing import CliRunner

from tests.conftest import REFERENCE_TINY, REPO, TINY_PHASE1, run_twin, simulate_shared
from tests.fuzz_files import MUTATIONS, mutate
from twin.cli import app

# A tiny campaign with both phases: 1 capture of 3 s per sample (18 healthy, onset at 172 h) and
# two Phase II sessions of 2 runs; its reference data set as in tests/test_phase1_cli.py.
BOTH = [*TINY_PHASE1, "--set", "campaign.phase2=true", "--set", "phase2.session_hours=[50.0, 200.0]",
        "--set", "phase2.runs_per_session=2", "--set", "phase2.speeds_mm_s=[100.0, 500.0]",
        "--set", "phase2.dwell_s=0.5"]


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    ref, camp = root / "ref", root / "camp"
    simulate_shared(tmp_path_factory, REPO / "scenarios/paper-reference.toml", ref, *REFERENCE_TINY)
    run_twin("simulate", REPO / "scenarios/phase1-quick.toml", "-o", camp, *BOTH)
    return root, ref, camp / "measurements.h5"


def verbs(d, ref):
    out = [["detect", str(d), "--reference", str(ref), "-o", str(d / "p1"), "--method", "pca_t2"],
           ["backlash", str(d), "-o", str(d / "bl"), "--no-plots"]]
    if any(c.name == "check" or getattr(c.callback, "__name__", "") == "check" for c in app.registered_commands):
        out.append(["check", str(d)])
    return out


def has_message(verb: str, code: int, output: str) -> bool:
    """A refusal says why: ``error: ...`` (exit 2, or 1 for detect/backlash), or for ``twin check``
    (exit 1: errors found) its table with the count of errors and an ``error`` row."""
    if verb == "check" and code == 1:
        return re.search(r"\b[1-9]\d* errors?\b", output) is not None and "│ error" in output
    return "error:" in output


def plan(n: int, seed: int) -> list[str]:
    """n mutation kinds: every kind in turn, so each is drawn n / len(MUTATIONS) times."""
    kinds = sorted(MUTATIONS)
    order = np.random.default_rng(seed).permutation(n)
    return [kinds[i % len(kinds)] for i in order]


def test_fuzz_sample_in_process(sources, tmp_path):
    root, ref, src = sources
    runner = CliRunner()
    rng = np.random.default_rng(14)
    codes = {}
    for i, kind in enumerate(plan(len(MUTATIONS), 14)):
        d = tmp_path / f"m{i:03d}"
        what = mutate(src, d, rng, kind)
        for args in verbs(d, ref):
            r = runner.invoke(app, args)
            tb = "".join(traceback.format_exception(r.exception)) if r.exception else ""
            assert r.exception is None or isinstance(r.exception, SystemExit), f"{what}: {args[0]}:\n{tb}"
            assert r.exit_code in (0, 1, 2), f"{what}: {args[0]} exit {r.exit_code}"
            if r.exit_code:
                assert has_message(args[0], r.exit_code, r.output), \
                    f"{what}: {args[0]}: no message:\n{r.output[-1000:]}"
            assert "Traceback" not in r.output
            codes.setdefault(args[0], []).append(r.exit_code)
    print({v: {c: cs.count(c) for c in sorted(set(cs))} for v, cs in codes.items()})
    # The sample is not all refusals: some mutations leave a file the analysis can use.
    assert 0 in codes["backlash"] and 2 in codes["backlash"] and 2 in codes["detect"]


def _child(args: list[str], log: str) -> None:
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    code = 99
    try:
        app(args, prog_name="twin")
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except BaseException:
        traceback.print_exc()
        code = 98
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


def run_forked(args: list[str], log, timeout_s: float = 30.0) -> tuple[int, float, float]:
    """(exit code, wall seconds, peak RSS in MB) of ``twin ARGS`` in a forked child; a child
    still running after ``timeout_s`` is killed (exit code -9)."""
    t0 = time.monotonic()
    pid = os.fork()
    if pid == 0:
        _child(args, str(log))
    while True:
        wpid, status, usage = os.wait4(pid, os.WNOHANG)
        if wpid:
            break
        if time.monotonic() - t0 > timeout_s:
            os.kill(pid, signal.SIGKILL)
            _, status, usage = os.wait4(pid, 0)
            return -9, time.monotonic() - t0, usage.ru_maxrss / 1024
        time.sleep(0.01)
    return os.waitstatus_to_exitcode(status), time.monotonic() - t0, usage.ru_maxrss / 1024


@pytest.mark.slow
@pytest.mark.timeout(4 * 3600)  # 1500 verb runs: about 70 min on a shared 2-core machine
def test_fuzz_500(sources, tmp_path):
    root, ref, src = sources
    n = int(os.environ.get("FUZZ_N", "500"))
    rng = np.random.default_rng(2026)
    rows = []
    for i, kind in enumerate(plan(n, 2026)):
        d = tmp_path / f"m{i:04d}"
        what = mutate(src, d, rng, kind)
        for args in verbs(d, ref):
            log = d / f"{args[0]}.log"
            code, wall, rss = run_forked(args, log)
            text = log.read_text(errors="replace")
            rows.append((kind, args[0], code, wall, rss, what, text))
            if code not in (0, 1, 2) or "Traceback" in text:
                print(f"BAD {i} {what} {args[0]} exit {code}: {text[-300:]}", flush=True)
        if (i + 1) % 25 == 0:
            print(f"{i + 1} mutations: max wall {max(r[3] for r in rows):.1f} s, max RSS "
                  f"{max(r[4] for r in rows):.0f} MB", flush=True)
    by = {}
    for r in rows:
        by.setdefault(r[1], []).append(r[2])
    print(f"{n} mutations; exit codes per verb: "
          f"{ {v: {c: cs.count(c) for c in sorted(set(cs))} for v, cs in by.items()} }; "
          f"max wall {max(r[3] for r in rows):.1f} s; max RSS {max(r[4] for r in rows):.0f} MB; "
          f"parent CPU {resource.getrusage(resource.RUSAGE_SELF).ru_utime:.0f} s")
    bad = [r for r in rows if r[2] not in (0, 1, 2) or "Traceback" in r[6] or r[3] > 30 or r[4] > 2048
           or (r[2] and not has_message(r[1], r[2], r[6]))]
    assert not bad, "\n".join(f"{k} {v} exit {c} {w:.1f} s {m:.0f} MB {what}\n{t[-800:]}"
                              for k, v, c, w, m, what, t in bad[:10])
