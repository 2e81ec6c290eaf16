"""Signal artefacts (issue 15, deliverable 1c): each transform on synthetic arrays, exactly, and
their application to a recording in the dataset format.

The end-to-end check (a twin recording with a 50 Hz line on the Phase I accelerometers is
diagnosed as that artefact) lives in tests/test_diagnosis.py, on the benchmark's cache.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from analysis.diagnosis import artefacts as a
from analysis.diagnosis.attribution import ParamAxis, grid_edge

FS = 10_000.0


def _peak_hz(x: np.ndarray, fs: float) -> float:
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size)))
    f = np.fft.rfftfreq(x.size, 1.0 / fs)
    return float(f[np.argmax(spec)])


def test_gain_multiplies_the_channel():
    x = np.random.default_rng(0).normal(size=(1000, 3))
    np.testing.assert_array_equal(a.gain(x, 10.0), x * 1.1)
    np.testing.assert_array_equal(a.gain(x, -20.0), x * 0.8)


def test_fixed_line_stays_put_while_the_order_line_follows_the_speed():
    """Two cruises, 100 and 250 rad/s (15.9 and 39.8 Hz of rotation), 1 s each: the 50 Hz line
    is at 50 Hz in both; the order-2 line at 2·f_rot in each (31.8 and 79.6 Hz, within the
    1 Hz resolution)."""
    n = int(FS)
    speed = np.concatenate([np.full(n, 100.0), np.full(n, 250.0)])
    angle = a.shaft_angle(speed, FS)
    np.testing.assert_allclose(angle[n - 1], 100.0 * (n - 1) / FS, rtol=1e-12)
    zero = np.zeros(2 * n)
    fixed = a.fixed_line(zero, FS, 0.05, 50.0)
    order = a.order_line(zero, angle, 0.05, 2.0)
    for seg, w in ((slice(0, n), 100.0), (slice(n, 2 * n), 250.0)):
        assert _peak_hz(fixed[seg], FS) == pytest.approx(50.0, abs=1.0)
        assert _peak_hz(order[seg], FS) == pytest.approx(2 * w / (2 * np.pi), abs=1.0)
    np.testing.assert_allclose(np.abs(fixed).max(), 0.05, rtol=1e-3)
    # On every column of a triaxial channel alike.
    tri = a.fixed_line(np.zeros((100, 3)), FS, 0.05, 50.0)
    np.testing.assert_array_equal(tri[:, 0], tri[:, 2])


def test_clipping_clips_and_leaves_the_rest():
    x = np.linspace(-5.0, 5.0, 101)
    y = a.clip(x, 2.0)
    assert y.max() == 2.0 and y.min() == -2.0
    inside = np.abs(x) <= 2.0
    np.testing.assert_array_equal(y[inside], x[inside])
    np.testing.assert_array_equal(a.clip(x, 0.0), x)  # 0: no clipping


def test_delay_shifts_by_the_stated_samples():
    x = np.arange(10.0)
    np.testing.assert_array_equal(a.delay(x, 3), [0, 0, 0, 0, 1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(a.delay(x, -2), [2, 3, 4, 5, 6, 7, 8, 9, 9, 9])
    x2 = np.column_stack([x, -x])
    np.testing.assert_array_equal(a.delay(x2, 3)[3:], x2[:-3])
    # a machine's recording: the signal mirrored at the edge, no held value for twin check's dropout rule
    np.testing.assert_array_equal(a.delay(x, 3, "mirror"), [3, 2, 1, 0, 1, 2, 3, 4, 5, 6])
    np.testing.assert_array_equal(a.delay(x, -2, "mirror"), [2, 3, 4, 5, 6, 7, 8, 9, 8, 7])
    np.testing.assert_array_equal(a.delay(x2, 3, "mirror")[:3], x2[3:0:-1])
    with pytest.raises(ValueError, match="delay: edge 'wrap'; expected 'hold' or 'mirror'"):
        a.delay(x, 1, "wrap")


def test_a_time_offset_written_as_a_machine_records_it_is_no_dropout(tmp_path):
    """The calibrate benchmark writes a time offset into a recording with the signal mirrored at
    the edge: twin check finds no dropout there, where the held edge of the candidates' transform
    is one (calibrate-benchmark case 19's IMU, 16 samples at the start of every run)."""
    import h5py

    from analysis.ingest.check import _longest_run

    rng = np.random.default_rng(0)
    src = tmp_path / "measurements.h5"
    with h5py.File(src, "w") as f:
        g = f.create_group("phase2/s0000/r0000")
        ds = g.create_dataset("imu_acc", data=rng.normal(0.0, 1e-3, (2000, 3)).astype(np.float32))
        ds.attrs["fs_hz"] = 2000.0
        g.create_dataset("imu_gyro", data=rng.normal(0.0, 1e-3, (2000, 3)).astype(np.float32)).attrs["fs_hz"] = 2000.0
    offset = {"time_offset:imu": {"offset_ms": 8.0}}
    held = a.apply(src, tmp_path / "held.h5", offset, 1)
    mirrored = a.apply(src, tmp_path / "mirrored.h5", offset, 1, edge="mirror")
    with h5py.File(held) as fh, h5py.File(mirrored) as fm, h5py.File(src) as f0:
        x0 = f0["phase2/s0000/r0000/imu_acc"][:, 0]
        xh, xm = fh["phase2/s0000/r0000/imu_acc"][:, 0], fm["phase2/s0000/r0000/imu_acc"][:, 0]
    assert _longest_run(xh) == (17, 0)  # 16 samples shifted in, and the first: a dropout to twin check
    assert _longest_run(xm)[0] == 1
    np.testing.assert_array_equal(xm[16:], x0[:-16])


def test_bias_drift_is_linear_in_hours():
    x = np.zeros(5)
    np.testing.assert_allclose(a.bias_drift(x, 500.0, 0.2), 0.1, rtol=1e-12)
    np.testing.assert_array_equal(a.bias_drift(x, 0.0, 0.2), 0.0)


def test_noise_rms_and_seed():
    x = np.zeros(200_000)
    y1 = a.white_noise(x, 0.02, a.rng_for(11, "noise:acc1"))
    y2 = a.white_noise(x, 0.02, a.rng_for(11, "noise:acc1"))
    y3 = a.white_noise(x, 0.02, a.rng_for(12, "noise:acc1"))
    np.testing.assert_array_equal(y1, y2)  # every draw from the scenario's seed
    assert not np.array_equal(y1, y3)
    assert np.std(y1) == pytest.approx(0.02, rel=0.01)


def test_candidates_have_ranges_grids_and_words():
    kinds = {c.artefact for c in a.ARTEFACTS.values()}
    assert kinds == {"gain", "noise", "mains_line", "order_line", "bias_drift", "time_offset", "clipping"}
    for c in a.ARTEFACTS.values():
        for p in c.params:
            assert list(p.grid) == sorted(p.grid), (c.name, p.name)
            assert p.label and p.digits >= 1 and p.low <= p.high
            if p.off is not None:
                assert p.off in p.grid, (c.name, p.name)
        vals = {p.name: p.grid[-1] for p in c.params}
        c.phrase.format(**{k: str(v) for k, v in vals.items()})  # every placeholder is a parameter
        assert not c.is_off(vals)
    assert "electrical pickup" in a.ARTEFACTS["mains_line:acc"].phrase
    assert "following the speed" in a.ARTEFACTS["order_line:acc"].phrase


def test_mains_frequency_is_a_closed_grid():
    freq = ParamAxis("frequency_hz", (50.0, 60.0, 100.0), discrete=True, closed=True)
    assert grid_edge(freq, 50.0, (50.0, 50.0)) is None
    assert grid_edge(freq, 60.0, (50.0, 100.0)) == "both"


def _recording(path):
    rng = np.random.default_rng(1)
    with h5py.File(path, "w") as f:
        for i, hours in enumerate((0.0, 500.0)):
            g = f.create_group(f"phase1/c{i:06d}")
            g.attrs.update(fs_hz=FS, hours=hours, sample=i)
            g["speed"] = np.full(2000, 100.0, np.float32)
            g["torque"] = rng.normal(size=2000).astype(np.float32)
            g["acc1"] = rng.normal(size=(2000, 3)).astype(np.float32)
            g["acc2"] = rng.normal(size=(2000, 3)).astype(np.float32)
        s = f.create_group("phase2/s0000")
        s.attrs["hours"] = 1000.0
        r = s.create_group("r0000")
        r["imu_acc"] = np.zeros((300, 3), np.float32)
        r["imu_acc"].attrs["fs_hz"] = 1613.0
    return path


def test_apply_writes_a_post_processed_copy(tmp_path):
    src = _recording(tmp_path / "m.h5")
    dst = a.apply(src, tmp_path / "out" / "m.h5", {"gain:acc1": {"error_pct": 10.0},
                                                  "bias_drift:imu_acc": {"rate_per_kh": 0.2},
                                                  "mains_line:acc": {"amplitude": 0.0, "frequency_hz": 50.0}}, 5)
    with h5py.File(src) as f0, h5py.File(dst) as f1:
        for c in ("c000000", "c000001"):
            x0, x1 = f0[f"phase1/{c}/acc1"][...], f1[f"phase1/{c}/acc1"][...]
            assert x1.dtype == np.float32
            np.testing.assert_allclose(x1, x0.astype(float) * 1.1, rtol=1e-6)
            np.testing.assert_array_equal(f1[f"phase1/{c}/acc2"][...], f0[f"phase1/{c}/acc2"][...])
        np.testing.assert_allclose(f1["phase2/s0000/r0000/imu_acc"][...], 0.2, rtol=1e-6)


def test_apply_refuses_unknown_candidates_and_missing_channels(tmp_path):
    src = _recording(tmp_path / "m.h5")
    with pytest.raises(a.ArtefactError, match="unknown signal artefact 'hum:acc1'; the candidates are gain:speed"):
        a.apply(src, tmp_path / "x.h5", {"hum:acc1": {"amplitude": 1.0}}, 0)
    with pytest.raises(a.ArtefactError, match=r"artefact gain:acc1: parameters \['gain'\]; expected \['error_pct'\]"):
        a.apply(src, tmp_path / "x.h5", {"gain:acc1": {"gain": 1.1}}, 0)
    with h5py.File(src, "a") as f:
        del f["phase2/s0000/r0000/imu_acc"]
    with pytest.raises(a.ArtefactError,
                       match="/phase2/s0000/r0000/imu_acc is missing; artefact noise:imu_acc acts on it"):
        a.apply(src, tmp_path / "x.h5", {"noise:imu_acc": {"rms": 0.01}}, 0)


def test_edits_are_not_candidates_and_apply_like_artefacts(tmp_path):
    """The benchmark's out-of-everything recordings: edits no candidate models, applied by the
    artefacts' machinery from the case's seed."""
    from twin.harness.diagnosis.library import candidate_names

    assert {e.artefact for e in a.EDITS.values()} == {"spikes", "dropouts", "lowpass"}
    assert not set(a.EDITS) & set(a.ARTEFACTS)
    assert not set(a.EDITS) & set(candidate_names(("physical", "artefact", "parameter")))
    src = _recording(tmp_path / "m.h5")
    spec = {"spikes:acc": {"rate_hz": 20.0, "amplitude": 8.0}}
    d1, d2 = (a.apply(src, tmp_path / f"{k}.h5", spec, 3) for k in ("e1", "e2"))
    with h5py.File(src) as f0, h5py.File(d1) as f1, h5py.File(d2) as f2:
        diff = f1["phase1/c000000/acc1"][...].astype(float) - f0["phase1/c000000/acc1"][...]
        np.testing.assert_array_equal(f1["phase1/c000000/acc1"][...], f2["phase1/c000000/acc1"][...])
        np.testing.assert_array_equal(f1["phase1/c000000/torque"][...], f0["phase1/c000000/torque"][...])
    hit = np.abs(diff) > 1.0
    assert 1 <= hit.any(axis=1).sum() <= 30  # 20 per s over 2000 samples at 10 kHz: 4 expected
    np.testing.assert_allclose(np.abs(diff[hit]), 8.0, rtol=1e-5)


def test_spikes_dropouts_and_lowpass_transforms():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(200_000, 2))
    y = a.spikes(x, 10_000.0, 50.0, 5.0, np.random.default_rng(1))
    n_hit = int((np.abs(y - x) > 0).any(axis=1).sum())
    assert n_hit == pytest.approx(50.0 * 20.0, rel=0.1)  # 20 s at 50 per s
    ramp = np.arange(100_000, dtype=float)
    z = a.dropouts(ramp, 10_000.0, 2.0, 10.0, np.random.default_rng(2))
    held = np.flatnonzero(np.diff(z) == 0) + 1
    assert len(held) >= 100 and np.all(z <= ramp) and z[0] == 0.0  # 10 gaps of 100 samples, expected
    t = np.arange(20_000) / 10_000.0
    # 4th-order Butterworth, bilinear transform: |H| = 1/√(1 + (tan(πf/fs)/tan(πfc/fs))⁸)
    warped = np.tan(np.pi * 600.0 / 1e4) / np.tan(np.pi * 300.0 / 1e4)
    for f_hz, gain in ((30.0, 1.0), (600.0, 1.0 / np.sqrt(1.0 + warped ** 8))):
        out = a.lowpass(np.sin(2 * np.pi * f_hz * t), 10_000.0, 300.0)
        assert np.std(out[5000:]) * np.sqrt(2) == pytest.approx(gain, rel=0.02), f_hz
