"""``twin import SPEC --watch`` (issue 32, item 4): a laboratory's export folder imported while it
grows, as the live source of ``twin monitor``.

The reduced demo campaign (25 Phase I samples of 2 captures, onset 172 h; Phase II sessions of
3 runs at 100, 150 and 250 h; the IMU and the commanded position at 1000 Hz, one clock as a
lab's CSV has it) is written out as a lab hands it over (TDMS captures, vendor CSV runs:
``twin.harness.lab_export``) and imported in batch; ``twin detect --save-model`` fits the model on
the batch import. The same files are then copied one by one, in hours order and without atomic
renames, into a watched folder while ``twin import --watch`` and ``twin monitor`` run beside
them: one file written half-way and completed within the settle time, one that stalls half-way
longer than the settle time (refused as cut, then imported when whole), an unreadable file and a
run at a wrong rate; the watcher is stopped by SIGTERM half-way and started again.
"""

import json
import os
import shutil
import signal
import subprocess
import time

import h5py
import numpy as np
import pytest

from tests.conftest import REFERENCE_SMALL, REPO, TWIN, run_twin, simulate_shared

DEMO_LAB = ["--set", "campaign.total_hours=250", "--set", "phase2.session_hours=[100.0, 150.0, 250.0]",
            "--set", "phase2.runs_per_session=3", "--set", "sensors.imu_acc_fs_hz=1000.0",
            "--set", "sensors.imu_gyro_fs_hz=1000.0", "--set", "sensors.position_cmd_fs_hz=1000.0"]
ENV = dict(os.environ, PYTHONPATH=str(REPO), TWIN_WORKERS="1")
WATCH = ["--poll", "0.1", "--settle", "0.5"]


def _popen(*args):
    return subprocess.Popen([*TWIN, *map(str, args)], cwd=REPO, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _lines(path):
    return [json.loads(line) for line in path.read_text().splitlines()]


def _hours_order(lab):
    """The lab's files in the order they are recorded: hours, a capture before a run, name."""
    def key(p):
        if p.parent.name == "phase1":  # capture_00232.50h_023_047.tdms
            return (float(p.name.split("_")[1].rstrip("h")), 0, p.name)
        return (float(p.name.split("_")[1].rstrip("h")), 1, p.name)  # S03_250h_run01.csv
    return sorted([*lab.glob("phase1/*.tdms"), *lab.glob("phase2/*.csv")], key=key)


def _h5(path):
    """{object path: array or attributes} of an HDF5 file."""
    out = {}

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            out[name] = obj[...]
        out[name + "/@"] = {k: str(v) for k, v in obj.attrs.items()}

    with h5py.File(path, "r") as f:
        f.visititems(visit)
        out["/@"] = {k: str(v) for k, v in f.attrs.items()}
    return out


def _assert_same(a, b, where):
    assert sorted(a) == sorted(b), where
    for k, v in a.items():
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(v, b[k], err_msg=f"{where}: {k}")
        else:
            assert v == b[k], f"{where}: {k}"


def _wait_for(cond, what, timeout=120.0):
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    from twin.harness.lab_export import export

    root = tmp_path_factory.mktemp("watch")
    ref, batch = root / "ref", root / "batch"
    simulate_shared(tmp_path_factory, REPO / "scenarios/paper-reference.toml", ref, *REFERENCE_SMALL)
    run_twin("simulate", REPO / "scenarios/demo.toml", "-o", batch, *DEMO_LAB)
    spec = export(batch, root / "lab")
    run_twin("import", spec, "-o", root / "imported")
    model = root / "phase1.model"
    run_twin("detect", root / "imported", "--reference", ref, "-o", root / "detect", "--save-model", model)
    run_twin("backlash", root / "imported", "-o", root / "backlash", "--no-plots")
    return {"root": root, "lab": root / "lab", "imported": root / "imported", "model": model}


@pytest.fixture(scope="module")
def watched(lab):
    root, src = lab["root"], lab["lab"]
    w = root / "export"
    (w / "phase1").mkdir(parents=True)
    (w / "phase2").mkdir()
    text = (src / "import.toml").read_text().replace(f'output = "{lab["root"] / "batch"}"', 'output = "campaign"')
    assert 'output = "campaign"' in text
    (w / "import.toml").write_text(text + "\n[watch]\ncaptures_per_sample = 2\nruns_per_session = 3\n")
    files = _hours_order(src)
    assert len(files) == 59
    log = w / "campaign/import-watch.jsonl"
    refused = lambda name: log.is_file() and any(  # noqa: E731
        e["event"] == "file refused" and e["file"].endswith(name) for e in _lines(log))
    t0 = time.monotonic()
    mon = _popen("monitor", w / "campaign", "--model", lab["model"], "-o", root / "state", "--exit-at-end",
                 "--poll", "0.05")
    watcher = _popen("import", w / "import.toml", "--watch", *WATCH)
    stderr = []

    def copy(i, f):
        dst = w / f.relative_to(src)
        data = f.read_bytes()
        if i == 5:  # written half-way, completed within the settle time
            dst.write_bytes(data[: len(data) // 2])
            time.sleep(0.25)
            with open(dst, "ab") as fh:
                fh.write(data[len(data) // 2:])
        elif i == 9:  # a copy that stalls half-way for longer than the settle time
            dst.write_bytes(data[: len(data) // 2])
            _wait_for(lambda: refused(dst.name), "the stalled file's refusal")
            with open(dst, "ab") as fh:
                fh.write(data[len(data) // 2:])
        else:
            dst.write_bytes(data)  # as a DAQ writes: in place, no rename
        time.sleep(0.05)

    for i, f in enumerate(files):
        if i == 12:  # an unreadable file (hours 52 h in its name)
            (w / "phase1/capture_00052.00h_005_999.tdms").write_bytes(bytes(range(256)) * 40)
        if i == 20:  # the watcher stopped (SIGTERM) after some units; files keep arriving
            _wait_for(lambda: len(list((w / "campaign/live").glob("[0-9]*.json"))) >= 12, "12 units")
            watcher.send_signal(signal.SIGTERM)
            out, err = watcher.communicate(timeout=60)
            stderr.append(err)
            assert watcher.returncode == 0 and "stopped; resume with" in err and "Traceback" not in err, err
        if i == 30:
            watcher = _popen("import", w / "import.toml", "--watch", *WATCH, "--until-idle", "6")
        copy(i, f)
        if f.name == "S02_150h_run03.csv":  # a fourth run of session 2 at half the rate
            lines = f.read_text(encoding="utf-8").splitlines()
            head, body = lines[:5], lines[5:]
            slow = [";".join([f"{2 * float(r.split(';')[0].replace(',', '.')):.10g}".replace(".", ","),
                              *r.split(";")[1:]]) for r in body]
            (w / "phase2/S02_150h_run04.csv").write_text("\n".join(head + slow) + "\n", encoding="utf-8")
    out, err = watcher.communicate(timeout=300)
    stderr.append(err)
    assert watcher.returncode == 0, err
    mon_out, mon_err = mon.communicate(timeout=300)
    assert mon.returncode == 0, mon_out + mon_err
    return {**lab, "export": w, "campaign": w / "campaign", "log": log, "files": files,
            "watch_stderr": stderr, "monitor_stderr": mon_err, "seconds": time.monotonic() - t0}


def test_watched_import_equals_the_batch_import(watched):
    camp, batch = watched["campaign"], watched["imported"]
    _assert_same(_h5(camp / "measurements.h5"), _h5(batch / "measurements.h5"), "measurements.h5")
    # every live unit holds the batch import's capture or session, same arrays
    mans = sorted((json.loads(p.read_text()) for p in (camp / "live").glob("[0-9]*.json")),
                  key=lambda m: m["seq"])
    assert [m["seq"] for m in mans] == list(range(53))
    assert [m["hours"] for m in mans] == sorted(m["hours"] for m in mans)
    full = _h5(batch / "measurements.h5")
    for m in mans:
        unit = _h5(camp / "live" / m["file"])
        group = f"{m['kind']}/{m['name']}"
        assert sorted(k for k in unit if k.startswith(group)) == sorted(k for k in full if k.startswith(group))
        for k in unit:
            if k.startswith(group):
                if isinstance(unit[k], np.ndarray):
                    np.testing.assert_array_equal(unit[k], full[k], err_msg=k)
                else:
                    assert unit[k] == full[k], k
    batch_map = {os.path.basename(r["file"]): r for r in json.loads((batch / "import.json").read_text())["mapping"]}
    watch_map = {os.path.basename(r["file"]): r for r in json.loads((camp / "import.json").read_text())["mapping"]}
    assert {k: (r.get("capture"), r.get("session"), r.get("run"), r["hours"]) for k, r in watch_map.items()} == \
        {k: (r.get("capture"), r.get("session"), r.get("run"), r["hours"]) for k, r in batch_map.items()}
    assert (camp / "live/end.json").is_file()
    print(f"watched import of 59 files (+2 bad) with a restart: {watched['seconds']:.1f} s")


def test_a_half_written_file_is_never_imported_half_way(watched):
    lab = watched["lab"]
    mans = [json.loads(p.read_text()) for p in (watched["campaign"] / "live").glob("[0-9]*.json")]
    sources = {s["file"]: s for m in mans for s in m["sources"]}
    for i in (5, 9):
        rel = watched["files"][i].relative_to(lab).as_posix()
        assert sources[rel]["bytes"] == watched["files"][i].stat().st_size
    # the copy that stalled past the settle time was read, refused as cut, and imported when whole
    stalled = watched["files"][9].relative_to(lab).as_posix()
    refusals = [e for e in _lines(watched["log"]) if e["event"] == "file refused" and e["file"] == stalled]
    assert refusals and "the TDMS file is cut short" in refusals[0]["reason"]
    assert refusals[0]["bytes"] == watched["files"][9].stat().st_size // 2
    published = [e for e in _lines(watched["log"]) if e["event"] == "unit published" and stalled in e["files"]]
    assert len(published) == 1


def test_bad_files_are_refused_with_their_reason_and_the_watch_goes_on(watched):
    refused = {e["file"]: e["reason"] for e in _lines(watched["log"]) if e["event"] == "file refused"}
    export = watched["export"]
    assert refused["phase1/capture_00052.00h_005_999.tdms"].startswith(
        f"{export / 'phase1/capture_00052.00h_005_999.tdms'}: not a readable TDMS file")
    assert refused["phase2/S02_150h_run04.csv"] == (
        f"{export / 'phase2/S02_150h_run04.csv'}: channel imu_acc sampled at 500 Hz; expected 1000 Hz (the axis "
        "description's sensors.imu_accelerometer.fs_hz, within 0.0001 relative)")
    assert any("refused: " in e and "S02_150h_run04.csv" in e for e in watched["watch_stderr"])
    # and later units were imported: the last session
    assert (watched["campaign"] / "live/000052-phase2-s0002.json").is_file()


def test_a_restart_neither_repeats_nor_loses_a_file(watched):
    log = _lines(watched["log"])
    starts = [e for e in log if e["event"] == "watch started"]
    assert len(starts) == 2 and starts[1]["files_imported_before"] > 0
    stops = [e["ended"] for e in log if e["event"] == "watch stopped"]
    assert stops == ["stopped", "idle"]
    published = [e for e in log if e["event"] == "unit published"]
    assert [e["seq"] for e in published] == list(range(53))
    files = [f for e in published for f in e["files"]]
    assert sorted(files) == sorted(f.relative_to(watched["lab"]).as_posix() for f in watched["files"])


def test_monitor_on_the_watched_folder_equals_batch_detection_and_backlash(watched):
    events = _lines(watched["root"] / "state/events.jsonl")
    batch = json.loads((watched["root"] / "detect/detection.json").read_text())["methods"]
    scored = [e for e in events if e["event"] == "sample scored"]
    assert len(scored) == 25
    assert [e["hours"] for e in scored] == batch["pca_t2"]["hours"]
    for name, r in batch.items():
        np.testing.assert_allclose([e["scores"][name] for e in scored], r["scores"], rtol=1e-9, atol=1e-12,
                                   err_msg=name)
        alarms = [e["hours"] for e in events if e["event"] == "alarm" and e["detector"] == name]
        assert alarms[:1] == [r["detection_hours"]], name
    doc = json.loads((watched["root"] / "backlash/backlash.json").read_text())
    phase2 = [e for e in events if e["event"] in ("Phase II baseline", "Phase II estimated")]
    assert [e["session"] for e in phase2] == ["s0000", "s0001", "s0002"]
    for e, s in zip(phase2, doc["sessions"], strict=True):
        assert e["delta_backlash_um"] == s["delta_backlash_um"], e["session"]
    assert not [e for e in events if e["event"] == "input refused"]


def test_a_spec_that_names_one_file_is_refused_for_watching(lab, tmp_path):
    text = (lab["lab"] / "import.toml").read_text().replace('files = "phase1/*.tdms"',
                                                            'files = "phase1/capture_00002.00h_000_000.tdms"')
    (tmp_path / "import.toml").write_text(text)
    p = run_twin("import", tmp_path / "import.toml", "--watch", "--once", check=False)
    assert p.returncode == 2
    assert (f"{tmp_path / 'import.toml'}: phase1.files = 'phase1/capture_00002.00h_000_000.tdms' names one "
            "file; a watched export folder needs a pattern") in " ".join(p.stderr.split())


def test_a_sample_cut_by_a_kill_is_completed_on_restart(lab, tmp_path):
    """Killed between the two captures of a sample (the second unit not written), the watcher
    publishes the missing capture first, under its name and sequence number, and nothing twice."""
    from analysis.ingest.watch import ImportWatcher

    w = tmp_path / "export"
    (w / "phase1").mkdir(parents=True)
    for f in _hours_order(lab["lab"])[:4]:
        shutil.copy(f, w / "phase1" / f.name)
    spec = (lab["lab"] / "import.toml").read_text()
    (w / "import.toml").write_text(spec.split("[phase2]")[0].replace(f'output = "{lab["root"] / "batch"}"',
                                                                     'output = "campaign"'))
    said = []
    r = ImportWatcher(w / "import.toml", settle_s=0.0, say=said.append).run(0.01, once=True)
    assert (r.units, r.files, r.refused, r.ended) == (4, 4, 0, "once")
    live = w / "campaign/live"
    before = {p.name: p.read_bytes() for p in live.glob("0*")}
    for p in live.glob("000003-*"):  # the kill: the sample's second capture never written
        p.unlink()
    r = ImportWatcher(w / "import.toml", settle_s=0.0, say=said.append).run(0.01, once=True)
    assert r.units == 4 and {p.name: p.read_bytes() for p in live.glob("0*")} == before
    published = [e["name"] for e in _lines(w / "campaign/import-watch.jsonl") if e["event"] == "unit published"]
    assert published == ["c000000", "c000001", "c000002", "c000003", "c000003"]


def test_a_file_waits_for_its_line_in_a_growing_hours_table(lab, tmp_path):
    """Hours from a table the lab fills in as it goes: a run whose session has no line yet waits
    (neither imported nor refused) and is imported once the line is there."""
    from analysis.ingest.watch import ImportWatcher

    w = tmp_path / "export"
    (w / "phase2").mkdir(parents=True)
    runs = [f for f in _hours_order(lab["lab"]) if f.parent.name == "phase2"][:6]  # sessions 1 and 2
    for f in runs:
        shutil.copy(f, w / "phase2" / f.name)
    spec = (lab["lab"] / "import.toml").read_text()
    axis, phase2 = spec.split("[phase1]")[0], "[phase2]" + spec.split("[phase2]")[1]
    phase2 = phase2.replace("(?P<hours>[0-9.]+)", "[0-9.]+").replace(
        "[phase2.channels]", '[phase2.hours_table]\nfile = "hours.csv"\nkey = "session"\n[phase2.channels]')
    (w / "import.toml").write_text(axis.replace(f'output = "{lab["root"] / "batch"}"', 'output = "campaign"')
                                   + phase2 + "\n[watch]\nruns_per_session = 3\n")
    said = []
    r = ImportWatcher(w / "import.toml", settle_s=0.0, say=said.append).run(0.01, once=True)
    assert (r.units, r.files, r.refused) == (0, 0, 0)  # no table yet: the files wait
    assert any(s.startswith("waiting: ") and "hours.csv" in s for s in said)
    (w / "hours.csv").write_text("session,hours\n1,100.0\n")
    said = []
    r = ImportWatcher(w / "import.toml", settle_s=0.0, say=said.append).run(0.01, once=True)
    assert (r.units, r.files, r.refused) == (1, 3, 0)
    assert sum("has no line in the hours table" in s for s in said) == 3
    (w / "hours.csv").write_text("session,hours\n1,100.0\n2,150.0\n")
    r = ImportWatcher(w / "import.toml", settle_s=0.0, say=said.append).run(0.01, once=True)
    assert (r.units, r.files, r.refused) == (2, 6, 0)
    man = json.loads((w / "campaign/live/000001-phase2-s0001.json").read_text())
    assert man["hours"] == 150.0 and man["session_name"] == "02" and man["runs"] == 3


def test_nan_samples_are_refused_naming_channel_and_line_and_ctrl_c_stops_cleanly(lab, tmp_path):
    w = tmp_path / "export"
    (w / "phase2").mkdir(parents=True)
    spec = (lab["lab"] / "import.toml").read_text()
    axis, phase2 = spec.split("[phase1]")[0], "[phase2]" + spec.split("[phase2]")[1]
    (w / "import.toml").write_text(axis.replace(f'output = "{lab["root"] / "batch"}"', 'output = "campaign"')
                                   + phase2)
    run = next(f for f in _hours_order(lab["lab"]) if f.parent.name == "phase2")
    lines = run.read_text(encoding="utf-8").splitlines()
    cells = lines[10].split(";")
    cells[2] = "nan"  # Acc Y [g] on file line 11
    lines[10] = ";".join(cells)
    (w / "phase2" / run.name).write_text("\n".join(lines) + "\n", encoding="utf-8")
    proc = _popen("import", w / "import.toml", "--watch", "--poll", "0.05", "--settle", "0.1")
    log = w / "campaign/import-watch.jsonl"
    _wait_for(lambda: log.is_file() and any(e["event"] == "file refused" for e in _lines(log)), "the refusal")
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130 and "Traceback" not in err, err
    assert "stopped; resume with: twin import" in " ".join(err.split())
    refused = [e for e in _lines(log) if e["event"] == "file refused"]
    assert len(refused) == 1 and refused[0]["reason"] == (
        f"{w / 'phase2' / run.name}: channel 'Acc Y [g]', line 11: nan (1 non-finite value(s) in all); "
        "expected finite samples")
    assert [e["ended"] for e in _lines(log) if e["event"] == "watch stopped"] == ["stopped"]
