"""Tests of twin.sim.geometry: truck spatial filter, ball pass, lead error, rail statistics, signs."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from twin.sim import geometry as geo
from twin.sim.scenario import Scenario, to_axis

#: The default scenario's carriage layout.
CARRIAGE = geo.CarriageGeometry.from_carriage(to_axis(Scenario()).carriage)

LENGTH = geo.DEFAULT_RAIL_LENGTH_M
X_TRAVEL = np.linspace(0.0, geo.TRAVEL_M, 9001)


def _fit_amplitude(x: np.ndarray, y: np.ndarray, wavelength: float) -> float:
    """Amplitude of the sinusoid of known wavelength in y(x), by linear least squares."""
    k = 2.0 * math.pi / wavelength
    design = np.column_stack([np.sin(k * x), np.cos(k * x), np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return float(np.hypot(coef[0], coef[1]))


def _profiles_from_functions(vertical, lateral) -> geo.RailProfiles:
    """RailProfiles on the default grid from callables f(u) -> (2, n)."""
    u = geo.DEFAULT_RAIL_START_M + 0.05e-3 * np.arange(int(round(LENGTH / 0.05e-3)) + 1)
    return geo.RailProfiles(u, vertical(u), lateral(u))


@pytest.mark.parametrize("wavelength", [0.05, 0.2, 0.6])
@pytest.mark.parametrize("method", ["linear", "cubic"])
def test_truck_filter_vertical(wavelength, method):
    g = CARRIAGE
    amp = 1e-6
    prof = geo.sinusoidal_rail_profiles(LENGTH, wavelength, amp, "vertical", phase=0.3)
    motions = geo.error_motions_from_trucks(
        geo.truck_displacements(prof, g, X_TRAVEL, method), g)
    gain_s, gain_a = geo.truck_filter_gains(wavelength, g.truck_spacing_m)
    e_zx = _fit_amplitude(X_TRAVEL, motions[1], wavelength)
    e_bx = _fit_amplitude(X_TRAVEL, motions[3], wavelength)
    print(f"\nλ={wavelength} m ({method}): E_ZX {e_zx * 1e6:.4f} µm vs {amp * gain_s * 1e6:.4f}; "
          f"E_BX {e_bx * 1e6:.4f} µrad vs {amp * gain_a * 1e6:.4f}")
    assert e_zx == pytest.approx(amp * gain_s, rel=0.01)
    assert e_bx == pytest.approx(amp * gain_a, rel=0.01)
    # Identical rails: no roll, nothing lateral.
    assert np.max(np.abs(motions[2])) < 1e-15
    assert np.max(np.abs(motions[[0, 4]])) == 0.0


@pytest.mark.parametrize("wavelength", [0.05, 0.2, 0.6])
def test_truck_filter_lateral(wavelength):
    g = CARRIAGE
    amp = 1e-6
    prof = geo.sinusoidal_rail_profiles(LENGTH, wavelength, amp, "lateral")
    motions = geo.error_motions_from_trucks(geo.truck_displacements(prof, g, X_TRAVEL), g)
    gain_s, gain_a = geo.truck_filter_gains(wavelength, g.truck_spacing_m)
    assert _fit_amplitude(X_TRAVEL, motions[0], wavelength) == pytest.approx(amp * gain_s, rel=0.01)
    assert _fit_amplitude(X_TRAVEL, motions[4], wavelength) == pytest.approx(amp * gain_a, rel=0.01)


def test_truck_filter_gain_values():
    # a = λ: |cos π| = 1 (full straightness), sin π = 0 (no angle); a = λ/2: the reverse.
    gs, ga = geo.truck_filter_gains(np.array([0.1, 0.2]), 0.1)
    np.testing.assert_allclose(gs, [1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(ga, [0.0, 20.0], atol=1e-9)
    # Long wavelength: angle gain → slope gain 2π/λ.
    gs, ga = geo.truck_filter_gains(100.0, 0.12)
    assert gs == pytest.approx(1.0, abs=1e-5)
    assert ga == pytest.approx(2 * math.pi / 100.0, rel=1e-5)


def test_ball_pass_period_and_frequency():
    s = geo.ScrewSpec()
    period = geo.ball_pass_period_m(s)
    print(f"\nball-pass period {period * 1e3:.4f} mm, Z = {geo.balls_per_turn(s):.3f}")
    assert period == pytest.approx(1.10e-3, abs=0.02e-3)
    freqs = geo.ball_pass_frequency_hz(np.array([0.020, 0.100, 0.500]), s)
    print("ball-pass frequencies", freqs)
    np.testing.assert_allclose(freqs, [18.0, 90.0, 453.0], rtol=0.02)
    assert geo.ball_pass_frequency_hz(-0.1, s) == pytest.approx(freqs[1])
    # The excitation has that spatial period in nut travel.
    travel = np.linspace(0.0, 0.05, 50001)
    theta = 2 * math.pi * travel / s.lead_m
    shifted = 2 * math.pi * (travel + period) / s.lead_m
    np.testing.assert_allclose(geo.ball_pass(shifted, s), geo.ball_pass(theta, s),
                               atol=1e-12 * s.ball_pass_amplitude_m + 1e-21)
    assert np.max(np.abs(geo.ball_pass(theta, s))) == pytest.approx(s.ball_pass_amplitude_m,
                                                                      rel=1e-3)


@pytest.mark.parametrize("k", [1, 3, 17, 45])
def test_lead_error_revolution_increments(k):
    s = geo.draw_screw_phases(geo.ScrewSpec(), np.random.default_rng(4))
    theta = np.linspace(-3.0, 2 * math.pi * 40, 2001)
    shift = 2 * math.pi * k
    x0 = s.radius_per_rad_m * theta + geo.lead_error(theta, s)
    x1 = s.radius_per_rad_m * (theta + shift) + geo.lead_error(theta + shift, s)
    expected = k * s.lead_m * (1.0 + s.cumulative_lead_error_m_per_m)
    np.testing.assert_allclose(x1 - x0, expected, rtol=1e-12, atol=1e-15)
    # Cyclic part: periodic with one revolution, amplitudes of the harmonics as specified.
    cyclic = geo.lead_error(theta, s) - s.cumulative_lead_error_m_per_m * s.radius_per_rad_m * theta
    cyclic_next = (geo.lead_error(theta + 2 * math.pi, s)
                   - s.cumulative_lead_error_m_per_m * s.radius_per_rad_m * (theta + 2 * math.pi))
    np.testing.assert_allclose(cyclic_next, cyclic, atol=1e-18)
    one_rev = np.linspace(0, 2 * math.pi, 4096, endpoint=False)
    c1 = geo.lead_error(one_rev, s) - s.cumulative_lead_error_m_per_m * s.radius_per_rad_m * one_rev
    spectrum = np.abs(np.fft.rfft(c1)) * 2 / one_rev.size
    np.testing.assert_allclose(spectrum[1:4], s.cyclic_lead_error_m, rtol=1e-9)
    # nut_position without ball pass is R·θ + e(θ).
    np.testing.assert_allclose(geo.nut_position(theta, s, include_ball_pass=False), x0, atol=0)


def test_runout_once_per_rev():
    s = geo.ScrewSpec(runout_m=0.4e-6, runout_phase_rad=0.0)
    r = geo.runout(np.array([0.0, math.pi / 2, 2 * math.pi]), s)
    assert r.shape == (3, 2)
    np.testing.assert_allclose(r, [[0.4e-6, 0.0], [0.0, 0.4e-6], [0.4e-6, 0.0]], atol=1e-20)


def test_make_rail_profiles_deterministic_and_rms():
    spec = geo.RailSpec()
    a = geo.make_rail_profiles(spec, LENGTH, np.random.default_rng(123))
    b = geo.make_rail_profiles(spec, LENGTH, np.random.default_rng(123))
    c = geo.make_rail_profiles(spec, LENGTH, np.random.default_rng(124))
    np.testing.assert_array_equal(a.vertical, b.vertical)
    np.testing.assert_array_equal(a.lateral, b.lateral)
    assert not np.allclose(a.vertical, c.vertical)
    assert a.du == pytest.approx(spec.grid_step_m)
    assert a.u_range[0] == pytest.approx(geo.DEFAULT_RAIL_START_M)
    assert a.u_range[1] == pytest.approx(geo.DEFAULT_RAIL_START_M + LENGTH)
    for seed in range(5):
        p = geo.make_rail_profiles(spec, LENGTH, np.random.default_rng(seed))
        for which, prof in (("vertical", p.vertical), ("lateral", p.lateral)):
            rms = np.sqrt(np.mean(prof**2, axis=1))
            np.testing.assert_allclose(rms, spec.expected_rms_m(which), rtol=0.10)
    # Pure waviness component: rms exact; the spectrum slope is −p in PSD.
    only = geo.RailSpec(bolt_amplitude_vertical_m=0.0, bolt_amplitude_lateral_m=0.0,
                        roughness_rms_m=0.0, straightness_rms_vertical_m=2e-6,
                        rail_correlation_vertical=0.0)
    p = geo.make_rail_profiles(only, LENGTH, np.random.default_rng(9))
    np.testing.assert_allclose(np.sqrt(np.mean(p.vertical**2, axis=1)), 2e-6, rtol=1e-9)
    spec_power = np.abs(np.fft.rfft(p.vertical[0])) ** 2
    j = np.arange(spec_power.size)
    band = (j >= 2) & (j <= 1000)
    slope = np.polyfit(np.log(j[band]), np.log(spec_power[band]), 1)[0]
    assert slope == pytest.approx(-2.0, abs=0.01)
    # Correlation between the rails follows the spec.
    corr = geo.RailSpec(rail_correlation_vertical=0.8, bolt_amplitude_vertical_m=0.0,
                        roughness_rms_m=0.0)
    rhos = [np.corrcoef(geo.make_rail_profiles(corr, LENGTH, np.random.default_rng(s)).vertical)
            [0, 1] for s in range(20)]
    assert np.mean(rhos) == pytest.approx(0.8, abs=0.15)


def test_make_rail_profiles_needs_rng():
    with pytest.raises(ValueError):
        geo.make_rail_profiles(geo.RailSpec(), LENGTH)


def test_at_out_of_range_and_shapes():
    prof = geo.sinusoidal_rail_profiles(LENGTH, 0.1, 1e-6)
    v, lat = prof.at(np.array([0.0, 0.1, 0.2]))
    assert v.shape == (2, 3) and lat.shape == (2, 3)
    with pytest.raises(ValueError):
        prof.at(prof.u_range[1] + 1e-3)
    with pytest.raises(ValueError):
        prof.at(0.1, method="nearest")


def test_sign_conventions():
    g = CARRIAGE
    x0 = 0.2
    step = lambda u: 1e-6 * (u > x0)  # noqa: E731  rail raised ahead of the carriage centre

    # Both rails raised at the front only: front up → negative pitch, no roll.
    prof = _profiles_from_functions(lambda u: np.vstack([step(u), step(u)]),
                                    lambda u: np.zeros((2, u.size)))
    m = geo.error_motions_from_trucks(geo.truck_displacements(prof, g, x0), g)[:, 0]
    assert m[3] == pytest.approx(-1e-6 / g.truck_spacing_m)
    assert m[1] == pytest.approx(0.5e-6)
    assert m[2] == pytest.approx(0.0, abs=1e-18)

    # Rail 1 (+Y) raised everywhere: positive roll.
    prof = _profiles_from_functions(lambda u: np.vstack([0 * u, 1e-6 + 0 * u]),
                                    lambda u: np.zeros((2, u.size)))
    m = geo.error_motions_from_trucks(geo.truck_displacements(prof, g, x0), g)[:, 0]
    assert m[2] == pytest.approx(1e-6 / g.rail_spacing_m)
    assert m[3] == pytest.approx(0.0, abs=1e-18)

    # Rails shifted to +Y at the front only: positive yaw.
    prof = _profiles_from_functions(lambda u: np.zeros((2, u.size)),
                                    lambda u: np.vstack([step(u), step(u)]))
    m = geo.error_motions_from_trucks(geo.truck_displacements(prof, g, x0), g)[:, 0]
    assert m[4] == pytest.approx(1e-6 / g.truck_spacing_m)
    assert m[0] == pytest.approx(0.5e-6)


def test_rigid_pose_round_trip_and_abbe():
    """Rails that are exactly the trace of a rigid pose give that pose back; the reference point
    moves by t + ε × r (checked against a rotation matrix)."""
    g = dataclasses.replace(CARRIAGE, reference_offset_x_m=0.03, reference_offset_y_m=-0.02)
    t_y, t_z, e_a, e_b, e_c = 0.7e-6, -0.4e-6, 3e-6, -5e-6, 4e-6
    x0 = 0.25
    half_w = g.rail_spacing_m / 2
    y_rail = np.array([[-half_w], [half_w]])
    prof = _profiles_from_functions(
        lambda u: t_z + e_a * y_rail - e_b * (u - x0),
        lambda u: t_y + e_c * (u - x0) + 0 * y_rail)
    m = geo.error_motions_from_trucks(geo.truck_displacements(prof, g, x0), g)[:, 0]
    np.testing.assert_allclose(m, [t_y, t_z, e_a, e_b, e_c], rtol=1e-9, atol=1e-16)

    screw = geo.ScrewSpec(cyclic_lead_error_m=(), cyclic_lead_phase_rad=(),
                          cumulative_lead_error_m_per_m=0.0, ball_pass_amplitude_m=0.0)
    e = geo.true_error_motions(prof, g, screw, x0, 2 * math.pi * x0 / screw.lead_m)[:, 0]
    # Small-angle rotation matrix R ≈ I + [ε]×; P moves by t + (R − I)·r_P.
    eps = np.array([e_a, e_b, e_c])
    skew = np.array([[0, -eps[2], eps[1]], [eps[2], 0, -eps[0]], [-eps[1], eps[0], 0]])
    r_p = g.reference_point_m
    r_n = np.array([0.0, g.screw_offset_y_m, g.screw_height_m])
    move_p = np.array([0.0, t_y, t_z]) + skew @ r_p
    move_n = np.array([0.0, t_y, t_z]) + skew @ r_n
    np.testing.assert_allclose(e[1:3], move_p[1:], rtol=1e-9)
    np.testing.assert_allclose(e[0], move_p[0] - move_n[0], rtol=1e-9)  # relative to the nut
    np.testing.assert_allclose(e[3:], eps, rtol=1e-9)
    # Negative pitch (front up) tips the top of the carriage backward: E_XX < 0 above the screw.
    assert e_b < 0 and e[0] < 0


def test_true_error_motions_defaults():
    rng = np.random.default_rng(2024)
    prof = geo.make_rail_profiles(geo.RailSpec(), LENGTH, rng)
    screw = geo.draw_screw_phases(geo.ScrewSpec(), rng)
    g = CARRIAGE
    theta = 2 * math.pi * X_TRAVEL / screw.lead_m
    e = geo.true_error_motions(prof, g, screw, X_TRAVEL, theta)
    assert e.shape == (6, X_TRAVEL.size)
    assert np.all(np.isfinite(e))
    pv = np.ptp(e, axis=1)
    print("\ndefault p-v over the travel: E_XX/E_YX/E_ZX µm, E_AX/E_BX/E_CX µrad:",
          np.round(pv * 1e6, 2))
    # Magnitudes in the twin's guideway ranges (a few µm, tens of µrad at most).
    assert np.all(pv[1:3] < 10e-6) and np.all(pv[3:] < 60e-6)
    # Screw errors follow θ: the lead error alone equals E_XX when the carriage has no angles.
    flat = geo.sinusoidal_rail_profiles(LENGTH, 0.1, 0.0)
    e_flat = geo.true_error_motions(flat, g, screw, X_TRAVEL, theta)
    np.testing.assert_allclose(e_flat[0], geo.nut_axial_deviation(theta, screw), atol=0)
    with pytest.raises(ValueError):
        geo.true_error_motions(prof, g, screw, X_TRAVEL, theta[:-1])
