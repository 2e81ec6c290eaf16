"""The ball nut's contact (issue 13, item 6): with a clearance b > 0 the nut transmits no force
inside the gap, and on a flank it is a Kelvin–Voigt contact K·δ + C·δ' that only pushes (the
tendon's limit constraint, see twin.sim.model); with b = 0 it is the bilateral spring and damper.

The nut's force on the carriage is read from MuJoCo, not from the contact law: the ball-nut
tendon's passive force (``qfrc_passive`` of ``carriage_x``, whose coefficient in the tendon is 1
and which no other tendon moves) plus the generalised force of the tendon-limit constraint rows
(``efc_type == mjCNSTR_LIMIT_TENDON``; the ball nut is the only limited tendon) on ``carriage_x``.
``pytest -s`` prints the figures.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from twin.sim.model import (
    BaseMode,
    MechanicalState,
    ModelIndex,
    ModelLayoutError,
    apply_state,
    ballnut_invweight0,
    build_mjcf,
    build_model,
    state_fields,
)
from twin.sim.scenario import Scenario, to_axis

AXIS = to_axis(Scenario())
DT = Scenario().phase1.timestep_s
IX = ModelIndex.of(build_model(AXIS, DT))
B = 10e-6  # m, the clearance of the gap tests
V_CROSS = 9e-3  # m/s: a 10 µm gap crossed at a 400 mm/s reversal (module docstring of twin.sim.model)


def _model(backlash: float, axis=AXIS) -> tuple[mujoco.MjModel, object]:
    model = build_model(axis, DT)
    state = MechanicalState(preload=axis.screw.preload, backlash=backlash)
    apply_state(model, axis, state)
    return model, state_fields(axis, state, float(model.tendon_invweight0[0]))


def _dead_band(model: mujoco.MjModel, fields, backlash: float) -> None:
    """The contact as it was before item 6: a passive dead-band spring with the damper acting
    everywhere, inside the gap too."""
    ballnut = model.tendon("ballnut").id
    model.tendon_limited[ballnut] = False
    model.tendon_stiffness[ballnut] = fields.nut_stiffness
    model.tendon_damping[ballnut] = fields.nut_damping
    model.tendon_lengthspring[ballnut] = (-backlash / 2.0, backlash / 2.0)


def _nut_force_x(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[float, float]:
    """(passive, limit constraint) force of the ball-nut tendon on carriage_x, N, of the state
    the last mj_step started from."""
    dof = model.joint("carriage_x").dofadr[0]
    rows = np.zeros(data.nefc)
    limit = data.efc_type[:data.nefc] == mujoco.mjtConstraint.mjCNSTR_LIMIT_TENDON
    rows[limit] = data.efc_force[:data.nefc][limit]
    generalised = np.zeros(model.nv)
    if data.nefc:
        mujoco.mj_mulJacTVec(model, data, generalised, rows)
    return float(data.qfrc_passive[dof]), float(generalised[dof])


def _cross_and_rebound(model: mujoco.MjModel, duration: float, lock_screw: bool = False) -> np.ndarray:
    """The carriage starts 0.5 µm inside the lower flank at V_CROSS, screw held by the servo at 0
    (``lock_screw``: and locked, armature 1e6, so that the flank is rigid), and runs ``duration``
    s: across the gap, onto the upper flank and back. Rows: tendon length L (m), its rate (m/s),
    passive force, constraint force (N), of the state each step started from."""
    if lock_screw:
        model.dof_armature[model.joint("screw").dofadr[0]] = 1e6
    data = mujoco.MjData(model)
    data.qpos[IX.x] = -B / 2.0 + 0.5e-6
    data.qvel[IX.x] = V_CROSS
    out = np.empty((int(round(duration / DT)), 4))
    for k in range(out.shape[0]):
        mujoco.mj_step(model, data)
        out[k] = (data.ten_length[0], data.ten_velocity[0], *_nut_force_x(model, data))
    return out


def test_no_force_inside_the_gap():
    """Crossing the 10 µm gap at 9 mm/s the carriage feels less than 1 N from the nut (measured:
    0); the dead band crossed is asserted (from within 1 µm of one flank to within 1 µm of the
    other). The same crossing with the former dead-band spring, whose damper acts inside the gap
    too, feels C·v = 55 N (asserted > 1 N and within 10 % of C·v): the test can fail."""
    new, fields = _model(B)
    old = build_model(AXIS, DT)
    apply_state(old, AXIS, MechanicalState(preload=AXIS.screw.preload, backlash=B))
    _dead_band(old, fields, B)
    drag = {}
    for name, model in (("limit constraint", new), ("dead band (before)", old)):
        run = _cross_and_rebound(model, 1.6 * B / V_CROSS)
        inside = np.abs(run[:, 0]) < B / 2.0
        assert run[inside, 0].min() < -B / 2.0 + 1e-6 and run[inside, 0].max() > B / 2.0 - 1e-6, name
        assert inside.sum() >= 5, name
        force = run[inside, 2] + run[inside, 3]
        drag[name] = np.abs(force).max()
        print(f"\n[gap] {name}: {inside.sum()} steps inside the gap, L {run[inside, 0].min() * 1e6:+.2f}"
              f"..{run[inside, 0].max() * 1e6:+.2f} µm at {run[inside, 1].mean() * 1e3:.2f} mm/s; max "
              f"|nut force| {drag[name]:.3g} N (passive {np.abs(run[inside, 2]).max():.3g}, "
              f"constraint {np.abs(run[inside, 3]).max():.3g}); C·v = {fields.nut_damping * V_CROSS:.1f} N",
              end="")
    assert drag["limit constraint"] < 1.0
    assert drag["dead band (before)"] > 1.0
    assert drag["dead band (before)"] == pytest.approx(fields.nut_damping * V_CROSS, rel=0.1)


@pytest.mark.parametrize("zeta", [None, 0.5])
def test_flank_contact_only_pushes(zeta):
    """b = 10 µm, screw locked: the carriage crosses the gap at 9 mm/s, hits the upper flank and
    rebounds (its mass on K: a 3.7 ms half period), up to the gap's middle. On the
    flank the nut's force is the constraint alone (passive 0) and it never pulls (F_x ≤ 0 on the
    upper flank, 0 off it); where the Kelvin–Voigt law K·δ + C·δ' is positive the force equals it
    within 0.1 % + 0.05 N (the impedance's leak, 1e-4 of the other forces). At the end of the
    rebound the law turns negative (the damper would pull) while δ < C·|δ'|/K: 0.6 nm with the
    axis's ζ = 0.03 (rarely a sampled step), about 10 nm with a contact damping ratio of 0.5,
    where the force is asserted to be 0 on such steps, and such steps to exist (the clamp is
    tested)."""
    axis = AXIS if zeta is None else to_axis(Scenario.model_validate(
        {"axis": {"contact_damping_ratio": zeta}}))
    model, fields = _model(B, axis)
    run = _cross_and_rebound(model, 8e-3, lock_screw=True)
    hit = int(np.argmax(run[:, 0] > B / 2.0))
    run = run[:hit + int(np.argmax(run[hit:, 0] < 0.0))]  # until back in the gap's middle
    length, rate, passive, constraint = run.T
    delta = length - B / 2.0  # compression of the upper flank
    law = fields.nut_stiffness * delta + fields.nut_damping * rate
    on = delta > 0.0
    pulls = on & (law < 0.0)
    print(f"\n[flank] ζ {axis.screw.contact_damping_ratio}: max compression {delta.max() * 1e6:.2f} µm, "
          f"peak force {-constraint.min():.1f} N, rebound speed {-rate[-1] * 1e3:.2f} mm/s (hit at "
          f"{V_CROSS * 1e3:.0f}); {on.sum()} steps on the flank, {pulls.sum()} where K·δ + C·δ' < 0 "
          f"(down to {law[pulls].min() if pulls.any() else 0:.1f} N), force there "
          f"{np.abs(constraint[pulls]).max() if pulls.any() else 0:.3g} N")
    assert on.sum() >= 5 and rate[-1] < 0.0  # it hit the flank and came back
    assert np.all(passive == 0.0)
    assert np.all(constraint <= 0.0)  # pushes the carriage back (−x), never pulls it (+x)
    assert np.all(constraint[~on] == 0.0)
    push = on & (law > 0.0)
    assert np.all(np.abs(-constraint[push] - law[push]) <= 1e-3 * law[push] + 0.05)
    assert np.all(constraint[pulls] == 0.0)
    if zeta is not None:
        assert pulls.sum() >= 3


def _two_dof_damping_ratio(fields) -> float:
    """Damping ratio of the axial mode of the carriage on x and pitch (screw locked): the nut's K,
    C act on x + z_n·pitch, the trucks' vertical springs and dampers on the pitch."""
    c = AXIS.carriage
    zn, a = c.nut_height - c.com_height, c.truck_spacing / 2.0
    k, cn = fields.nut_stiffness, fields.nut_damping
    kv, cv = fields.tendon_stiffness[1], fields.tendon_damping[1]
    mass = np.diag([c.mass, c.inertia[1]])
    stiff = np.array([[k, k * zn], [k * zn, 4 * kv * a * a + k * zn * zn]])
    damp = np.array([[cn, cn * zn], [cn * zn, 4 * cv * a * a + cn * zn * zn]])
    inv = np.linalg.inv(mass)
    state = np.block([[np.zeros((2, 2)), np.eye(2)], [-inv @ stiff, -inv @ damp]])
    ev = np.linalg.eigvals(state)
    low = min(ev[ev.imag > 0], key=abs)
    return float(-low.real / abs(low))


def _ring_in_contact(backlash: float, push: float) -> tuple[np.ndarray, object]:
    """Tendon length L(t), m, of a ring-down on a flank: screw locked (armature 1e6), rail and nut
    friction 0, the carriage pressed by ``push`` N along x (the ``rail_stribeck`` force) and settled
    with heavy joint damping, then kicked by 0.5 mm/s (about 0.6 µm of ring, a quarter of the
    2.3 µm static compression, so it never leaves the flank) and rung for 0.15 s."""
    model, fields = _model(backlash)
    model.dof_armature[model.joint("screw").dofadr[0]] = 1e6
    model.dof_frictionloss[:] = 0.0
    data = mujoco.MjData(model)
    data.qpos[IX.x] = math.copysign(backlash / 2.0, push) + push / fields.nut_stiffness
    data.ctrl[IX.stribeck] = push
    damping = model.dof_damping.copy()
    model.dof_damping[:] = 1e5
    for _ in range(int(round(0.3 / DT))):
        mujoco.mj_step(model, data)
    model.dof_damping[:] = damping
    data.qvel[IX.x] += 0.5e-3
    length = np.empty(int(round(0.15 / DT)))
    for k in range(length.size):
        mujoco.mj_step(model, data)
        length[k] = data.ten_length[0]
    return length, fields


def _damping_ratio(length: np.ndarray) -> tuple[float, float]:
    """(ζ, damped frequency in Hz) from the positive peaks of a ring-down about its final half's
    mean, those above a tenth of the first (the rest is at the level of the slow drift of the
    mean): a line through log(peak) against time gives the decay rate σ, the peak spacing ω_d,
    ζ = σ/√(σ² + ω_d²)."""
    y = length - length[length.size // 2:].mean()
    peaks = np.flatnonzero((y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:]) & (y[1:-1] > 0.0)) + 1
    low = y[peaks] < 0.1 * y[peaks[0]]
    peaks = peaks[:int(np.argmax(low))] if low.any() else peaks
    assert peaks.size >= 8, "too short a ring-down to measure its damping"
    t = peaks * DT
    sigma = -np.polyfit(t, np.log(y[peaks]), 1)[0]
    omega_d = 2.0 * math.pi * (peaks.size - 1) / (t[-1] - t[0])
    return float(sigma / math.hypot(sigma, omega_d)), float(omega_d / (2.0 * math.pi))


@pytest.mark.parametrize(("backlash", "push"), [(0.0, 200.0), (B, 200.0), (B, -200.0)])
def test_contact_damping_ratio(backlash, push):
    """In contact the axial mode's damping ratio is the axis's ζ = contact_damping_ratio (0.03)
    within 10 %, and the two-degree-of-freedom (x, pitch) value within 3 %: the nut sits z_n below
    the centre of mass, so the axial mode carries some pitch, whose trucks damp it a little less
    (ζ = 0.0274 for 0.03). The same for b = 0 (both flanks, the passive spring and damper) and
    for b > 0 on either flank (the limit constraint, never leaving the flank: asserted). A damper
    in the constraint with the spring left passive damps about half as much (the clamp removes its
    pull on the rebound of each cycle; measured the same way: ζ = 0.014 at b = 10 µm): outside both
    bounds."""
    length, fields = _ring_in_contact(backlash, push)
    zeta, freq = _damping_ratio(length)
    zeta_nominal = AXIS.screw.contact_damping_ratio
    zeta_2dof = _two_dof_damping_ratio(fields)
    flank = math.copysign(backlash / 2.0, push)
    print(f"\n[contact ζ] b = {backlash * 1e6:.0f} µm, push {push:+.0f} N: ζ {zeta:.5f} at {freq:.2f} Hz "
          f"(axis {zeta_nominal}, x-pitch model {zeta_2dof:.5f}); L {length.min() * 1e6:+.2f}.."
          f"{length.max() * 1e6:+.2f} µm, flank at {flank * 1e6:+.1f} µm")
    if backlash > 0.0:
        assert np.all(np.sign(push) * (length - flank) > 0.0)  # never leaves the flank
    assert abs(zeta - zeta_nominal) <= 0.10 * zeta_nominal
    assert abs(zeta - zeta_2dof) <= 0.03 * zeta_2dof


@pytest.mark.parametrize("base", [None, BaseMode(mass=500.0, frequency=100.0, damping_ratio=0.05)])
def test_contact_fields_agree_between_the_mjcf_and_apply_state(base):
    """Â of the ball-nut tendon: the analytic 1/m + z_n²/I_yy + R²/J + 1/M_flank (+ 1/M_base) is
    the compiler's ``tendon_invweight0`` (within 1e-12), so the MJCF's ``solreflimit`` is what
    :func:`apply_state` writes for the new state; with backlash apply_state switches the contact
    to the limit and back."""
    model = build_model(AXIS, DT, base)
    assert ballnut_invweight0(AXIS, base) == pytest.approx(model.tendon_invweight0[0], rel=1e-12)
    compiled = (model.tendon_limited[0], model.tendon_range[0].copy(), model.tendon_solref_lim[0].copy(),
                model.tendon_solimp_lim[0].copy(), model.tendon_stiffness[0], model.tendon_damping[0])
    apply_state(model, AXIS, MechanicalState(preload=AXIS.screw.preload, backlash=B))
    assert model.tendon_limited[0] and model.tendon_stiffness[0] == model.tendon_damping[0] == 0.0
    assert np.array_equal(model.tendon_range[0], [-B / 2.0, B / 2.0])
    apply_state(model, AXIS, MechanicalState(preload=AXIS.screw.preload))
    assert not compiled[0] and not model.tendon_limited[0]
    for a, b in zip(compiled[1:], (model.tendon_range[0], model.tendon_solref_lim[0], model.tendon_solimp_lim[0],
                                   model.tendon_stiffness[0], model.tendon_damping[0]), strict=True):
        assert np.allclose(a, b, rtol=1e-12, atol=0.0)
    assert 'limited="false"' in build_mjcf(AXIS, DT, base)


def test_contact_invariants():
    """A negative clearance, a ball-nut limit margin (the contact would act inside the gap) and
    disabled limits are refused with their reason."""
    model = build_model(AXIS, DT)
    with pytest.raises(ValueError, match="clearance must be >= 0"):
        apply_state(model, AXIS, MechanicalState(preload=AXIS.screw.preload, backlash=-1e-6))
    with pytest.raises(ValueError, match="positive and finite"):
        state_fields(AXIS, MechanicalState(preload=AXIS.screw.preload), 0.0)
    model.tendon_margin[0] = 1e-6
    with pytest.raises(ModelLayoutError, match="limit margin"):
        apply_state(model, AXIS, MechanicalState(preload=AXIS.screw.preload, backlash=B))
    model.tendon_margin[0] = 0.0
    model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_LIMIT
    with pytest.raises(ModelLayoutError, match="limit constraints are disabled"):
        apply_state(model, AXIS, MechanicalState(preload=AXIS.screw.preload, backlash=B))
