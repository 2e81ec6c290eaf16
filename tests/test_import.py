"""``twin import`` and ``twin check`` (issue 14, deliverables 1 and 3).

Each reader (CSV, MATLAB v5 and v7.3, TDMS, MDF) imports a small recording written in the lab's
units, and the samples come back in SI within float rounding; bad files and specs are refused
naming file, channel and line; an import resumes; ``twin check`` finds injected problems.
"""

from __future__ import annotations

import json
import os
import shutil

import h5py
import numpy as np
import pytest
from conftest import run_twin

from analysis.dataset import open_measurements
from analysis.ingest import ImportSpecError, run_import
from analysis.ingest.check import check_recording

G = 9.80665
FS = 500.0
N = 600


def _lab_run(seed: int) -> dict[str, np.ndarray]:
    """One run in the lab's units: acc in g (gravity on z), gyro in deg/s, position in mm."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / FS
    pos = 100 * (1 - np.cos(np.pi * t / t[-1]))
    out = {"t": t, "pos_mm": pos}
    for j, ax in enumerate("xyz"):
        out[f"a{ax}"] = rng.normal(0, 1e-3, N) + (1.0 if j == 2 else 0.0)
        out[f"g{ax}"] = rng.normal(0, 0.05, N)
    return out


RUNS = {("1", "120.5", "1"): 1, ("1", "120.5", "2"): 2, ("2", "250", "1"): 3}
CHANNELS = '''
[phase2.channels]
imu_acc = {{ channels = ["{ax}", "{ay}", "{az}"], unit = "g" }}
imu_gyro = {{ channels = ["{gx}", "{gy}", "{gz}"], unit = "deg/s" }}
position_cmd = {{ channel = "{pos}", unit = "mm" }}
'''
HEAD = '''spec_version = 1
output = "out"
[axis]
lead_mm = 5.0
travel_mm = 300.0
[phase2]
files = "runs/*.{ext}"
name_pattern = 'S(?P<session>\\d+)_(?P<hours>[0-9.]+)h_r(?P<run>\\d+)'
'''
NAMES = {"ax": "ax", "ay": "ay", "az": "az", "gx": "gx", "gy": "gy", "gz": "gz", "pos": "pos"}


def _write_lab(tmp_path, kind: str) -> tuple:
    runs = tmp_path / "runs"
    runs.mkdir(parents=True)
    data = {}
    for (s, h, r), seed in RUNS.items():
        d = _lab_run(seed)
        data[(s, h, r)] = d
        stem = runs / f"S{s}_{h}h_r{r}"
        cols = {"ax": d["ax"], "ay": d["ay"], "az": d["az"], "gx": d["gx"], "gy": d["gy"], "gz": d["gz"],
                "pos": d["pos_mm"]}
        if kind == "csv":
            np.savetxt(f"{stem}.csv", np.column_stack([d["t"], *cols.values()]), delimiter=",",
                       header=",".join(["time", *cols]), comments="", fmt="%.17g")
        elif kind == "mat5":
            from scipy.io import savemat
            savemat(f"{stem}.mat", {"daq": {"acc": np.column_stack([d["ax"], d["ay"], d["az"]]),
                                            "gyro": np.column_stack([d["gx"], d["gy"], d["gz"]]),
                                            "pos": d["pos_mm"]}})
        elif kind == "mat73":  # what MATLAB's save -v7.3 writes: HDF5, arrays transposed
            with h5py.File(f"{stem}.mat", "w", userblock_size=512) as f:
                g = f.create_group("daq")
                g["acc"] = np.column_stack([d["ax"], d["ay"], d["az"]]).T
                g["gyro"] = np.column_stack([d["gx"], d["gy"], d["gz"]]).T
                g["pos"] = d["pos_mm"][None, :].T.T  # 1 x n in MATLAB -> (n, 1) in HDF5
        elif kind == "tdms":
            from nptdms import ChannelObject, TdmsWriter
            with TdmsWriter(f"{stem}.tdms") as w:
                w.write_segment([ChannelObject("IMU", k, v, properties={"wf_increment": 1 / FS})
                                 for k, v in cols.items()])
        elif kind == "mdf":
            from asammdf import MDF, Signal
            mdf = MDF(version="4.10")
            mdf.append([Signal(v, d["t"], name=k) for k, v in cols.items()])
            mdf.save(f"{stem}.mf4", overwrite=True)
            mdf.close()
    return data


SPECS = {
    "csv": ("csv", 'time_channel = "time"\n', NAMES),
    "mat5": ("mat", f"fs_hz = {FS}\n", {"ax": "daq.acc[0]", "ay": "daq.acc[1]", "az": "daq.acc[2]",
                                        "gx": "daq.gyro[0]", "gy": "daq.gyro[1]", "gz": "daq.gyro[2]",
                                        "pos": "daq.pos"}),
    "tdms": ("tdms", "", NAMES),
    "mdf": ("mf4", "", NAMES),
}
SPECS["mat73"] = SPECS["mat5"]


def _spec(tmp_path, kind: str, extra: str = "") -> os.PathLike:
    ext, timing, names = SPECS[kind]
    text = HEAD.format(ext=ext) + timing + extra + CHANNELS.format(**names)
    p = tmp_path / "import.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize("kind", ["csv", "mat5", "mat73", "tdms", "mdf"])
def test_each_reader_imports_in_si(tmp_path, kind):
    data = _write_lab(tmp_path, kind)
    s = run_import(_spec(tmp_path, kind))
    assert (s.sessions, s.runs, s.converted, s.reused) == (2, 3, 3, 0)
    with open_measurements(tmp_path / "out" / "measurements.h5") as m:
        m.validate()
        assert m.phase2_sessions() == ["s0000", "s0001"]
        assert m.phase2_runs("s0000") == ["r0000", "r0001"]
        expect = {("s0000", "r0001"): ("1", "120.5", "2"), ("s0001", "r0000"): ("2", "250", "1")}
        for (sname, rname), key in expect.items():
            r, d = m.phase2(sname, rname), data[key]
            assert r.hours == float(key[1])
            assert r.imu_acc_fs_hz == pytest.approx(FS, rel=1e-9)
            np.testing.assert_allclose(r.imu_acc, np.column_stack([d["ax"], d["ay"], d["az"]]) * G, rtol=1e-12)
            np.testing.assert_allclose(r.imu_gyro, np.deg2rad(np.column_stack([d["gx"], d["gy"], d["gz"]])),
                                       rtol=1e-12)
            np.testing.assert_allclose(r.position_cmd, d["pos_mm"] * 1e-3, rtol=1e-12, atol=1e-15)
        assert m.axis()["lead_mm"] == 5.0
    src = json.loads((tmp_path / "out" / "import.json").read_text())["phase2"]
    assert src["s0001/r0000"].endswith(f"S2_250h_r1.{SPECS[kind][0]}")


def test_resume_reads_only_new_or_changed_files(tmp_path):
    _write_lab(tmp_path, "csv")
    spec = _spec(tmp_path, "csv")
    run_import(spec)
    s = run_import(spec)
    assert (s.converted, s.reused) == (0, 3)
    f = tmp_path / "runs" / "S1_120.5h_r2.csv"
    f.write_text(f.read_text())  # touched: read again
    os.utime(f, ns=(f.stat().st_atime_ns, f.stat().st_mtime_ns + 10**9))
    s = run_import(spec)
    assert (s.converted, s.reused) == (1, 2)


def _bad(tmp_path, kind, edit=None, extra=""):
    _write_lab(tmp_path, kind)
    if edit:
        edit(tmp_path)
    with pytest.raises(ImportSpecError) as e:
        run_import(_spec(tmp_path, kind, extra))
    return " ".join(str(e.value).split())


def test_errors_name_file_channel_and_line(tmp_path):
    def garble(p):  # line 6 of the file (header = line 1), column gz
        f = p / "runs" / "S1_120.5h_r2.csv"
        lines = f.read_text().splitlines()
        cells = lines[5].split(",")
        cells[6] = "1.2.3"
        lines[5] = ",".join(cells)
        f.write_text("\n".join(lines) + "\n")
    msg = _bad(tmp_path / "a", "csv", garble)
    assert msg == f"{tmp_path / 'a' / 'runs' / 'S1_120.5h_r2.csv'}: channel 'gz', line 6: '1.2.3' is not a number"

    def empty(p):
        f = p / "runs" / "S2_250h_r1.csv"
        lines = f.read_text().splitlines()
        cells = lines[10].split(",")
        cells[3] = ""
        lines[10] = ",".join(cells)
        f.write_text("\n".join(lines) + "\n")
    msg = _bad(tmp_path / "b", "csv", empty)
    assert msg.endswith("S2_250h_r1.csv: channel 'az', line 11: nan (1 non-finite value(s) in all); "
                        "expected finite samples")

    def hole(p):  # a dropout in the time column
        f = p / "runs" / "S1_120.5h_r1.csv"
        lines = f.read_text().splitlines()
        del lines[100:103]
        f.write_text("\n".join(lines) + "\n")
    msg = _bad(tmp_path / "c", "csv", hole)
    assert "S1_120.5h_r1.csv: time channel 'time', line 101: a step of 0.008 s where the rate gives 0.002 s" in msg

    d = tmp_path / "d"
    d.mkdir()
    _write_lab(d, "tdms")
    (d / "import.toml").write_text(HEAD.format(ext="tdms") + CHANNELS.format(**dict(NAMES, gz="Gyro Z")))
    with pytest.raises(ImportSpecError) as e:
        run_import(d / "import.toml")
    assert str(e.value) == (f"{d / 'runs' / 'S1_120.5h_r1.tdms'}: channel 'Gyro Z' not found; the file has "
                            "'ax', 'ay', 'az', 'gx', 'gy', 'gz', 'pos'")


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('unit = "g"', 'unit = "furlong"'),
     "phase2.channels.imu_acc.unit is 'furlong'; expected one of m/s^2, m/s2, g, mg, mV, V (acceleration)"),
    (lambda t: t.replace('unit = "g"', 'unit = "mV"'),
     "channel 'ax' (phase2.channels.imu_acc): unit 'mV' needs the accelerometer's sensitivity"),
    (lambda t: t.replace("lead_mm = 5.0", "lead_m = 0.005"),
     "key 'lead_m' is not part of the axis contract: write 'lead_mm'"),
    (lambda t: t.replace("[phase2]", "[phase2]\nfs = 3"), "phase2.fs = 3: not a key of the import spec"),
    (lambda t: t.replace("(?P<hours>[0-9.]+)h", "[0-9.]+h"),
     "phase2: the operating hours come from 0 places; expected exactly one of"),
])
def test_bad_specs_are_refused_naming_the_key(tmp_path, edit, message):
    _write_lab(tmp_path, "csv")
    p = _spec(tmp_path, "csv")
    p.write_text(edit(p.read_text()))
    with pytest.raises(ValueError) as e:
        run_import(p)
    assert message in " ".join(str(e.value).split())


def test_cli_import_and_check(tmp_path):
    _write_lab(tmp_path, "csv")
    spec = _spec(tmp_path, "csv")
    r = run_twin("import", spec)
    assert "imported 0 Phase I captures, 2 Phase II sessions (3 runs)" in " ".join(r.stderr.split())
    r = run_twin("check", tmp_path / "out", "--json")
    doc = json.loads(r.stdout)
    assert doc["errors"] == 0 and doc["summary"]["phase2"]["runs"] == 3
    assert doc["summary"]["hours"] == [120.5, 250.0]
    p = tmp_path / "import.toml"
    p.write_text(p.read_text().replace('"time"', '"Time"'))
    r = run_twin("import", p, check=False)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "channel 'Time' not found in the header (line 1)" in " ".join(r.stderr.split())


# --- twin check on injected problems ------------------------------------------------------------
@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("clean")
    _write_lab(tmp, "csv")
    run_import(_spec(tmp, "csv"))
    return tmp / "out" / "measurements.h5"


def _damaged(clean, tmp_path, edit):
    p = tmp_path / "measurements.h5"
    shutil.copy(clean, p)
    with h5py.File(p, "r+") as f:
        edit(f)
    return p


def _replace(f, key, fn):
    a = f[key][()]
    attrs = dict(f[key].attrs)
    del f[key]
    f[key] = fn(a)
    f[key].attrs.update(attrs)


@pytest.mark.parametrize("edit, level, where, what", [
    (lambda f: _replace(f, "phase2/s0000/r0000/imu_gyro", lambda a: np.column_stack([a[:, 0], a[:, 1], 0 * a[:, 2]])),
     "error", "/phase2/s0000/r0000/imu_gyro[z]", "flat line: all 600 samples are 0"),
    (lambda f: _replace(f, "phase2/s0000/r0001/imu_acc", lambda a: np.where(np.arange(len(a))[:, None] % 600 >= 200,
                                                                            a, a[200])),
     "warning", "/phase2/s0000/r0001/imu_acc[x]", "dropout: 201 samples in a row hold"),
    (lambda f: _replace(f, "phase2/s0001/r0000/imu_gyro", lambda a: np.clip(a, -0.001, 0.001)),
     "warning", "/phase2/s0001/r0000/imu_gyro[x]", "clipping: 80 samples at the maximum 0.001"),
    (lambda f: f["phase2/s0001"].attrs.modify("hours", 100.0),
     "error", "/phase2/s0001", "operating hours go back: 100 h after /phase2/s0000 at 120.5 h"),
    (lambda f: f["phase2/s0001/r0000/imu_gyro"].attrs.modify("fs_hz", 400.0),
     "warning", "/phase2/*/*/imu_gyro", "runs at different rates [400.0, 500.0] Hz"),
    (lambda f: _replace(f, "phase2/s0000/r0000/imu_acc", lambda a: a / G),
     "error", "/phase2/s0000/r0000/imu_acc", "mean acceleration 1 m/s^2; expected about 9.81 (gravity) (samples in g"),
    (lambda f: _replace(f, "phase2/s0000/r0000/imu_acc", lambda a: a[:, ::-1].copy()),
     "warning", "/phase2/s0000/r0000/imu_acc", "gravity is on the x axis"),
    (lambda f: _replace(f, "phase2/s0000/r0000/imu_acc",
                        lambda a: np.where(np.arange(len(a))[:, None] == 7, np.nan, a)),
     "error", "/phase2/s0000/r0000", "imu_acc has 3 non-finite values (NaN or inf), first at index (7, 0)"),
])
def test_check_finds_injected_problems(clean, tmp_path, edit, level, where, what):
    assert check_recording(clean).findings == []
    rep = check_recording(_damaged(clean, tmp_path, edit))
    hits = [f for f in rep.findings if f.where == where and what in f.what]
    assert [f.level for f in hits] == [level], rep.findings
    r = run_twin("check", tmp_path, check=False)
    assert r.returncode == (1 if level == "error" else 0) and "Traceback" not in r.stderr
    assert where.rsplit("/", 1)[-1] in r.stdout  # the table keeps the axis: imu_gyro[z], not imu_gyro


def test_a_dropout_is_located_at_its_first_held_sample():
    from analysis.ingest.check import _longest_run

    assert _longest_run(np.array([1.0, 2, 2, 2, 3])) == (3, 1)
    assert _longest_run(np.array([5.0, 5, 5, 1, 2])) == (3, 0)
    assert _longest_run(np.array([1.0, 2, 3, 3])) == (2, 2)
    assert _longest_run(np.array([1.0, 2, 3])) == (1, 0)


def test_check_finds_a_sensor_that_saturates_only_at_its_peaks():
    """A long run clipped at its peaks only (37 of 50 000 samples at the rail: below the 0.1 %
    rule) piles up at the rail and is flagged; the same signal not clipped, as floats or quantised
    (2.5 to 10 steps per noise sigma), thins out towards its extremes and is not."""
    from analysis.ingest.check import _clipped

    t = np.arange(50_000) / 1000.0
    x = 20.0 * np.sin(2 * np.pi * 0.5 * t) + np.random.default_rng(0).normal(0.0, 0.5, t.size)
    clipped = np.clip(x, -21.0, 21.0)
    k = int(np.count_nonzero(clipped == 21.0))
    assert 8 <= k < 50
    assert _clipped(clipped, "maximum") == (
        f"clipping: {k} samples at the maximum 21 against 1 at the next value inside "
        f"({x[x < 21.0].max():g}): a pile-up at a converter's rail (the sensor saturates at its peaks)")
    assert _clipped(clipped, "minimum").startswith("clipping: 48 samples at the minimum -21 against 1 ")
    for q in (None, 0.05, 0.1, 0.2):
        xq = x if q is None else np.round(x / q) * q
        assert _clipped(xq, "maximum") is None and _clipped(xq, "minimum") is None, q


def test_scenario_init_refusals(tmp_path, clean):
    r = run_twin("scenario", "init", tmp_path / "nowhere", "-o", tmp_path / "s.toml", check=False)
    assert r.returncode == 2 and "Traceback" not in r.stderr and "measurements.h5" in r.stderr
    r = run_twin("scenario", "init", clean.parent, "-o", tmp_path, check=False)
    assert r.returncode == 2 and "is a directory; expected a scenario file path" in " ".join(r.stderr.split())


def test_a_stand_alone_imu_imports_without_position_and_carries_the_routine(tmp_path):
    """No position channel (format_version 2): the runs are written without ``position_cmd`` and
    carry the axis description's routine as run attributes, which the IMU-axis analyses read."""
    _write_lab(tmp_path, "csv")
    p = _spec(tmp_path, "csv")
    text = p.read_text().replace('position_cmd = { channel = "pos", unit = "mm" }\n', "")
    text = text.replace("travel_mm = 300.0\n", "travel_mm = 300.0\n[axis.phase2_routine]\nspeeds_mm_s = [100.0]\n"
                        "accel_mm_s2 = 5000.0\nstart_mm = 0.0\nend_mm = 200.0\ndwell_s = 1.0\n")
    p.write_text(text)
    run_import(p)
    with open_measurements(tmp_path / "out" / "measurements.h5") as m:
        m.validate()
        r = m.phase2("s0000", "r0000")
        assert r.position_cmd is None
        assert r.speeds_mm_s == (100.0,)
        assert r.routine == {"accel_mm_s2": 5000.0, "start_mm": 0.0, "end_mm": 200.0, "dwell_s": 1.0}
