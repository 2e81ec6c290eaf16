"""Tests of the on-disk dataset format (analysis/dataset.py): parts, assembly, validation."""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np
import pytest

from analysis.dataset import (
    DOFS,
    TRUTH_KEYS,
    DatasetError,
    assemble_measurements,
    assemble_truth,
    measurement_keys,
    open_measurements,
    open_truth,
    truth_mentions,
)
from twin.sim.parts import PartStore

AXIS = {"lead_mm": 10.0, "travel_mm": 450.0, "load_kg": 100.0, "instruments": ["acc1", "acc2", "imu"]}
N1 = 200  # samples per Phase I capture
CAPTURES = [f"c{i:06d}" for i in range(4)]
SESSIONS = ["s0000", "s0001"]
RUNS = ["r0000", "r0001"]


def _capture(i: int) -> tuple[dict, dict]:
    rng = np.random.default_rng(i)
    attrs = {"hours": 10.0 * (len(CAPTURES) - i), "sample": i // 2, "fs_hz": 10_000.0}
    data = {
        "speed": rng.standard_normal(N1).astype(np.float32),
        "torque": rng.standard_normal(N1).astype(np.float32),
        "acc1": rng.standard_normal((N1, 3)).astype(np.float32),
        "acc2": rng.standard_normal((N1, 3)),  # float64 stays float64
    }
    return attrs, data


def _run(s: int, r: int) -> tuple[dict, dict, dict]:
    rng = np.random.default_rng(100 + 10 * s + r)
    data = {
        "imu_acc": rng.standard_normal((161, 3)).astype(np.float32),
        "imu_gyro": rng.standard_normal((100, 3)).astype(np.float32),
        "position_cmd": np.linspace(0.0, 0.45, 50),
    }
    dattrs = {"imu_acc": {"fs_hz": 1613.0}, "imu_gyro": {"fs_hz": 1000.0}, "position_cmd": {"fs_hz": 500.0}}
    return {"speeds_mm_s": [20.0, 100.0, 500.0]}, data, dattrs


def _session_truth(s: int) -> tuple[dict, np.ndarray, np.ndarray]:
    x = np.linspace(0.0, 0.45, 30)
    E = np.random.default_rng(200 + s).standard_normal((6, 30)) * 1e-6
    return {"hours": 5.0 + s, "backlash_um": 3.0 + s, "origin_offset_m": 1e-3 * s}, x, E


def _compute_parts(store: PartStore, stop_after: int | None = None) -> int:
    """The work of a campaign, skipping finished parts; returns how many parts were computed."""
    done = 0
    for i, name in enumerate(CAPTURES):
        if not store.has("phase1", name):
            if stop_after is not None and done == stop_after:
                return done
            store.write("phase1", name, *_capture(i))
            done += 1
    for s, sname in enumerate(SESSIONS):
        if not store.has("session", sname):
            store.write("session", sname, {"hours": 5.0 + s}, {})
            done += 1
        for r, rname in enumerate(RUNS):
            if not store.has(f"phase2/{sname}", rname):
                rattrs, data, dattrs = _run(s, r)
                store.write(f"phase2/{sname}", rname, rattrs, data, dattrs)
                done += 1
        if not store.has("truth_phase2", sname):
            attrs, x, E = _session_truth(s)
            store.write("truth_phase2", sname, attrs, {"x_m": x, "E": E})
            done += 1
    return done


def _assemble(store: PartStore, out) -> tuple:
    def phase2():
        for sname, sattrs, _, _ in store.items("session"):
            runs = ((r, a, d, da) for r, a, d, da in store.items(f"phase2/{sname}"))
            yield sname, sattrs, runs

    m = assemble_measurements(
        out / "measurements.h5",
        AXIS,
        ((n, a, d) for n, a, d, _ in store.items("phase1")),
        phase2(),
        (np.array([0.0, 500.0]), np.array([12.7, 25.4])),
    )
    t = assemble_truth(
        out / "truth.h5",
        json.dumps({"name": "tiny", "seed": 1}),
        250.0,
        {
            "hours": np.array([0.0, 100.0, 200.0]),
            "preload_N": np.array([900.0, 850.0, 600.0]),
            "backlash_um": np.array([1.0, 2.0, 8.0]),
            "axial_stiffness_N_per_m": np.array([3e8, 2.9e8, 2e8]),
        },
        ((n, a, d["x_m"], d["E"]) for n, a, d, _ in store.items("truth_phase2")),
        {"friction_drift": {"gain": 0.1}},
    )
    return m, t


@pytest.fixture
def campaign(tmp_path):
    store = PartStore(tmp_path)
    _compute_parts(store)
    return _assemble(store, tmp_path)


def test_round_trip(campaign):
    mpath, tpath = campaign
    with open_measurements(mpath) as m:
        assert m.axis() == {**AXIS, "axis_version": 1}
        # sorted by (hours, name): capture i has hours 10 * (4 - i)
        assert m.phase1_captures() == CAPTURES[::-1]
        for i, name in enumerate(CAPTURES):
            attrs, data = _capture(i)
            c = m.phase1(name)
            assert (c.name, c.hours, c.sample, c.fs_hz) == (name, attrs["hours"], attrs["sample"], 10_000.0)
            for ch in ("speed", "torque", "acc1", "acc2"):
                got = getattr(c, ch)
                assert got.dtype == np.float64
                np.testing.assert_array_equal(got, data[ch].astype(np.float64))
        assert m.phase2_sessions() == SESSIONS
        assert m.session_hours("s0001") == 6.0
        assert m.phase2_runs("s0001") == RUNS
        _, data, dattrs = _run(1, 1)
        run = m.phase2("s0001", "r0001")
        assert (run.session, run.run, run.hours) == ("s0001", "r0001", 6.0)
        assert (run.imu_acc_fs_hz, run.imu_gyro_fs_hz, run.position_cmd_fs_hz) == (1613.0, 1000.0, 500.0)
        assert run.speeds_mm_s == (20.0, 100.0, 500.0)
        for ch in ("imu_acc", "imu_gyro", "position_cmd"):
            np.testing.assert_array_equal(getattr(run, ch), data[ch].astype(np.float64))
        hours, backlash = m.dial_indicator()
        np.testing.assert_array_equal(hours, [0.0, 500.0])
        np.testing.assert_array_equal(backlash, [12.7, 25.4])
        m.validate()
    # arrays keep the dtype they were given
    with h5py.File(mpath, "r") as f:
        assert f["phase1/c000000/speed"].dtype == np.float32
        assert f["phase1/c000000/acc2"].dtype == np.float64
        assert f["phase1/c000000/acc1"].attrs["unit"] == "m/s^2"
        assert f.attrs["format_version"] == 2

    with open_truth(tpath) as t:
        assert t.onset_hours == 250.0
        assert t.scenario() == {"name": "tiny", "seed": 1}
        assert t.effects() == {"friction_drift": {"gain": 0.1}}
        tl = t.timeline()
        assert list(tl)[:3] == ["hours", "preload_N", "backlash_um"]
        np.testing.assert_array_equal(tl["axial_stiffness_N_per_m"], [3e8, 2.9e8, 2e8])
        assert t.sessions() == SESSIONS
        x, E, attrs = t.session("s0001")
        want_attrs, want_x, want_E = _session_truth(1)
        np.testing.assert_array_equal(x, want_x)
        np.testing.assert_array_equal(E, want_E)
        assert attrs == want_attrs
    with h5py.File(tpath, "r") as f:
        assert list(f["phase2/s0000/E"].attrs["dofs"]) == list(DOFS)


def test_resumed_campaign_equals_uninterrupted(tmp_path):
    full = tmp_path / "full"
    _compute_parts(PartStore(full))
    _assemble(PartStore(full), full)

    resumed = tmp_path / "resumed"
    store = PartStore(resumed)
    assert _compute_parts(store, stop_after=2) == 2  # "killed" after two captures
    # a write killed mid-way leaves a temporary file behind
    (resumed / ".parts" / "phase1" / ".c000002.abc123.tmp").write_bytes(b"\x89HDF\r\n half")
    assert store.names("phase1") == ["c000000", "c000001"]
    done = _compute_parts(store)
    assert done == 2 + 2 * (1 + len(RUNS) + 1)  # finished captures are not recomputed
    _assemble(store, resumed)

    for fname in ("measurements.h5", "truth.h5"):
        a, b = full / fname, resumed / fname
        with h5py.File(a, "r") as fa, h5py.File(b, "r") as fb:
            keys = []
            fa.visititems(lambda k, o, keys=keys: keys.append(k) if isinstance(o, h5py.Dataset) else None)
            assert keys
            for k in keys:
                assert fa[k].dtype == fb[k].dtype
                assert fa[k][()].tobytes() == fb[k][()].tobytes(), k
        assert a.read_bytes() == b.read_bytes()  # even the whole file is identical


def test_part_store_ignores_killed_writes(tmp_path):
    store = PartStore(tmp_path)
    attrs, data = _capture(0)
    store.write("phase1", "c000000", attrs, data, {"speed": {"unit": "rad/s"}})
    got_attrs, got_data, got_dattrs = store.read("phase1", "c000000")
    assert got_attrs == attrs
    assert got_dattrs == {"speed": {"unit": "rad/s"}}
    for k, v in data.items():
        assert got_data[k].dtype == v.dtype
        np.testing.assert_array_equal(got_data[k], v)

    kind_dir = tmp_path / ".parts" / "phase1"
    (kind_dir / ".c000001.x1y2z3.tmp").write_bytes(b"partial")  # killed before os.replace
    good = store.path("phase1", "c000000").read_bytes()
    store.path("phase1", "c000002").write_bytes(good[: len(good) // 2])  # truncated part
    store.path("phase1", "c000003").write_bytes(b"")  # empty part

    assert store.has("phase1", "c000000")
    assert not store.has("phase1", "c000001")
    assert not store.has("phase1", "c000002")
    assert not store.has("phase1", "c000003")
    assert not store.has("phase1", "c000004")
    assert "c000001" not in store.names("phase1")
    path2 = store.path("phase1", "c000002")
    with pytest.raises(DatasetError) as e:
        store.read("phase1", "c000002")
    assert str(e.value) == (
        f"{path2}: not a readable HDF5 file: it is truncated ({len(good) // 2} of {len(good)} bytes present); "
        f"rewrite it"
    )
    # rerunning the unit of work replaces the bad part
    store.write("phase1", "c000002", *_capture(2))
    assert store.has("phase1", "c000002")
    assert store.remove_temporaries() == 1
    assert not list(kind_dir.glob("*.tmp"))
    assert not store.has("nothing/here", "c000000")


def test_part_store_rejects_bad_names_and_dtypes(tmp_path):
    store = PartStore(tmp_path)
    with pytest.raises(ValueError, match="part name '../x'"):
        store.write("phase1", "../x", {}, {})
    with pytest.raises(ValueError, match="part kind '/abs'"):
        store.has("/abs", "c0")
    with pytest.raises(ValueError, match="dataset 'x' has dtype object"):
        store.write("phase1", "c0", {}, {"x": np.array([{}, None], dtype=object)})
    with pytest.raises(TypeError, match="attribute 'cfg'"):
        store.write("phase1", "c0", {"cfg": {"a": 1}}, {})
    assert store.names("phase1") == []
    assert not list(tmp_path.rglob("*.tmp"))


# ---------------------------------------------------------------------------------------------
# Bad files give exact messages.
# ---------------------------------------------------------------------------------------------


def _edit(path, fn):
    with h5py.File(path, "r+") as f:
        fn(f)


def _error(path, fn=lambda m: m.validate()) -> str:
    with pytest.raises(DatasetError) as e:
        with open_measurements(path) as m:
            fn(m)
    return str(e.value)


def test_wrong_format(campaign):
    mpath, tpath = campaign
    _edit(mpath, lambda f: f.attrs.__setitem__("format", "somebody/else"))
    assert _error(mpath) == f"{mpath}: /@format is 'somebody/else'; expected 'ballscrew-twin/measurements'"
    with pytest.raises(DatasetError) as e:
        open_truth(mpath)
    assert str(e.value) == f"{mpath}: /@format is 'somebody/else'; expected 'ballscrew-twin/truth'"
    with pytest.raises(DatasetError) as e:
        open_measurements(tpath)
    assert str(e.value) == f"{tpath}: /@format is 'ballscrew-twin/truth'; expected 'ballscrew-twin/measurements'"


def test_unsupported_version(campaign):
    mpath, _ = campaign
    _edit(mpath, lambda f: f.attrs.__setitem__("format_version", 3))
    assert _error(mpath) == (
        f"{mpath}: /@format_version is 3; this reader supports format_version 1, 2 (a newer ballscrew-twin may read it)"
    )


def test_missing_channel(campaign):
    mpath, _ = campaign
    _edit(mpath, lambda f: f.__delitem__("phase1/c000003/torque"))
    assert _error(mpath, lambda m: m.phase1("c000003")) == (
        f"{mpath}: /phase1/c000003/torque is missing; expected a dataset of motor torque in N*m, shape (n,)"
    )
    assert _error(mpath, lambda m: m.phase1("c000042")) == (
        f"{mpath}: /phase1/c000042 is missing; expected a Phase I capture group"
    )


def test_wrong_shape(campaign):
    mpath, _ = campaign

    def reshape(f):
        del f["phase1/c000003/acc1"]
        f.create_dataset("phase1/c000003/acc1", data=np.zeros((N1, 2))).attrs["unit"] = "m/s^2"

    _edit(mpath, reshape)
    assert _error(mpath, lambda m: m.phase1("c000003")) == (
        f"{mpath}: /phase1/c000003/acc1 has shape ({N1}, 2); expected (n, 3) with n equal to len(speed) = {N1}"
    )


def test_wrong_length_unit_and_rate(campaign):
    mpath, _ = campaign

    def edit(f):
        del f["phase1/c000001/torque"]
        f.create_dataset("phase1/c000001/torque", data=np.zeros(N1 - 1)).attrs["unit"] = "N*m"
        f["phase1/c000002/acc2"].attrs["unit"] = "g"
        f["phase2/s0000/r0001/imu_gyro"].attrs["fs_hz"] = 0.0
        f["phase1/c000000"].attrs["fs_hz"] = -1.0

    _edit(mpath, edit)
    assert _error(mpath, lambda m: m.phase1("c000001")) == (
        f"{mpath}: /phase1/c000001/torque has shape ({N1 - 1},); expected (n,) with n equal to len(speed) = {N1}"
    )
    assert _error(mpath, lambda m: m.phase1("c000002")) == (
        f"{mpath}: /phase1/c000002/acc2@unit is 'g'; expected 'm/s^2' (convert to SI before writing)"
    )
    assert _error(mpath, lambda m: m.phase2("s0000", "r0001")) == (
        f"{mpath}: /phase2/s0000/r0001/imu_gyro@fs_hz is 0.0; expected a finite sampling rate > 0 Hz"
    )
    assert _error(mpath, lambda m: m.phase1("c000000")) == (
        f"{mpath}: /phase1/c000000@fs_hz is -1.0; expected a finite sampling rate > 0 Hz"
    )


def test_nan_in_channel(campaign):
    mpath, _ = campaign

    def poison(f):
        acc = f["phase1/c000002/acc1"]
        a = acc[()]
        a[17, 2] = np.nan
        a[40, 0] = np.inf
        a[41, 1] = np.nan
        acc[...] = a
        sp = f["phase2/s0001/r0000/position_cmd"]
        p = sp[()]
        p[5] = np.nan
        sp[...] = p

    _edit(mpath, poison)
    assert _error(mpath, lambda m: m.phase1("c000002")) == (
        f"{mpath}: /phase1/c000002/acc1 has 3 non-finite values (NaN or inf), first at index (17, 2); "
        f"expected finite samples"
    )
    assert _error(mpath, lambda m: m.phase2("s0001", "r0000")) == (
        f"{mpath}: /phase2/s0001/r0000/position_cmd has 1 non-finite value (NaN or inf), first at index 5; "
        f"expected finite samples"
    )


def test_object_dtype_rejected(campaign):
    mpath, _ = campaign

    def edit(f):
        del f["phase1/c000001/speed"]
        f.create_dataset("phase1/c000001/speed", data=["a", "b"], dtype=h5py.string_dtype())

    _edit(mpath, edit)
    assert _error(mpath, lambda m: m.phase1("c000001")) == (
        f"{mpath}: /phase1/c000001/speed has dtype object; expected real numbers (float or integer)"
    )


def test_bad_axis_json(campaign):
    mpath, _ = campaign
    _edit(mpath, lambda f: f.attrs.__setitem__("axis", "__import__('os')"))
    msg = _error(mpath, lambda m: m.axis())
    assert msg.startswith(f"{mpath}: /@axis is not valid JSON (")
    assert msg.endswith("); expected a JSON object")


def test_truncated_file(campaign, tmp_path):
    mpath, _ = campaign
    data = mpath.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(DatasetError) as e:
        open_measurements(cut)
    assert str(e.value) == (
        f"{cut}: not a readable HDF5 file: it is truncated ({len(data) // 2} of {len(data)} bytes present); rewrite it"
    )
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(DatasetError, match=r"junk\.h5: not a readable HDF5 file; it may be truncated or corrupt"):
        open_measurements(junk)
    with pytest.raises(FileNotFoundError):
        open_measurements(tmp_path / "absent.h5")


# ---------------------------------------------------------------------------------------------
# Writers validate, and measurements never reveal the truth.
# ---------------------------------------------------------------------------------------------


def test_assemble_rejects_bad_input_and_leaves_nothing(tmp_path):
    out = tmp_path / "measurements.h5"
    attrs, data = _capture(0)
    data["acc1"] = data["acc1"][:, :2]
    with pytest.raises(DatasetError) as e:
        assemble_measurements(out, AXIS, [("c000000", attrs, data)], [], None)
    assert str(e.value) == (
        f"{out}: /phase1/c000000/acc1 has shape ({N1}, 2); expected (n, 3) with n equal to len(speed) = {N1}"
    )
    attrs, data = _capture(0)
    data["torque"] = data["torque"].copy()
    data["torque"][3] = np.nan
    with pytest.raises(DatasetError, match=r"/phase1/c000000/torque has 1 non-finite value"):
        assemble_measurements(out, AXIS, [("c000000", attrs, data)])
    assert not out.exists() and not list(tmp_path.glob("*.tmp"))


def test_measurement_keys_and_no_truth_leak(campaign):
    mpath, tpath = campaign
    keys = measurement_keys(mpath)
    for k in (
        "/@format",
        "/@format_version",
        "/@axis",
        "/phase1",
        "/phase1/c000000",
        "/phase1/c000000@hours",
        "/phase1/c000000@sample",
        "/phase1/c000000@fs_hz",
        "/phase1/c000000/speed",
        "/phase1/c000000/speed@unit",
        "/phase2/s0000@hours",
        "/phase2/s0000/r0000@speeds_mm_s",
        "/phase2/s0000/r0000/imu_gyro@fs_hz",
        "/dial_indicator/backlash_um",
    ):
        assert k in keys
    assert keys == sorted(keys)

    # the scan a reviewer would write by hand: names and string values, dial backlash allowed
    with h5py.File(mpath, "r") as f:
        texts = list(keys)
        f.visititems(lambda k, o: texts.extend(str(v) for v in o.attrs.values()))
        texts.extend(str(v) for v in f.attrs.values())
    for text in texts:
        text = text.replace("/dial_indicator/backlash_um", "/dial_indicator/<reading>")
        for word in TRUTH_KEYS:
            assert word not in text.lower(), (word, text)
    assert truth_mentions(mpath) == []
    assert truth_mentions(tpath)  # the truth file does mention them


def test_assemble_refuses_truth_in_measurements(tmp_path):
    out = tmp_path / "measurements.h5"
    attrs, data = _capture(0)
    with pytest.raises(ValueError) as e:
        assemble_measurements(
            out, {**AXIS, "nominalPreload_N": 900.0}, [("c000000", {**attrs, "wear_index": 0.3}, data)]
        )
    assert str(e.value) == (
        f"{out}: refusing to write measurements that reveal the injected truth: "
        f"/@axis (value mentions 'preload'); /phase1/c000000@wear_index (name mentions 'wear')"
    )
    assert not out.exists() and not list(tmp_path.glob("*.tmp"))
    # whole words only: 'effective' and 'default' are not 'effect' and 'fault'
    assemble_measurements(out, {"effective_mass_kg": 100.0, "mode": "default"}, [])
    assert truth_mentions(out) == []


def test_truth_without_onset_and_extra_units(tmp_path):
    path = assemble_truth(
        tmp_path / "truth.h5",
        "{}",
        None,
        {"hours": [0.0, 1.0], "preload_N": [1.0, 1.0], "backlash_um": [0.0, 0.0], "drag_torque_Nm": [0.1, 0.2]},
        [],
        {},
    )
    with open_truth(path) as t:
        assert t.onset_hours is None
        assert t.sessions() == []
        assert t.effects() == {}
    with h5py.File(path, "r") as f:
        assert f["timeline/drag_torque_Nm"].attrs["unit"] == "N*m"
        assert f["timeline/preload_N"].attrs["unit"] == "N"
    with pytest.raises(ValueError, match="expected a JSON object string"):
        assemble_truth(tmp_path / "t2.h5", "not json", 1.0, {}, [], {})
    with pytest.raises(DatasetError) as e:
        assemble_truth(tmp_path / "t2.h5", "{}", 1.0, {"hours": [0.0]}, [], {})
    assert str(e.value) == f"{tmp_path / 't2.h5'}: /timeline/preload_N is missing; expected a (t,) array"
    assert not os.path.exists(tmp_path / "t2.h5")


def _doc_converter():
    """The converter example of docs/dataset-format.md, executed as written."""
    doc = Path(__file__).resolve().parent.parent / "docs" / "dataset-format.md"
    blocks = doc.read_text(encoding="utf-8").split("```python\n")[1:]
    code = next(b.split("```")[0] for b in blocks if "def write_measurements" in b)
    ns: dict = {}
    exec(compile(code, str(doc), "exec"), ns)
    return ns["write_measurements"]


def test_doc_converter_writes_readable_file_and_matlab_style_attrs(tmp_path):
    write_measurements = _doc_converter()
    rng = np.random.default_rng(7)
    n = 500
    captures = [
        {"name": "c000000", "hours": 312.5, "sample": 0, "fs_hz": 10_000.0,
         "speed_rpm": rng.standard_normal(n) * 100, "torque_Nm": rng.standard_normal(n),
         "acc1_g": rng.standard_normal((n, 3)), "acc2_g": rng.standard_normal((n, 3))},
    ]
    sessions = [{"name": "s0000", "hours": 320.0, "runs": [
        {"name": "r0000", "imu_acc_g": rng.standard_normal((80, 3)), "imu_acc_fs_hz": 1613.0,
         "imu_gyro_dps": rng.standard_normal((50, 3)), "imu_gyro_fs_hz": 1000.0,
         "position_mm": np.linspace(0, 450, 20), "position_fs_hz": 200.0},
    ]}]
    path = tmp_path / "measurements.h5"
    write_measurements(path, {"name": "lab axis 2", "lead_mm": 10.0}, captures, sessions, dial=([312.0], [12.7]))

    # what MATLAB's h5writeatt produces: fixed-length strings, scalars as 1-element doubles
    def matlab_style(f):
        f.attrs["format"] = np.bytes_(b"ballscrew-twin/measurements")
        f.attrs["format_version"] = np.array([1.0])
        f["phase1/c000000"].attrs["sample"] = np.array([0.0])
        f["phase1/c000000"].attrs["fs_hz"] = np.array([10_000.0])
        f["phase1/c000000/speed"].attrs["unit"] = np.bytes_(b"rad/s")

    _edit(path, matlab_style)
    with open_measurements(path) as m:
        m.validate()
        c = m.phase1("c000000")
        assert (c.sample, c.fs_hz, c.hours) == (0, 10_000.0, 312.5)
        np.testing.assert_allclose(c.speed, captures[0]["speed_rpm"] * 2 * np.pi / 60)
        np.testing.assert_allclose(c.acc2, captures[0]["acc2_g"] * 9.80665)
        run = m.phase2("s0000", "r0000")
        np.testing.assert_allclose(run.imu_gyro, np.deg2rad(sessions[0]["runs"][0]["imu_gyro_dps"]))
        assert run.speeds_mm_s is None
        assert m.axis() == {"name": "lab axis 2", "lead_mm": 10.0}
    assert truth_mentions(path) == []
