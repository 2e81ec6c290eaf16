"""Interrupts and odd arguments (issue 14, deliverable 6): Ctrl-C during ``twin simulate`` stops
within 2 s, cancels the queued units, says how many finished parts are kept and how to resume,
exits 130; the rerun resumes from those parts; Ctrl-C during ``twin gate``'s build exits 130
saying how to resume. ``--workers`` below 1 and an output path below a
regular file exit 2 with a message; ``twin detect`` without measurements.h5 says exactly that."""

import os
import re
import shlex
import shutil
import signal
import subprocess
import time

import pytest

from tests.conftest import REPO, SMALL, TWIN, run_twin
from twin.harness import gate
from twin.sim.campaign import plan
from twin.sim.scenario import load


def one_line(text: str) -> str:
    return " ".join(text.split())


def parts(out):
    return sorted(p.name for p in (out / ".parts").rglob("*.h5") if not p.name.startswith("."))


@pytest.mark.parametrize("workers", ["2", "1"])
def test_ctrl_c_stops_simulate_and_the_rerun_resumes(tmp_path, workers):
    out = tmp_path / "camp"
    args = ["simulate", "quick", "-o", str(out), *SMALL, "--workers", workers]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    # A shell's background job (CI started with `&`) inherits SIGINT ignored; Ctrl-C is what we test.
    p = subprocess.Popen([*TWIN, *args], cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # noqa: PLW1509
    t0 = time.monotonic()
    while not (out / ".parts").is_dir() or not parts(out):
        assert p.poll() is None, p.communicate()
        assert time.monotonic() - t0 < 300, "no part written in 300 s"
        time.sleep(0.02)
    p.send_signal(signal.SIGINT)
    t_sig = time.monotonic()
    _, err = p.communicate(timeout=60)
    stopped_s = time.monotonic() - t_sig
    msg = one_line(err)
    print(f"--workers {workers}: exit {p.returncode} {stopped_s:.2f} s after SIGINT; {msg[-300:]}")
    assert p.returncode == 130
    assert stopped_s < 2.0
    assert "Traceback" not in err
    kept = parts(out)
    total = len(plan(load("quick", [v for k, v in zip(SMALL, SMALL[1:], strict=False) if k == "--set"])))
    resume = "twin " + shlex.join(args)
    assert (f"error: interrupted: {len(kept)} of {total} units finished and kept in {out / '.parts'}, the "
            f"other {total - len(kept)} cancelled; resume with: {resume}") in msg
    time.sleep(1.0)
    assert parts(out) == kept  # no worker left running on the cancelled units
    assert 1 <= len(kept) < total
    r = run_twin(*args[:-2], "--workers", "1")
    assert re.search(rf"\b{total - len(kept)} units simulated \([^)]*\), {len(kept)} reused,", one_line(r.stderr))
    assert (out / "measurements.h5").is_file()


def test_workers_below_one_exit_2(tmp_path):
    for verb in (["simulate", "quick", "-o", str(tmp_path / "x")], ["demo", "-o", str(tmp_path / "x")]):
        for w in ("0", "-1"):
            r = run_twin(*verb, "--workers", w, check=False)
            assert r.returncode == 2 and "Traceback" not in r.stderr
            assert "--workers" in r.stderr and "greater than or equal to 1" in one_line(r.stderr)
    assert not (tmp_path / "x").exists()


def test_output_below_a_regular_file_exits_2(tmp_path, small_campaign):
    f = tmp_path / "afile"
    f.write_text("not a directory")
    below = f / "sub" / "out"
    r = run_twin("simulate", "quick", "-o", below, check=False)
    assert r.returncode == 2
    assert one_line(r.stderr) == (f"error: {below}: cannot write the campaign directory there: {f} is a "
                                  "file, not a directory")
    r = run_twin("backlash", small_campaign, "-o", below, check=False)
    assert r.returncode == 2
    assert one_line(r.stderr) == (f"error: {below}: cannot write the output directory there: {f} is a "
                                  "file, not a directory")
    r = run_twin("detect", small_campaign, "--reference", small_campaign, "-o", f, check=False)
    assert r.returncode == 2
    assert one_line(r.stderr) == (f"error: {f}: cannot write the output directory there: {f} is a "
                                  "file, not a directory")
    r = run_twin("report", small_campaign, "-o", below, check=False)
    assert r.returncode == 2 and "is a file, not a directory" in r.stderr


def test_detect_without_measurements_says_exactly_that(tmp_path, small_campaign):
    empty = tmp_path / "empty"
    empty.mkdir()
    r = run_twin("detect", empty, "--reference", small_campaign, check=False)
    assert r.returncode == 2
    assert one_line(r.stderr) == (f"error: {empty}: no measurements.h5; expected the recording in the "
                                  "dataset format (docs/dataset-format.md)")
    assert not (empty / "phase1").exists()  # nothing computed, nothing claimed
    r = run_twin("detect", small_campaign, "--reference", empty, "-o", tmp_path / "p1", check=False)
    assert r.returncode == 2
    assert one_line(r.stderr) == (f"error: {empty}: no measurements.h5; expected the reference data set "
                                  "in the dataset format (docs/dataset-format.md)")
    # A reference without truth.h5 (its labels): the error names it and claims no partial results.
    ref = tmp_path / "ref"
    ref.mkdir()
    shutil.copy(small_campaign / "measurements.h5", ref)
    r = run_twin("detect", small_campaign, "--reference", ref, "-o", tmp_path / "p1", check=False)
    assert r.returncode == 2
    assert one_line(r.stderr) == (f"error: {ref / 'truth.h5'}: no such file; expected the reference data "
                                  "set's truth.h5 (its condition labels)")


def test_ctrl_c_stops_a_gate_building_its_cache_saying_how_to_resume(tmp_path):
    """Ctrl-C while `twin gate` builds its cache: exit 130, no traceback, what it finished kept in
    the build's folder and the command to resume (without --rebuild, which would start over);
    the resuming itself: tests/test_gate.py."""
    args = ["gate", "--cache", str(tmp_path), "--rebuild"]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    p = subprocess.Popen([*TWIN, *args], cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # noqa: PLW1509
    t0 = time.monotonic()
    while not list(tmp_path.glob("*.building/campaigns/steps/.parts/*")):
        assert p.poll() is None, p.communicate()
        assert time.monotonic() - t0 < 300, "the build started no campaign in 300 s"
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 130, out + err
    assert "Traceback" not in err
    assert ("stopped; a build of the cache goes on from where it stopped when you run: "
            f"twin gate --cache {tmp_path}") in one_line(err)
    folder = gate.cache_dir(tmp_path, gate.SUITES["standard"])
    assert (folder.with_name(f"{folder.name}.building") / "campaigns" / "steps" / ".parts").is_dir()
    assert not folder.exists()
