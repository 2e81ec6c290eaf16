"""`twin view`: the Rerun recording read back with `rerun.chunk.RrdReader` (issue 5, check 5)."""

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import h5py
import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader
from scipy.spatial.transform import Rotation

from analysis.dataset import open_measurements, open_truth
from tests.conftest import REPO, TWIN, run_twin
from twin.harness.view import EXAGGERATION, POSE_RATE_HZ, carriage_poses, hours_to_ns
from twin.sim.scenario import Scenario, from_dict, to_axis


@pytest.fixture(scope="module")
def campaign(demo_run):
    """A simulated and analysed campaign (``twin demo`` at small scale, tests/conftest.py):
    measurements.h5, truth.h5, phase1/, backlash/. The tests take their expectations from the
    directory's own files."""
    return demo_run[0]


@pytest.fixture(scope="module")
def recording(campaign, tmp_path_factory):
    """`twin view DIR --save FILE`: (FILE, completed process)."""
    out = tmp_path_factory.mktemp("view_rrd") / "view.rrd"
    return out, run_twin("view", campaign, "--save", out)


def _store(path):
    return RrdReader(path).store()


def _rows(store, entity: str, timeline: str):
    """(index (n,) int64 ns, {component: list of per-row values}) of an entity's temporal rows,
    sorted by the index."""
    chunks = store.stream().filter(content=entity, has_timeline=timeline).to_chunks()
    assert chunks, f"{entity} has no data on {timeline}"
    idx, cols = [], {}
    for ch in chunks:
        b = ch.to_record_batch()
        idx.append(b.column(timeline).cast(pa.int64()).to_numpy())
        for name in b.schema.names:
            if ":" in name:
                cols.setdefault(name, []).extend(b.column(name).to_pylist())
    idx = np.concatenate(idx)
    order = np.argsort(idx, kind="stable")
    return idx[order], {k: [v[i] for i in order] for k, v in cols.items()}


def _scalars(store, entity: str, timeline: str):
    idx, cols = _rows(store, entity, timeline)
    vals = cols["Scalars:scalars"]
    assert all(len(v) == 1 for v in vals)
    return idx, np.array([v[0] for v in vals])


def _property(store, name: str) -> dict:
    chunks = store.stream().filter(content=f"/__properties/{name}").to_chunks()
    assert len(chunks) == 1, f"property {name}: {len(chunks)} chunks"
    b = chunks[0].to_record_batch()
    return {k: b.column(k).to_pylist()[0] for k in b.schema.names if not k.startswith("rerun.")}


def _entities(store) -> set[str]:
    return {line.split()[0] for line in store.summary().splitlines()}


def test_recording_reads_back(campaign, recording):
    d, (rrd, proc) = campaign, recording
    assert f"rerun {rrd}" in proc.stderr.replace("\n", " ")
    store = _store(rrd)
    blueprints = RrdReader(rrd).blueprints()
    assert blueprints, "no blueprint in the recording"
    layout = RrdReader(rrd).store(store=blueprints[0]).summary()
    assert "EyeControls3D" in layout and "TimePanelBlueprint:timeline" in layout
    # The viewer's own loader accepts every chunk (archetypes, blueprint).
    rerun_cli = shutil.which("rerun", path=str(Path(sys.executable).parent)) or shutil.which("rerun")
    verify = subprocess.run([rerun_cli, "rrd", "verify", rrd], capture_output=True, text=True, timeout=120,
                            check=False)
    assert verify.returncode == 0 and "verified without error" in verify.stdout + verify.stderr, verify.stderr
    with open_measurements(d / "measurements.h5") as m, open_truth(d / "truth.h5") as t:
        session = m.phase2_sessions()[-1]
        run = m.phase2_runs(session)[0]
        data = m.phase2(session, run)
        caps = m.phase1_captures()
        n_samples = len({m.phase1(c).sample for c in caps})
        last = m.phase1(caps[-1])
        scenario = t.scenario()
        xt, et, attrs = t.session(session)
        onset = t.onset_hours
        injected = {s: t.session(s)[2]["backlash_um"] for s in t.sessions()}

    # The carriage over the last session's first run: one pose per 1/POSE_RATE_HZ s.
    step = round(data.position_cmd_fs_hz / POSE_RATE_HZ)
    idx = np.arange(0, len(data.position_cmd), step)
    t_ns, cols = _rows(store, "/world/carriage", "sim_time")
    assert len(t_ns) == len(idx) > 1000
    np.testing.assert_allclose(t_ns * 1e-9, idx / data.position_cmd_fs_hz, atol=1e-9)
    trans = np.array(cols["Transform3D:translation"])[:, 0, :]
    quat = np.array(cols["Transform3D:quaternion"])[:, 0, :]
    x_rail = data.position_cmd[idx] + attrs["origin_offset_m"]
    e = np.array([np.interp(x_rail, xt, et[i]) for i in range(6)])
    k = EXAGGERATION
    rot = Rotation.from_quat(quat)  # x, y, z, w
    np.testing.assert_allclose(rot.as_euler("xyz"), k * e[3:].T, atol=2e-6)
    # The IMU point of the carriage frame is at the rail position plus k times the translations.
    c = to_axis(from_dict(scenario)).carriage
    imu = trans + rot.apply([0.0, 0.0, c.imu_height - c.com_height])
    np.testing.assert_allclose(imu[:, 0] - k * e[0], x_rail, atol=2e-6)
    np.testing.assert_allclose(imu[:, 1], k * e[1], atol=2e-6)
    np.testing.assert_allclose(imu[:, 2] - k * e[2], c.imu_height, atol=2e-6)
    # ... over the whole stroke (the demo's Phase II routine: 0 to 450 mm), with visible motions.
    assert x_rail.min() == pytest.approx(attrs["origin_offset_m"], abs=1e-9)
    assert x_rail.max() == pytest.approx(0.450 + attrs["origin_offset_m"], abs=1e-9)
    assert np.ptp(trans[:, 0]) > 0.440 and np.ptp(trans[:, 2]) > 1e-3
    view = _property(store, "view")
    assert view["exaggeration"] == [k] and view["error_motion_source"] == ["truth.h5"]
    assert view["session"] == [session] and view["run"] == [run]
    assert view["n_poses"] == [len(idx)]

    # The T² trajectory (and the five other methods): one point per Phase I sample, the values
    # and hours of detection.json, the limit, the injected onset.
    det = json.loads((d / "phase1" / "detection.json").read_text())["methods"]
    assert set(det) >= {"pca_t2"}
    for name, r in det.items():
        h_ns, scores = _scalars(store, f"/hours/phase1/{name}/score", "hours")
        assert len(scores) == n_samples == len(r["scores"]) >= 20
        assert scores.tolist() == r["scores"]
        np.testing.assert_array_equal(h_ns, hours_to_ns(r["hours"]))
        _, limit = _scalars(store, f"/hours/phase1/{name}/limit", "hours")
        assert limit.tolist() == [r["threshold"]] * n_samples
        o_ns, _ = _scalars(store, f"/hours/phase1/{name}/onset", "hours")
        np.testing.assert_array_equal(o_ns, hours_to_ns([onset, onset]))
    t2 = np.array(det["pca_t2"]["scores"])
    assert t2[-1] > det["pca_t2"]["threshold"]  # the preload loss is visible in what we read back

    # Backlash estimates, the dial indicator and the injected change over operating hours.
    bl = json.loads((d / "backlash" / "backlash.json").read_text())
    sessions = bl["sessions"]
    assert len(sessions) == 3
    for key in ("delta_backlash_um_shift", "smoothed_um", "dial_delta_um"):
        want = [(s["hours"], s[key]) for s in sessions if s.get(key) is not None]
        assert len(want) == 3, key
        h_ns, vals = _scalars(store, f"/hours/backlash/{key}", "hours")
        assert vals.tolist() == [v for _, v in want]
        np.testing.assert_array_equal(h_ns, hours_to_ns([h for h, _ in want]))
    _, inj = _scalars(store, "/hours/backlash/injected_delta_um", "hours")
    ref = injected[sessions[0]["session"]]
    np.testing.assert_allclose(inj, [injected[s["session"]] - ref for s in sessions], rtol=0, atol=1e-12)
    assert inj[-1] > 1.0  # backlash grew by the last session

    # The scenario as properties.
    props = _property(store, "scenario")
    assert props["name"] == [scenario["name"]] == ["demo"]
    assert props["seed"] == [scenario["seed"]] == [5]
    assert props["phase2.session_hours"] == scenario["phase2"]["session_hours"]
    assert json.loads(props["json"][0]) == scenario

    # The sensor streams, at full rate here (shorter than the decimation threshold).
    _, torque = _scalars(store, f"/phase1/{caps[-1]}/torque", "sim_time")
    np.testing.assert_array_equal(torque, last.torque)
    s_ns, acc_x = _scalars(store, f"/phase2/{session}/{run}/imu_acc/x", "sim_time")
    np.testing.assert_array_equal(acc_x, data.imu_acc[:, 0])
    np.testing.assert_allclose(s_ns[-1] * 1e-9, (len(acc_x) - 1) / data.imu_acc_fs_hz, atol=1e-9)
    ents = _entities(store)
    for ch in ("speed", "acc1/x", "acc2/z"):
        assert f"/phase1/{caps[0]}/{ch}" in ents and f"/phase1/{caps[-1]}/{ch}" in ents
    for ch in ("imu_gyro/z", "position_cmd", "error_motion/E_BX"):
        assert f"/phase2/{session}/{run}/{ch}" in ents


def test_no_truth_still_records(campaign, tmp_path):
    """A real machine's directory: measurements.h5 and backlash/ but no truth.h5 nor phase1/."""
    d = campaign
    real = tmp_path / "real"
    real.mkdir()
    (real / "measurements.h5").symlink_to(d / "measurements.h5")
    (real / "backlash").symlink_to(d / "backlash")
    proc = run_twin("view", real, "--session", "s0001", "--run", "r0001", "--capture", "c000003",
                    "--exaggeration", "500")
    out = real / "view.rrd"  # the default place
    err = proc.stderr.replace("\n", " ")
    assert f"open it with: rerun {out}" in err
    assert "phase1/detection.json not found" in err and "twin detect" in err
    assert "truth.h5" in err
    store = _store(out)
    ents = _entities(store)
    assert not any(e.startswith(("/hours/phase1", "/hours/truth")) for e in ents)
    assert "/hours/backlash/injected_delta_um" not in ents and "/__properties/scenario" not in ents
    assert _property(store, "measurements")["axis.travel_mm"] == [450.0]
    view = _property(store, "view")
    assert view["error_motion_source"] == ["backlash/error_motions.h5"]
    assert view["exaggeration"] == [500.0] and view["session"] == ["s0001"] and view["run"] == ["r0001"]
    assert view["truth"] == [False]
    t_ns, cols = _rows(store, "/world/carriage", "sim_time")
    trans = np.array(cols["Transform3D:translation"])[:, 0, :]
    with open_measurements(real / "measurements.h5") as m:
        x = m.phase2("s0001", "r0001").position_cmd
    xs = x[::10]
    assert len(t_ns) == len(xs)
    # The estimated error motions of the session: the forward profile while moving forward, the
    # reverse one in reverse, at the commanded position (no origin offset is known).
    with h5py.File(d / "backlash" / "error_motions.h5", "r") as f:
        xe, fwd, rev = (f["s0001"][k][...] for k in ("x_m", "forward", "reverse"))
    c = to_axis(Scenario()).carriage
    rot = Rotation.from_quat(np.array(cols["Transform3D:quaternion"])[:, 0, :])
    imu = trans + rot.apply([0.0, 0.0, c.imu_height - c.com_height])
    dx = imu[:, 0] - xs
    k_fwd, k_rev = 500.0 * np.interp(xs, xe, fwd[0]), 500.0 * np.interp(xs, xe, rev[0])
    is_fwd, is_rev = np.abs(dx - k_fwd) < 2e-6, np.abs(dx - k_rev) < 2e-6
    assert np.all(is_fwd | is_rev)
    # Poses well inside a move (1 mm per pose at 100 mm/s) both before and after.
    back, ahead = np.diff(xs, prepend=xs[0]), np.diff(xs, append=xs[-1])
    forward, reverse = (back > 1e-4) & (ahead > 1e-4), (back < -1e-4) & (ahead < -1e-4)
    assert forward.sum() > 100 and reverse.sum() > 100
    assert np.all(is_fwd[forward]) and np.all(is_rev[reverse])
    assert np.max(np.abs(k_fwd - k_rev)) > 1e-5  # the two profiles differ, so this tells them apart
    assert {f"/phase1/c000003/{c}" for c in ("torque", "speed")} <= ents
    bl = json.loads((d / "backlash" / "backlash.json").read_text())
    _, vals = _scalars(store, "/hours/backlash/delta_backlash_um_shift", "hours")
    assert vals.tolist() == [s["delta_backlash_um_shift"] for s in bl["sessions"]]


@pytest.mark.parametrize("args, message", [
    ((), "measurements.h5: no such file"),
    (("--session", "s0042"), "--session s0042"),
    (("--capture", "c999999"), "--capture c999999"),
    (("--exaggeration", "-1"), "--exaggeration"),
    (("--serve", "--save", "x.rrd"), "--save and --serve"),
])
def test_bad_input_exits_2(campaign, tmp_path, args, message):
    d = campaign
    target = tmp_path / "empty" if not args else d
    target.mkdir(exist_ok=True)
    out = tmp_path / "bad.rrd"
    extra = () if "--save" in args else ("--save", out)
    proc = run_twin("view", target, *args, *extra, check=False)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    err = proc.stderr.replace("\n", " ")
    assert message in err
    if not args:
        assert str(target / "measurements.h5") in err
    assert not out.exists() and not (tmp_path / "bad.rrd.partial").exists()


def test_carriage_poses_place_the_imu():
    """The pose puts the IMU point at x + k·E_XX, k·E_YX, height + k·E_ZX, turned by k·angles."""
    rng = np.random.default_rng(1)
    x = np.linspace(0.0, 0.45, 7)
    e = rng.normal(0.0, 1e-5, (6, 7))
    trans, quat = carriage_poses(x, e, 2000.0, com_height=0.08, imu_offset=0.12)
    rot = Rotation.from_quat(quat)
    np.testing.assert_allclose(rot.as_euler("xyz"), 2000.0 * e[3:].T, atol=1e-12)
    imu = trans + rot.apply([0.0, 0.0, 0.12])
    np.testing.assert_allclose(imu, np.c_[x + 2000 * e[0], 2000 * e[1], 0.2 + 2000 * e[2]], atol=1e-12)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_serve_blocks_until_ctrl_c(campaign):
    """--serve: a web viewer answers on --web-port while the command blocks; Ctrl-C ends it (exit 0)."""
    d = campaign
    web, grpc = _free_port(), _free_port()
    proc = subprocess.Popen([*TWIN, "view", d, "--serve", "--web-port", str(web), "--grpc-port", str(grpc)],
                            cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            # a shell's background job ignores SIGINT; Ctrl-C is what we test
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # noqa: PLW1509
    try:
        status, deadline = None, time.monotonic() + 120
        while status is None and time.monotonic() < deadline and proc.poll() is None:
            try:
                status = urllib.request.urlopen(f"http://127.0.0.1:{web}/", timeout=2).status
            except OSError:
                time.sleep(0.5)
        assert status == 200 and proc.poll() is None
        time.sleep(1.0)
        assert proc.poll() is None  # still serving
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert f"serving the web viewer at http://localhost:{web}/" in err and "stopped" in err
