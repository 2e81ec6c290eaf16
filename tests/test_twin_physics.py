"""Physics of the MuJoCo twin: the issue's checks 1-6 and the two-pass rail lookup.

Run ``pytest -q tests/test_twin_physics.py -s`` to see the measured figures of every check.

Conventions used throughout:

- Row k of a :class:`twin.sim.simulate.Trajectory` is the state at t_k = k·dt, the time of command
  sample k and of MuJoCo's sensor row k (:func:`_at_rows` is the identity; it marks the places
  where that alignment matters: at 20 mm/s and dt = 0.2 ms one sample is 4 µm of travel).
- "Nut point": the ball-nut tendon acts along the screw axis, ZN below the centre of mass, so
  x_nut = x + ZN·pitch. The centre of mass additionally carries the Abbe term −ZN·pitch of the
  rail-driven pitch.
- Ball-nut tendon: L = x + ZN·pitch − (1+s)·R·θ − ε, s the lead stretch (cumulative + thermal),
  ε = qpos[IX.flank] the lead flank, driven along the cyclic lead error + ball pass
  ε_cmd = nut_axial_deviation(θ_cmd) − cumulative·R·θ_cmd (Simulator.flank_motion). The backlash
  gap is |L| < b/2; the carriage is on a flank when |L| ≥ b/2.
- Worlds are varied with ``dataclasses.replace`` (flat rails, screws without cyclic lead error);
  each test says which one it uses and why.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import mujoco
import numpy as np
import pytest
from conftest import signed
from scipy import signal

from twin.sim import campaign as cp
from twin.sim import geometry as geo
from twin.sim.drive import Move, Profile, command_profile
from twin.sim.model import MechanicalState, ModelIndex, apply_state, build_model, state_fields, stiffness_of
from twin.sim.scenario import DialConfig, Scenario, to_axis
from twin.sim.simulate import (
    PHASE2_LEAD_IN,
    Condition,
    Simulator,
    dial_indicator,
    phase1_capture,
    phase1_profile,
    phase2_moves,
    phase2_trajectory,
)

#: Columns of qpos, sens and ctrl of the axis model, looked up by name.
IX = ModelIndex.of(build_model(to_axis(Scenario()), 2e-4))


SCEN = Scenario()
WORLD = cp.make_world(SCEN)
AXIS = WORLD.axis
R = AXIS.screw.radius_per_rad
LEAD = AXIS.screw.lead
F_NOM = AXIS.screw.preload
ZN = AXIS.carriage.nut_height - AXIS.carriage.com_height  # nut axis below the centre of mass (< 0)
RAIL_START, RAIL_LENGTH = -0.2, 0.85  # covers the travel ± truck spacing ± origin offsets

DT_SLOW = SCEN.phase2.timestep_s  # 0.2 ms, the Phase II / dial time step
DT_FAST = 1e-4  # 0.1 ms, the finest step in use (Phase I at the DAQ rate)


# ---------------------------------------------------------------------------------------------
# Helpers


def _flat_rails() -> geo.RailProfiles:
    return geo.sinusoidal_rail_profiles(RAIL_LENGTH, 0.2, 0.0, "vertical", u_start_m=RAIL_START)


def _no_cyclic(spec: geo.ScrewSpec) -> geo.ScrewSpec:
    """The screw without its cyclic (1, 2, 3 per revolution) lead error; ball pass, runout and
    the cumulative error kept."""
    return replace(spec, cyclic_lead_error_m=tuple(0.0 for _ in spec.cyclic_lead_error_m))


def _no_screw_errors(spec: geo.ScrewSpec, cumulative: bool = False) -> geo.ScrewSpec:
    """The screw without cyclic lead error, ball pass and runout (and without the cumulative
    lead error unless ``cumulative``)."""
    return replace(_no_cyclic(spec), ball_pass_amplitude_m=0.0, runout_m=0.0,
                   cumulative_lead_error_m_per_m=(spec.cumulative_lead_error_m_per_m
                                                  if cumulative else 0.0))


def _at_rows(a: np.ndarray) -> np.ndarray:
    """A command-sampled array at the rows' times: row k is command sample k."""
    return a


def _steady(cmd: Profile, speed: float, fs: float, trim_s: float, direction: int = 0) -> np.ndarray:
    """Row indices at constant commanded speed ``speed`` (m/s), ``trim_s`` cut off both ends of
    every constant-speed run; ``direction`` +1/−1 selects forward/reverse (0: both)."""
    v = _at_rows(cmd.v)
    m = np.abs(np.abs(v) - speed) < 1e-9 * max(speed, 1e-3)
    if direction:
        m &= np.sign(v) == direction
    edges = np.flatnonzero(np.diff(np.concatenate([[0], m.astype(int), [0]])))
    n = int(round(trim_s * fs))
    out = [np.arange(a + n, b - n) for a, b in zip(edges[::2], edges[1::2], strict=False) if b - a > 2 * n]
    return np.concatenate(out) if out else np.zeros(0, int)


def _fit_sin(x: np.ndarray, y: np.ndarray, wavelength: float) -> tuple[float, float, float]:
    """Least squares y ≈ s·sin(kx) + c·cos(kx) + d, k = 2π/λ. Returns (s, c, d)."""
    k = 2.0 * math.pi / wavelength
    design = np.column_stack([np.sin(k * x), np.cos(k * x), np.ones_like(x)])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    return float(coef[0]), float(coef[1]), float(coef[2])


def _healthy(temperature_rise: float = 0.0, **mech) -> Condition:
    return Condition(mech=MechanicalState(preload=F_NOM, **mech), temperature_rise=temperature_rise)


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def _cyclic(world, theta) -> np.ndarray:
    """The cyclic part of the lead error + ball pass at screw angle ``theta``, m: what the lead
    flank is driven along (the cumulative part is in the tendon's lead coefficient)."""
    theta = np.asarray(theta, float)
    return (geo.nut_axial_deviation(theta, world.screw)
            - world.screw.cumulative_lead_error_m_per_m * R * theta)


def _tendon(sim: Simulator, traj, cond: Condition, vel: bool = False) -> np.ndarray:
    """Ball-nut tendon length L (or its rate), m: x + ZN·pitch − (1+s)·R·θ − ε."""
    coef = np.zeros(sim.model.nv)
    coef[IX.x], coef[IX.pitch], coef[IX.flank] = 1.0, ZN, -1.0
    coef[IX.screw] = -(1.0 + sim.lead_stretch(cond)) * R
    return (traj.qvel if vel else traj.qpos) @ coef


def _nut_force(sim: Simulator, traj, cond: Condition) -> np.ndarray:
    """Axial force of the ball nut on the carriage, N, by the model's contact law (twin.sim.model):
    with b = 0 the spring and damper −K·L − C·L'; with b > 0 the flank in contact pushes with
    K·δ + C·δ' (δ the compression beyond b/2), never pulls, and nothing inside the gap
    (tests/test_nut_contact.py checks this law against MuJoCo's constraint force)."""
    f = state_fields(sim.world.axis, cond.mech, float(sim.model.tendon_invweight0[0]))
    length, rate = _tendon(sim, traj, cond), _tendon(sim, traj, cond, True)
    k, c, half = f.nut_stiffness, f.nut_damping, cond.mech.backlash / 2.0
    if half == 0.0:
        return -k * length - c * rate
    upper = np.where(length > half, np.maximum(k * (length - half) + c * rate, 0.0), 0.0)
    lower = np.where(length < -half, np.maximum(-k * (length + half) - c * rate, 0.0), 0.0)
    return lower - upper


def _gap_stats(sim: Simulator, traj, cond: Condition, idx: np.ndarray) -> tuple[float, float]:
    """Over rows ``idx`` (constant speed): fraction of the time inside the gap |L| < b/2, and the
    largest depth into it from the driving flank (m; negative: the smallest compression)."""
    length = _tendon(sim, traj, cond)[idx]
    direction = np.sign(_at_rows(traj.cmd.v)[idx])
    half = cond.mech.backlash / 2.0
    return float(np.mean(np.abs(length) < half)), float(np.max(half + direction * length))


# ---------------------------------------------------------------------------------------------
# Check 1: lead

# Commanded, m: 10.25, 10.12, 10.38 and 8.37 revolutions apart, so that the cyclic lead error
# (1, 2, 3 per revolution) does not cancel between them (up to 0.8 µm of Δε here).
LEAD_POSITIONS = (0.05, 0.1525, 0.2537, 0.3575, 0.4412)
LEAD_SPEED = 0.02  # m/s


def _lead_run(world, cond):
    """20 mm/s moves from 0.02 m through the five positions, 1 s dwell at each. Returns the
    simulator, the command, the trajectory and the row index at the end of each dwell (at
    rest)."""
    sim = Simulator(world, DT_SLOW)
    pts = (0.02,) + LEAD_POSITIONS
    moves = [Move(a, b, LEAD_SPEED, 0.5, 1.0) for a, b in zip(pts[:-1], pts[1:], strict=True)]
    lead_in = 0.5
    cmd = command_profile(moves, sim.fs, lead_in=lead_in)
    traj = sim.run(cond, cmd, passes=1)  # b = 0: pass 1 looks the rails up at x within 0.14 µm
    ends, t_end = [], lead_in
    for mv in moves:
        t_end += mv.duration
        ends.append(int(round(t_end * sim.fs)) - 3)  # last rows of the dwell
    return sim, cmd, traj, np.array(ends)


def test_lead_quasi_static_no_cyclic_error():
    """Check 1(a). Screw without cyclic lead error, ball pass and runout; flat rails (so no Abbe
    pitch); 3 K above reference. At rest after 20 mm/s moves, the carriage displacement between
    the five positions equals k·lead·(1 + c + α·ΔT) with k the screw revolutions (measured; the
    commanded k gives the same), within 0.1 µm. The lead flank stays at 0 (within the compliance
    of its drive, F_nut/kp ≈ 0.2 nm here)."""
    world = replace(WORLD, rails=_flat_rails(),
                    screw=_no_screw_errors(WORLD.screw, cumulative=True))
    cond = _healthy(temperature_rise=3.0)
    sim, cmd, traj, ends = _lead_run(world, cond)
    stretch = sim.lead_stretch(cond)
    assert stretch == pytest.approx(world.screw.cumulative_lead_error_m_per_m
                                    + world.thermal_expansion * 3.0, rel=1e-12)
    x = traj.x[ends]
    th = traj.qpos[ends, IX.screw]
    k = np.diff(th) / (2.0 * math.pi)
    k_cmd = np.diff(LEAD_POSITIONS) / LEAD
    err = np.diff(x) - k * LEAD * (1.0 + stretch)
    err_cmd = np.diff(x) - k_cmd * LEAD * (1.0 + stretch)
    flank = float(np.abs(traj.qpos[:, IX.flank]).max())
    print(f"\n[lead a] stretch c+αΔT = {stretch * 1e6:.2f} µm/m; revolutions {np.round(k, 6)}")
    print(f"[lead a] Δx − k·lead·(1+s) nm: {np.round(err * 1e9, 2)}; with the commanded k: "
          f"{np.round(err_cmd * 1e9, 2)}; lead-error part per 100 mm "
          f"{10 * LEAD * stretch * 1e6:.3f} µm; max |flank| {flank * 1e9:.2g} nm")
    assert np.all(np.abs(err) <= 0.1e-6)
    assert np.all(np.abs(err_cmd) <= 0.1e-6)
    assert flank <= 1e-9  # only the compliance of the flank drive, F_nut/kp


@pytest.mark.quoted
def test_lead_quasi_static_default_world(quote):
    """Check 1(b). Default world (random rails, cyclic lead error + ball pass), 3 K.

    At rest the nut flanks carry the cyclic lead error too (lead_flank coordinate), so the nut
    point's displacement between the positions must equal k·lead·(1+s) + Δε(θ_cmd), ε the cyclic
    part nut_axial_deviation − cumulative·R·θ at the commanded angle, within 0.1 µm (the positions
    are not whole revolutions apart: Δε up to 0.8 µm, so leaving it out must fail). The centre of
    mass additionally moves by the Abbe term −ZN·ΔE_BX of the rail pitch (printed),
    predicted from the rail geometry at the true x.

    In motion at 20 mm/s: x_nut − (1+s)·R·θ − ε(θ) is constant (peak-to-peak ≤ 0.1 µm, against
    over 0.5 µm without subtracting ε, asserted) and equals the elastic lag −F_rail/K_axial within 0.01 µm."""
    world = WORLD
    cond = _healthy(temperature_rise=3.0)
    sim, cmd, traj, ends = _lead_run(world, cond)
    stretch = sim.lead_stretch(cond)
    rows = ends
    x, th, pitch = traj.x[rows], traj.qpos[rows, IX.screw], traj.qpos[rows, IX.pitch]
    th_cmd = _at_rows(traj.theta_cmd)[rows]
    k = np.diff(th) / (2.0 * math.pi)
    d_eps = np.diff(_cyclic(world, th_cmd))
    nominal = k * LEAD * (1.0 + stretch) + d_eps
    err_nut = np.diff(x + ZN * pitch) - nominal
    err_nut_no_cyclic = err_nut + d_eps
    e_bx = geo.true_error_motions(world.rails, world.carriage, world.screw, x, th)[4]
    err_com = np.diff(x) - (nominal - ZN * np.diff(e_bx))
    print(f"\n[lead b] at rest: revolutions {np.round(k, 4)}; Δε(θ_cmd) µm "
          f"{np.round(d_eps * 1e6, 3)}")
    print(f"[lead b] at rest: nut point Δx_nut − k·lead·(1+s) − Δε nm {np.round(err_nut * 1e9, 2)}"
          f" (without −Δε {np.round(err_nut_no_cyclic * 1e9, 1)}); Δx_COM − k·lead·(1+s) − Δε µm "
          f"{np.round((np.diff(x) - nominal) * 1e6, 3)} (Abbe); COM − Abbe(geometry) nm "
          f"{np.round(err_com * 1e9, 2)}")
    assert np.all(np.abs(err_nut) <= 0.1e-6)
    assert np.all(np.abs(err_com) <= 0.1e-6)
    assert np.abs(err_nut_no_cyclic).max() > 0.3e-6  # the cyclic error is there at rest
    quote("lead_error_at_nut_nm", float(np.abs(err_nut).max() * 1e9), f"{np.abs(err_nut).max() * 1e9:.1g} nm")

    # In motion: the cyclic lead error and ball pass are reproduced.
    th_all = traj.qpos[:, IX.screw]
    x_nut = traj.x + ZN * traj.qpos[:, IX.pitch]
    resid0 = x_nut - (1.0 + stretch) * R * th_all
    resid = resid0 - _cyclic(world, th_all)
    idx = _steady(cmd, LEAD_SPEED, sim.fs, trim_s=0.5, direction=1)
    elastic = AXIS.carriage.rail_friction / stiffness_of(AXIS, cond.mech)["axial"]
    p2p, p2p0 = np.ptp(resid[idx]), np.ptp(resid0[idx])
    print(f"[lead b] in motion 20 mm/s: residual after ε p2p {p2p * 1e6:.4f} µm "
          f"(without subtracting it {p2p0 * 1e6:.3f} µm); mean {resid[idx].mean() * 1e6:.4f} µm "
          f"vs −F_rail/K {-elastic * 1e6:.4f} µm")
    assert p2p <= 0.1e-6
    assert p2p0 > 0.5e-6  # the cyclic error is present in motion
    assert abs(resid[idx].mean() + elastic) <= 0.01e-6


# ---------------------------------------------------------------------------------------------
# Check 2: backlash by the dial indicator


@pytest.mark.quoted
@pytest.mark.parametrize("b_um", [0.0, 5.0, 10.0, 20.0])
def test_dial_indicator_measures_clearance(b_um, quote):
    """Check 2: the simulated dial-indicator procedure (no reading noise, 10 repeats) returns the
    injected clearance within 0.5 µm plus the documented elastic term 2·F_rail/K_axial."""
    sim = Simulator(WORLD, DT_SLOW)
    cond = cp.condition_at(SCEN, 100.0)
    cond = replace(cond, mech=replace(cond.mech, backlash=b_um * 1e-6))
    res = dial_indicator(sim, DialConfig(reading_noise_um=0.0, repeats=10), cond,
                         cp.rng_for(0, cp.KIND_DIAL, int(b_um)))
    print(f"\n[dial] b = {b_um:4.1f} µm: measured {res.backlash_um:.3f} µm, elastic "
          f"{res.elastic_um:.3f} µm, repeats {np.round(res.repeats_um, 2)}")
    assert abs(res.backlash_um - b_um) <= 0.5 + res.elastic_um
    quote(f"dial_reads_um_b{b_um:g}", res.backlash_um, signed(res.backlash_um))


# ---------------------------------------------------------------------------------------------
# Check 3: preload → stiffness, natural frequency, drag torque

PRELOAD_FRACTIONS = (1.0, 0.5, 0.1)


def test_nut_stiffness_follows_hertz_rule():
    """Check 3: K_N(F) ∝ F^(1/3) (50 % and 10 % preload, within 1e-9), and apply_state writes the
    series axial stiffness into the ball-nut tendon."""
    s = AXIS.screw
    sim = Simulator(WORLD, DT_SLOW)
    for frac in (0.5, 0.1):
        ratio = s.nut_stiffness(frac * F_NOM) / s.nut_stiffness(F_NOM)
        print(f"\n[stiffness] {frac:.0%}: K_N ratio {ratio:.12f} vs {frac ** (1 / 3):.12f}; "
              f"K_axial {s.axial_stiffness(frac * F_NOM) / 1e6:.2f} N/µm")
        assert abs(ratio - frac ** (1.0 / 3.0)) <= 1e-9
    for frac in PRELOAD_FRACTIONS:
        apply_state(sim.model, AXIS, MechanicalState(preload=frac * F_NOM))
        k_model = sim.model.tendon_stiffness[sim.model.tendon("ballnut").id]
        k_series = 1.0 / (1.0 / s.shaft_stiffness + 1.0 / s.nut_stiffness(frac * F_NOM)
                          + 1.0 / s.bearing_stiffness)
        assert k_model == pytest.approx(k_series, rel=1e-12)


def _ring(sim: Simulator, preload: float, v0: float, duration: float = 0.5) -> np.ndarray:
    """x(t) − x0 of the carriage given an initial velocity v0, screw locked (armature 1e6)."""
    m = sim.model
    apply_state(m, sim.world.axis, MechanicalState(preload=preload))
    m.dof_armature[m.joint("screw").dofadr[0]] = 1e6
    d = mujoco.MjData(m)
    x0 = 0.2
    d.qpos[IX.x], d.qpos[IX.screw] = x0, x0 / R
    d.ctrl[IX.servo_pos] = d.qpos[IX.screw]
    d.qvel[IX.x] = v0
    n = int(round(duration / m.opt.timestep))
    x = np.empty(n)
    for i in range(n):
        mujoco.mj_step(m, d)
        x[i] = d.qpos[IX.x] - x0
    return x


def _ring_frequency(x: np.ndarray, dt: float) -> tuple[float, float]:
    """(zero-crossing, FFT-peak) frequency of a ring-down, Hz."""
    y = x - x.mean()
    zc = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))
    tz = (zc + (-y[zc]) / (y[zc + 1] - y[zc])) * dt
    f_zc = (tz.size - 1) / (tz[-1] - tz[0])
    nfft = 16 * y.size
    spec = np.abs(np.fft.rfft(y * np.hanning(y.size), nfft))
    return float(f_zc), float(np.fft.rfftfreq(nfft, dt)[np.argmax(spec)])


def _axial_pitch_frequency(k_axial: float) -> float:
    """Lower eigenfrequency of carriage x and pitch coupled through the nut, which sits ZN below
    the centre of mass (screw locked), Hz."""
    c = AXIS.carriage
    k_pitch = 4.0 * c.truck_stiffness_vertical * (c.truck_spacing / 2.0) ** 2
    mass = np.diag([c.mass, c.inertia[1]])
    stiff = np.array([[k_axial, k_axial * ZN], [k_axial * ZN, k_pitch + k_axial * ZN**2]])
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(mass, stiff)).real)
    return float(math.sqrt(w2[0]) / (2.0 * math.pi))


@pytest.mark.quoted
def test_axial_natural_frequency_follows_preload(quote):
    """Check 3: the axial natural frequency (screw locked, carriage given 10 mm/s) is within 5 %
    of sqrt(K_axial/m)/2π at 100/50/10 % preload.

    The measured frequency sits a little below sqrt(K/m)/2π because the nut pushes ZN = −50 mm below
    the centre of mass and so couples the axial mode to pitch; it matches the two-degree-of-
    freedom (x, pitch) eigenvalue within 0.5 %, asserted too. Set-up: flat rails and no screw
    errors (no excitation), contact damping ratio 0.002 (long ring), and rail friction 0: MuJoCo's
    regularised ``frictionloss`` acts against the acceleration rather than the velocity in a fast
    oscillation and lowers the ring frequency in an amplitude-dependent way (printed for the 12 N
    rail friction; figures in docs/validation.md)."""
    ax = replace(AXIS, screw=replace(AXIS.screw, contact_damping_ratio=0.002),
                 carriage=replace(AXIS.carriage, rail_friction=0.0))
    world = replace(WORLD, axis=ax, rails=_flat_rails(), screw=_no_screw_errors(WORLD.screw))
    sim = Simulator(world, DT_FAST)
    freqs, rows = {}, []
    for frac in PRELOAD_FRACTIONS:
        f_load = frac * F_NOM
        k = ax.screw.axial_stiffness(f_load)
        f_expected = math.sqrt(k / ax.carriage.mass) / (2.0 * math.pi)
        f_2dof = _axial_pitch_frequency(k)
        f_zc, f_fft = _ring_frequency(_ring(sim, f_load, 0.01), DT_FAST)
        freqs[frac] = f_zc
        rows.append((k / 1e6, f_zc, f_expected))
        print(f"\n[natural freq] {frac:.0%}: K {k / 1e6:.2f} N/µm, sqrt(K/m)/2π {f_expected:.2f} Hz,"
              f" x-pitch model {f_2dof:.2f} Hz; measured zero crossings {f_zc:.2f} Hz, FFT "
              f"{f_fft:.2f} Hz ({(f_zc / f_expected - 1) * 100:+.2f} %)")
        assert abs(f_zc - f_expected) <= 0.05 * f_expected
        assert abs(f_fft - f_expected) <= 0.05 * f_expected
        assert abs(f_zc - f_2dof) <= 0.005 * f_2dof
    assert freqs[1.0] > freqs[0.5] > freqs[0.1]
    for i, name in enumerate(("axial_stiffness_N_per_um", "axial_mode_hz", "axial_sqrt_k_over_m_hz")):
        quote(name, rows[0][i], " / ".join(f"{r[i]:.1f}" for r in rows))
    # Information: the same ring with the 12 N rail friction (MuJoCo frictionloss).
    ax_f = replace(ax, carriage=AXIS.carriage)
    sim_f = Simulator(replace(world, axis=ax_f), DT_FAST)
    for v0 in (0.002, 0.01, 0.05):
        x = _ring(sim_f, F_NOM, v0)
        print(f"[natural freq] 100 %, rail friction 12 N, amplitude {np.abs(x).max() * 1e6:5.1f} µm:"
              f" {_ring_frequency(x, DT_FAST)[0]:.1f} Hz")


@pytest.mark.quoted
def test_drag_torque_follows_preload(quote):
    """Check 3: the nut drag torque is linear in preload; apply_state writes it as the screw's
    frictionloss; the mean servo torque at constant speed (Phase I-like 400 mm/s moves) differs
    between 100 % and 10 % (and 50 %) preload by the drag difference within 10 %, and equals drag
    + viscous·ω + F_rail·R within 2 %."""
    s = AXIS.screw
    sim = Simulator(WORLD, DT_FAST)
    p1 = SCEN.phase1
    v, acc = p1.speed_mm_s * 1e-3, p1.accel_mm_s2 * 1e-3
    a, b = p1.start_mm * 1e-3, p1.end_mm * 1e-3
    cmd = command_profile([Move(a, b, v, acc, 0.3), Move(b, a, v, acc, 0.3)], sim.fs, lead_in=0.2)
    slope = (s.drag_torque(F_NOM) - s.drag_torque(0.0)) / F_NOM
    omega = v / R
    torque = {}
    for frac in PRELOAD_FRACTIONS:
        f_load = frac * F_NOM
        assert s.drag_torque(f_load) == pytest.approx(s.drag_torque(0.0) + slope * f_load,
                                                      rel=1e-12)
        traj = sim.run(Condition(mech=MechanicalState(preload=f_load)), cmd, passes=1)
        fl = sim.model.dof_frictionloss[sim.model.joint("screw").dofadr[0]]
        assert fl == pytest.approx(s.drag_torque(f_load), rel=1e-12)
        tq = traj.sens[:, IX.servo_torque]
        fwd = tq[_steady(cmd, v, sim.fs, 0.05, +1)].mean()
        rev = tq[_steady(cmd, v, sim.fs, 0.05, -1)].mean()
        torque[frac] = (fwd, rev)
        expected = s.drag_torque(f_load) + s.drag_viscous * omega + AXIS.carriage.rail_friction * R
        print(f"\n[drag] {frac:.0%}: frictionloss {fl:.4f} N·m = drag_torque; mean servo torque "
              f"fwd {fwd:+.4f} rev {rev:+.4f} N·m; drag+viscous+rail {expected:.4f} N·m")
        assert abs(fwd - expected) <= 0.02 * expected
        assert abs(-rev - expected) <= 0.02 * expected
    followed = []
    for frac in (0.1, 0.5):
        d_drag = s.drag_torque(F_NOM) - s.drag_torque(frac * F_NOM)
        d_fwd = torque[1.0][0] - torque[frac][0]
        d_rev = torque[frac][1] - torque[1.0][1]
        followed += [abs(d_fwd - d_drag), abs(d_rev - d_drag)]
        print(f"[drag] 100 % − {frac:.0%}: drag difference {d_drag:.4f} N·m; measured fwd "
              f"{d_fwd:.4f} rev {d_rev:.4f} N·m")
        assert abs(d_fwd - d_drag) <= 0.1 * d_drag
        assert abs(d_rev - d_drag) <= 0.1 * d_drag
    quote("drag_torque_Nm_100_to_10_pct", s.drag_torque(F_NOM),
          f"{s.drag_torque(F_NOM):.3f} → {s.drag_torque(0.1 * F_NOM):.3f} N·m")
    quote("drag_followed_mNm", 1e3 * max(followed), f"{1e3 * max(followed):.2f} mN·m")


# ---------------------------------------------------------------------------------------------
# Check 4: rail waviness through the truck spacing


@pytest.mark.quoted
@pytest.mark.parametrize("wavelength", [0.2, 0.05])
def test_rail_waviness_through_truck_spacing(wavelength, quote):
    """Check 4: one vertical sinusoid (1 µm) on both rails; at 20 mm/s the carriage's z and pitch
    are the geometric values A·cos(πa/λ)·sin(kx) and −(2A/a)·sin(πa/λ)·cos(kx) (gains of
    truck_filter_gains), fitted against the true x over the constant-speed part: amplitude within
    5 %, and the quadrature (phase) component below 5 % of it. Screw errors zeroed."""
    amp, a = 1e-6, AXIS.carriage.truck_spacing
    rails = geo.sinusoidal_rail_profiles(RAIL_LENGTH, wavelength, amp, "vertical",
                                         u_start_m=RAIL_START)
    world = replace(WORLD, rails=rails, screw=_no_screw_errors(WORLD.screw))
    sim = Simulator(world, DT_SLOW)
    v = 0.02
    cmd = command_profile([Move(0.02, 0.43, v, 0.5, 0.2)], sim.fs, lead_in=0.2)
    traj = sim.run(_healthy(), cmd, passes=2)
    idx = _steady(cmd, v, sim.fs, 0.1)
    x, z, pitch = traj.x[idx], traj.qpos[idx, IX.z], traj.qpos[idx, IX.pitch]
    g_s, g_a = geo.truck_filter_gains(wavelength, a)
    arg = math.pi * a / wavelength
    z_s, z_c, _ = _fit_sin(x, z, wavelength)
    p_s, p_c, _ = _fit_sin(x, pitch, wavelength)
    z_amp, p_amp = math.hypot(z_s, z_c), math.hypot(p_s, p_c)
    print(f"\n[rails λ={wavelength * 1e3:.0f} mm] G_s {float(g_s):.4f}, G_a {float(g_a):.3f} rad/m;"
          f" z: sin {z_s * 1e6:+.4f} cos {z_c * 1e6:+.4f} µm (expected sin "
          f"{amp * math.cos(arg) * 1e6:+.4f}); pitch: sin {p_s * 1e6:+.4f} cos {p_c * 1e6:+.4f} µrad"
          f" (expected cos {-2 * amp / a * math.sin(arg) * 1e6:+.4f})")
    assert abs(z_amp - amp * g_s) <= 0.05 * amp * g_s
    assert abs(p_amp - amp * g_a) <= 0.05 * amp * g_a
    assert abs(z_s - amp * math.cos(arg)) <= 0.05 * amp * g_s
    assert abs(p_c + 2.0 * amp / a * math.sin(arg)) <= 0.05 * amp * g_a
    dz, dp = abs(z_amp / (amp * g_s) - 1), abs(p_amp / (amp * g_a) - 1)
    quote(f"rail_waviness_{wavelength * 1e3:.0f}mm", max(dz, dp),
          f"{dz:.0e} and {dp:.0e} of their values (λ = {wavelength * 1e3:.0f} mm)")


def _pitch_registration(dt: float, v: float = 0.02, wavelength: float = 0.05):
    """Fit the pitch of a constant-speed forward move over a sinusoidal rail as the geometric
    pitch at x_true + Δ; returns (Δ m, sim)."""
    amp = 1e-6
    rails = geo.sinusoidal_rail_profiles(RAIL_LENGTH, wavelength, amp, "vertical",
                                         u_start_m=RAIL_START)
    world = replace(WORLD, rails=rails, screw=_no_screw_errors(WORLD.screw))
    sim = Simulator(world, dt)
    cmd = command_profile([Move(0.10, 0.20, v, 0.5, 0.05)], sim.fs, lead_in=0.05)
    traj = sim.run(_healthy(), cmd, passes=2)
    idx = _steady(cmd, v, sim.fs, 0.2)
    s, c, _ = _fit_sin(traj.x[idx], traj.qpos[idx, IX.pitch], wavelength)
    # pitch = −G·cos(k(x + Δ)) = −G·cos(kΔ)·cos(kx) + G·sin(kΔ)·sin(kx)
    k = 2.0 * math.pi / wavelength
    return math.atan2(s, -c) / k, sim


def test_rail_lookup_timing_is_step_independent():
    """Pass 2 must look the rails up at the true position at the START of each step (row k−1):
    then the registration of the pitch trace against the true x is a physical lag, independent of
    the time step: −v·τ with τ = C_pitch/K_pitch (damping over stiffness of the pitch suspension,
    the low-frequency group delay), ≈ −0.7 µm at 20 mm/s. Looking them up at row k (the state at
    the END of the step) shifts the trace ahead by v·dt (+3.3 µm at dt = 0.2 ms, +1.3 µm at
    0.1 ms: the bug fixed in Simulator.run)."""
    v = 0.02
    d_slow, sim = _pitch_registration(DT_SLOW, v)
    d_fast, _ = _pitch_registration(DT_FAST, v)
    m = sim.model
    c_p = sum(m.tendon_damping[m.tendon(f"truck_v{i}").id] * (AXIS.carriage.truck_spacing / 2) ** 2
              for i in range(4)) + m.tendon_damping[m.tendon("ballnut").id] * ZN**2
    k_p = sum(m.tendon_stiffness[m.tendon(f"truck_v{i}").id] * (AXIS.carriage.truck_spacing / 2) ** 2
              for i in range(4)) + m.tendon_stiffness[m.tendon("ballnut").id] * ZN**2
    tau = c_p / k_p
    print(f"\n[rail timing] pitch registration Δ at 20 mm/s: dt 0.2 ms {d_slow * 1e6:+.3f} µm, "
          f"dt 0.1 ms {d_fast * 1e6:+.3f} µm; −v·C/K = {-v * tau * 1e6:+.3f} µm (τ {tau * 1e6:.1f} µs)")
    assert abs(d_slow - d_fast) <= 0.2e-6
    assert abs(d_slow + v * tau) <= 0.2e-6
    assert abs(d_fast + v * tau) <= 0.2e-6


# ---------------------------------------------------------------------------------------------
# Check 5: backlash shift between forward and reverse traces


@pytest.mark.quoted
@pytest.mark.parametrize("b_um", [5.0, 20.0])
def test_backlash_shift_forward_reverse(b_um, quote):
    """Check 5: default world (rails, cyclic lead error and ball pass as drawn), clearance b: the
    true trace x_true − (1+s)·x_cmd over the constant-speed parts of a 20 mm/s Phase II run
    (origin offset 1.3 mm) is shifted by b + 2·F_rail/K_axial between forward and reverse (the
    elastic term, ~0.28 µm): asserted within 0.5 µm of b + elastic and of b.

    The carriage must stay on the driving flank during constant-speed motion: the ball-nut tendon
    L = x + ZN·pitch − (1+s)·R·θ − ε never inside the gap |L| < b/2 (printed: the smallest
    compression beyond the flank and the smallest driving nut force). Also printed: the shift of
    the rail-driven pitch trace against the commanded position (what an IMU analysis sees):
    b + elastic + 2·v·τ_pitch (pitch-suspension lag, see
    test_rail_lookup_timing_is_step_independent)."""
    sim = Simulator(WORLD, DT_SLOW)
    cfg = SCEN.phase2.model_copy(update={"speeds_mm_s": [20.0], "dwell_s": 1.0})
    cond = Condition(mech=MechanicalState(preload=F_NOM, backlash=b_um * 1e-6),
                     temperature_rise=3.0, origin_offset=1.3e-3)
    t0 = time.perf_counter()
    traj = phase2_trajectory(sim, cfg, cond)
    elapsed = time.perf_counter() - t0
    cmd, v = traj.cmd, 0.02
    stretch = 1.0 + sim.lead_stretch(cond)
    x_cmd = _at_rows(cmd.x) + cond.origin_offset
    dev = traj.x - stretch * x_cmd
    fwd, rev = _steady(cmd, v, sim.fs, 0.1, +1), _steady(cmd, v, sim.fs, 0.1, -1)
    lo = max(x_cmd[fwd].min(), x_cmd[rev].min())
    hi = min(x_cmd[fwd].max(), x_cmd[rev].max())
    fwd = fwd[(x_cmd[fwd] >= lo) & (x_cmd[fwd] <= hi)]
    rev = rev[(x_cmd[rev] >= lo) & (x_cmd[rev] <= hi)]
    shift = dev[rev].mean() - dev[fwd].mean()
    k_axial = stiffness_of(AXIS, cond.mech)["axial"]
    elastic = 2.0 * AXIS.carriage.rail_friction / k_axial
    b = b_um * 1e-6
    steady = np.concatenate([fwd, rev])
    in_gap, depth = _gap_stats(sim, traj, cond, steady)
    force = _nut_force(sim, traj, cond)[steady] * np.sign(_at_rows(cmd.v)[steady])
    # Registration of the pitch trace against the commanded position (information).
    grid = np.linspace(lo, hi, 40_000)
    p_f = np.interp(grid, x_cmd[fwd], traj.qpos[fwd, IX.pitch])
    order = np.argsort(x_cmd[rev])
    p_r = np.interp(grid, x_cmd[rev][order], traj.qpos[rev, IX.pitch][order])
    grad = np.gradient(p_f, grid)
    coef, *_ = np.linalg.lstsq(np.column_stack([grad, np.ones_like(grad)]), p_f - p_r, rcond=None)
    print(f"\n[backlash shift] b = {b_um:.0f} µm ({elapsed:.1f} s): shift {shift * 1e6:.3f} µm vs "
          f"b + elastic {(b + elastic) * 1e6:.3f} µm (elastic {elastic * 1e6:.3f}; shift − b − "
          f"elastic {(shift - b - elastic) * 1e9:+.1f} nm); pitch-trace shift "
          f"{-coef[0] * 1e6:.3f} µm")
    print(f"[backlash shift] cruise: fraction inside the gap {in_gap:.3f}, smallest compression "
          f"beyond the driving flank {-depth * 1e9:.0f} nm, driving nut force {force.min():.1f}.."
          f"{force.max():.1f} N; std of x − (1+s)x_cmd fwd {dev[fwd].std() * 1e6:.3f} µm")
    assert in_gap == 0.0
    assert abs(shift - b - elastic) <= 0.5e-6
    assert abs(shift - b) <= 0.5e-6
    quote(f"backlash_shift_beyond_b_um_b{b_um:g}", (shift - b) * 1e6, f"{(shift - b) * 1e6:.2f}")
    quote("backlash_elastic_um", elastic * 1e6, f"{elastic * 1e6:.2f}")


# ---------------------------------------------------------------------------------------------
# Contact with the driving flank; the lead-flank drive


@pytest.fixture(scope="module")
def phase2_passes():
    """Phase II-like run (20, 100, 500 mm/s over 100-300 mm, 0.3 s dwells) of the default world,
    b = 10 µm, 3 K, origin offset 1.3 mm, rolled out with passes = 1, 2 and 3."""
    sim = Simulator(WORLD, DT_SLOW)
    cfg = SCEN.phase2.model_copy(update={"speeds_mm_s": [20.0, 100.0, 500.0], "dwell_s": 0.3,
                                         "start_mm": 100.0, "end_mm": 300.0})
    cmd = command_profile(phase2_moves(cfg), sim.fs, lead_in=PHASE2_LEAD_IN)
    cond = Condition(mech=MechanicalState(preload=F_NOM, backlash=10e-6), temperature_rise=3.0,
                     origin_offset=1.3e-3)
    t0 = time.perf_counter()
    trajs = [sim.run(cond, cmd, passes=k) for k in (1, 2, 3)]
    return sim, cfg, cmd, cond, trajs, time.perf_counter() - t0


def _phase1_traj(world, backlash: float, capture_s: float | None = None):
    """The motion of a Phase I capture (the profile phase1_capture simulates, 400 mm/s, dt 0.1 ms,
    one pass) in the 100-h condition with clearance ``backlash``."""
    sim = Simulator(world, DT_FAST)
    base = cp.condition_at(SCEN, 100.0)
    cond = replace(base, mech=replace(base.mech, backlash=backlash))
    cfg = (SCEN.phase1 if capture_s is None
           else SCEN.phase1.model_copy(update={"capture_s": capture_s}))
    cmd = phase1_profile(cfg, sim.fs, cp.rng_for(SCEN.seed, cp.KIND_PHASE1, 0))
    return sim, cond, sim.run(cond, cmd, passes=1)


@pytest.fixture(scope="module")
def phase1_contact():
    """Phase I captures at 400 mm/s with b = 10 µm and b = 0 (bilateral contact): the default
    world (full 10-s capture), flat rails, and flat rails with the screw's cyclic lead error
    removed (4-s captures)."""
    worlds = {"default": (WORLD, None),
              "flat rails": (replace(WORLD, rails=_flat_rails()), 4.0),
              "flat rails, no cyclic": (replace(WORLD, rails=_flat_rails(),
                                                screw=_no_cyclic(WORLD.screw)), 4.0)}
    return {name: {b: _phase1_traj(world, b, capture_s) for b in (10e-6, 0.0)}
            for name, (world, capture_s) in worlds.items()}


@pytest.mark.quoted
def test_carriage_stays_on_driving_flank(phase2_passes, phase1_contact, quote):
    """The cyclic lead error moves the flanks, so it no longer pushes the carriage into the gap;
    b = 10 µm, constant-speed parts (0.1 s / 0.05 s trimmed after reaching speed).

    - 20 mm/s (Phase II-like run, pass 2): never inside the gap (asserted; the smallest
      compression beyond the flank is printed), the driving nut force stays positive (around the
      12 N rail friction).
    - 400 mm/s (Phase I capture) the carriage does leave the driving flank, and rightly: it does so
      exactly when the nut would have to PULL to keep it on the flank, i.e. when the nut force of
      the same capture with b = 0 (bilateral contact) changes sign (asserted for three worlds).
      In the default world the rail waviness excites the pitch mode, whose Abbe offset
      ZN = −50 mm moves the nut point (x + ZN·pitch) and swings the bilateral nut force far
      beyond the 12 N of rail friction that holds the nut on its flank: the carriage spends a
      large part of the cruise time inside the gap. With flat rails the cyclic lead error alone
      (its 120 Hz line near the axial mode) still takes the force below zero (a small part of the
      cruise time in the gap, shallow); with flat rails and no cyclic error the force stays
      positive and the carriage never enters the gap (asserted).
    Printed for information: the fractions at 100 and 500 mm/s of the Phase II-like run (same
    cause); the printed figures are in docs/validation.md."""
    sim, cfg, cmd, cond, trajs, _ = phase2_passes
    traj = trajs[1]
    for v in cfg.speeds_mm_s:
        idx = _steady(cmd, v * 1e-3, sim.fs, 0.1)
        in_gap, depth = _gap_stats(sim, traj, cond, idx)
        force = _nut_force(sim, traj, cond)[idx] * np.sign(_at_rows(cmd.v)[idx])
        print(f"\n[flank contact] Phase II-like, b = 10 µm, {v:5.0f} mm/s: fraction inside the gap "
              f"{in_gap:.4f}, max depth into the gap {depth * 1e9:+.0f} nm, driving nut force "
              f"{force.min():.1f}..{force.max():.1f} N", end="")
        if v == 20.0:
            assert in_gap == 0.0 and force.min() > 0.0
        if v == max(cfg.speeds_mm_s):
            quote("in_gap_pct_phase2_fastest", 100 * in_gap, f"{100 * in_gap:.0f} %")
    print()
    for name, runs in phase1_contact.items():
        sim1, cond1, traj1 = runs[10e-6]
        idx = _steady(traj1.cmd, SCEN.phase1.speed_mm_s * 1e-3, sim1.fs, 0.05)
        in_gap, depth = _gap_stats(sim1, traj1, cond1, idx)
        sim0, cond0, traj0 = runs[0.0]
        f0 = _nut_force(sim0, traj0, cond0)[idx] * np.sign(_at_rows(traj0.cmd.v)[idx])
        print(f"[flank contact] Phase I 400 mm/s, {name:21s}: b = 10 µm: fraction inside the gap "
              f"{in_gap:.3f}, max depth {depth * 1e9:+.0f} nm; b = 0: driving nut force "
              f"{f0.min():+.1f}..{f0.max():+.1f} N (negative {np.mean(f0 < 0):.3f} of the time)")
        assert (in_gap > 0.0) == (f0.min() < 0.0), name
        if name == "default":
            quote("in_gap_pct_phase1", 100 * in_gap, f"{100 * in_gap:.0f} %")
        if name == "flat rails, no cyclic":
            assert in_gap == 0.0 and f0.min() > 0.0


FLANK_TOLERANCE = 10e-9  # m


def _flank_lines(sim: Simulator, traj, idx: np.ndarray) -> list[tuple[float, complex]]:
    """Least-squares fit of the flank position and of its command over rows ``idx`` on the lines
    of the lead error (1, 2, 3 per revolution) and of the ball pass, in θ_cmd. Returns, per line,
    (order, flank/command complex gain)."""
    th = _at_rows(traj.theta_cmd)[idx]
    eps = _cyclic(sim.world, th)
    orders = (1.0, 2.0, 3.0, float(geo.ball_pass_per_rev(sim.world.screw)))
    cols = [np.ones_like(th), th] + [f(o * th) for o in orders for f in (np.sin, np.cos)]
    design = np.column_stack(cols)
    c_flank, *_ = np.linalg.lstsq(design, traj.qpos[idx, IX.flank], rcond=None)
    c_cmd, *_ = np.linalg.lstsq(design, eps, rcond=None)
    return [(o, complex(*c_flank[2 + 2 * i:4 + 2 * i]) / complex(*c_cmd[2 + 2 * i:4 + 2 * i]))
            for i, o in enumerate(orders)]


def test_lead_flank_follows_command(phase2_passes, phase1_contact):
    """The lead_flank coordinate follows its command ε_cmd(θ_cmd) (cyclic lead error + ball pass,
    0.58 µm summed amplitude): max |qpos[IX.flank] − ε_cmd| over a whole Phase I capture
    (400 mm/s, dt 0.1 ms, b = 10 µm) and over the Phase II-like run with its 500 mm/s moves
    (dt 0.2 ms, b = 10 µm) below 10 nm (a third of the 30 nm ball pass, 1.7 % of the summed
    amplitude), and every line (1, 2, 3 per revolution, ball pass) reproduced within 1 % in
    amplitude and 1° in phase at constant speed.

    What remains is the compliance of the flank drive, F_nut/kp (kp = M·(0.5/dt)²: 0.4 nm/kN at
    0.1 ms, 1.6 nm/kN at 0.2 ms; the nut carries ~2.4 kN when the carriage accelerates at
    19.6 m/s²), printed. (With the central-difference velocity and feed-forward first used in
    Simulator.flank_motion the error was larger, most at 500 mm/s, and the ball-pass line lost
    amplitude and phase there: MuJoCo's implicit damping of the velocity term takes half the
    feed-forward unless the velocity target is the one the step reaches.)"""
    sim2, cfg, cmd, cond2, trajs, _ = phase2_passes
    sim1, cond1, traj1 = phase1_contact["default"][10e-6]
    cases = (("Phase I capture, 400 mm/s", sim1, cond1, traj1, SCEN.phase1.speed_mm_s),
             ("Phase II-like run, 500 mm/s", sim2, cond2, trajs[1], 500.0))
    for name, sim, cond, traj, speed in cases:
        err = traj.qpos[:, IX.flank] - _cyclic(sim.world, _at_rows(traj.theta_cmd))
        idx = _steady(traj.cmd, speed * 1e-3, sim.fs, 0.0)
        kp = -sim.model.actuator_biasprm[sim.model.actuator("lead_flank").id, 1]
        force = np.abs(_nut_force(sim, traj, cond)).max()
        lines = _flank_lines(sim, traj, idx)
        print(f"\n[lead flank] {name}: max |flank − ε_cmd| {np.abs(err[idx]).max() * 1e9:.2f} "
              f"nm at {speed:.0f} mm/s, {np.abs(err).max() * 1e9:.2f} nm over the whole run (rms "
              f"{_rms(err) * 1e9:.2f} nm); max |F_nut|/kp {force / kp * 1e9:.2f} nm "
              f"(max |F_nut| {force:.0f} N)")
        print("[lead flank]   lines (gain, phase): " + ", ".join(
            f"{o:.2f}/rev {abs(g):.5f} {math.degrees(np.angle(g)):+.3f}°" for o, g in lines))
        assert np.abs(err).max() < FLANK_TOLERANCE
        for o, g in lines:
            assert abs(abs(g) - 1.0) <= 0.01 and abs(math.degrees(np.angle(g))) <= 1.0, (o, g)


# ---------------------------------------------------------------------------------------------
# Check 6: Phase I spectra

_LINES = (40.0, 80.0, 120.0)


def _cruise_psd(x: np.ndarray, speed: np.ndarray, fs: float, omega: float, nseg: int = 4096):
    """Mean Hann periodogram of the centre ``nseg`` samples of every constant-speed run (speed
    within 1 % of ``omega`` rad/s). Returns (f, psd, number of runs)."""
    m = np.abs(np.abs(speed) - omega) < 0.01 * omega
    edges = np.flatnonzero(np.diff(np.concatenate([[0], m.astype(int), [0]])))
    psds = []
    for a, b in zip(edges[::2], edges[1::2], strict=False):
        if b - a >= nseg:
            c = (a + b) // 2
            f, p = signal.periodogram(x[c - nseg // 2:c + nseg // 2], fs, window="hann",
                                      detrend="constant")
            psds.append(p)
    return f, np.mean(psds, axis=0), len(psds)


def _line_ratio(f, p, f0) -> float:
    """PSD at the line (max of the 3 nearest bins) over the median PSD 5-15 Hz away."""
    i = int(np.argmin(np.abs(f - f0)))
    near = (np.abs(f - f0) >= 5.0) & (np.abs(f - f0) <= 15.0)
    return float(p[max(i - 1, 0):i + 2].max() / np.median(p[near]))


def _line_psd(f, p, f0) -> float:
    i = int(np.argmin(np.abs(f - f0)))
    return float(p[max(i - 1, 0):i + 2].max())


def _dwell_ring_frequency(acc: np.ndarray, speed: np.ndarray, fs: float, nseg: int = 2048) -> float:
    """Peak (60-250 Hz) of the mean periodogram of the first ``nseg`` samples of each standstill:
    the ring-down of the carriage after the stops."""
    still = np.abs(speed) < 0.5
    edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
    psds = []
    for a, b in zip(edges[::2], edges[1::2], strict=False):
        if b - a > nseg:
            f, p = signal.periodogram(acc[a:a + nseg], fs, window="boxcar", detrend="constant",
                                      nfft=8 * nseg)
            psds.append(p)
    p = np.mean(psds, axis=0)
    band = (f > 60.0) & (f < 250.0)
    return float(f[band][np.argmax(p[band])])


def _linear_axial_mode(sim: Simulator, preload: float) -> float:
    """Axial mode of the servo-held axis linearised in motion (friction sliding, so frictionloss
    removed): the damped eigenvalue between 60 and 250 Hz whose mode shape is dominated by the
    carriage travel x and the screw (R·θ) rather than pitch, Hz. (Carriage, 120 kg, against the
    rotor, J/R² ≈ 130 kg, on the nut spring, damped by the velocity loop.)"""
    m = sim.model
    apply_state(m, sim.world.axis, MechanicalState(preload=preload))
    saved = m.dof_frictionloss.copy()
    m.dof_frictionloss[:] = 0.0
    try:
        d = mujoco.MjData(m)
        d.qpos[IX.x], d.qpos[IX.screw] = 0.2, 0.2 / R
        d.ctrl[IX.servo_pos] = d.qpos[IX.screw]
        mujoco.mj_forward(m, d)
        nx = 2 * m.nv + m.na
        a_mat = np.zeros((nx, nx))
        mujoco.mjd_transitionFD(m, d, 1e-8, True, a_mat, None, None, None)
        lam, vec = np.linalg.eig(a_mat)
    finally:
        m.dof_frictionloss[:] = saved
    s = np.log(lam.astype(complex)) / m.opt.timestep
    # Displacement scale of each dof: screw R·θ; x, y, z, lead flank as they are; angles × 0.1 m.
    scale = np.array([R, 1.0, 1.0, 1.0, 0.1, 0.1, 0.1, 1.0])
    found = []
    for j in np.flatnonzero((s.imag > 2 * math.pi * 60) & (s.imag < 2 * math.pi * 250)):
        shape = np.abs(vec[:m.nv, j]) * scale
        if max(shape[IX.x], shape[IX.screw]) >= shape.max() and shape[IX.pitch] < 0.5 * shape[IX.x]:
            found.append(abs(s[j]) / (2 * math.pi))
    assert len(found) == 1, found
    return float(found[0])


@pytest.fixture(scope="module")
def phase1_runs():
    sim = Simulator(WORLD, DT_FAST)
    base = cp.condition_at(SCEN, 100.0)
    runs = {}
    for frac in PRELOAD_FRACTIONS:
        cond = replace(base, mech=replace(base.mech, preload=frac * F_NOM, backlash=0.0))
        sig = phase1_capture(sim, SCEN.phase1, cond, cp.rng_for(SCEN.seed, cp.KIND_PHASE1, 0))
        runs[frac] = sig
    return sim, runs


@pytest.mark.quoted
def test_phase1_spectral_lines(phase1_runs, quote):
    """Check 6: at 400 mm/s the torque and both nut accelerometers' x axes show the lead-error
    lines at 40, 80, 120 Hz and the ball-pass line (~362 Hz) at least 10× above the median PSD
    5-15 Hz around them, at 100, 50 and 10 % preload (mean periodogram of the constant-speed
    parts, 2.4 Hz resolution)."""
    sim, runs = phase1_runs
    omega = SCEN.phase1.speed_mm_s * 1e-3 / R
    f_bp = float(geo.ball_pass_frequency_hz(SCEN.phase1.speed_mm_s * 1e-3, WORLD.screw))
    lines = _LINES + (f_bp,)
    every = []
    for frac, sig in runs.items():
        for name, x in (("torque", sig["torque"]), ("acc1 x", sig["acc1"][:, 0]),
                        ("acc2 x", sig["acc2"][:, 0])):
            f, p, n = _cruise_psd(x.astype(float), sig["speed"], sig["fs_hz"], omega)
            ratios = [_line_ratio(f, p, f0) for f0 in lines]
            every += ratios
            print(f"\n[phase1 lines] {frac:.0%} {name}: " + ", ".join(
                f"{f0:.0f} Hz ×{r:.0f}" for f0, r in zip(lines, ratios, strict=True)) + f" ({n} runs)", end="")
            assert n >= 4
            assert min(ratios) >= 10.0, (name, frac, dict(zip(lines, ratios, strict=True)))
    print()
    quote("phase1_lines", None, f"40/80/120 Hz and ball-pass ({f_bp:.0f} Hz) lines {min(every):.0f}–"
          f"{max(every):.0f}× above their neighbourhood (torque and both nut accelerometers' x, at 100, "
          "50 and 10 % preload)")


@pytest.mark.quoted
def test_phase1_trends_with_preload(phase1_runs, quote):
    """Check 6, trends as the preload falls 100 → 50 → 10 % (observed and asserted):

    - the axial resonance falls: (i) the ring-down after the stops, in the dwell parts of the
      nut accelerometer (below the locked-screw 131 Hz because MuJoCo's regularised friction on
      the stuck screw and carriage softens the small ring), and (ii) the servo-held axial mode
      linearised in motion (well damped);
    - the 120 Hz line in the nut acceleration (x) grows:
      the lead flank moves by the error e and drives the carriage through the nut spring K; below
      the resonance the carriage follows e as a displacement (acceleration ~ω²·e, independent of
      K) and the falling resonance amplifies the 120 Hz line more. The 40 Hz line (far below
      resonance) stays within 15 %;
    - the ball-pass line (~362 Hz, above the resonance, where the spring passes the force K·e and
      the acceleration is ~K·e/m) falls with K.
    The torque lines follow the same pattern (printed). The resonances and the 40-120 Hz lines
    are those of the earlier force-pair model (K·e on the tendon): with b = 0 the nut never
    leaves its flank, where both give the same spring force. The ball-pass line is a few %
    higher than with the force pair, mostly because that left out the tendon damping's share
    c·ε̇ (~16 % of K·e, in quadrature, at 362 Hz). The printed figures are in
    docs/validation.md."""
    sim, runs = phase1_runs
    omega = SCEN.phase1.speed_mm_s * 1e-3 / R
    f_bp = float(geo.ball_pass_frequency_hz(SCEN.phase1.speed_mm_s * 1e-3, WORLD.screw))
    lines = _LINES + (f_bp,)
    psd120, psd40, psd_bp, ring, modal = [], [], [], [], []
    for frac, sig in runs.items():
        fs = sig["fs_hz"]
        f, p_acc, _ = _cruise_psd(sig["acc1"][:, 0].astype(float), sig["speed"], fs, omega)
        _, p_tq, _ = _cruise_psd(sig["torque"].astype(float), sig["speed"], fs, omega)
        psd120.append(_line_psd(f, p_acc, 120.0))
        psd40.append(_line_psd(f, p_acc, 40.0))
        psd_bp.append(_line_psd(f, p_acc, f_bp))
        ring.append(_dwell_ring_frequency(sig["acc1"][:, 0].astype(float), sig["speed"], fs))
        modal.append(_linear_axial_mode(sim, frac * F_NOM))
        print(f"\n[phase1 trends] {frac:.0%}: acc1 x PSD " + ", ".join(
            f"{f0:.0f} Hz {_line_psd(f, p_acc, f0):.3g}" for f0 in lines) + " (m/s²)²/Hz; torque "
            + ", ".join(f"{f0:.0f} Hz {_line_psd(f, p_tq, f0):.3g}" for f0 in lines)
            + f" (N·m)²/Hz; dwell ring-down {ring[-1]:.1f} Hz; linearised axial mode "
            f"{modal[-1]:.1f} Hz", end="")
    print()
    assert ring[0] > ring[1] > ring[2]
    assert modal[0] > modal[1] > modal[2]
    assert psd120[0] < psd120[1] < psd120[2]
    assert max(psd40) <= 1.15 * min(psd40)
    assert psd_bp[0] > psd_bp[1] > psd_bp[2]
    quote("phase1_trends", None, f"from 100 to 10 % preload the axial resonance falls (ring-down {ring[0]:.1f} → "
          f"{ring[2]:.1f} Hz, linearised mode {modal[0]:.1f} → {modal[2]:.1f} Hz), the 120 Hz acceleration "
          f"line's power grows by {(psd120[2] / psd120[0] - 1) * 100:.0f} % and the ball-pass line's falls to "
          f"{psd_bp[2] / psd_bp[0] * 100:.0f} %")


# ---------------------------------------------------------------------------------------------
# The two-pass rail lookup


def test_two_pass_rail_lookup_converges(phase2_passes):
    """Phase II-like run of the default world (20, 100, 500 mm/s over 100-300 mm, 0.3 s dwells),
    b = 10 µm, origin offset 1.3 mm: passes=1, 2 and 3.

    Asserted: over the constant-speed parts (0.1 s after reaching speed) the axial trajectories of
    passes 1 and 2 differ by < 1 nm rms, and a third pass changes x by < 1 nm rms there and over
    the whole run (pass 2 is a fixed point); the rail input (truck displacements looked up at the
    x of pass 2 vs pass 3) agrees to < 0.1 nm.

    Not asserted, printed: per speed, and over the whole run, where passes 1 and 2 differ by
    more. At the stops and reversals the carriage crosses the 10 µm gap and comes to rest
    somewhere in it (rail friction); where (and the following start transient) is sensitive to
    nm-level differences of the Abbe term ZN·pitch between pass 1 (rails at the command) and
    pass 2, giving rest-position differences in the dwells: indeterminacy of the
    rest point inside the clearance, not a failure of the rail lookup (a 0.3 µm position error
    moves the rail input by < 0.1 nm). Likewise at 500 mm/s, where the carriage rattles in the
    gap (test_carriage_stays_on_driving_flank), passes 1 and 2 differ more than at 20 and
    100 mm/s; the pooled figure is what is asserted (figures: docs/validation.md)."""
    sim, cfg, cmd, cond, trajs, elapsed = phase2_passes
    world = sim.world
    x = [t.x for t in trajs]
    steady = np.concatenate([_steady(cmd, v * 1e-3, sim.fs, 0.1) for v in cfg.speeds_mm_s])
    d12, d23 = x[0] - x[1], x[1] - x[2]
    disp2 = geo.truck_displacements(world.rails, world.carriage, x[1])["vertical"]
    disp3 = geo.truck_displacements(world.rails, world.carriage, x[2])["vertical"]
    rail_change = float(np.abs(disp2 - disp3).max())
    print(f"\n[two-pass] default world ({elapsed:.1f} s for 3 runs): steady speed rms x1−x2 "
          f"{_rms(d12[steady]) * 1e9:.3f} nm, x2−x3 {_rms(d23[steady]) * 1e9:.4f} nm; whole run "
          f"rms x1−x2 {_rms(d12) * 1e9:.1f} nm (max {np.abs(d12).max() * 1e9:.0f} nm), x2−x3 "
          f"{_rms(d23) * 1e9:.3f} nm (max {np.abs(d23).max() * 1e9:.1f} nm); rail input change "
          f"pass 2→3 {rail_change * 1e12:.3f} pm")
    for v in cfg.speeds_mm_s:
        i = _steady(cmd, v * 1e-3, sim.fs, 0.1)
        print(f"[two-pass]   {v:5.0f} mm/s: rms x1−x2 {_rms(d12[i]) * 1e9:.3f} nm, x2−x3 "
              f"{_rms(d23[i]) * 1e9:.4f} nm")
    assert _rms(d12[steady]) < 1e-9
    assert _rms(d23[steady]) < 1e-9
    assert _rms(d23) < 1e-9
    assert rail_change < 0.1e-9
