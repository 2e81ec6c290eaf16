"""Issue 31, deliverable 3: the analyses refuse a recording that ``twin check`` finds errors in
(exit 2, the errors listed) unless ``--force``, and carry check's warnings into their JSON and
console output.

The issue's case: one run recorded in m/s² but labelled g (its acceleration 9.81 times too
large, gravity 96 m/s²). ``twin backlash``, ``detect`` and ``diagnose`` refuse it naming the run
and the value; with ``--force`` backlash analyses it and records the forced error. A warning
only (a dropout) lets the analysis run and is written into backlash.json and printed.
"""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest

from analysis.ingest.check import RecordingRefused, require_clean_recording
from tests.conftest import REPO, run_twin

G = 9.80665


def one_line(text: str) -> str:
    return " ".join(text.split())


@pytest.fixture
def mislabelled(small_campaign, tmp_path):
    """The small campaign with run s0000/r0000's acceleration multiplied by g (m/s² taken as g)."""
    d = tmp_path / "camp"
    d.mkdir()
    shutil.copy(small_campaign / "measurements.h5", d)
    with h5py.File(d / "measurements.h5", "a") as f:
        key = "phase2/s0000/r0000/imu_acc"
        arr, attrs = f[key][()] * G, dict(f[key].attrs)
        del f[key]
        f.create_dataset(key, data=arr, fletcher32=True).attrs.update(attrs)
        g = float(np.linalg.norm(arr.mean(axis=0)))
    return d, g


def test_backlash_refuses_a_recording_with_check_errors_unless_forced(mislabelled):
    d, g = mislabelled
    h5 = d / "measurements.h5"
    with pytest.raises(RecordingRefused) as e:
        require_clean_recording(d, verb="twin backlash")
    want = (f"{h5}: twin check finds 1 error(s), so twin backlash refuses the recording (--force analyses it "
            f"anyway):\n  /phase2/s0000/r0000/imu_acc: mean acceleration {g:.3g} m/s^2; expected about 9.81 "
            "(gravity)")
    assert str(e.value) == want
    r = run_twin("backlash", d, "--no-plots", check=False)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert one_line(r.stderr) == one_line(f"error: {want}")
    assert not (d / "backlash" / "backlash.json").exists()
    r = run_twin("backlash", d, "--no-plots", "--force", check=False)
    assert r.returncode == 0, r.stderr
    assert (f"error (forced): twin check: /phase2/s0000/r0000/imu_acc: mean acceleration {g:.3g} m/s^2"
            in one_line(r.stderr))
    doc = json.loads((d / "backlash" / "backlash.json").read_text())
    assert doc["check"]["forced"] is True
    assert [(f["level"], f["where"]) for f in doc["check"]["errors"]] == [("error", "/phase2/s0000/r0000/imu_acc")]


def test_detect_and_diagnose_refuse_it_too(mislabelled):
    d, g = mislabelled
    for args in (["detect", d, "--reference", d, "-o", d / "p1"],
                 ["diagnose", d, "--scenario", REPO / "scenarios/quick.toml", "-o", d / "gap"]):
        r = run_twin(*args, check=False)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
        assert (f"so twin {args[0]} refuses the recording (--force analyses it anyway): "
                f"/phase2/s0000/r0000/imu_acc: mean acceleration {g:.3g} m/s^2" in one_line(r.stderr))


def test_warnings_are_carried_into_the_json_and_the_console(small_campaign, tmp_path):
    d = tmp_path / "camp"
    d.mkdir()
    shutil.copy(small_campaign / "measurements.h5", d)
    with h5py.File(d / "measurements.h5", "a") as f:  # a dropout: 50 samples held
        key = "phase2/s0001/r0001/imu_gyro"
        arr, attrs = f[key][()], dict(f[key].attrs)
        arr[1000:1050] = arr[1000]
        del f[key]
        f.create_dataset(key, data=arr, fletcher32=True).attrs.update(attrs)
    findings = require_clean_recording(d)
    assert [(x.level, x.where) for x in findings] == [("warning", f"/{key}[{a}]") for a in "xyz"]
    r = run_twin("backlash", d, "--no-plots", check=False)
    assert r.returncode == 0, r.stderr
    assert f"warning: twin check: /{key}[x]: dropout: 50 samples in a row hold" in one_line(r.stderr)
    doc = json.loads((d / "backlash" / "backlash.json").read_text())
    assert doc["check"]["forced"] is False and doc["check"]["errors"] == []
    assert [w["where"] for w in doc["check"]["warnings"]] == [f"/{key}[{a}]" for a in "xyz"]


def test_the_check_is_cached_until_the_recording_changes(small_campaign, tmp_path, monkeypatch):
    """The gate reads a recording once: a second analysis reuses .twin-check.json while
    measurements.h5 is unchanged, and checks again after it changed."""
    import analysis.ingest.check as chk

    d = tmp_path / "camp"
    d.mkdir()
    shutil.copy(small_campaign / "measurements.h5", d)
    assert require_clean_recording(d) == []
    assert (d / chk.CACHE_NAME).is_file()
    calls = []
    real = chk.check_recording
    monkeypatch.setattr(chk, "check_recording", lambda p: calls.append(p) or real(p))
    assert require_clean_recording(d) == [] and calls == []
    with h5py.File(d / "measurements.h5", "a") as f:  # m/s² labelled g
        key = "phase2/s0000/r0000/imu_acc"
        arr, attrs = f[key][()] * G, dict(f[key].attrs)
        del f[key]
        f.create_dataset(key, data=arr, fletcher32=True).attrs.update(attrs)
    with pytest.raises(RecordingRefused):
        require_clean_recording(d)
    assert len(calls) == 1
