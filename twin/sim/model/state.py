"""A degradation state in the model's fields: the physical state (:class:`MechanicalState`),
the fields it gives (:func:`state_fields`, :class:`StateFields`), written into a compiled model
in place (:func:`apply_state`); the ball-nut tendon's inverse weight before compiling
(:func:`ballnut_invweight0`) and the constants of the lead flank and the ball-nut contact.
See :mod:`twin.sim.model`, "The ball-nut contact"."""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.sim.axis import Axis
from twin.sim.degradation import contact_stiffness
from twin.sim.model.index import ModelLayoutError
from twin.sim.model.machine_base import BaseMode
from twin.sim.sensors.instruments import STANDARD_GRAVITY as GRAVITY  # m/s²

FLANK_MASS = 1e5  # kg, see the module docstring of twin.sim.model
# Impedance of the ball-nut contact's limit constraint: MuJoCo's smallest (mjMINIMP), constant
# (d_min = d_max; width, midpoint and power then do not matter), see twin.sim.model.
CONTACT_SOLIMP = (mujoco.mjMINIMP, mujoco.mjMINIMP, 0.001, 0.5, 2.0)


@dataclass(frozen=True)
class MechanicalState:
    """The float fields that change with degradation, in SI units.

    Attributes:
        preload: nut preload in N.
        backlash: axial clearance of the ball nut in m (the gap between its flanks, >= 0).
        truck_preload_fraction: truck preload relative to new (1 = new), scales truck stiffness by
            the Hertz rule fraction^(1/3).
        drag_scale: multiplier on the nut drag torque (e.g. thermal viscosity change), 1 = nominal.
        lead_stretch: relative deviation of the effective lead from nominal (dimensionless): the
            cumulative lead error per unit travel plus thermal growth α·ΔT. It is put into the
            ball-nut tendon's screw coefficient −R·(1 + lead_stretch), so this part of the lead
            error is exact kinematics (it can reach tens of µm over the stroke and must not act
            as a force inside the backlash gap).
    """

    preload: float
    backlash: float = 0.0
    truck_preload_fraction: float = 1.0
    drag_scale: float = 1.0
    lead_stretch: float = 0.0


def stiffness_of(axis: Axis, state: MechanicalState) -> dict[str, float]:
    """Physical stiffnesses for a state: axial (N/m), truck vertical and lateral (N/m each)."""
    c, frac = axis.carriage, state.truck_preload_fraction
    return {
        "axial": axis.screw.axial_stiffness(state.preload),
        "truck_vertical": float(contact_stiffness(c.truck_stiffness_vertical, frac, 1.0)),
        "truck_lateral": float(contact_stiffness(c.truck_stiffness_lateral, frac, 1.0)),
    }


def ballnut_invweight0(axis: Axis, base: BaseMode | None = None) -> float:
    """Inverse effective mass of the ball-nut tendon at qpos0, 1/kg: what MuJoCo's compiler stores
    as ``tendon_invweight0`` (J·M⁻¹·Jᵀ of L = x + z_n·pitch − R·θ − ε [− x_b]; the carriage's
    joints sit at its centre of mass on its principal axes, so M is diagonal in these joints):
    1/m + z_n²/I_yy + R²/(J_motor + J_screw) + 1/M_flank, plus 1/M_base with a compliant base."""
    c, s = axis.carriage, axis.screw
    zn = c.nut_height - c.com_height
    inv = (1.0 / c.mass + zn**2 / c.inertia[1]
           + s.radius_per_rad**2 / (axis.servo.motor_inertia + s.screw_inertia) + 1.0 / FLANK_MASS)
    return inv + (1.0 / base.mass if base is not None else 0.0)


@dataclass(frozen=True)
class StateFields:
    """The model's fields for one state, in SI units.

    Attributes:
        nut_stiffness, nut_damping: the ball-nut contact's K (N/m) and C = 2ζ·√(K·m) (N·s/m), of
            both flanks together when b = 0, of the flank in contact when b > 0.
        tendon_stiffness, tendon_damping: (9,) N/m and N·s/m, tendon order ballnut,
            truck_v0, truck_l0, ..., truck_v3, truck_l3 (as in :func:`twin.sim.model.spec.build_spec`). The ball
            nut's are K and C when b = 0 and 0 when b > 0 (its contact is then the limit
            constraint).
        tendon_lengthspring: (9, 2) m (0 0 for the ball nut; the weight-carrying rest length of
            the vertical trucks).
        ballnut_limited: whether the ball nut's contact is its limit constraint (b > 0).
        ballnut_range: (2,) −b/2, +b/2, m: the flanks.
        ballnut_solreflimit: (2,) the direct solref (−K·Â, −C·Â), Â the tendon's
            ``tendon_invweight0`` (see the module docstring).
        ballnut_solimplimit: (5,) :data:`CONTACT_SOLIMP`.
        screw_frictionloss: nut drag torque, N·m.
        screw_coef: the ball-nut tendon's coefficient of the screw joint, −R·(1 + lead_stretch),
            m/rad.
    """

    nut_stiffness: float
    nut_damping: float
    tendon_stiffness: np.ndarray
    tendon_damping: np.ndarray
    tendon_lengthspring: np.ndarray
    ballnut_limited: bool
    ballnut_range: np.ndarray
    ballnut_solreflimit: np.ndarray
    ballnut_solimplimit: np.ndarray
    screw_frictionloss: float
    screw_coef: float


def state_fields(axis: Axis, state: MechanicalState, ballnut_invweight: float) -> StateFields:
    """The fields of the model in ``state`` (one source for the spec and for
    :func:`apply_state`). ``ballnut_invweight``: Â of the ball-nut tendon, 1/kg (the model's
    ``tendon_invweight0``, :func:`ballnut_invweight0` before compiling).

    Raises ValueError for a negative backlash or a Â that is not positive and finite."""
    if not state.backlash >= 0.0:
        raise ValueError(f"backlash {state.backlash!r} m: the ball nut's clearance must be >= 0")
    if not (math.isfinite(ballnut_invweight) and ballnut_invweight > 0.0):
        raise ValueError(f"ball-nut inverse weight {ballnut_invweight!r} 1/kg: must be positive and "
                         "finite (the compiled model's tendon_invweight0)")
    k = stiffness_of(axis, state)
    c = axis.carriage
    # Effective mass of the axial mode with the screw held by the servo: the carriage.
    k_nut = k["axial"]
    c_nut = 2.0 * axis.screw.contact_damping_ratio * math.sqrt(k_nut * c.mass)
    gap = state.backlash > 0.0
    stiff = [0.0 if gap else k_nut]
    damp = [0.0 if gap else c_nut]
    rest = [(0.0, 0.0)]
    # The rest length carries the weight, so the equilibrium is at carriage_z = 0.
    sag = c.mass * GRAVITY / (4.0 * k["truck_vertical"])
    for _ in range(4):
        for key, length in (("truck_vertical", sag), ("truck_lateral", 0.0)):
            stiff.append(k[key])
            damp.append(2.0 * c.truck_damping_ratio * math.sqrt(k[key] * c.mass / 4.0))
            rest.append((length, length))
    return StateFields(
        nut_stiffness=k_nut, nut_damping=c_nut,
        tendon_stiffness=np.array(stiff), tendon_damping=np.array(damp),
        tendon_lengthspring=np.array(rest), ballnut_limited=gap,
        ballnut_range=np.array([-state.backlash / 2.0, state.backlash / 2.0]),
        ballnut_solreflimit=np.array([-k_nut * ballnut_invweight, -c_nut * ballnut_invweight]),
        ballnut_solimplimit=np.array(CONTACT_SOLIMP),
        screw_frictionloss=axis.screw.drag_torque(state.preload) * state.drag_scale,
        screw_coef=-axis.screw.radius_per_rad * (1.0 + state.lead_stretch))


def apply_state(model: mujoco.MjModel, axis: Axis, state: MechanicalState) -> None:
    """Write a degradation state into the model's fields (in place).

    Raises :class:`ModelLayoutError` when the model cannot carry the ball-nut contact as built
    (tendon order, the screw's place in the ball-nut tendon, a limit margin, limits disabled);
    ValueError for a negative backlash (:func:`state_fields`)."""
    if model.tendon("ballnut").id != 0 or model.tendon("truck_l3").id != model.ntendon - 1:
        raise ModelLayoutError("the tendons are expected in the order ballnut, truck_v0, truck_l0, ..., "
                               "truck_l3 (state_fields writes their parameters as one array)")
    ballnut = model.tendon("ballnut").id
    if model.tendon_margin[ballnut] != 0.0:
        raise ModelLayoutError(f"the ball-nut tendon has a limit margin {model.tendon_margin[ballnut]!r} m; "
                               "it must be 0, or its flank contact would act inside the backlash gap")
    if model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_LIMIT:
        raise ModelLayoutError("limit constraints are disabled (mjDSBL_LIMIT): the ball nut's flank "
                               "contact with backlash is a tendon limit and would vanish")
    f = state_fields(axis, state, float(model.tendon_invweight0[ballnut]))
    model.tendon_stiffness[:] = f.tendon_stiffness
    model.tendon_damping[:] = f.tendon_damping
    model.tendon_lengthspring[:] = f.tendon_lengthspring
    model.tendon_limited[ballnut] = f.ballnut_limited
    model.tendon_range[ballnut] = f.ballnut_range
    model.tendon_solref_lim[ballnut] = f.ballnut_solreflimit
    model.tendon_solimp_lim[ballnut] = f.ballnut_solimplimit
    model.dof_frictionloss[model.joint("screw").dofadr[0]] = f.screw_frictionloss
    # The screw is the third joint of the ball-nut tendon (see build_spec).
    wrap = model.tendon_adr[ballnut] + 2
    if model.wrap_objid[wrap] != model.joint("screw").id:
        raise ModelLayoutError("the third joint of the ball-nut tendon is not the screw hinge; "
                               "its coefficient (the lead) cannot be set")
    model.wrap_prm[wrap] = f.screw_coef
