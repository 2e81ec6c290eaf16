"""``twin monitor`` on ``twin simulate --live`` (issue 32, items 2, 3 and 5).

The demo campaign, reduced (25 Phase I samples of 2 captures, onset 172 h; Phase II sessions at
100, 150 and 250 h of 3 runs), is simulated once in batch; ``twin detect --save-model`` fits the
model on it and ``twin detect`` / ``twin backlash`` give the batch results. The same campaign is
then replayed through ``--live`` (the stored parts copied, so the replay publishes at its scaled
times without simulating again) while ``twin monitor`` watches it.
"""

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from analysis.base.files import write_json
from tests.conftest import DEMO_SMALL, REFERENCE_SMALL, REPO, TWIN, run_twin, simulate_shared

ENV = dict(os.environ, PYTHONPATH=str(REPO), TWIN_WORKERS="1", COLUMNS="200")  # a console line per event


def _popen(*args):
    return subprocess.Popen([*TWIN, *map(str, args)], cwd=REPO, env=ENV, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _events(path):
    return [json.loads(line) for line in path.read_text().splitlines()]


def _comparable(events):
    """The log without the (re)start lines and the event numbers, which a restart shifts."""
    return [{k: v for k, v in e.items() if k != "n"} for e in events if e["event"] != "monitor started"]


@pytest.fixture(scope="module")
def replay(tmp_path_factory):
    root = tmp_path_factory.mktemp("monitor")
    ref, batch, live = root / "ref", root / "batch", root / "live"
    simulate_shared(tmp_path_factory, REPO / "scenarios/paper-reference.toml", ref, *REFERENCE_SMALL)
    simulate_shared(tmp_path_factory, REPO / "scenarios/demo.toml", batch, *DEMO_SMALL)
    model = root / "phase1.model"
    run_twin("detect", batch, "--reference", ref, "-o", root / "detect", "--save-model", model)
    run_twin("backlash", batch, "-o", root / "backlash", "--no-plots")
    live.mkdir()
    shutil.copytree(batch / ".parts", live / ".parts")
    # 248 h of the campaign in about 6 s: the monitor runs beside the live source.
    mon = _popen("monitor", live, "--model", model, "-o", root / "state", "--exit-at-end", "--poll", "0.05")
    t0 = time.monotonic()
    src = run_twin("simulate", REPO / "scenarios/demo.toml", "-o", live, *DEMO_SMALL, "--live",
                   "--speedup", "150000", timeout=600)
    src_seconds = time.monotonic() - t0
    out, err = mon.communicate(timeout=600)
    assert mon.returncode == 0, out + err
    return {"root": root, "model": model, "live": live, "batch": batch, "state": root / "state",
            "monitor_stderr": err, "source_stderr": src.stderr, "source_seconds": src_seconds}


def test_live_source_publishes_in_time_order_at_scaled_times(replay):
    live = replay["live"] / "live"
    manifests = [json.loads(p.read_text()) for p in sorted(live.glob("[0-9]*.json"))]
    assert [m["seq"] for m in manifests] == list(range(53))
    hours = [m["hours"] for m in manifests]
    assert hours == sorted(hours) and hours[0] == 2.0 and hours[-1] == 250.0
    assert sum(m["kind"] == "phase2" for m in manifests) == 3
    # 248 h at 150000x: 5.95 s of scaled time at least (the copied parts need no simulation).
    assert replay["source_seconds"] >= 248 * 3600 / 150000
    assert (live / "end.json").is_file()
    assert not list(live.glob("*.tmp")) and not list(live.glob(".*"))
    # The assembled campaign is the batch one, byte for byte.
    for f in ("measurements.h5", "truth.h5"):
        assert (replay["live"] / f).read_bytes() == (replay["batch"] / f).read_bytes()


def test_live_source_killed_resumes(replay, tmp_path):
    """kill -9 of `twin simulate --live` mid-campaign, then the same command: every unit published
    once and complete, the campaign assembled as in batch."""
    live = tmp_path / "live"
    live.mkdir()
    shutil.copytree(replay["batch"] / ".parts", live / ".parts")
    args = ("simulate", REPO / "scenarios/demo.toml", "-o", live, *DEMO_SMALL, "--live", "--speedup", "100000")
    proc = _popen(*args)
    while len(list((live / "live").glob("[0-9]*.json"))) < 10:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (live / "live/end.json").exists()
    run_twin(*args, timeout=600)
    from analysis.dataset.live import manifest_ok

    manifests = [json.loads(p.read_text()) for p in sorted((live / "live").glob("[0-9]*.json"))]
    assert [m["seq"] for m in manifests] == list(range(53))
    assert all(manifest_ok(live / "live", m) for m in manifests)
    assert (live / "measurements.h5").read_bytes() == (replay["batch"] / "measurements.h5").read_bytes()


def test_monitor_alarms_equal_batch_detection(replay):
    events = _events(replay["state"] / "events.jsonl")
    details = json.loads((replay["root"] / "detect/detection_details.json").read_text())
    batch = json.loads((replay["root"] / "detect/detection.json").read_text())["methods"]
    scored = [e for e in events if e["event"] == "sample scored"]
    assert len(scored) == details["n_samples"] == 25
    assert [e["hours"] for e in scored] == batch["pca_t2"]["hours"]
    assert sum(e["baseline"] for e in scored) == 15
    onset = details["onset_hours"]
    # The alarm state after each sample's batch of events (the sample scored, then its alarms).
    batches, cur = [], []
    for e in events:
        cur.append(e)
        if e.get("commit"):
            batches.append(cur)
            cur = []
    in_alarm, first = {}, {}
    for b in batches:
        for e in b:
            if e["event"] in ("alarm", "alarm cleared"):
                in_alarm[e["detector"]] = e["event"] == "alarm"
        for e in b:
            if e["event"] == "sample scored" and e["hours"] > onset:
                for name, on in in_alarm.items():
                    if on:
                        first.setdefault(name, e["hours"])
    for name, r in batch.items():
        scores = np.array([e["scores"][name] for e in scored])
        np.testing.assert_allclose(scores, r["scores"], rtol=1e-9, atol=1e-12, err_msg=name)
        assert [e["hours"] for e in scored if name in e["above"] and not e["baseline"]] == \
            [h for h, s in list(zip(r["hours"], r["scores"], strict=True))[15:] if s > r["threshold"]], name
        assert first.get(name) == r["detection_hours"], name
    print({n: (first.get(n), r["detection_hours"]) for n, r in batch.items()})
    requested = [e for e in events if e["event"] == "Phase II requested"]
    assert len(requested) == 1
    assert "Phase II requested at" in replay["monitor_stderr"]


def test_monitor_backlash_equals_twin_backlash(replay):
    events = _events(replay["state"] / "events.jsonl")
    doc = json.loads((replay["root"] / "backlash/backlash.json").read_text())
    batch = {s["session"]: s for s in doc["sessions"]}
    phase2 = [e for e in events if e["event"] in ("Phase II baseline", "Phase II estimated")]
    assert [e["session"] for e in phase2] == ["s0000", "s0001", "s0002"]
    requested = next(e["n"] for e in events if e["event"] == "Phase II requested")
    for e in phase2:
        assert (e["event"] == "Phase II estimated") == (e["n"] > requested)
        assert e["delta_backlash_um"] == batch[e["session"]]["delta_backlash_um"], e["session"]
    last = phase2[-1]
    assert last["event"] == "Phase II estimated" and last["delta_backlash_um"] > 1.0
    assert last["prognosis"] == doc["prognosis"]
    assert last["trend"]["smoothed_um"] == doc["sessions"][-1]["smoothed_um"]
    assert "Phase II session s0002 at 250 h: change of backlash" in replay["monitor_stderr"]


@pytest.mark.quoted
def test_console_says_each_alarm_and_session(replay, quote):
    """The console's event lines, one per alarm, request and session (docs/monitoring.md quotes
    them): as many as the log's events."""
    events = _events(replay["state"] / "events.jsonl")
    lines = [s for s in replay["monitor_stderr"].splitlines() if s.startswith(("alarm", "Phase II"))]
    said = [e for e in events if e["event"] in ("alarm", "alarm cleared", "Phase II requested", "Phase II estimated")]
    assert len(lines) == len(said), lines
    quote.table("console", "```\n" + "\n".join(lines) + "\n```\n")


def test_kill_9_and_restart_gives_the_same_log(replay, tmp_path):
    reference = _comparable(_events(replay["state"] / "events.jsonl"))
    state = tmp_path / "state"
    args = ("monitor", replay["live"], "--model", replay["model"], "-o", state, "--exit-at-end")
    kills = 0
    for threshold in (8, 20):  # two kills: mid-Phase I and after the alarm
        proc = _popen(*args)
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            log = state / "events.jsonl"
            if log.is_file() and log.read_bytes().count(b"\n") >= threshold:
                break
            time.sleep(0.01)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        kills += 1
        # killed mid-campaign: part of the events are written
        assert threshold <= len((state / "events.jsonl").read_bytes().split(b"\n")) - 1 < len(reference)
    # A torn line as a kill in the middle of a write would leave it.
    with open(state / "events.jsonl", "ab") as fh:
        fh.write(b'{"n": 999, "event": "sample sco')
    proc = run_twin(*args, timeout=600)
    events = _events(state / "events.jsonl")
    assert sum(e["event"] == "monitor started" for e in events) == kills + 1
    assert _comparable(events) == reference
    assert [e["n"] for e in events] == list(range(len(events)))
    assert events[-1]["commit"] is True and "source finished" in proc.stderr


def _one_unit_source(replay, tmp_path, seqs):
    """A source folder holding copies of the live units ``seqs`` (data file and manifest)."""
    src = tmp_path / "src"
    src.mkdir()
    shutil.copy(replay["live"] / "live/source.json", src / "source.json")
    for seq in seqs:
        for p in (replay["live"] / "live").glob(f"{seq:06d}-*"):
            shutil.copy(p, src / p.name)
    return src


def test_half_written_capture_is_never_read(replay, tmp_path):
    from analysis.dataset.live import sha256_of
    from twin.harness.monitor import Monitor

    src = _one_unit_source(replay, tmp_path, [])
    live = replay["live"] / "live"
    man = json.loads((live / "000000-phase1-c000000.json").read_text())
    full = (live / man["file"]).read_bytes()
    mon = Monitor(src, replay["model"], tmp_path / "state", say=lambda s: None)
    mon._resume()
    # 1. The data file half written, no manifest yet: not a unit.
    (src / man["file"]).write_bytes(full[: len(full) // 2])
    assert mon.complete_units() == [] and mon.step() == 0
    # 2. A manifest that arrived before the data file was finished: size and sha256 differ.
    write_json(src / "000000-phase1-c000000.json", man)
    assert mon.complete_units() == [] and mon.step() == 0
    # 3. Same size, other content (a file preallocated and being filled): sha256 differs.
    (src / man["file"]).write_bytes(full[: len(full) // 2] + bytes(len(full) - len(full) // 2))
    assert mon.complete_units() == [] and mon.step() == 0
    assert not (tmp_path / "state/events.jsonl").exists()
    # 4. Complete: read once.
    (src / man["file"]).write_bytes(full)
    assert sha256_of(src / man["file"]) == man["sha256"]
    assert [m["seq"] for m in mon.complete_units()] == [0]
    assert mon.step() == 1 and mon.complete_units() == []


def test_bad_capture_is_refused_with_its_reason_and_the_monitor_goes_on(replay, tmp_path):
    from analysis.dataset.live import sha256_of
    from twin.harness.monitor import Monitor

    src = _one_unit_source(replay, tmp_path, range(4))  # samples 0 and 1, two captures each
    bad = src / "000001-phase1-c000001.h5"
    with h5py.File(bad, "r+") as f:
        acc = f["phase1/c000001/acc1"]
        data = acc[...]
        data[1234, 2] = np.nan
        acc[...] = data
    man = json.loads((src / "000001-phase1-c000001.json").read_text())
    write_json(src / "000001-phase1-c000001.json", {**man, "bytes": bad.stat().st_size,
                                                     "sha256": sha256_of(bad)})
    said = []
    mon = Monitor(src, replay["model"], tmp_path / "state", say=said.append)
    mon._resume()
    assert mon.step() == 4
    events = _events(tmp_path / "state/events.jsonl")
    assert [e["event"] for e in events] == ["input refused", "sample scored", "sample scored"]
    refused = events[0]
    assert refused["unit"] == "c000001" and refused["units"] == [1] and refused["hours"] == 2.5
    assert refused["reason"] == (f"{bad}: /phase1/c000001/acc1 has 1 non-finite value (NaN or inf), "
                                 "first at index (1234, 2); expected finite samples")
    assert events[1]["captures"] == ["c000000"] and events[1]["units"] == [0]
    assert events[2]["captures"] == ["c000002", "c000003"]
    assert any("input refused at 2.5 h" in s for s in said)


def test_model_of_another_rate_is_refused_at_start(replay, tmp_path):
    from analysis.dataset.live import sha256_of

    src = _one_unit_source(replay, tmp_path, [0])
    f5 = src / "000000-phase1-c000000.h5"
    with h5py.File(f5, "r+") as f:
        f["phase1/c000000"].attrs["fs_hz"] = np.float64(5000.0)
    man = json.loads((src / "000000-phase1-c000000.json").read_text())
    write_json(src / "000000-phase1-c000000.json", {**man, "bytes": f5.stat().st_size, "sha256": sha256_of(f5)})
    proc = run_twin("monitor", src, "--model", replay["model"], "-o", tmp_path / "state", check=False,
                    timeout=120)
    assert proc.returncode == 2
    msg = " ".join(proc.stderr.split())
    assert (f"{f5}: /phase1/c000000 does not match the Phase I model fitted on {replay['batch']}: "
            "sampling rate fs_hz = 5000 Hz, the model expects 10000 Hz") in msg, msg


def test_monitor_streams_scores_limits_alarms_and_backlash_to_rerun(replay, tmp_path):
    """--rrd streams what --serve / --connect stream; read back on the hours timeline."""
    from tests.test_view import _rows, _scalars, _store

    rrd = tmp_path / "monitor.rrd"
    run_twin("monitor", replay["live"], "--model", replay["model"], "-o", tmp_path / "state",
             "--exit-at-end", "--rrd", rrd, timeout=600)
    events = _events(tmp_path / "state/events.jsonl")
    scored = [e for e in events if e["event"] == "sample scored"]
    store = _store(rrd)
    for name in ("pca_t2", "ocsvm"):
        idx, vals = _scalars(store, f"/hours/phase1/{name}/score", "hours")
        np.testing.assert_array_equal(idx, np.round(np.array([e["hours"] for e in scored]) * 3600e9))
        np.testing.assert_array_equal(vals, [e["scores"][name] for e in scored])
        _, lim = _scalars(store, f"/hours/phase1/{name}/limit", "hours")
        assert len(set(lim)) == 1 and len(lim) == len(scored)
    _, delta = _scalars(store, "/hours/backlash/delta_um", "hours")
    phase2 = [e for e in events if e["event"].startswith("Phase II ") and "session" in e]
    np.testing.assert_array_equal(delta, [e["delta_backlash_um"] for e in phase2])
    _, texts = _rows(store, "/hours/events", "hours")
    logged = [t[0] for t in texts["TextLog:text"]]
    assert sum(t.startswith("alarm: ") for t in logged) == sum(e["event"] == "alarm" for e in events)
    assert any(t.startswith("Phase II requested: ") for t in logged)


def test_second_monitor_on_the_same_state_is_refused(replay, tmp_path):
    from twin.harness.monitor import Monitor

    first = Monitor(replay["live"], replay["model"], tmp_path / "state", say=lambda s: None)
    first._lock()
    proc = run_twin("monitor", replay["live"], "--model", replay["model"], "-o", tmp_path / "state",
                    "--exit-at-end", check=False, timeout=120)
    assert proc.returncode == 2
    assert (f"{tmp_path / 'state'}: another twin monitor is writing this state directory; stop it "
            "first, or give another -o") in " ".join(proc.stderr.split())


def test_monitor_runs_without_the_simulator_and_rerun(replay, tmp_path):
    """A maintenance engineer's install (`pip install .`): MuJoCo, Rerun and Dask unimportable."""
    from tests.test_install import run_blocked

    r = run_blocked("monitor", replay["live"], "--model", replay["model"], "-o", tmp_path / "state",
                    "--exit-at-end", cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-2000:]
    assert _comparable(_events(tmp_path / "state/events.jsonl")) == \
        _comparable(_events(replay["state"] / "events.jsonl"))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(pytest.main([__file__, "-q"]))
