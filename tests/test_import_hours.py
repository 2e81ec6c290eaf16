"""Issue 31, deliverables 1 and 2: the operating hours from where laboratories keep them, and
what ``twin import`` / ``twin check`` say about hours, sessions and files that look wrong.

Each source of hours is given known hours and must bring them back exactly (per-session table with
other column names, a semicolon and decimal commas; a TDMS file property; a MAT variable; an MDF
header field; the files' start times and modification times with an offset). Hours typed in the
wrong order, two sessions at the same hours, a run cut at a line end and a file cut mid-line are
each named, with the file, line or session.
"""

from __future__ import annotations

import datetime as dt
import json
import os

import numpy as np
import pytest
from conftest import run_twin

from analysis.dataset import open_measurements
from analysis.ingest import ImportSpecError, run_import
from analysis.ingest.check import check_recording

FS = 200.0
N = 300
AXIS = """spec_version = 1
output = "out"
[axis]
lead_mm = 16.0
travel_mm = 300.0
"""
CHANNELS = """[phase2.channels]
imu_acc = { channels = ["ax", "ay", "az"], unit = "g" }
imu_gyro = { channels = ["gx", "gy", "gz"], unit = "deg/s" }
position_cmd = { channel = "pos", unit = "mm" }
"""
NAMES = ("ax", "ay", "az", "gx", "gy", "gz", "pos")


def _run(seed: int, n: int = N) -> dict[str, np.ndarray]:
    """One run in the lab's units (g with gravity on z, deg/s, mm)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    out = {"t": t, "pos": 100 * (1 - np.cos(np.pi * t / t[-1]))}
    for j, ax in enumerate("xyz"):
        out[f"a{ax}"] = rng.normal(0, 1e-3, n) + (1.0 if j == 2 else 0.0)
        out[f"g{ax}"] = rng.normal(0, 0.05, n)
    return out


def _csv(path, d, delimiter=",", decimal="."):
    rows = np.column_stack([d["t"], *(d[k] for k in NAMES)])
    lines = [delimiter.join(["time", *NAMES])]
    for row in rows:
        cells = [f"{v:.17g}" for v in row]
        lines.append(delimiter.join(c.replace(".", decimal) for c in cells))
    path.write_text("\n".join(lines) + "\n")


def _write_runs(root, sessions: dict[str, int], kind: str = "csv", runs: int = 3, **kw) -> list:
    """Files ``runs/S<session>_run<r>.<ext>`` for each session; returns their paths."""
    d = root / "runs"
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for s, seed in sessions.items():
        for r in range(1, runs + 1):
            data = _run(seed * 10 + r)
            stem = d / f"S{s}_run{r}"
            if kind == "csv":
                p = stem.with_suffix(".csv")
                _csv(p, data, kw.get("delimiter", ","), kw.get("decimal", "."))
            elif kind == "tdms":
                from nptdms import ChannelObject, RootObject, TdmsWriter

                p = stem.with_suffix(".tdms")
                start = kw["start"][s] + dt.timedelta(minutes=5 * r)
                with TdmsWriter(p) as w:
                    w.write_segment([RootObject(properties={"Operating hours": kw["hours"][s]}) if "hours" in kw
                                     else RootObject(properties={}),
                                     *(ChannelObject("IMU", k, data[k], properties={
                                         "wf_increment": 1 / FS,
                                         "wf_start_time": np.datetime64(start.replace(tzinfo=None), "us")})
                                       for k in NAMES)])
            elif kind == "mat":
                from scipy.io import savemat

                p = stem.with_suffix(".mat")
                savemat(p, {"daq": {k: data[k] for k in NAMES}, "meta": {"hours": kw["hours"][s]}})
            elif kind == "mdf":
                from asammdf import MDF, Signal

                p = stem.with_suffix(".mf4")
                mdf = MDF(version="4.10")
                mdf.append([Signal(data[k], data["t"], name=k) for k in NAMES])
                mdf.header.comment = ("<HDcomment><TX>lab</TX><common_properties><e name=\"Hour meter\">"
                                      f"{kw['hours'][s]}</e></common_properties></HDcomment>")
                mdf.save(p, overwrite=True)
                mdf.close()
            paths.append(p)
    return paths


def _hours_of_sessions(out) -> list[tuple[str, float]]:
    with open_measurements(out / "measurements.h5") as m:
        return [(s, m.session_hours(s)) for s in m.phase2_sessions()]


def _names(out) -> dict[str, str]:
    doc = json.loads((out / "import.json").read_text())
    return {k: v["name"] for k, v in doc["sessions"].items()}


# --- deliverable 1: where the hours come from ---------------------------------------------------
def test_per_session_table_with_its_own_columns_delimiter_and_decimal_comma(tmp_path):
    _write_runs(tmp_path, {"01": 1, "02": 2, "03": 3})
    (tmp_path / "sessions.csv").write_text("Session;Operating hours;Operator\n1;100,5;ab\n02;200;cd\n3;350,25;ef\n")
    spec = tmp_path / "import.toml"
    spec.write_text(AXIS + """[phase2]
files = "runs/*.csv"
name_pattern = 'S(?P<session>\\d+)_run(?P<run>\\d+)'
time_channel = "time"
[phase2.hours_table]
file = "sessions.csv"
key = "session"
key_column = "Session"
hours_column = "Operating hours"
decimal = ","
""" + CHANNELS)
    s = run_import(spec)
    assert (s.sessions, s.runs, s.warnings) == (3, 9, [])
    assert _hours_of_sessions(tmp_path / "out") == [("s0000", 100.5), ("s0001", 200.0), ("s0002", 350.25)]
    assert _names(tmp_path / "out") == {"s0000": "01", "s0001": "02", "s0002": "03"}
    row = next(r for r in s.mapping if r["file"].endswith("S03_run2.csv"))
    assert (row["session"], row["run"], row["hours"]) == ("s0002", "r0001", 350.25)
    assert row["hours_from"].endswith("sessions.csv, session '3'")
    # a session the table does not list is named, with what the table has
    (tmp_path / "sessions.csv").write_text("Session;Operating hours\n1;100,5\n2;200\n")
    with pytest.raises(ImportSpecError) as e:
        run_import(spec)
    assert str(e.value) == (f"{tmp_path / 'runs' / 'S03_run1.csv'}: no line for session '3' in the hours table "
                            f"{tmp_path / 'sessions.csv'} (column 'Session'); the table has '1', '2'")
    # a misnamed column is named, with the columns the table has
    spec.write_text(spec.read_text().replace('hours_column = "Operating hours"', 'hours_column = "Hours"'))
    with pytest.raises(ImportSpecError) as e:
        run_import(spec)
    assert str(e.value) == (f"{tmp_path / 'sessions.csv'}: column 'Hours' (phase2.hours_table.hours_column) is "
                            "missing; the table has 'Session', 'Operating hours'")


def test_a_table_key_that_is_not_a_group_of_the_name_is_refused(tmp_path):
    spec = tmp_path / "import.toml"
    spec.write_text(AXIS + """[phase2]
files = "runs/*.csv"
name_pattern = 'S(?P<session>\\d+)_run(?P<run>\\d+)'
hours_table = { file = "sessions.csv", key = "campaign" }
""" + CHANNELS)
    with pytest.raises(ImportSpecError) as e:
        run_import(spec)
    assert str(e.value).endswith("phase2.hours_table.key is 'campaign'; expected 'file' or a named group of "
                                 "phase2.name_pattern (run, session)")


@pytest.mark.parametrize("kind, prop", [("tdms", "Operating hours"), ("mat", "meta.hours"), ("mdf", "Hour meter")])
def test_hours_from_a_property_the_file_states(tmp_path, kind, prop):
    hours = {"1": 120.0, "2": 480.5}
    _write_runs(tmp_path, {"1": 1, "2": 2}, kind, runs=2, hours=hours,
                start={"1": dt.datetime(2026, 1, 1, tzinfo=dt.UTC), "2": dt.datetime(2026, 1, 2, tzinfo=dt.UTC)})
    names = {k: f"daq.{k}" for k in NAMES} if kind == "mat" else {k: k for k in NAMES}
    ch = CHANNELS
    for k, v in names.items():
        ch = ch.replace(f'"{k}"', f'"{v}"')
    ext = {"tdms": "tdms", "mat": "mat", "mdf": "mf4"}[kind]
    spec = tmp_path / "import.toml"
    spec.write_text(AXIS + f"""[phase2]
files = "runs/*.{ext}"
name_pattern = 'S(?P<session>\\d+)_run(?P<run>\\d+)'
hours_property = "{prop}"
{'fs_hz = 200.0' if kind == 'mat' else ''}
""" + ch)
    s = run_import(spec)
    assert _hours_of_sessions(tmp_path / "out") == [("s0000", 120.0), ("s0001", 480.5)]
    assert s.warnings == []
    assert prop in s.mapping[0]["hours_from"]
    spec.write_text(spec.read_text().replace(f'hours_property = "{prop}"', 'hours_property = "Odometer"'))
    with pytest.raises(ImportSpecError) as e:
        run_import(spec)
    msg = str(e.value)
    assert msg.startswith(str(tmp_path / "runs" / f"S1_run1.{ext}")) and "'Odometer'" in msg
    assert {"tdms": "the file has 'Operating hours'", "mat": "not found among the variables; the file has "
            "'daq', 'meta'", "mdf": "the MDF header has 'Hour meter'"}[kind] in msg


def test_hours_from_the_files_start_times_with_an_offset(tmp_path):
    """TDMS wf_start_time: a session's runs 5 min apart take the earliest; the hour meter read
    1000 h at the origin and the axis runs a third of the time."""
    start = {"1": dt.datetime(2026, 3, 1, 8, 0, tzinfo=dt.UTC), "2": dt.datetime(2026, 3, 4, 8, 0, tzinfo=dt.UTC)}
    _write_runs(tmp_path, {"1": 1, "2": 2}, "tdms", runs=2, start=start)
    spec = tmp_path / "import.toml"
    spec.write_text(AXIS + """[phase2]
files = "runs/*.tdms"
name_pattern = 'S(?P<session>\\d+)_run(?P<run>\\d+)'
hours_clock = { origin = "2026-03-01T00:00:00Z", hours_at_origin = 1000.0, duty = 0.3333333333333333 }
""" + CHANNELS)
    s = run_import(spec)
    # first run of each session at 08:05 (5 min after the session start): 1000 + (8 + 1/12) / 3
    want = [1000 + (8 + 5 / 60) / 3, 1000 + (80 + 5 / 60) / 3]
    got = _hours_of_sessions(tmp_path / "out")
    np.testing.assert_allclose([h for _, h in got], want, rtol=0, atol=1e-9)
    assert "wf_start_time" not in s.mapping[0]["hours_from"] and "start time 2026-03-01T08:05:00" in \
        s.mapping[0]["hours_from"]
    # runs of a session further apart than max_session_span_hours are refused, naming both
    spec.write_text(spec.read_text().replace('position_cmd', 'position_cmd', 1).replace(
        "[phase2]\n", "[phase2]\nmax_session_span_hours = 0.01\n"))
    with pytest.raises(ImportSpecError) as e:
        run_import(spec)
    assert "runs of session '1' at" in str(e.value) and \
        "expected the runs of a session within 0.01 h (phase2.max_session_span_hours)" in str(e.value)


def test_hours_from_the_files_modification_times(tmp_path):
    paths = _write_runs(tmp_path, {"1": 1, "2": 2}, runs=1)
    t0 = dt.datetime(2026, 5, 1, tzinfo=dt.UTC).timestamp()
    for p, h in zip(paths, (10.0, 34.0), strict=True):
        os.utime(p, (t0 + h * 3600, t0 + h * 3600))
    spec = tmp_path / "import.toml"
    spec.write_text(AXIS + """[phase2]
files = "runs/*.csv"
name_pattern = 'S(?P<session>\\d+)_run(?P<run>\\d+)'
time_channel = "time"
hours_clock = { source = "mtime", origin = "2026-05-01T00:00:00+00:00", hours_at_origin = 500.0 }
""" + CHANNELS)
    run_import(spec)
    assert _hours_of_sessions(tmp_path / "out") == [("s0000", 510.0), ("s0001", 534.0)]


# --- deliverable 2: the mapping, and what check says ---------------------------------------------
def _table_spec(tmp_path, table: str):
    (tmp_path / "sessions.csv").write_text(table)
    spec = tmp_path / "import.toml"
    spec.write_text(AXIS + """[phase2]
files = "runs/*.csv"
name_pattern = 'S(?P<session>\\d+)_run(?P<run>\\d+)'
time_channel = "time"
hours_table = { file = "sessions.csv", key = "session" }
""" + CHANNELS)
    return spec


def test_hours_in_the_wrong_order_are_named_by_import_and_check(tmp_path):
    """The issue's case: session 03 given 150 h (between 01 at 100 h and 02 at 200 h) becomes
    s0001; import prints the mapping and warns, check warns naming both sessions."""
    _write_runs(tmp_path, {"01": 1, "02": 2, "03": 3})
    spec = _table_spec(tmp_path, "session,hours\n1,100\n2,200\n3,150\n")
    r = run_twin("import", spec)
    err = " ".join(r.stderr.split())
    assert "S03_run1.csv │ phase2 │ s0001/r0000 │ 03 │ 150 │" in err
    want = ("session '03' (150 h) has fewer hours than session '02' (200 h) named before it: the sessions' hours "
            "order differs from their names' order (hours typed in the wrong order?)")
    assert f"warning: {want}" in err
    assert want in json.loads((tmp_path / "out" / "import.json").read_text())["warnings"][0]
    rep = check_recording(tmp_path / "out")
    assert [(f.level, f.where) for f in rep.findings] == [("warning", "/phase2/s0001")]
    assert rep.findings[0].what.startswith("session '03' (150 h) has fewer hours than session '02' (200 h) named "
                                           "before it, so the sessions' hours order differs from their names' order")
    r = run_twin("check", tmp_path / "out")
    assert r.returncode == 0 and "0 errors, 1 warnings" in r.stderr + r.stdout


def test_two_sessions_at_the_same_hours_are_a_warning(tmp_path):
    _write_runs(tmp_path, {"1": 1, "2": 2, "3": 3})
    spec = _table_spec(tmp_path, "session,hours\n1,100\n2,200\n3,200\n")
    run_import(spec)
    rep = check_recording(tmp_path / "out")
    assert [(f.level, f.where, f.what) for f in rep.findings] == [
        ("warning", "/phase2/s0002", "the same operating hours (200 h) as /phase2/s0001; expected distinct hours "
                                     "per session")]


def test_a_run_cut_at_a_line_end_is_named_by_import_and_check(tmp_path):
    paths = _write_runs(tmp_path, {"1": 1, "2": 2})
    cut = paths[4]  # S2_run2.csv: half its lines
    lines = cut.read_text().splitlines()
    cut.write_text("\n".join(lines[: 1 + N // 2]) + "\n")
    s = run_import(_table_spec(tmp_path, "session,hours\n1,100\n2,200\n"))
    assert s.warnings == [f"{cut}: {ch} lasts 0.75 s where the other files of phase2 last 1.5 s (median); a "
                          "file cut short or a run stopped early?" for ch in ("imu_acc", "imu_gyro", "position_cmd")]
    rep = check_recording(tmp_path / "out")
    assert [(f.level, f.where, f.what) for f in rep.findings] == [
        ("warning", "/phase2/s0001/r0001", "run duration of 0.75 s where its siblings last 1.5 s (median); expected "
                                           "within 10% (a file cut short, a run stopped early?)")]


def test_a_file_cut_mid_line_is_refused_as_cut_naming_the_line(tmp_path):
    paths = _write_runs(tmp_path, {"1": 1, "2": 2})
    cut = paths[1]
    text = cut.read_text()
    cut.write_text(text[: text.index("\n", len(text) // 2) + 25])  # 25 characters into a line
    line = text[: text.index("\n", len(text) // 2)].count("\n") + 2
    with pytest.raises(ImportSpecError) as e:
        run_import(_table_spec(tmp_path, "session,hours\n1,100\n2,200\n"))
    assert str(e.value) == (f"{cut}: line {line} is cut: it has 2 of the header's 8 columns and no line end, the "
                            "last line of the file (a copy or recording cut short?); expected 8 columns")
    # a complete last line without its line end imports, with a warning naming the line
    cut.write_text(text.rstrip("\n"))
    s = run_import(_table_spec(tmp_path, "session,hours\n1,100\n2,200\n"))
    assert s.warnings == [f"{cut}: line {N + 1} (the last) has no line end: the file may be cut mid-number; its "
                          "values were kept"]
