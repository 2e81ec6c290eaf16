"""``twin backlash`` (issue 4, check 6 and the JSON schema).

Bad runs are skipped by default, each with a warning on stderr and an entry in
``backlash.json["skipped_runs"]`` naming session, run and reason (channel); ``--strict`` instead
exits with code 2 and one message naming session, run and channel. Never a traceback.
"""

from __future__ import annotations

import json
import math
import os
import shutil

import h5py
import numpy as np
import pytest
from conftest import REPO, run_twin, truncate_dataset
from test_phase2_backlash import SLOW, steps_campaign

DOFS = ("E_XX", "E_YX", "E_ZX", "E_AX", "E_BX", "E_CX")


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """backlash-steps reduced to two sessions (0 and 20 µm) of two runs at 20 mm/s (shared with
    check 3 in test_phase2_backlash.py)."""
    return steps_campaign(tmp_path_factory, *SLOW)


@pytest.fixture(scope="module")
def small_result(small):
    out = small / "out"
    r = run_twin("backlash", small, "-o", out)
    return r, out, json.loads((out / "backlash.json").read_text())


def test_json_schema_table_and_figures(small_result):
    r, out, doc = small_result
    print("\n" + r.stdout)
    assert set(doc) >= {"sessions", "prognosis"}
    assert [s["session"] for s in doc["sessions"]] == ["s0000", "s0001"]
    for s in doc["sessions"]:
        assert set(s) >= {"hours", "delta_backlash_um_shift", "delta_backlash_um_pitch",
                          "observed_pitch_mm", "gamma"}
        assert set(s["gamma"]) == set(DOFS)
        assert isinstance(s["hours"], float) and isinstance(s["delta_backlash_um_shift"], float)
        assert s["delta_backlash_um_pitch"] is None or isinstance(s["delta_backlash_um_pitch"], float)
        assert all(g is None or -1.0 <= g <= 1.0 + 1e-9 for g in s["gamma"].values())
    last = doc["sessions"][-1]
    print(f"two sessions, 2 runs at 20 mm/s: Δbacklash {last['delta_backlash_um_shift']:.3f} µm "
          "(injected 20; not the gate, which is check 2 at 10 runs)")
    assert last["delta_backlash_um_shift"] == pytest.approx(20.0, abs=4.0)
    assert doc["sessions"][0]["delta_backlash_um_shift"] == pytest.approx(0.0, abs=1e-9)
    p = doc["prognosis"]
    assert set(p) >= {"crossing_hours", "remaining_hours", "band_hours", "limit_um"}
    assert doc["skipped_runs"] == []
    for col in ("hours", "shifts", "pitch", "smoothed", "dial"):
        assert col in r.stdout
    pngs = sorted(q.name for q in out.glob("*.png"))
    assert len(pngs) == 7 and all((out / q).stat().st_size > 10_000 for q in pngs), pngs


def _copy(src, dst):
    dst.mkdir()
    shutil.copy(src / "measurements.h5", dst / "measurements.h5")
    return dst / "measurements.h5"


def _missing(f):
    del f["phase2/s0001/r0001/imu_acc"]
    return "s0001", "r0001", "imu_acc"


def _cut_short(f):
    for key in ("imu_acc", "imu_gyro", "position_cmd"):
        truncate_dataset(f["phase2/s0001/r0001"], key, 0.4)
    return "s0001", "r0001", ""


def _nan(f):
    ds = f["phase2/s0001/r0000/imu_gyro"]
    data = ds[...]
    data[:, 1] = np.nan
    ds[...] = data
    return "s0001", "r0000", "imu_gyro"


@pytest.mark.parametrize("damage", [_missing, _cut_short, _nan], ids=["missing", "cut-short", "nan"])
def test_check6_bad_runs(small, tmp_path, damage):
    d = tmp_path / "bad"
    path = _copy(small, d)
    with h5py.File(path, "r+") as f:
        session, run, channel = damage(f)
    # strict: exit 2 naming session, run (and channel)
    r = run_twin("backlash", d, "-o", d / "strict", "--strict", "--no-plots", check=False)
    print(f"\n--strict ({damage.__name__}): exit {r.returncode}: {r.stderr.strip()}")
    assert r.returncode == 2
    assert "Traceback" not in r.stderr + r.stdout
    msg = " ".join(r.stderr.split())
    assert session in msg and run in msg and channel in msg
    # default: skip with a warning recorded in the JSON, the other runs still give a number
    # (--force: past twin check's refusal of a recording with errors, to the analysis's own skip)
    r = run_twin("backlash", d, "-o", d / "skip", "--no-plots", "--force", check=False)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    warn = " ".join(r.stderr.split())
    assert "warning" in warn and session in warn and run in warn
    doc = json.loads((d / "skip" / "backlash.json").read_text())
    skipped = doc["skipped_runs"]
    print(f"skip ({damage.__name__}): {skipped}")
    assert [(s["session"], s["run"]) for s in skipped] == [(session, run)]
    assert channel in skipped[0]["reason"]
    est = doc["sessions"][-1]["delta_backlash_um_shift"]
    assert math.isfinite(est) and est == pytest.approx(20.0, abs=4.0)


def test_cache_gives_the_computed_result_and_misses_a_changed_recording(small, tmp_path):
    """`twin backlash --cache DIR`: the second run takes every session's error motions from the
    cache and writes the backlash.json (skipped run and its warning included) of the first, which
    computed them; the skip and --strict policies and a changed recording are kept apart."""
    from analysis.dataset import DatasetError, open_measurements
    from analysis.phase2.backlash import campaign_backlash
    from analysis.phase2.error_motion_cache import ErrorMotionCache

    d = tmp_path / "rec"
    path = _copy(small, d)
    with h5py.File(path, "r+") as f:
        session, run, _ = _nan(f)
    env = {k: v for k, v in os.environ.items() if k != "TWIN_BACKLASH_CACHE"} | {"PYTHONPATH": str(REPO)}
    cache = tmp_path / "cache"
    for out, hits in (("first", 0), ("second", 2)):  # the first computes every session
        r = run_twin("backlash", d, "-o", d / out, "--no-plots", "--force", "--cache", cache, env=env)
        text = " ".join((r.stdout + r.stderr).split())
        assert f"error motions: {hits} of 2 sessions from the cache {cache}" in text
        assert f"warning: skipped session {session} run {run}" in text
    assert (json.loads((d / "second" / "backlash.json").read_text())
            == json.loads((d / "first" / "backlash.json").read_text()))
    kw = {"cache": ErrorMotionCache(cache), "position_reference": "command"}  # the options as the CLI gives them
    with open_measurements(path) as m:
        assert campaign_backlash(m, **kw).from_cache == 2
        with pytest.raises(DatasetError, match=f"{session}.*{run}"):  # not the skip policy's entry
            campaign_backlash(m, on_bad_run="raise", **kw)
    with h5py.File(path, "r+") as f:
        f["phase2/s0000/r0000/imu_acc"][0, 0] += 1e-3
    with open_measurements(path) as m:
        assert campaign_backlash(m, **kw).from_cache == 0


def test_missing_campaign_exits_2(tmp_path):
    r = run_twin("backlash", tmp_path / "nowhere", check=False)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "measurements.h5" in r.stderr


def test_imu_position_reference_is_recorded_and_needs_the_routine(small, tmp_path):
    """``--position-reference imu`` analyses the runs without position_cmd (strokes from the
    accelerometer, the routine from the runs' metadata) and says so in backlash.json and
    error_motions.h5; a run without its routine metadata is refused naming the missing keys;
    an unknown reference exits 2 naming it."""
    out = tmp_path / "imu"
    run_twin("backlash", small, "-o", out, "--position-reference", "imu", "--no-plots")
    doc = json.loads((out / "backlash.json").read_text())
    assert doc["parameters"]["position_reference"] == "imu"
    assert doc["position_reference"].startswith("IMU-based position")
    with h5py.File(out / "error_motions.h5") as f:
        assert f.attrs["position_reference"] == "imu"
    broken = tmp_path / "no-routine"
    broken.mkdir()
    shutil.copy(small / "measurements.h5", broken / "measurements.h5")
    with h5py.File(broken / "measurements.h5", "r+") as f:
        del f["phase2/s0001/r0000"].attrs["accel_mm_s2"]
        axis = json.loads(f.attrs["axis"])
        del axis["phase2_routine"]["accel_mm_s2"]  # the axis contract's routine is the fallback
        f.attrs["axis"] = json.dumps(axis)
    r = run_twin("backlash", broken, "--position-reference", "imu", "--strict", "--no-plots", check=False)
    msg = " ".join(r.stderr.split())
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "session s0001, run r0000, channel imu_acc: the run's routine metadata lacks accel_mm_s2" in msg
    r = run_twin("backlash", small, "--position-reference", "gps", check=False)
    msg = " ".join(r.stderr.split())
    assert r.returncode == 2 and "--position-reference 'gps': expected 'auto', 'command' or 'imu'" in msg


def test_a_stand_alone_imu_recording_is_analysed_on_the_imu_axis(small, tmp_path):
    """A recording without ``position_cmd`` (format_version 2: a stand-alone IMU, as the paper
    records it) validates, and ``twin backlash`` analyses it on the IMU axis by default (written
    in backlash.json) with the same estimates as ``--position-reference imu`` on the full
    recording; asking for the command axis skips every run naming the absent channel, and with
    ``--strict`` exits 2 with that message. A format_version 1 file must still have it."""
    from analysis.dataset import DatasetError, open_measurements

    imu_only = tmp_path / "imu-only"
    imu_only.mkdir()
    shutil.copy(small / "measurements.h5", imu_only / "measurements.h5")
    with h5py.File(imu_only / "measurements.h5", "r+") as f:
        for s in f["phase2"]:
            for r in f["phase2"][s]:
                del f["phase2"][s][r]["position_cmd"]
    with open_measurements(imu_only / "measurements.h5") as m:
        m.validate()
        assert m.phase2("s0000", "r0000").position_cmd is None
        assert m.phase2_channels("s0000", "r0000") == ["imu_acc", "imu_gyro"]
    run_twin("backlash", imu_only, "-o", tmp_path / "auto", "--no-plots")
    run_twin("backlash", small, "-o", tmp_path / "imu", "--position-reference", "imu", "--no-plots")
    auto = json.loads((tmp_path / "auto" / "backlash.json").read_text())
    imu = json.loads((tmp_path / "imu" / "backlash.json").read_text())
    assert auto["parameters"]["position_reference"] == "imu"
    assert [s["delta_backlash_um_shift"] for s in auto["sessions"]] == \
        [s["delta_backlash_um_shift"] for s in imu["sessions"]]
    # Eq. 5 on the IMU axis, 2 runs at 20 mm/s: the same 4 µm as the command axis on this campaign
    assert auto["sessions"][-1]["delta_backlash_um_shift"] == pytest.approx(20.0, abs=4.0)
    r = run_twin("backlash", imu_only, "--position-reference", "command", "--strict", "--no-plots", check=False)
    msg = " ".join(r.stderr.split())
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert ("session s0000, run r0000, channel position_cmd: absent (a recording of a stand-alone IMU); "
            "expected the controller's position for the command position reference") in msg
    with h5py.File(imu_only / "measurements.h5", "r+") as f:
        f.attrs["format_version"] = 1
    with open_measurements(imu_only / "measurements.h5") as m, pytest.raises(DatasetError) as e:
        m.phase2("s0000", "r0000")
    assert "/phase2/s0000/r0000/position_cmd is missing" in str(e.value)


def test_truth_holds_the_rest_to_rest_travels(small):
    """truth.h5 holds, per session and move, the true rest-to-rest travels (what Eq. 9 assumes
    to be L − b): the screw follows the command within 0.1 µm (the servo holds it at rest), the
    carriage travels the same forward and in reverse without backlash (within 0.1 µm), and 20 µm
    of backlash changes its forward travel by 5–25 µm (measured: the carriage coasts across the
    gap at the paper's 19.6 m/s², so D is not L − b; docs/error-motions.md)."""
    from analysis.dataset import open_truth

    with open_truth(small / "truth.h5") as t:
        st = {s: t.strokes(s) for s in t.sessions()}
        b = {s: t.session(s)[2]["backlash_um"] for s in t.sessions()}
    s0, s1 = sorted(st, key=b.get)
    for d in st.values():
        assert np.allclose(d["speed_m_s"], [0.02, -0.02], rtol=1e-9)
        assert np.allclose(d["screw_m"], d["command_m"], atol=1e-7)
        assert np.allclose(np.abs(d["command_m"]), 0.45, atol=1e-9)
    assert abs(st[s0]["carriage_m"][0] + st[s0]["carriage_m"][1]) < 1e-7
    change_um = (st[s1]["carriage_m"][0] - st[s0]["carriage_m"][0]) * 1e6
    print(f"\n[strokes] forward travel change with {b[s1]:g} µm of backlash: {change_um:+.2f} µm")
    assert 5.0 < change_um < 25.0


@pytest.mark.parametrize("edit, message", [
    (lambda a: a.pop("lead_mm"), "/@axis.lead_mm is missing; the Phase II backlash estimate (Eq. 9: travel L "
                                 "and lead p) needs it"),
    (lambda a: a.update(lead_mm="x"), "/@axis.lead_mm is 'x'; expected input should be a valid number"),
    (lambda a: a.update(lead_m=0.005), "key 'lead_m' is not part of the axis contract: write 'lead_mm'"),
])
def test_axis_contract_refusals_exit_2_naming_the_key(small, tmp_path, edit, message):
    """The axis contract (issue 14): a key the analysis needs and the file lacks, a wrongly typed
    one, or one spelt with another unit exits 2 naming it; no silent fallback on the twin's lead."""
    broken = tmp_path / "axis"
    broken.mkdir()
    shutil.copy(small / "measurements.h5", broken / "measurements.h5")
    with h5py.File(broken / "measurements.h5", "r+") as f:
        axis = json.loads(f.attrs["axis"])
        edit(axis)
        f.attrs["axis"] = json.dumps(axis)
    r = run_twin("backlash", broken, "--no-plots", check=False)
    assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr
    assert message in " ".join(r.stderr.split())
