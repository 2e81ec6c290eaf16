"""Issue 4, check 1 (and the error-motion contract the backlash methods rely on).

Figures are printed (``pytest -s``). Campaigns are simulated once per module: a quick campaign
with the paper's IMU noise and 10 runs (check 1), and a noise-free two-session campaign with a
20 µm backlash step (the slow traces keep the forward/reverse lag). Bad-run handling works on
copies of the first campaign's file.
"""

from __future__ import annotations

import json
import shutil

import h5py
import numpy as np
import pytest
from scipy import signal

from analysis.dataset import DatasetError, open_measurements, open_truth
from analysis.phase2 import fusion
from analysis.phase2.error_motions import session_error_motions
from analysis.phase2.traces import DOFS, DirectionalTraces, SessionErrorMotions
from tests.conftest import REPO, run_twin, truncate_dataset

QUICK = REPO / "scenarios/quick.toml"
NO_PHASE1 = ["--set", "campaign.phase1=false"]
NO_NOISE = ["--set", "sensors.imu_acc_noise_ug_per_rthz=0",
            "--set", "sensors.imu_gyro_noise_urad_s_per_rthz=0"]

# Check 1 tolerances (issue 4): after removing the unobservable terms.
STRAIGHTNESS_RMS_M = 1e-6
ANGLE_RMS_RAD = 3e-6
SHORT_WAVELENGTH_M = 0.020
STRAIGHTNESS_SHORT_RMS_M = 0.2e-6
ANGLE_SHORT_RMS_RAD = 1e-6


@pytest.fixture(scope="module")
def noisy_campaign(tmp_path_factory):
    """One session, 10 runs, the paper's IMU noise (scenario defaults), 20/100/500 mm/s."""
    out = tmp_path_factory.mktemp("em_noisy")
    run_twin("simulate", QUICK, "-o", out, *NO_PHASE1, "--set", "phase2.runs_per_session=10",
             "--set", "phase2.session_hours=[50.0]")
    return out


@pytest.fixture(scope="module", params=["command", "imu"])
def noisy_result(noisy_campaign, request):
    """The session's error motions on both position axes: the controller's position_cmd, and the
    IMU-based one (strokes from the accelerometer, the routine from the run's metadata)."""
    with open_measurements(noisy_campaign / "measurements.h5") as m:
        return session_error_motions(m, "s0000", position_reference=request.param)


@pytest.fixture(scope="module")
def backlash_step_campaign(tmp_path_factory):
    """Two noise-free sessions of one run, backlash 0 then 20 µm, new origin each."""
    out = tmp_path_factory.mktemp("em_step")
    run_twin("simulate", QUICK, "-o", out, *NO_PHASE1, *NO_NOISE,
             "--set", "phase2.runs_per_session=1", "--set", "phase2.session_hours=[100.0, 200.0]",
             "--set", "degradation.law=table", "--set", "degradation.table_hours=[100.0, 200.0]",
             "--set", "degradation.table_preload_fraction=[1.0, 1.0]",
             "--set", "degradation.table_backlash_um=[0.0, 20.0]")
    return out


def truth_on_grid(truth_path, session: str, x_cmd: np.ndarray) -> np.ndarray:
    """True error motions (6, n) at the commanded grid ``x_cmd``: the truth grid is the true
    carriage position, which is the commanded one plus the session's origin offset
    (``twin.sim.simulate.true_error_motions``); without backlash and up to the lead error, which
    moves rail features by < 4 µm over the stroke. Unobservable terms removed."""
    with open_truth(truth_path) as t:
        x, e, attrs = t.session(session)
    ref = np.array([np.interp(x_cmd + attrs["origin_offset_m"], x, e[i]) for i in range(6)])
    return fusion.remove_unobservable(ref, x_cmd)


def band_rms(err: np.ndarray, dx: float, max_wavelength: float) -> np.ndarray:
    """RMS of the wavelengths below ``max_wavelength`` of (k, n) rows."""
    n = err.shape[-1]
    k = np.fft.rfftfreq(n, dx)
    spec = np.fft.rfft(err, axis=-1)
    spec[..., k < 1.0 / max_wavelength] = 0
    return np.sqrt((np.fft.irfft(spec, n, axis=-1) ** 2).mean(axis=-1))


@pytest.mark.quoted
def test_check1_error_motions_against_truth(noisy_campaign, noisy_result, quote):
    """Check 1: the error motions of the quick campaign (one session, 10 runs, the paper's IMU
    noise) against the truth, within the issue's tolerances; the table of docs/validation.md."""
    r = noisy_result
    tr = r.combined
    ref = truth_on_grid(noisy_campaign / "truth.h5", "s0000", tr.x_m)
    print(f"\ncheck 1 ({r.position_reference} axis): combined grid {tr.x_m[0] * 1e3:.1f}.."
          f"{tr.x_m[-1] * 1e3:.1f} mm, step "
          f"{tr.dx_m * 1e3:.2f} mm, {len(r.runs)} runs; RMS error (all | < 20 mm) / truth RMS")
    failures = []
    worst = np.zeros((2, 6))  # the larger of the forward and reverse traces: all wavelengths, < 20 mm
    for name, est in (("forward", tr.forward), ("reverse", tr.reverse)):
        err = est - ref
        rms = np.sqrt((err ** 2).mean(axis=1))
        short = band_rms(err, tr.dx_m, SHORT_WAVELENGTH_M)
        worst = np.maximum(worst, [rms, short])
        size = np.sqrt((ref ** 2).mean(axis=1))
        for i, dof in enumerate(DOFS):
            unit, scale = ("µm", 1e6) if i < 3 else ("µrad", 1e6)
            print(f"  {name:7s} {dof}: {rms[i] * scale:6.3f} | {short[i] * scale:6.3f} {unit}"
                  f"  (truth {size[i] * scale:6.3f})")
        for i in (1, 2):
            if rms[i] > STRAIGHTNESS_RMS_M or short[i] > STRAIGHTNESS_SHORT_RMS_M:
                failures.append(f"{name} {DOFS[i]} {rms[i] * 1e6:.3f} | {short[i] * 1e6:.3f} µm")
        for i in (3, 4, 5):
            if rms[i] > ANGLE_RMS_RAD or short[i] > ANGLE_SHORT_RMS_RAD:
                failures.append(f"{name} {DOFS[i]} {rms[i] * 1e6:.3f} | {short[i] * 1e6:.3f} µrad")
        # E_XX is not part of check 1 (the kinematic truth leaves out the axial dynamics the IMU
        # sees); a loose bound still catches a broken positioning channel.
        assert rms[0] < 1e-6, f"{name} E_XX {rms[0] * 1e6:.3f} µm RMS"
    assert not failures, "beyond check 1 tolerances: " + "; ".join(failures)
    order = [1, 2, 3, 4, 5, 0]  # E_YX E_ZX E_AX E_BX E_CX E_XX, as the docs' table
    unit = ["µm", "µm", "µm", "µrad", "µrad", "µrad"]
    cells = [[f"{worst[k, i] * 1e6:.2f} {unit[i]}" for i in order] for k in range(2)]
    quote.table(f"error_motions_{r.position_reference}", "\n".join([
        "| DOF | " + " | ".join(DOFS[i] for i in order) + " |", "|---" * 7 + "|",
        "| RMS error, all wavelengths | " + " | ".join(cells[0]) + " |",
        "| RMS error, wavelengths < 20 mm | " + " | ".join(cells[1]) + " |",
        "| tolerance (issue) | 1 / 0.2 µm | 1 / 0.2 µm | 3 / 1 µrad | 3 / 1 µrad | 3 / 1 µrad | – |"]) + "\n")


def test_result_contract(noisy_campaign, noisy_result):
    r = noisy_result
    assert isinstance(r, SessionErrorMotions)
    assert r.session == "s0000" and r.skipped == ()
    assert r.runs == tuple(f"r{i:04d}" for i in range(10))
    with open_measurements(noisy_campaign / "measurements.h5") as m:
        assert r.hours == m.session_hours("s0000")
    for tr, step in ((r.combined, 0.5e-3), (r.slow, 10e-6)):
        assert isinstance(tr, DirectionalTraces)
        assert tr.forward.shape == tr.reverse.shape == (6, tr.x_m.size)
        assert np.all(np.isfinite(tr.forward)) and np.all(np.isfinite(tr.reverse))
        np.testing.assert_allclose(np.diff(tr.x_m), step, rtol=1e-6)
        # Unobservable terms removed: angles have zero mean.
        np.testing.assert_allclose(tr.forward[3:].mean(axis=1), 0.0, atol=1e-12)
    # The slow grid covers the slow stroke (0..450 mm minus the trimmed ramps: 0.1 s at 20 mm/s),
    # the combined one what the 500 mm/s passes cover at constant speed.
    assert r.slow.x_m[0] < 3e-3 and r.slow.x_m[-1] > 447e-3
    assert r.combined.x_m[0] < 60e-3 and r.combined.x_m[-1] > 390e-3
    print(f"\nslow grid {r.slow.x_m[0] * 1e3:.2f}..{r.slow.x_m[-1] * 1e3:.2f} mm step "
          f"{r.slow.dx_m * 1e6:.1f} µm; combined {r.combined.x_m[0] * 1e3:.1f}.."
          f"{r.combined.x_m[-1] * 1e3:.1f} mm")


def test_slow_component_keeps_the_ball_pass(noisy_campaign, noisy_result):
    """The ~1.1 mm ball-pass line of E_XX is in ``slow`` with its true amplitude (within 25 %)."""
    tr = noisy_result.slow
    ref = truth_on_grid(noisy_campaign / "truth.h5", "s0000", tr.x_m)
    n = tr.x_m.size
    win = signal.windows.hann(n)
    k = np.fft.rfftfreq(n, tr.dx_m)
    band = (k > 1 / 1.3e-3) & (k < 1 / 0.9e-3)
    amp_true = np.abs(np.fft.rfft(ref[0] * win))[band]
    peak = int(np.argmax(amp_true))
    for name, est in (("forward", tr.forward), ("reverse", tr.reverse)):
        amp = np.abs(np.fft.rfft(est[0] * win))[band]
        ratio = amp[peak] / amp_true[peak]
        print(f"\nslow {name} E_XX at {1e3 / k[band][peak]:.3f} mm: amplitude ratio to truth "
              f"{ratio:.3f}")
        assert 0.75 < ratio < 1.25


def _lag_m(a: np.ndarray, b: np.ndarray, dx: float, max_lag_m: float = 200e-6) -> float:
    """Lag L (m) maximising Σ a(x)·b(x − L), sub-sample by a parabola through the peak."""
    n = a.size
    c = signal.correlate(a, b, mode="full", method="fft")
    lags = signal.correlation_lags(n, n)
    sel = np.abs(lags) * dx <= max_lag_m
    c, lags = c[sel], lags[sel]
    j = int(np.clip(np.argmax(c), 1, c.size - 2))
    y0, y1, y2 = c[j - 1:j + 2]
    return (lags[j] + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)) * dx


def _band(e: np.ndarray, dx: float, lo: float = 0.5e-3, hi: float = 20e-3) -> np.ndarray:
    n = e.size
    k = np.fft.rfftfreq(n, dx)
    spec = np.fft.rfft(e - e.mean())
    spec[(k < 1 / hi) | (k > 1 / lo)] = 0
    return np.fft.irfft(spec, n)


def test_slow_traces_keep_the_backlash_lag(backlash_step_campaign):
    """Rail-fixed features lag between the forward and reverse ``slow`` traces by the backlash
    (commanded-position reference, not corrected). From a session with 0 µm to one with 20 µm
    (and a new origin) the lag in the 0.5-20 mm band grows by 20 µm for E_YX and E_CX, whose
    short wavelengths are rail-fixed (within 1.5 µm), and grows (by > 2 µm) for every DOF. The
    others grow by less because the carriage really moves with screw-fixed features there
    (ball-pass pitching of the nut load, runout), which the kinematic truth leaves out (printed
    with -s; figures in docs/validation.md)."""
    lags = {}
    with open_measurements(backlash_step_campaign / "measurements.h5") as m:
        for s in ("s0000", "s0001"):
            tr = session_error_motions(m, s).slow
            lags[s] = [_lag_m(_band(tr.forward[i], tr.dx_m), _band(tr.reverse[i], tr.dx_m),
                              tr.dx_m) for i in range(6)]
    change = np.array(lags["s0001"]) - np.array(lags["s0000"])
    print("\nforward-reverse lag of slow traces (0.5-20 mm band), 0 -> 20 µm backlash, µm: "
          + ", ".join(f"{d} {a * 1e6:.2f} -> {b * 1e6:.2f}"
                      for d, a, b in zip(DOFS, lags["s0000"], lags["s0001"], strict=True)))
    for i in (1, 5):
        assert abs(change[i] - 20e-6) < 1.5e-6, f"{DOFS[i]} lag change {change[i] * 1e6:.2f} µm"
    assert np.all(change > 2e-6), f"lag changes {change * 1e6} µm"


def test_fusion_recovers_synthetic_error_motions():
    """Noise-free synthetic IMU signals from the measurement model (analysis.phase2.fusion) at three
    speeds, both directions: the fusion returns the error motions (signs, gravity coupling)."""
    dx = 0.5e-3
    x = np.arange(0.05, 0.40, dx)
    rng = np.random.default_rng(4)
    L = x[-1] - x[0]

    def profile(amp):
        """A sum of sines: values, first and second derivatives (analytic)."""
        f, f1, f2 = np.zeros_like(x), np.zeros_like(x), np.zeros_like(x)
        for lam in (0.2, 0.06, 0.015, 0.004):
            a, k, ph = amp * lam / 0.2, 2 * np.pi / lam, rng.uniform(0, 2 * np.pi)
            f += a * np.sin(k * x + ph)
            f1 += a * k * np.cos(k * x + ph)
            f2 -= a * k * k * np.sin(k * x + ph)
        return f, f1, f2

    (t, _, t2), (r, r1, _) = profile(1e-6), profile(5e-6)
    streams = []
    for v in (0.02, -0.02, 0.1, -0.1, 0.5, -0.5):
        acc = v * v * t2 - fusion.G * r  # the (E_XX, E_BX) pair: f_x = v²·E_XX'' − g·E_BX
        # The synthetic signals are not filtered: unit sensor response (bandwidth 1e9 Hz).
        streams.append(fusion.Stream(acc - acc.mean(), "acc", v, 7e-5, 1e9, 150.0, 10))
        streams.append(fusion.Stream(v * r1, "gyro", v, 35e-6, 1e9, 100.0, 10))
    te, re = fusion.solve(streams, dx, coupling=-1.0, prior_t=fusion.Prior(20e-6),
                          prior_r=fusion.Prior(20e-6))
    est = fusion.remove_unobservable(np.vstack([te, 0 * te, 0 * te, 0 * te, re, 0 * te]), x)
    ref = fusion.remove_unobservable(np.vstack([t, 0 * t, 0 * t, 0 * t, r, 0 * t]), x)
    et = np.sqrt(np.mean((est[0] - ref[0]) ** 2))
    er = np.sqrt(np.mean((est[4] - ref[4]) ** 2))
    print(f"\nsynthetic: translation error {et * 1e9:.1f} nm of {np.std(ref[0]) * 1e9:.0f} nm, "
          f"angle error {er * 1e9:.1f} nrad of {np.std(ref[4]) * 1e9:.0f} nrad (L = {L:.3f} m)")
    assert et < 0.05 * np.std(ref[0])
    assert er < 0.05 * np.std(ref[4])


@pytest.mark.quoted
def test_posterior_psd_predicts_the_noise_of_the_estimate(quote):
    """Monte Carlo: pure accelerometer noise (70 µg/√Hz, 10 runs averaged, 100 mm/s), no error
    motion. In a band the data determine (2–5 mm), the RMS of the estimate over 300 draws matches
    √(Σ P(k)·Δk) of fusion.posterior_psd within 10 %; at long wavelengths, where the prior
    dominates, the posterior bound is conservative (the estimate shrinks towards zero)."""
    rng = np.random.default_rng(11)
    dx, n, v, nd, count = 0.5e-3, 800, 0.1, 70e-6 * fusion.G, 10
    prior = fusion.Prior(5e-6)
    est = []
    for _ in range(300):
        a = rng.normal(0.0, nd * np.sqrt(v / dx / 2) / np.sqrt(count), n)  # sampled at v/dx Hz
        s = fusion.Stream(a - a.mean(), "acc", v, nd, 300.0, 150.0, count)
        est.append(fusion.solve([s], dx, coupling=None, prior_t=prior, prior_r=prior)[0])
    k, p_t, _ = fusion.posterior_psd([s], dx, coupling=None, prior_t=prior, prior_r=prior)
    for (lo, hi), rel in (((2e-3, 5e-3), 0.10), ((50e-3, 100e-3), None)):
        sel = (k >= 1 / hi) & (k < 1 / lo)
        predicted = np.sqrt(p_t[sel].sum() * k[0])
        actual = np.sqrt(np.mean(fusion.band_limit(np.array(est), dx, (lo, hi)) ** 2))
        print(f"\n{lo * 1e3:g}-{hi * 1e3:g} mm: predicted {predicted * 1e9:.1f} nm, Monte Carlo {actual * 1e9:.1f} nm")
        if rel is not None:
            quote("posterior_psd_check", None, f"{predicted * 1e9:.1f} nm predicted against {actual * 1e9:.1f} nm "
                  f"at {lo * 1e3:g}–{hi * 1e3:g} mm; 300 draws")
            assert actual == pytest.approx(predicted, rel=rel)
        else:
            assert actual < predicted
    band = fusion.resolved_band(k, p_t, 0.2e-6)
    assert band is not None and 1e-3 <= band[0] < band[1]
    sel = (k >= 1 / band[1] * (1 - 1e-9)) & (k <= 1 / band[0] * (1 + 1e-9))
    assert np.sqrt(p_t[sel].sum() * k[0]) <= 0.2e-6


@pytest.fixture(scope="module")
def one_speed_campaign(tmp_path_factory):
    """As the demo records it: one speed (100 mm/s), 10 runs, the paper's IMU noise."""
    out = tmp_path_factory.mktemp("em_one_speed")
    run_twin("simulate", QUICK, "-o", out, *NO_PHASE1, "--set", "phase2.runs_per_session=10",
             "--set", "phase2.session_hours=[50.0]", "--set", "phase2.speeds_mm_s=[100.0]")
    return out


@pytest.mark.quoted
def test_resolved_band_says_what_one_speed_cannot_see(one_speed_campaign, noisy_campaign, tmp_path, quote):
    """Issue 13, item 7: with one speed the long wavelengths are not observable. The stated band
    of E_YX and E_ZX ends below 100 mm at 100 mm/s alone and reaches further with 20/100/500 mm/s;
    inside it the error is within the band's precision (0.2 µm, 1 µrad; 1.5× allowed for the
    model errors the noise bound leaves out), outside it larger. backlash.json and score.json
    carry the band and the in-band errors."""
    with open_measurements(one_speed_campaign / "measurements.h5") as m:
        one = session_error_motions(m, "s0000").combined
    with open_measurements(noisy_campaign / "measurements.h5") as m:
        three = session_error_motions(m, "s0000").combined
    ref = truth_on_grid(one_speed_campaign / "truth.h5", "s0000", one.x_m)
    est = 0.5 * (one.forward + one.reverse)
    print(f"\nresolved band (mm): one speed {np.round(one.band_m * 1e3, 2).tolist()}; "
          f"three speeds {np.round(three.band_m * 1e3, 2).tolist()}")
    unit = {1: "µm", 2: "µm", 3: "µrad", 4: "µrad", 5: "µrad"}
    rows = ["| speeds | | " + " | ".join(DOFS[i] for i in unit) + " |", "|---|---|" + "---|" * len(unit)]
    band_text = lambda b: " | ".join(f"{b[i, 0] * 1e3:.1f}–{b[i, 1] * 1e3:.0f} mm" for i in unit)  # noqa: E731
    errors = []
    for i in (1, 2, 3, 4, 5):
        lo, hi = one.band_m[i]
        assert 0.9e-3 <= lo < hi
        err_band = np.sqrt(np.mean((fusion.band_limit(est[i] - ref[i], one.dx_m, (lo, hi))) ** 2))
        err_all = np.sqrt(np.mean((est[i] - ref[i]) ** 2))
        tol = 1.5 * (0.2e-6 if i < 3 else 1e-6)
        print(f"  {DOFS[i]}: {lo * 1e3:.2f}-{hi * 1e3:.1f} mm, in band {err_band * 1e6:.3f}, "
              f"whole stroke {err_all * 1e6:.3f} (µm or µrad)")
        errors.append(f"{err_band * 1e6:.2f} \\| {err_all * 1e6:.2f} {unit[i]}")
        assert err_band <= tol
        assert err_all > err_band
    rows += [f"| 100 mm/s (as the demo) | band | {band_text(one.band_m)} |",
             f"| | RMS error: band \\| whole stroke | {' | '.join(errors)} |",
             f"| 20, 100, 500 mm/s | band | {band_text(three.band_m)} |"]
    quote.table("resolved_band", "\n".join(rows) + "\n")
    for i in (1, 2):
        assert one.band_m[i, 1] < 0.1
        assert three.band_m[i, 1] > 1.5 * one.band_m[i, 1]
    run_twin("backlash", one_speed_campaign, "--no-plots", "-o", tmp_path / "bl")
    doc = json.loads((tmp_path / "bl" / "backlash.json").read_text())
    band = doc["sessions"][0]["error_motion_band_mm"]
    assert band["E_YX"] == pytest.approx((one.band_m[1] * 1e3).tolist())
    assert doc["parameters"]["error_motion_band_precision"]["E_YX"] == pytest.approx(0.2)


# --------------------------------------------------------------------------------------------
# Bad runs: raise naming session, run and channel, or skip and record the reason.


def _damaged_copy(src, dst, damage) -> None:
    shutil.copy(src / "measurements.h5", dst / "measurements.h5")
    with h5py.File(dst / "measurements.h5", "r+") as f:
        damage(f)


def _delete_gyro(f):
    del f["/phase2/s0000/r0003/imu_gyro"]


def _cut_short(f):
    truncate_dataset(f["/phase2/s0000/r0004"], "imu_acc", 0.5)


def _cut_command(f):
    truncate_dataset(f["/phase2/s0000/r0006"], "position_cmd", 0.9)


def _nan_gyro(f):
    ds = f["/phase2/s0000/r0005/imu_gyro"]
    a = ds[...]
    a[:, 1] = np.nan
    ds[...] = a


@pytest.mark.parametrize("damage, run, channel", [
    (_delete_gyro, "r0003", "imu_gyro"),
    (_cut_short, "r0004", "imu_acc"),
    (_nan_gyro, "r0005", "imu_gyro"),
    (_cut_command, "r0006", "position_cmd"),
])
def test_bad_run_raises_or_is_skipped(noisy_campaign, tmp_path, damage, run, channel):
    _damaged_copy(noisy_campaign, tmp_path, damage)
    with open_measurements(tmp_path / "measurements.h5") as m:
        with pytest.raises(DatasetError) as exc:
            session_error_motions(m, "s0000")
        msg = str(exc.value)
        print(f"\nraise: {msg}")
        assert "s0000" in msg and run in msg and channel in msg
        r = session_error_motions(m, "s0000", on_bad_run="skip")
    assert [s[0] for s in r.skipped] == [run]
    assert channel in r.skipped[0][1]
    assert run not in r.runs and len(r.runs) == 9
    assert np.all(np.isfinite(r.combined.forward)) and np.all(np.isfinite(r.slow.reverse))


def test_all_runs_bad_and_bad_arguments(noisy_campaign, tmp_path):
    def nan_everywhere(f):
        for r in f["/phase2/s0000"]:
            ds = f[f"/phase2/s0000/{r}/imu_acc"]
            a = ds[...]
            a[5, 0] = np.nan
            ds[...] = a

    _damaged_copy(noisy_campaign, tmp_path, nan_everywhere)
    with open_measurements(tmp_path / "measurements.h5") as m:
        with pytest.raises(DatasetError, match="no usable run"):
            session_error_motions(m, "s0000", on_bad_run="skip")
        with pytest.raises(ValueError, match="on_bad_run"):
            session_error_motions(m, "s0000", on_bad_run="ignore")


def _greedy_band(k, psd, precision):
    """The resolved band's definition, one frequency at a time (the specification)."""
    dk, budget = k[0], precision ** 2
    lo = hi = int(np.argmin(psd))
    total = psd[lo] * dk
    if total > budget:
        return None
    while True:
        left = psd[lo - 1] if lo > 0 else np.inf
        right = psd[hi + 1] if hi + 1 < psd.size else np.inf
        step = min(left, right)
        if not np.isfinite(step) or total + step * dk > budget:
            return 1.0 / k[hi], 1.0 / k[lo]
        total += step * dk
        lo, hi = (lo - 1, hi) if left <= right else (lo, hi + 1)


def test_resolved_band_is_the_greedy_growth():
    """fusion.resolved_band (sorted in one pass) gives exactly the band of the frequency-by-
    frequency growth, on spectra with ties, steps, infinite values and smooth minima."""
    rng = np.random.default_rng(3)
    for trial in range(3000):
        n = int(rng.integers(1, 80))
        k = np.arange(1, n + 1) * 0.5
        p = [rng.random(n), rng.integers(1, 5, n).astype(float), np.exp(3 * rng.normal(size=n)),
             np.where(rng.random(n) < 0.2, np.inf, rng.random(n))][trial % 4]
        finite = p[np.isfinite(p)]
        precision = float(np.sqrt(rng.random() * 0.5 * finite.sum())) if finite.size else 1.0
        assert fusion.resolved_band(k, p, precision) == _greedy_band(k, p, precision)


def test_zero_phase_lowpass_is_scipys_sosfiltfilt():
    """The gridding's low-pass with its design cached is scipy.signal.sosfiltfilt to the bit,
    for each order the gridding uses, short and long records."""
    from scipy import signal

    from analysis.phase2.imu_runs import _lowpass, _zero_phase_lowpass

    rng = np.random.default_rng(0)
    for order in (2, 3, 4, 5):
        for n in (40, 1000, 36001):
            x = np.ascontiguousarray(rng.normal(size=(3, n)))
            expected = signal.sosfiltfilt(_lowpass(order, 50.0, 1613.0)[0].copy(), x, axis=-1)
            assert np.array_equal(_zero_phase_lowpass(x, order, 50.0, 1613.0), expected)
