"""The axis model built with MuJoCo's model-editing API: :func:`build_spec` adds the bodies,
joints, tendons, actuators and sensors described in :mod:`twin.sim.model` to a
``mujoco.MjSpec``, :func:`build_model` compiles it.

The spec is what an MJCF file of the same model parses into (MuJoCo documentation, Programming
chapter, "Model Editing": "This data structure is in one-to-one correspondence with MJCF";
mujoco.readthedocs.io/en/4.0.0/programming/modeledit.html), so each element below names the MJCF
attribute it stands for where the spec's name differs. Every number enters the spec as the float
computed here (no text in between), and the compiled model equals, array for array, the one the
MJCF text of version 3e88f11 compiled to (tests/test_model_spec.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco

from twin.sim.axis import Axis
from twin.sim.model.index import ModelIndex
from twin.sim.model.machine_base import BaseMode, check_base_mode
from twin.sim.model.state import (
    FLANK_MASS,
    GRAVITY,
    MechanicalState,
    StateFields,
    ballnut_invweight0,
    state_fields,
)

TRUCKS = ("FL", "FR", "RL", "RR")
MODEL_NAME = "ballscrew_linear_axis"

_HINGE, _SLIDE = mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE
_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
# MJCF <pid input="pos vel ff">: three control inputs, position, velocity and feed-forward (the
# actuator's ctrlspec, a bit set of mjtCtrlInput).
_PID_INPUTS = int(mujoco.mjtCtrlInput.mjINPUT_POS | mujoco.mjtCtrlInput.mjINPUT_VEL
                  | mujoco.mjtCtrlInput.mjINPUT_FF)
_DEFAULT_SITE_SIZE = 0.005  # m, MuJoCo's default site size (MJCF size="r" sets only the first)


@dataclass(frozen=True)
class TruckLayout:
    """Truck contact positions relative to the centre of mass, m: x_i (4,), y_i (4,), h (scalar)."""

    x: tuple[float, float, float, float]
    y: tuple[float, float, float, float]
    height_below_com: float

    @classmethod
    def of(cls, axis: Axis) -> TruckLayout:
        a = axis.carriage.truck_spacing / 2.0
        w = axis.carriage.rail_spacing / 2.0
        # FL, FR, RL, RR: front = +X, left = −Y (rail 0), right = +Y (rail 1).
        return cls(x=(a, a, -a, -a), y=(-w, w, -w, w), height_below_com=axis.carriage.com_height)


def _display_geom(body: mujoco.MjsBody, rgba: tuple[float, float, float, float], **geom) -> None:
    """A massless geom for display only: no collisions (contype = conaffinity = 0), mass 0."""
    body.add_geom(contype=0, conaffinity=0, mass=0.0, rgba=list(rgba), **geom)


def _inertial(body: mujoco.MjsBody, mass: float, diaginertia, pos=(0.0, 0.0, 0.0)) -> None:
    """The body's explicit inertia (MJCF ``<inertial pos mass diaginertia>``): mass in kg, the
    principal moments (3,) in kg·m² at ``pos`` (3,) m in the body frame, principal axes along the
    body's. ``explicitinertial`` marks them as given, as the MJCF parser does for ``<inertial>``,
    so that the compiler does not infer them from the geoms."""
    body.mass = float(mass)
    body.inertia = [float(v) for v in diaginertia]
    body.ipos = [float(v) for v in pos]
    body.explicitinertial = True


def _friction_solver(axis: Axis) -> dict:
    """The soft-constraint parameters of a friction joint (MJCF ``solreffriction`` (timeconst,
    dampratio) and ``solimpfriction`` (d0, dwidth, width, midpoint, power)) for the axis's
    settings; {} keeps MuJoCo's defaults (see :class:`twin.sim.axis.Axis`)."""
    out = {}
    if axis.friction_timeconst is not None:
        out["solref_friction"] = [float(axis.friction_timeconst), 1.0]
    if axis.friction_impedance is not None:
        d = float(axis.friction_impedance)
        out["solimp_friction"] = [d, d, 0.001, 0.5, 2.0]
    return out


def _spring(tendon: mujoco.MjsTendon, new: StateFields, i: int) -> None:
    """The passive spring and damper of tendon ``i`` (order of :class:`StateFields`): a linear
    stiffness (N/m; the spec's ``stiffness`` holds the coefficients of MuJoCo's polynomial
    spring, the first is the linear one) about the rest length ``springlength`` (lo, hi) m and a
    linear damping (N·s/m, likewise)."""
    tendon.springlength = [float(v) for v in new.tendon_lengthspring[i]]
    tendon.stiffness = [float(new.tendon_stiffness[i]), 0.0, 0.0]
    tendon.damping = [float(new.tendon_damping[i]), 0.0, 0.0]


def _bodies(spec: mujoco.MjSpec, axis: Axis, base: BaseMode | None) -> None:
    """The worldbody: the machine bed (a display geom), the screw, the carriage, the lead flank
    and, with a compliant base, the base (appended last so that the qpos indices stay)."""
    c, s = axis.carriage, axis.screw
    zn = c.nut_height - c.com_height  # nut axis relative to the centre of mass (m, negative)
    zi = c.imu_height - c.com_height
    half_travel = axis.travel / 2.0
    fric = _friction_solver(axis)
    world = spec.worldbody
    world.add_geom(name="base", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[half_travel, 0.0, -0.06],
                   size=[half_travel + 0.1, 0.2, 0.02], contype=0, conaffinity=0, rgba=[0.5, 0.5, 0.5, 1.0])

    screw = world.add_body(name="screw", pos=[0.0, 0.0, c.nut_height])
    screw.add_joint(name="screw", type=_HINGE, axis=_X, armature=axis.servo.motor_inertia,
                    damping=[s.drag_viscous, 0.0, 0.0], frictionloss=s.drag_torque(s.preload), **fric)
    _inertial(screw, s.screw_mass, (s.screw_inertia, 0.05, 0.05), pos=(half_travel, 0.0, 0.0))
    _display_geom(screw, (0.7, 0.7, 0.75, 1.0), type=mujoco.mjtGeom.mjGEOM_CYLINDER,
               fromto=[0.0, 0.0, 0.0, axis.travel, 0.0, 0.0], size=[s.root_diameter / 2, 0.0, 0.0])

    carriage = world.add_body(name="carriage", pos=[0.0, 0.0, c.com_height])
    carriage.add_joint(name="carriage_x", type=_SLIDE, axis=_X, frictionloss=c.rail_friction, **fric)
    for name, kind, ax in (("carriage_y", _SLIDE, _Y), ("carriage_z", _SLIDE, _Z), ("carriage_roll", _HINGE, _X),
                           ("carriage_pitch", _HINGE, _Y), ("carriage_yaw", _HINGE, _Z)):
        carriage.add_joint(name=name, type=kind, axis=ax)
    _inertial(carriage, c.mass, c.inertia)
    box = mujoco.mjtGeom.mjGEOM_BOX
    _display_geom(carriage, (0.3, 0.4, 0.8, 1.0), type=box, size=[0.1, 0.13, 0.02],
                  pos=[0.0, 0.0, -c.com_height + 0.02])
    _display_geom(carriage, (0.25, 0.25, 0.25, 1.0), type=box, size=[0.08, 0.08, 0.06], pos=[0.0, 0.0, zi - 0.07])
    layout = TruckLayout.of(axis)
    sites = [("imu", (0.0, 0.0, zi), 0.01), ("nut", (0.0, 0.0, zn), 0.01),
             ("nut_acc1", (0.02, 0.025, zn + 0.02), 0.005), ("nut_acc2", (-0.02, -0.025, zn - 0.02), 0.005)]
    sites += [(f"truck_{n}", (layout.x[i], layout.y[i], -layout.height_below_com), 0.01)
              for i, n in enumerate(TRUCKS)]
    for name, pos, radius in sites:
        carriage.add_site(name=name, pos=list(pos), size=[radius, _DEFAULT_SITE_SIZE, _DEFAULT_SITE_SIZE])

    flank = world.add_body(name="lead_flank")
    flank.add_joint(name="lead_flank", type=_SLIDE, axis=_X)
    _inertial(flank, FLANK_MASS, (1.0, 1.0, 1.0))

    if base is not None:
        body = world.add_body(name="base")
        body.add_joint(name="base_x", type=_SLIDE, axis=_X, springref=0.0, stiffness=[base.stiffness, 0.0, 0.0],
                       damping=[base.damping, 0.0, 0.0])
        _inertial(body, base.mass, (1.0, 1.0, 1.0))


def _tendons(spec: mujoco.MjSpec, axis: Axis, new: StateFields, base: BaseMode | None) -> None:
    """The fixed tendons, in the order :func:`twin.sim.model.state.apply_state` expects: the ball
    nut (L = x + z_n·pitch − R·θ − ε [− x_b]) with its contact, then truck_v<i>, truck_l<i>."""
    c = axis.carriage
    zn = c.nut_height - c.com_height
    nut = spec.add_tendon(name="ballnut")
    _spring(nut, new, 0)
    # The flank contact (see twin.sim.model): MJCF limited / range / solreflimit / solimplimit.
    nut.limited = mujoco.mjtLimited.mjLIMITED_TRUE if new.ballnut_limited else mujoco.mjtLimited.mjLIMITED_FALSE
    nut.range = [float(v) for v in new.ballnut_range]
    nut.solref_limit = [float(v) for v in new.ballnut_solreflimit]
    nut.solimp_limit = [float(v) for v in new.ballnut_solimplimit]
    for joint, coef in (("carriage_x", 1.0), ("carriage_pitch", zn), ("screw", -axis.screw.radius_per_rad),
                        ("lead_flank", -1.0)):
        nut.wrap_joint(joint, coef)
    if base is not None:
        nut.wrap_joint("base_x", -1.0)
    layout = TruckLayout.of(axis)
    for i in range(len(TRUCKS)):
        xi, yi, h = layout.x[i], layout.y[i], layout.height_below_com
        vertical = spec.add_tendon(name=f"truck_v{i}")
        _spring(vertical, new, 1 + 2 * i)
        for joint, coef in (("carriage_z", 1.0), ("carriage_roll", yi), ("carriage_pitch", -xi)):
            vertical.wrap_joint(joint, coef)
        lateral = spec.add_tendon(name=f"truck_l{i}")
        _spring(lateral, new, 2 + 2 * i)
        for joint, coef in (("carriage_y", 1.0), ("carriage_yaw", xi), ("carriage_roll", h)):
            lateral.wrap_joint(joint, coef)


def _motor(spec: mujoco.MjSpec, name: str, trn: mujoco.mjtTrn, target: str, gear=(1.0, 0, 0, 0, 0, 0)) -> None:
    """A ``<motor>``: force = gear · control on a joint, tendon or site (``gear`` (6,): for a site
    the force and torque directions in the site's frame)."""
    act = spec.add_actuator(name=name, trntype=trn, target=target, gear=[float(v) for v in gear])
    act.set_to_motor()


def _actuators(spec: mujoco.MjSpec, axis: Axis, timestep: float) -> None:
    """The actuators in the order of :class:`twin.sim.model.ModelIndex`'s control columns: the
    servo (a PID with position, velocity and feed-forward inputs and the motor's torque limit),
    the ripple motor, the lead flank's stiff PID, the rail force pairs, runout, nut_axial and
    rail_stribeck. ``timestep`` in s sets the flank drive's gains (kp = M·(0.5/dt)², critically
    damped)."""
    joint, tendon, site = mujoco.mjtTrn.mjTRN_JOINT, mujoco.mjtTrn.mjTRN_TENDON, mujoco.mjtTrn.mjTRN_SITE
    kp, ki, kd = axis.servo_gains()
    servo = spec.add_actuator(name="servo", trntype=joint, target="screw")
    # MJCF <pid kp kv ki input="pos vel ff">; the spec's shortcut mjs_setToPID (MuJoCo API
    # reference, "mjs_setTo*" actuator shortcuts) sets gain, bias and dynamics as the parser does.
    servo.set_to_pid(kp=kp, kv=kd, ki=ki, ctrlspec=_PID_INPUTS)
    servo.forcerange = [-axis.servo.torque_limit, axis.servo.torque_limit]  # forcelimited by autolimits
    _motor(spec, "ripple", joint, "screw")
    flank_kp = FLANK_MASS * (0.5 / timestep) ** 2
    flank = spec.add_actuator(name="lead_flank", trntype=joint, target="lead_flank")
    flank.set_to_pid(kp=flank_kp, kv=2.0 * math.sqrt(flank_kp * FLANK_MASS), ctrlspec=_PID_INPUTS)
    for kind in ("v", "l"):
        for i in range(len(TRUCKS)):
            _motor(spec, f"rail_{kind}{i}", tendon, f"truck_{kind}{i}")
    _motor(spec, "runout_y", site, "nut", (0, 1.0, 0, 0, 0, 0))
    _motor(spec, "runout_z", site, "nut", (0, 0, 1.0, 0, 0, 0))
    _motor(spec, "nut_axial", site, "nut", (1.0, 0, 0, 0, 0, 0))
    _motor(spec, "rail_stribeck", joint, "carriage_x")


def _sensors(spec: mujoco.MjSpec) -> None:
    """The sensors in the order of :class:`twin.sim.model.ModelIndex`'s ``sensordata`` columns:
    IMU accelerometer and gyro, the two nut accelerometers, the servo's and the ripple motor's
    actuator force."""
    sens, obj = mujoco.mjtSensor, mujoco.mjtObj
    for name, kind, objtype, target in (
            ("imu_acc", sens.mjSENS_ACCELEROMETER, obj.mjOBJ_SITE, "imu"),
            ("imu_gyro", sens.mjSENS_GYRO, obj.mjOBJ_SITE, "imu"),
            ("nut1_acc", sens.mjSENS_ACCELEROMETER, obj.mjOBJ_SITE, "nut_acc1"),
            ("nut2_acc", sens.mjSENS_ACCELEROMETER, obj.mjOBJ_SITE, "nut_acc2"),
            ("servo_torque", sens.mjSENS_ACTUATORFRC, obj.mjOBJ_ACTUATOR, "servo"),
            ("ripple_torque", sens.mjSENS_ACTUATORFRC, obj.mjOBJ_ACTUATOR, "ripple")):
        spec.add_sensor(name=name, type=kind, objtype=objtype, objname=target)


def build_spec(axis: Axis, timestep: float, base: BaseMode | None = None) -> mujoco.MjSpec:
    """The ``mujoco.MjSpec`` of the axis in its new (healthy, zero-backlash) state, a complete
    model that holds still when compiled on its own; other states are written into the compiled
    model by :func:`twin.sim.model.apply_state`. ``timestep`` in s. ``base``: a compliant machine
    base (one more DOF, ``base_x``, see :mod:`twin.sim.model`); None = rigid base, the 8-DOF model.

    Raises ValueError when the base is too light for the time step (:func:`check_base_mode`)."""
    if base is not None:
        check_base_mode(axis, timestep, base)
    new = state_fields(axis, MechanicalState(preload=axis.screw.preload), ballnut_invweight0(axis, base))
    spec = mujoco.MjSpec()
    spec.modelname = MODEL_NAME
    spec.compiler.degree = False  # MJCF <compiler angle="radian">
    spec.compiler.autolimits = True  # a range given is a range in force (MJCF autolimits="true")
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.gravity = [0.0, 0.0, -GRAVITY]
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT  # MJCF <flag contact="disable"/>
    _bodies(spec, axis, base)
    _tendons(spec, axis, new, base)
    _actuators(spec, axis, timestep)
    _sensors(spec)
    return spec


def build_model(axis: Axis, timestep: float, base: BaseMode | None = None) -> mujoco.MjModel:
    """Compile the axis model of :func:`build_spec` (same arguments); checks that every element
    the simulator drives or reads is there with its width (:class:`ModelIndex`)."""
    model = build_spec(axis, timestep, base).compile()
    ModelIndex.of(model)
    return model
