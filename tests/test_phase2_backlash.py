"""Backlash by signal shifts and by perceived pitch (issue 4, checks 2, 3, 4).

Unit tests on synthetic traces with known shifts, then the CI gate on ``scenarios/backlash-steps.toml``
(simulated once per session, analysed through ``twin backlash``). ``pytest -s`` prints the figures.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import REPO, run_twin, signed, simulate_shared

from analysis.phase2.backlash import NON_POSITIONING, BacklashEstimator, weighted_sum
from analysis.phase2.shifts import correlate_traces, shift_between
from analysis.phase2.traces import DOFS, DirectionalTraces
from analysis.phase2.winfilt import highpass, savgol_window, winfilt

STEPS = REPO / "scenarios/backlash-steps.toml"
_CAMPAIGNS: dict = {}
_JSON: dict = {}


def steps_campaign(tmp_path_factory, *overrides: str):
    """backlash-steps simulated with ``--set`` overrides: once per test run (shared with
    test_phase2_cli.py and test_trend_keeps_up.py, :func:`conftest.simulate_shared`), one copy per
    test process."""
    key = tuple(overrides)
    if key not in _CAMPAIGNS:
        out = tmp_path_factory.mktemp("steps") / "campaign"
        simulate_shared(tmp_path_factory, STEPS, out, *[a for o in overrides for a in ("--set", o)])
        _CAMPAIGNS[key] = out
    return _CAMPAIGNS[key]


def backlash_json(directory, *args: str) -> dict:
    """``twin backlash DIR -o DIR/backlash`` once per directory; the parsed backlash.json."""
    key = (str(directory), args)
    if key not in _JSON:
        out = directory / "backlash"
        run_twin("backlash", directory, "-o", out, *args)
        _JSON[key] = json.loads((out / "backlash.json").read_text())
    return _JSON[key]


def injected_change_um(directory) -> dict:
    from analysis.dataset import open_truth

    with open_truth(directory / "truth.h5") as t:
        b = {s: t.session(s)[2]["backlash_um"] for s in t.sessions()}
    first = b[min(b)]
    return {s: v - first for s, v in b.items()}


# ---------------------------------------------------------------------------------------------
# Synthetic traces


def rail_profile(rng, lam_min=0.4e-3, lam_max=60e-3, amp=1e-6, du=2e-6):
    """A random rail-like profile (random phases, amplitude ∝ wavelength between ``lam_min`` and
    ``lam_max``, rms ``amp``), synthesised by inverse FFT on a 2 µm grid and interpolated."""
    u = np.arange(-0.01, 0.47, du)
    k = np.fft.rfftfreq(u.size, du)
    band = (k >= 1 / lam_max) & (k <= 1 / lam_min)
    spec = np.zeros(k.size, dtype=complex)
    spec[band] = np.exp(1j * rng.uniform(0, 2 * math.pi, band.sum())) / k[band]
    prof = np.fft.irfft(spec, u.size)
    prof *= amp / np.sqrt(np.mean(prof ** 2))
    return lambda x: np.interp(x, u, prof)


def directional(rng_seed, backlash, origin, x, profiles, screw, noise=0.0, stretch=1.0):
    """(forward, reverse) (6, n) traces against commanded position x: E_XX screw-fixed (no
    backlash shift), the others rail-fixed; the carriage trails the nut by b/2."""
    rng = np.random.default_rng(rng_seed)
    out = []
    for sign in (+1, -1):
        xt = stretch * (x + origin) - sign * backlash / 2.0
        rows = [screw(x + origin)] + [p(xt) for p in profiles]
        out.append(np.array(rows) + noise * rng.standard_normal((6, x.size)))
    return DirectionalTraces(x, out[0], out[1])


@pytest.fixture(scope="module")
def synthetic():
    rng = np.random.default_rng(42)
    profiles = [rail_profile(rng) for _ in range(5)]
    period = 0.010 / 8  # an 8-per-revolution screw-fixed feature
    screw_rng = rail_profile(rng, amp=0.05e-6)
    def screw(u):
        return 0.1e-6 * np.sin(2 * math.pi * u / period) + screw_rng(u)
    x = np.arange(0.002, 0.252, 10e-6)  # 250 mm of the stroke keeps the test fast
    return profiles, screw, x


def test_winfilt_window_and_cutoff():
    assert savgol_window(10e-6) == 31  # 0.603 * 0.5 mm / 10 µm = 30.15 -> 31 (odd)
    assert savgol_window(20e-6) == 15
    dx = 10e-6
    x = np.arange(0, 0.2, dx)
    w = savgol_window(dx) * dx
    lam_c = w / 0.603  # the cutoff of the rounded window
    gains = {}
    for lam in (lam_c / 3, lam_c, 3 * lam_c):
        hp = highpass(np.sin(2 * math.pi * x / lam), dx)[2000:-2000]
        gains[lam] = np.sqrt(2 * np.mean(hp ** 2))
    print(f"\nwinfilt: W = 31 samples on 10 µm, λc = {lam_c * 1e3:.4f} mm; high-pass gain "
          + ", ".join(f"{g:.3f} at {lam * 1e3:.3f} mm" for lam, g in gains.items()))
    assert gains[lam_c] == pytest.approx(0.5, abs=0.01)
    assert gains[lam_c / 3] > 0.9 and gains[3 * lam_c] < 0.1
    out = winfilt(np.sin(2 * math.pi * x / 0.3e-3) + 5.0, dx)
    assert abs(out[0]) < 1e-12 and abs(out[-1]) < 1e-12 and abs(out.mean()) < 0.05


def test_shift_sign_and_subsample_precision():
    rng = np.random.default_rng(1)
    dx = 10e-6
    x = np.arange(0, 0.45, dx)
    errs = []
    for _ in range(6):
        f = rail_profile(rng)
        true = rng.uniform(-4e-3, 4e-3)
        r = shift_between(winfilt(f(x - true), dx), winfilt(f(x), dx), dx)
        errs.append(r.shift_m - true)
    errs = np.array(errs) * 1e9
    print(f"\nsynthetic shifts (±4 mm, sub-sample): errors {np.round(errs, 1)} nm")
    assert np.all(np.abs(errs) < 20)  # 20 nm = 1/500 of the grid step
    # features at a larger position -> positive shift; offset grids are accounted for
    f = rail_profile(rng)
    r = shift_between(winfilt(f(x[100:] - 30e-6), dx), winfilt(f(x), dx), dx, x[100], x[0])
    assert r.shift_m == pytest.approx(30e-6, abs=0.02e-6)


def test_correlation_upsampled_matches_plain():
    rng = np.random.default_rng(3)
    smooth = np.hanning(9) / np.hanning(9).sum()  # band-limited, as winfiltered traces are
    a = np.convolve(rng.standard_normal(500), smooth, "same")
    b = np.convolve(rng.standard_normal(400), smooth, "same")
    l1, c1 = correlate_traces(a, b, 1.0, upsample=1)
    l8, c8 = correlate_traces(a, b, 1.0, upsample=8)
    on_grid = np.isclose(l8 % 1.0, 0.0)
    assert np.allclose(l8[on_grid], l1) and np.allclose(c8[on_grid], c1, atol=2e-3)


def test_comb_spacing_and_peak_numbers():
    dx = 10e-6
    x = np.arange(0, 0.45, dx)
    period = 1.25e-3
    rng = np.random.default_rng(5)
    f = rail_profile(rng, amp=0.02e-6)
    def sig(u):
        return np.sin(2 * math.pi * u / period) * 1e-7 + f(u)
    r = shift_between(winfilt(sig(x - 0.3e-3), dx), winfilt(sig(x), dx), dx)
    print(f"\ncomb: {r.n_peaks} peaks, spacing {r.spacing_m * 1e6:.4f} µm (true 1250), "
          f"shift {r.shift_m * 1e6:.3f} µm (true 300)")
    assert r.n_peaks > 20
    assert r.spacing_m == pytest.approx(period, abs=0.01e-6)
    assert r.shift_m == pytest.approx(0.3e-3, abs=0.05e-6)


def test_weighted_sum_eq6():
    assert weighted_sum([1.0, 3.0], [1.0, 1.0]) == pytest.approx(2.0)
    assert weighted_sum([1.0, 3.0], [1.0, 0.5], sigma=4) == pytest.approx((1 + 3 / 16) / (1 + 1 / 16))
    assert math.isnan(weighted_sum([np.nan], [1.0]))


@pytest.mark.parametrize("stationary", ["command", "E_XX"])
def test_estimator_recovers_injected_backlash_on_synthetic_traces(synthetic, stationary):
    profiles, screw, x = synthetic
    ref = directional(0, 3e-6, 0.7e-3, x, profiles, screw)
    est = BacklashEstimator(stationary=stationary, pitch_dofs=("E_XX",), dofs=NON_POSITIONING).fit(ref)
    rows = []
    for i, (db, o) in enumerate([(0.0, -1.0e-3), (2e-6, 1.9e-3), (5e-6, -1.6e-3), (20e-6, 0.1e-3)]):
        r = est.estimate(directional(i + 1, 3e-6 + db, o, x, profiles, screw))
        rows.append((db, r.delta_backlash_shift_m))
        for d in DOFS[1:]:
            assert r.delta_position_shift_m[d] == pytest.approx(db, abs=0.03e-6), d
        assert r.delta_position_shift_m["E_XX"] == pytest.approx(0.0, abs=0.03e-6)
        assert r.delta_backlash_shift_m == pytest.approx(db, abs=0.03e-6)
    print(f"\nsynthetic ({stationary}): injected -> estimated "
          + ", ".join(f"{a * 1e6:g} -> {b * 1e6:.3f}" for a, b in rows) + " µm")


def test_pitch_formula_eq9_on_stretched_traces(synthetic):
    """Eq. 9 on the mechanism the paper assumes: the IMU-based position scales by L/(L − b)."""
    profiles, screw, x = synthetic
    L, p = 0.45, 0.010
    ref = directional(0, 0.0, 0.0, x, profiles, screw)
    # only the pitch is stretched here (the shifts stay 0), so the bound by the shifts is off
    est = BacklashEstimator(travel_m=L, lead_m=p, pitch_dofs=("E_XX",), pitch_bound_factor=math.inf).fit(ref)
    assert est.reference_pitch_m_ == pytest.approx(p, abs=0.1e-6)
    for b in (5e-6, 20e-6):
        s = L / (L - b)
        tr = DirectionalTraces(x, screw(x / s)[None].repeat(6, 0), screw(x / s)[None].repeat(6, 0))
        r = est.estimate(tr)
        print(f"\nEq. 9 with the IMU position stretched by L/(L−b), b = {b * 1e6:g} µm: "
              f"pitch {r.observed_pitch_m * 1e3:.6f} mm, Δbacklash {r.delta_backlash_pitch_m * 1e6:.2f} µm")
        assert r.delta_backlash_pitch_m == pytest.approx(b, abs=0.1 * b)
        # the cross-correlation comb has the mean spacing of the two traces (why the pitch comes
        # from the session's own autocorrelation)
        cross = r.shifts[("E_XX", "forward")].spacing_m * 8
        assert cross == pytest.approx(p * (1 + s) / 2, abs=0.1e-6)


def test_eq9_beyond_its_plausibility_bound_is_withheld_with_the_reason(synthetic):
    """Issue 31, deliverable 5: a perceived pitch stretched by L/(L − b) with b = 200 µm while
    the shifts show no change: Eq. 9 reads about 200 µm, beyond max(3 × 0, 5 µm), and is withheld
    (NaN) naming the value and the bound; with b = 2 µm it is within the bound and kept."""
    profiles, screw, x = synthetic
    L, p = 0.45, 0.010
    est = BacklashEstimator(travel_m=L, lead_m=p, pitch_dofs=("E_XX",)).fit(
        directional(0, 0.0, 0.0, x, profiles, screw))
    for b, kept in ((200e-6, False), (2e-6, True)):
        s = L / (L - b)
        tr = DirectionalTraces(x, screw(x / s)[None].repeat(6, 0), screw(x / s)[None].repeat(6, 0))
        r = est.estimate(tr)
        assert abs(r.delta_backlash_shift_m) < 0.1e-6
        assert r.delta_backlash_pitch_raw_m == pytest.approx(b, rel=0.1)
        if kept:
            assert r.delta_backlash_pitch_m == r.delta_backlash_pitch_raw_m and r.pitch_note == ""
        else:
            assert math.isnan(r.delta_backlash_pitch_m)
            assert r.pitch_note == (f"withheld: Eq. 9 gives {r.delta_backlash_pitch_raw_m * 1e6:.2f} µm (pitch "
                                    f"{r.observed_pitch_m * 1e3:.6f} mm), beyond the plausibility bound 5.00 µm "
                                    f"(3 × the {abs(r.delta_backlash_shift_m) * 1e6:.2f} µm by shifts, at least 5 µm)")
            assert r.to_json()["delta_backlash_um_pitch"] is None
            assert r.to_json()["pitch_note"] == r.pitch_note


def test_eq9_never_prints_the_issues_nonsense(tmp_path_factory):
    """Issue 31: with threshold=0.5 Eq. 9 on backlash-steps reads tens to thousands of µm (the
    commanded reference cannot show backlash in the pitch); every such value is withheld in
    backlash.json and the table says so; with the defaults the JSON says why there is no pitch."""
    d = steps_campaign(tmp_path_factory)
    out = d / "bl-threshold"
    r = run_twin("backlash", d, "-o", out, "--no-plots", "--set-param", "threshold=0.5")
    doc = json.loads((out / "backlash.json").read_text())
    text = " ".join(r.stderr.split())
    for rec in doc["sessions"]:
        est, raw = rec["delta_backlash_um_pitch"], rec["delta_backlash_um_pitch_unbounded"]
        bound = max(3 * abs(rec["delta_backlash_um_shift"]), 5.0)
        if est is None:
            assert rec["pitch_note"].startswith(f"withheld: Eq. 9 gives {raw:.2f} µm")
            assert abs(raw) > bound
            assert f"note: Δb pitch (Eq. 9) of {rec['session']} withheld: Eq. 9 gives {raw:.2f} µm" in text
        else:
            assert abs(est) <= bound
    print("\nEq. 9 on backlash-steps, threshold 0.5: (session, shift, pitch shown, unbounded) µm",
          [(x["session"], round(x["delta_backlash_um_shift"], 2), x["delta_backlash_um_pitch"],
            x["delta_backlash_um_pitch_unbounded"]) for x in doc["sessions"]])
    assert sum(x["delta_backlash_um_pitch"] is None for x in doc["sessions"]) >= 3
    default = backlash_json(d, "--no-plots")
    assert all(x["delta_backlash_um_pitch"] is None and x["pitch_note"].startswith("no comb")
               for x in default["sessions"])


# ---------------------------------------------------------------------------------------------
# The CI gate on backlash-steps (100 mm/s, 10 runs, paper IMU noise, origins within ±2 mm)


@pytest.mark.quoted
def test_check2_backlash_steps_shift_based(tmp_path_factory, quote):
    """The CI gate on backlash-steps: every session's change by shifts within max(1 µm, 10 %) of
    the injected one; the errors after the reference session are quoted in docs/validation.md."""
    d = steps_campaign(tmp_path_factory)
    doc = backlash_json(d, "--no-plots")
    injected = injected_change_um(d)
    print("\ncheck 2 (backlash-steps): session, injected, by shifts, by pitch (µm)")
    bad = []
    for rec in doc["sessions"]:
        inj = injected[rec["session"]]
        est = rec["delta_backlash_um_shift"]
        tol = max(1.0, 0.1 * inj)
        gam = {k: round(v, 3) for k, v in rec["gamma"].items()}
        print(f"  {rec['session']}  {inj:5.1f}  {est:7.3f}  {rec['delta_backlash_um_pitch']}"
              f"  (tolerance {tol:.1f}, error {est - inj:+.3f}, γ {gam})")
        if not abs(est - inj) <= tol:
            bad.append((rec["session"], inj, est))
    assert len(doc["sessions"]) == 6
    assert not bad, f"sessions outside 1 µm / 10 %: {bad}"
    errors = [r["delta_backlash_um_shift"] - injected[r["session"]] for r in doc["sessions"][1:]]
    quote("gate_errors_um", max(map(abs, errors)), ", ".join(signed(e) for e in errors))


@pytest.mark.quoted
def test_check4_no_backlash_anywhere(tmp_path_factory, quote):
    """backlash-steps with no backlash in any session: every estimate within 1 µm of 0 (the
    range is quoted in docs/validation.md)."""
    d = steps_campaign(tmp_path_factory, "degradation.table_backlash_um=[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]",
                       "phase2.session_hours=[100.0, 300.0, 500.0, 600.0]")
    doc = backlash_json(d, "--no-plots")
    est = [rec["delta_backlash_um_shift"] for rec in doc["sessions"]]
    print(f"\ncheck 4 (no backlash anywhere): estimates {np.round(est, 3)} µm")
    assert all(abs(v) <= 1.0 for v in est)
    quote("no_backlash_range_um", max(map(abs, est)), f"{signed(min(est))} … {signed(max(est))}")


def test_baseline_sessions_rezero_on_their_mean(tmp_path_factory):
    """--baseline-sessions 2 on backlash-steps (its first two sessions share the initial
    backlash): every estimate moves by the mean of the first two raw estimates, the offset is
    recorded, and the CI gate's tolerance still holds. A count beyond the sessions exits 2."""
    d = steps_campaign(tmp_path_factory)
    raw = backlash_json(d, "--no-plots")
    doc = backlash_json(d, "--no-plots", "--baseline-sessions", "2")
    r = np.array([rec["delta_backlash_um_shift"] for rec in raw["sessions"]])
    k2 = np.array([rec["delta_backlash_um_shift"] for rec in doc["sessions"]])
    injected = injected_change_um(d)
    inj = np.array([injected[rec["session"]] for rec in doc["sessions"]])
    print(f"\nbaseline of 2 sessions: raw {np.round(r, 3)}, re-zeroed {np.round(k2, 3)}, "
          f"injected {inj} µm")
    assert doc["parameters"]["baseline_sessions"] == 2
    assert doc["parameters"]["baseline_offset_um"]["shift"] == pytest.approx(r[:2].mean(), abs=1e-9)
    assert np.allclose(k2, r - r[:2].mean(), atol=1e-9)
    assert np.all(np.abs(k2 - inj) <= np.maximum(1.0, 0.1 * inj))
    bad = run_twin("backlash", d, "-o", d / "bad", "--no-plots", "--baseline-sessions", "7",
                   check=False)
    assert bad.returncode == 2
    assert "baseline sessions = 7; expected 1 to 6" in bad.stderr


SLOW = ("phase2.speeds_mm_s=[20.0]", "phase2.session_hours=[100.0, 600.0]",
        "phase2.runs_per_session=2")
"""backlash-steps at the paper's slow speed (20 mm/s), two sessions (0 and 20 µm), two runs: the
campaign of check 3 and of test_phase2_cli.py."""


@pytest.fixture(scope="module")
def slow_campaign(tmp_path_factory):
    return steps_campaign(tmp_path_factory, *SLOW)


@pytest.fixture(scope="module")
def slow_result(slow_campaign):
    from analysis.dataset import open_measurements
    from analysis.phase2.backlash import campaign_backlash

    with open_measurements(slow_campaign / "measurements.h5") as m:
        return campaign_backlash(m, on_bad_run="raise")


@pytest.mark.quoted
def test_check3_observed_pitch(slow_campaign, slow_result, quote):
    from twin.sim.scenario import load

    s = load(STEPS)
    expected = s.axis.lead_mm * 1e-3 * (1.0 + s.geometry.cumulative_lead_error_um_per_m * 1e-6)
    pitches = [r.observed_pitch_m for r in slow_result.sessions]
    ref = slow_result.estimator.reference_pitch_m_
    print(f"\ncheck 3: observed pitch {np.round(np.array(pitches) * 1e3, 6)} mm (reference "
          f"{ref * 1e3:.6f}); lead·(1 + cumulative error) = {expected * 1e3:.6f} mm; in the "
          f"commanded frame the screw-fixed comb has exactly the nominal lead {s.axis.lead_mm:g} mm")
    for p in [ref, *pitches]:
        assert abs(p - expected) <= 0.5e-6
    quote("observed_pitch_mm", None, " and ".join(f"{p * 1e3:.5f}" for p in pitches))
    quote("expected_pitch_mm", expected * 1e3, f"{expected * 1e3:.5f}")


@pytest.mark.xfail(strict=True, reason=(
    "Eq. 9 assumes the IMU-based position scales by L/(L - b); with the commanded position the "
    "comb of correlation peaks is screw-fixed (the motor's 8-per-revolution torque ripple) and "
    "cannot change its spacing with backlash, so the pitch-based change stays near 0 (README)"))
@pytest.mark.quoted
def test_check2_pitch_based_at_slow_speed(slow_campaign, slow_result, quote):
    injected = injected_change_um(slow_campaign)
    rows = [(r.session, injected[r.session], r.delta_backlash_pitch_m * 1e6) for r in slow_result.sessions]
    print(f"\ncheck 2, pitch-based at 20 mm/s: (session, injected, estimated µm) {rows}")
    quote("pitch_based_20mm_s", None, f"{rows[-1][2]:.1f} µm for an injected {rows[-1][1]:g}")
    for _, inj, est in rows:
        assert abs(est - inj) <= max(2.0, 0.2 * inj)


REVERSAL = REPO / "scenarios/backlash-slow-reversal.toml"


@pytest.fixture(scope="module")
def reversal_campaign(tmp_path_factory):
    """backlash-slow-reversal simulated once per test run (shared with the gate's cold build,
    test_gate.py): 4 sessions, 0, 5, 10, 20 µm."""
    return simulate_shared(tmp_path_factory, REVERSAL, tmp_path_factory.mktemp("reversal") / "campaign")


@pytest.mark.quoted
def test_slow_reversal_travels_l_minus_b(reversal_campaign, quote):
    """Eq. 9's premise on backlash-slow-reversal: every move, the first of a run included,
    travels D = L − b between rests: D − L changes with the injected backlash by −Δb within
    0.5 µm, forward and reverse (the carriage stops on the driving flank and the next move
    crosses the whole clearance). The changes are quoted in docs/error-motions.md."""
    from analysis.dataset import open_truth

    injected = injected_change_um(reversal_campaign)
    with open_truth(reversal_campaign / "truth.h5") as t:
        dl = {s: (np.abs(t.strokes(s)["carriage_m"]) - np.abs(t.strokes(s)["command_m"])) * 1e6
              for s in t.sessions()}
        speeds = {s: t.strokes(s)["speed_m_s"] for s in t.sessions()}
    ref = min(dl)
    rows = [(s, injected[s], np.round(dl[s] - dl[ref], 3)) for s in sorted(dl)]
    print(f"\n[slow reversal] (session, injected Δb µm, Δ(D − L) forward, reverse µm) {rows}")
    assert len(rows) == 4 and max(injected.values()) == pytest.approx(20.0)
    for s, inj, d in rows:
        assert np.allclose(speeds[s], [0.02, -0.02], rtol=1e-9)
        assert np.all(np.abs(d + inj) <= 0.5), (s, inj, d)
    moved = [f"{signed(d[0])} | {signed(d[1])}" for _, inj, d in rows if inj > 0]
    quote("slow_reversal_dl_um", None, ", ".join(moved[:-1]) + f" and {moved[-1]} µm")


@pytest.mark.quoted
def test_eq9_on_the_imu_axis_where_d_is_l_minus_b(reversal_campaign, quote):
    """Issue 13, item 4: where the carriage travels D = L − b, Eq. 9 on the IMU axis (strokes
    timed by their cruise-side edges and the travel lost near the rest, Eq. 8's pitch from the
    comb's harmonic) recovers every change of backlash within max(2 µm, 20 %)."""
    doc = backlash_json(reversal_campaign, "--no-plots", "--position-reference", "imu")
    injected = injected_change_um(reversal_campaign)
    rows = [(r["session"], injected[r["session"]], r["delta_backlash_um_pitch"]) for r in doc["sessions"]]
    print(f"\nEq. 9, IMU axis, slow reversals: (session, injected, estimated µm) {rows}")
    assert doc["parameters"]["position_reference"] == "imu" and len(rows) == 4
    for _, inj, est in rows:
        assert abs(est - inj) <= max(2.0, 0.2 * inj)
    quote("eq9_imu_slow_reversal_um", None, ", ".join(f"{est:+.2f}" for _, inj, est in rows if inj > 0))


@pytest.mark.validate  # in `make test`, the gate's steps-imu-20mm_s check gates the same (test_gate.py)
@pytest.mark.quoted
def test_eq5_on_the_imu_axis_at_the_papers_slow_speed(tmp_path_factory, quote):
    """The CI gate on the IMU axis (issue 13, item 8), the paper's Phase II as it runs it: the
    IMU-based position (no position_cmd read), the paper's 20 mm/s, Eq. 5 (each DOF's shift
    subtracted from E_XX's): backlash-steps with 40 runs per session recovers every change within
    max(1 µm, 10 %) (the gate's tolerance needs the averaging of 40 runs); 20 mm/s, because at
    100 mm/s E_XX at the IMU is mostly rail-fixed and its shift does not follow the backlash on
    an axis that follows the carriage (the 100 mm/s gate above is the command axis's). Without
    Eq. 5 (Eq. 4 alone on the IMU axis) the rail-fixed DOFs stay put and the estimate misses the
    20 µm step by more than 10 µm: on an axis that follows the carriage only E_XX's screw-locked
    content moves."""
    d = steps_campaign(tmp_path_factory, "phase2.speeds_mm_s=[20.0]", "phase2.runs_per_session=40")
    doc = backlash_json(d, "--no-plots", "--position-reference", "imu")
    injected = injected_change_um(d)
    assert doc["parameters"]["position_reference"] == "imu" and doc["parameters"]["stationary"] == "E_XX"
    rows = [(r["session"], injected[r["session"]], r["delta_backlash_um_shift"]) for r in doc["sessions"]]
    print(f"\nEq. 5, IMU axis, 20 mm/s, 40 runs: (session, injected, estimated µm) {rows}")
    assert len(rows) == 6
    for _, inj, est in rows:
        assert abs(est - inj) <= max(1.0, 0.1 * inj)
    from analysis.dataset import open_measurements
    from analysis.phase2.backlash import campaign_backlash, estimator_for

    with open_measurements(d / "measurements.h5") as m:
        eq4 = campaign_backlash(m, estimator=estimator_for(m), position_reference="imu")
    last = eq4.sessions[-1].delta_backlash_shift_m * 1e6
    print(f"Eq. 4 alone on the IMU axis: {[round(s.delta_backlash_shift_m * 1e6, 2) for s in eq4.sessions]} µm")
    assert abs(last - 20.0) > 10.0
    worst = max(rows, key=lambda r: abs(r[2] - r[1]))
    quote.table("eq5_imu_20mm_s", "| runs | injected (µm) | Eq. 5, IMU axis (µm) | worst error "
                "| Eq. 4 alone, IMU axis (µm) |\n|---|---|---|---|---|\n"
                f"| 40 | {', '.join(f'{r[1]:g}' for r in rows)} | {', '.join(signed(r[2]) for r in rows)} | "
                f"{signed(worst[2] - worst[1])} µm ({worst[1]:g} µm step) | "
                f"{', '.join(signed(x.delta_backlash_shift_m * 1e6) for x in eq4.sessions)} |\n")


@pytest.mark.quoted
def test_imu_axis_at_100mm_s_does_not_follow_the_backlash(tmp_path_factory, quote):
    """Why the IMU axis needs the paper's slow speed: on backlash-steps at 100 mm/s E_XX at the
    IMU is mostly rail-fixed (Abbe terms), so on an axis that follows the carriage Eq. 5 recovers
    under 10 % of the 20 µm step (the command axis, by the gate above, all of it)."""
    d = steps_campaign(tmp_path_factory)
    doc = backlash_json(d, "--no-plots", "--position-reference", "imu")
    est = [r["delta_backlash_um_shift"] for r in doc["sessions"]]
    print(f"\nEq. 5, IMU axis, 100 mm/s: {np.round(est, 2).tolist()} µm")
    assert len(est) == 6 and max(map(abs, est)) < 0.1 * 20.0
    quote("imu_axis_100mm_s_um", max(map(abs, est)), ", ".join(signed(e) for e in est))
    command = backlash_json(d, "--no-plots")
    quote("command_axis_100mm_s_um", None, ", ".join(signed(r["delta_backlash_um_shift"]) for r in command["sessions"]))


def _three_ways(d) -> dict:
    """Change of backlash per session (µm) by Eq. 4 and Eq. 5 on the command axis and Eq. 5 on
    the IMU axis."""
    from analysis.dataset import open_measurements
    from analysis.phase2.backlash import campaign_backlash, estimator_for

    out = {}
    with open_measurements(d / "measurements.h5") as m:
        for key, ref, stationary in (("eq4_command", "command", "command"),
                                     ("eq5_command", "command", "E_XX"), ("eq5_imu", "imu", "E_XX")):
            res = campaign_backlash(m, estimator=estimator_for(m, stationary=stationary),
                                    position_reference=ref, on_bad_run="raise")
            out[key] = [s.delta_backlash_shift_m * 1e6 for s in res.sessions]
    return out


@pytest.mark.quoted
def test_eq5_cancels_a_clock_drift_that_eq4_reads_as_backlash(tmp_path_factory, quote):
    """The check-3 campaign (20 mm/s, 2 runs, sessions at 100 and 600 h with 0 and 20 µm) with the
    controller's position running ahead of the IMU by 0.5 ms per 1000 h: on the command axis Eq. 4
    reads the 0.25 ms of drift as 2·v·Δτ = 10 µm of extra backlash (within 4 µm, this campaign's
    noise), Eq. 5 on either axis does not (within 4 µm of the injected 20 µm)."""
    d = steps_campaign(tmp_path_factory, *SLOW, "sensors.position_cmd_lead_ms_per_kh=0.5")
    est = _three_ways(d)
    print(f"\nclock drift 0.25 ms between the sessions: {est} µm (injected 0, 20)")
    assert est["eq4_command"][-1] - 20.0 == pytest.approx(2 * 0.02 * 0.25e-3 * 1e6, abs=4.0)
    assert est["eq5_command"][-1] == pytest.approx(20.0, abs=4.0)
    assert est["eq5_imu"][-1] == pytest.approx(20.0, abs=4.0)
    quote("drift_2_runs", None, f"Eq. 4 {est['eq4_command'][-1]:.1f} µm for 20 (the drift's 10 µm added), Eq. 5 "
          f"{est['eq5_command'][-1]:.1f} µm on the command axis and {est['eq5_imu'][-1]:.1f} µm on the IMU axis")


@pytest.mark.validate
@pytest.mark.quoted
def test_backlash_drift_scenario_eq5_gate(tmp_path_factory, quote):
    """scenarios/backlash-drift.toml (backlash-steps at 20 mm/s, 40 runs, a controller-to-IMU
    latency drifting 0.5 ms per 1000 h, origins within ±2 mm): Eq. 5 on the IMU axis recovers
    every change within max(1 µm, 10 %); Eq. 4 on the command axis errs by 2·v·Δτ, growing with
    the drift (within 1.5 µm of it in every session)."""
    d = tmp_path_factory.mktemp("drift")
    run_twin("simulate", REPO / "scenarios/backlash-drift.toml", "-o", d)
    injected = injected_change_um(d)
    inj = [injected[s] for s in sorted(injected)]
    est = _three_ways(d)
    hours = np.array([100.0, 200.0, 300.0, 400.0, 500.0, 600.0])
    drift_um = 2 * 0.02 * 0.5e-6 * (hours - hours[0]) * 1e6
    print(f"\nbacklash-drift: injected {inj}; drift 2vΔτ {drift_um.round(2).tolist()} µm; {est}")
    for e, i in zip(est["eq5_imu"], inj, strict=True):
        assert abs(e - i) <= max(1.0, 0.1 * i)
    eq4_err = np.array(est["eq4_command"]) - np.array(inj)
    assert np.all(np.abs(eq4_err - drift_um) <= 1.5)
    row = lambda name, xs: f"| {name} | " + " | ".join(signed(x) for x in xs) + " |"  # noqa: E731
    quote.table("drift", "\n".join([
        "| session (h) | " + " | ".join(f"{h:g}" for h in hours) + " |", "|---|" + "---|" * hours.size,
        "| injected Δb (µm) | " + " | ".join(f"{i:g}" for i in inj) + " |",
        "| drift 2·v·Δτ (µm) | " + " | ".join(f"{x:g}" for x in drift_um.round(2)) + " |",
        row("Eq. 4, command axis", est["eq4_command"]), row("Eq. 5, command axis", est["eq5_command"]),
        row("Eq. 5, IMU axis", est["eq5_imu"])]) + "\n")
    quote("drift_eq4_within_um", float(np.max(np.abs(eq4_err - drift_um))),
          f"{np.max(np.abs(eq4_err - drift_um)):.2f} µm")


@pytest.mark.slow
def test_paper_rtf_fig13_analogue(tmp_path_factory):
    """The paper's campaign (paper-rtf.toml) at a tenth of the runs and a session every 500 h
    (17 sessions x 9 runs of 20/100/500 mm/s, Phase I off): the shift-based change stays near 0
    before the wear onset (2500 h) and reaches about 10 µm near 8000 h, as in the paper's
    Fig. 13a."""
    out = tmp_path_factory.mktemp("rtf")
    run_twin("simulate", REPO / "scenarios/paper-rtf.toml", "-o", out, "--set", "campaign.scale=0.1",
             "--set", "phase2.session_interval_hours=500", "--set", "phase2.dwell_s=2",
             "--set", "campaign.phase1=false")
    doc = backlash_json(out, "--process-noise", "ml")
    inj = injected_change_um(out)
    print("\npaper-rtf (reduced): hours, injected, by shifts, smoothed, by pitch, pitch mm")
    for r in doc["sessions"]:
        print(f"  {r['hours']:6.0f}  {inj[r['session']]:6.2f}  {r['delta_backlash_um_shift']:6.2f}  "
              f"{r['smoothed_um']:6.2f}  {r['delta_backlash_um_pitch']:6.2f}  {r['observed_pitch_mm']:.6f}")
    print(f"  prognosis: {doc['prognosis']}")
    early = [r["delta_backlash_um_shift"] for r in doc["sessions"] if inj[r["session"]] < 0.1]
    late = [(r["delta_backlash_um_shift"], inj[r["session"]]) for r in doc["sessions"] if r["hours"] >= 7500]
    assert early and all(abs(v) <= 2.5 for v in early)
    assert late and all(abs(v - t) <= 2.5 for v, t in late)


def test_bad_input_errors(synthetic):
    profiles, screw, x = synthetic
    ref = directional(0, 0.0, 0.0, x[:3000], profiles, screw)
    with pytest.raises(ValueError, match="stationary"):
        BacklashEstimator(stationary="rails").fit(ref)
    with pytest.raises(RuntimeError, match="fit"):
        BacklashEstimator().estimate(ref)
    est = BacklashEstimator(pitch_dofs=("E_XX",)).fit(ref)
    coarse = directional(1, 0.0, 0.0, x[:6000:2], profiles, screw)
    with pytest.raises(ValueError, match="20 µm differs from the reference's 10 µm"):
        est.estimate(coarse)
    bad = DirectionalTraces(ref.x_m, ref.forward.copy(), ref.reverse.copy())
    bad.forward[2, 5] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        est.estimate(bad)


def test_readme_phase2_example_prints_what_it_claims(tmp_path_factory, monkeypatch, capsys):
    """README, "Method developer": ``twin simulate scenarios/backlash-steps.toml -o runs/steps``
    (the campaign above, no override), then the README's Python block, run as written with
    ``runs/steps`` pointing at that campaign: it prints the list its comment line shows."""
    import re

    readme = (REPO / "README.md").read_text()
    assert "twin simulate scenarios/backlash-steps.toml -o runs/steps " in readme
    block = next(b for b in re.findall(r"```python\n(.*?)```", readme, re.S)
                 if "runs/steps/measurements.h5" in b)
    claim = re.search(r"^# (\[[-0-9., ]+\]) µm against the injected", block, re.M)
    assert claim, block
    d = steps_campaign(tmp_path_factory)
    runs = tmp_path_factory.mktemp("readme")
    (runs / "runs").mkdir()
    (runs / "runs" / "steps").symlink_to(d)
    monkeypatch.chdir(runs)
    exec(compile(block, "README.md", "exec"), {})
    printed = capsys.readouterr().out.strip()
    with capsys.disabled():
        print(f"\nREADME Phase II example prints {printed}; the README says {claim.group(1)}")
    assert printed == claim.group(1)
