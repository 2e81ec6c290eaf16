"""The MuJoCo model of the linear axis: MJCF text built from :class:`twin.sim.axis.Axis`.

Degrees of freedom (8, or 9 with a compliant machine base):
- ``screw``: hinge of the motor rotor and screw about X (the servo acts here);
- the carriage with its steel load, as one rigid body on six joints at its centre of mass:
  ``carriage_x`` (travel), ``carriage_y``, ``carriage_z``, ``carriage_roll`` (about X),
  ``carriage_pitch`` (about Y) and ``carriage_yaw`` (about Z);
- ``lead_flank``: the prescribed cyclic lead error of the nut flanks (see below);
- ``base_x`` (only when a :class:`BaseMode` is given): a structural mode of the machine base
  along X, see below.

Couplings, all fixed tendons (linear in the joint coordinates, exact for the µm/µrad motions here):
- ``ballnut``: L = x + z_n·pitch − R·θ − ε with R = lead/2π, ε the lead flank (z_n: nut axis height below the centre of
  mass). Its stiffness K is the series axial stiffness of shaft, nut contact and support bearings,
  which follows the nut preload (Hertz, k ∝ F^(1/3)); its damping C = 2ζ·√(K·m) (ζ the axis's
  ``contact_damping_ratio``, m the carriage). How the nut transmits force depends on the backlash
  b, see *The ball-nut contact* below.
- ``truck_v<i>`` / ``truck_l<i>`` (i = 0..3, FL, FR, RL, RR): vertical and lateral contact of each
  truck on its rail, L = z + y_i·roll − x_i·pitch and L = y + x_i·yaw + h·roll.

Geometric errors enter as prescribed displacements e inside these springs. A spring with a
displacement error, F = −K·(L − e), is exactly the unperturbed spring plus a force pair K·e along the
tendon, so the rail waviness under each truck is applied by a ``motor`` actuator on the truck's
tendon with control K·e(t), and screw runout pushes the carriage radially at the nut through the
nut's radial stiffness (two site actuators). The ball nut has a backlash gap, where a force pair
would wrongly keep acting, so its cyclic lead error and ball passing move the flanks instead: an
eighth coordinate ``lead_flank`` (a slide in the ball-nut tendon, L = ... − ε) is driven along the
prescribed e(t) by a very stiff ``<pid>`` with position, velocity and acceleration
(feed-forward M·ë) inputs. Its mass M = 1e5 kg only makes that drive stiff (kp = M·(0.5/dt)²,
about 1e12 N/m: 1 nm under a 1 kN nut force) while it stays explicit-stable (ω·dt = 0.5); it
never carries the carriage's load, which the drive passes to the ground.

The servo is MuJoCo's ``<pid input="pos vel ff">`` actuator on the screw hinge (see
:class:`twin.sim.axis.Servo`); a second motor on the hinge carries the torque ripple of the motor,
which the controller does not know. Nut drag torque is Coulomb friction (``frictionloss``) plus
viscous damping on the hinge; rail and seal friction is ``frictionloss`` on ``carriage_x``.

Unmodelled-effect actuators (zero unless the scenario's ``[effects]`` switches them on, see
:class:`twin.sim.simulate.World`): ``nut_axial``, an axial force on the carriage at the nut site (ball
recirculation impulses), and ``rail_stribeck``, a force on ``carriage_x`` (Stribeck friction in
excess of the rail's Coulomb friction). The motor cogging torque shares the ``ripple`` motor.

Machine base (optional, :class:`BaseMode`): a single-DOF modal model of a base/column mode along
X (modal mass M, natural frequency f, damping ratio ζ; e.g. Altintas, *Manufacturing
Automation*, 2nd ed., ch. 3): body ``base`` on the slide ``base_x`` with joint stiffness
k = M(2πf)² and damping 2ζ√(kM) about 0, appended at the end of the worldbody so that the
qpos/qvel indices above are unchanged. The screw's support bearings sit on the base, so
``base_x`` enters the ball-nut tendon with coefficient −1 (L = x + z_n·pitch − R·θ − ε − x_b):
the nut force drives the base, and the base motion moves the carriage through the nut. The
accelerometers (absolute) see the resonance; the encoder (rotor angle relative to the base) only
through the servo's reaction. The rails, their Coulomb friction and the prescribed rail errors
stay on the ground (simplification: only the drive's support moves).

The ball-nut contact:
- b = 0 (a preloaded nut, both flanks loaded): the tendon's passive spring and damper,
  F = −K·L − C·L', linear through zero (``stiffness``, ``damping``, ``springlength`` 0 0).
- b > 0 (clearance): one flank at a time, and inside the gap [−b/2, +b/2] no force at all. The
  passive stiffness and damping are 0 and each flank is the tendon's limit constraint
  (``limited``, ``range`` = ±b/2, margin 0, so that no constraint row exists inside the gap),
  a no-tension Kelvin–Voigt contact F = max(0, K·δ + C·δ') of the compression δ beyond the
  flank. MuJoCo's soft constraints (documentation, Computation chapter, "Parameters" of the
  constraint solver, and Modeling chapter, "Solver parameters"; mujoco.readthedocs.io) give a
  single scalar constraint the dynamics a1 + d·(b·v + k·r) = (1 − d)·a0 (a0, a1: the
  acceleration in constraint space without and with the constraint force, r the residual,
  negative in contact, v its rate), with the regulariser R = (1 − d)/d·Â, Â the constraint's
  approximate inverse inertia: for a tendon limit ``tendon_invweight0`` (the compiler's value
  at qpos0). In the direct format ``solreflimit`` = (−stiffness, −damping) the solver takes
  b = damping/d_max and k = stiffness·d/d_max²; with a constant impedance d = d_min = d_max the
  force of the row is f = (a1 − a0)/A = −(stiffness·r + damping·v)/Â − d·a0/Â (A = J·M⁻¹·Jᵀ of
  the row, equal to Â here up to the µrad changes of M with the pose), and the solver
  clamps it to f ≥ 0 (a limit only pushes). So ``solreflimit`` = (−K·Â, −C·Â) is the contact
  K, C, and d = 10⁻⁴ (MuJoCo's smallest impedance, ``solimplimit`` 1e-4 1e-4) makes the leak
  d·a0/Â of the other forces 10⁻⁴ of them. Â = 1/m + z_n²/I_yy + R²/(J_motor + J_screw)
  + 1/M_flank (+ 1/M_base with the compliant base), :func:`ballnut_invweight0`; the MJCF uses
  that value, :func:`apply_state` the compiled model's own ``tendon_invweight0`` (the one the
  solver uses). The clamp applies to the whole contact force, so a rebounding flank is not
  pulled back by its damper; a damper alone in the constraint with a passive dead-band spring
  would lose its pull on rebound and damp the contact half as much (ζ 0.014 instead of 0.028
  in a ring on one flank, measured as in tests/test_nut_contact.py). tests/test_nut_contact.py checks
  the force against K·δ + C·δ', the damping ratio and the gap.

Known simplifications: the clearance is the wear law's average over the balls and may coexist
with the remaining preload of the others; the shaft stiffness is taken at mid-stroke; the
contact switches from the bilateral law (b = 0) to the one-flank law at the first b > 0.

Models in different degradation states differ only in model fields (the floats
``tendon_stiffness``, ``tendon_damping``, ``tendon_lengthspring``, ``dof_frictionloss``, the lead
coefficient in ``wrap_prm`` and the ball nut's ``tendon_range``, ``tendon_solref_lim``,
``tendon_solimp_lim``, and the byte ``tendon_limited``), see :func:`apply_state`, so that any
number of them can run in one ``mujoco.rollout`` call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from twin.sim.axis import Axis
from twin.sim.degradation import contact_stiffness
from twin.sim.sensors.instruments import STANDARD_GRAVITY as GRAVITY  # m/s²

TRUCKS = ("FL", "FR", "RL", "RR")

FLANK_MASS = 1e5  # kg, see the module docstring
# Impedance of the ball-nut contact's limit constraint: MuJoCo's smallest (mjMINIMP), constant
# (d_min = d_max; width, midpoint and power then do not matter), see the module docstring.
CONTACT_SOLIMP = (mujoco.mjMINIMP, mujoco.mjMINIMP, 0.001, 0.5, 2.0)
_RAILS = range(4)


class ModelLayoutError(RuntimeError):
    """The compiled model lacks a named element the simulator drives or reads."""


@dataclass(frozen=True)
class ModelIndex:
    """Where the simulator's controls, sensors and joints sit in a compiled axis model, looked up
    once by name (``model.actuator("servo")``, ``model.sensor("imu_acc")``, ``model.joint(...)``).

    Columns of ``data.ctrl`` (the ``<pid>`` actuators take three inputs: position, velocity,
    feed-forward): ``servo_pos``, ``servo_vel``, ``servo_ff``, ``ripple`` (screw torque, N*m),
    ``flank_pos``, ``flank_vel``, ``flank_ff`` (the lead flank), ``truck_v``, ``truck_l`` (4,)
    rail force pairs of the trucks FL FR RL RR (N), ``runout`` (2,) y, z forces at the nut (N),
    ``nut_axial``, ``stribeck`` (N). Columns of ``data.sensordata``: ``imu_acc``, ``imu_gyro``,
    ``nut1_acc``, ``nut2_acc`` (3 each) and ``servo_torque``. Entries of ``data.qpos``:
    ``screw`` (rad), ``x``, ``y``, ``z`` (m), ``roll``, ``pitch``, ``yaw`` (rad), ``flank`` (m),
    ``base`` (m; None without a compliant base). ``pose`` (5,): y, z, roll, pitch, yaw.
    """

    nu: int
    servo_pos: int
    servo_vel: int
    servo_ff: int
    ripple: int
    flank_pos: int
    flank_vel: int
    flank_ff: int
    truck_v: np.ndarray
    truck_l: np.ndarray
    runout: np.ndarray
    nut_axial: int
    stribeck: int
    imu_acc: slice
    imu_gyro: slice
    nut1_acc: slice
    nut2_acc: slice
    servo_torque: int
    screw: int
    x: int
    y: int
    z: int
    roll: int
    pitch: int
    yaw: int
    flank: int
    base: int | None
    pose: np.ndarray

    @classmethod
    def of(cls, model: mujoco.MjModel) -> ModelIndex:
        """Look every element up by name; a missing one raises :class:`ModelLayoutError`."""
        def element(kind: str, name: str):
            try:
                return getattr(model, kind)(name)
            except KeyError:
                raise ModelLayoutError(f"the axis model has no {kind} named {name!r}; the simulator "
                                       f"drives or reads it (see twin.sim.model.build_mjcf)") from None

        def ctrl(name: str, inputs: int = 1) -> int:
            i = element("actuator", name).id
            if model.actuator_ctrlnum[i] != inputs:
                raise ModelLayoutError(f"actuator {name!r} takes {model.actuator_ctrlnum[i]} control "
                                       f"inputs; the simulator writes {inputs}")
            return int(model.actuator_ctrladr[i])

        def sensor(name: str, dim: int) -> slice:
            i = element("sensor", name).id
            if model.sensor_dim[i] != dim:
                raise ModelLayoutError(f"sensor {name!r} has dimension {model.sensor_dim[i]}; expected {dim}")
            return slice(int(model.sensor_adr[i]), int(model.sensor_adr[i]) + dim)

        def qpos(name: str) -> int:
            return int(element("joint", name).qposadr[0])

        servo, flank = ctrl("servo", 3), ctrl("lead_flank", 3)
        pose = np.array([qpos(n) for n in ("carriage_y", "carriage_z", "carriage_roll", "carriage_pitch",
                                           "carriage_yaw")])
        has_base = any(model.joint(i).name == "base_x" for i in range(model.njnt))
        return cls(
            nu=int(model.nu), servo_pos=servo, servo_vel=servo + 1, servo_ff=servo + 2, ripple=ctrl("ripple"),
            flank_pos=flank, flank_vel=flank + 1, flank_ff=flank + 2,
            truck_v=np.array([ctrl(f"rail_v{i}") for i in _RAILS]),
            truck_l=np.array([ctrl(f"rail_l{i}") for i in _RAILS]),
            runout=np.array([ctrl("runout_y"), ctrl("runout_z")]),
            nut_axial=ctrl("nut_axial"), stribeck=ctrl("rail_stribeck"),
            imu_acc=sensor("imu_acc", 3), imu_gyro=sensor("imu_gyro", 3), nut1_acc=sensor("nut1_acc", 3),
            nut2_acc=sensor("nut2_acc", 3), servo_torque=sensor("servo_torque", 1).start,
            screw=qpos("screw"), x=qpos("carriage_x"), y=int(pose[0]), z=int(pose[1]), roll=int(pose[2]),
            pitch=int(pose[3]), yaw=int(pose[4]), flank=qpos("lead_flank"),
            base=qpos("base_x") if has_base else None, pose=pose)
BASE_MODE_MAX_OMEGA_DT = 1.0  # stability margin of the explicit base spring (limit 2)


@dataclass(frozen=True)
class BaseMode:
    """A structural mode of the machine base along X as a single-DOF modal model.

    Attributes:
        mass: modal mass M, kg (> 0).
        frequency: natural frequency of the base alone, f, Hz.
        damping_ratio: ζ (0 < ζ < 1).
    """

    mass: float
    frequency: float
    damping_ratio: float

    @property
    def stiffness(self) -> float:
        """k = M·(2πf)², N/m."""
        return self.mass * (2.0 * math.pi * self.frequency) ** 2

    @property
    def damping(self) -> float:
        """c = 2ζ·√(k·M), N·s/m."""
        return 2.0 * self.damping_ratio * math.sqrt(self.stiffness * self.mass)


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


def _fmt(v: float) -> str:
    return repr(float(v))


def check_base_mode(axis: Axis, timestep: float, base: BaseMode) -> None:
    """Raise ValueError (naming the scenario keys) when the base cannot be simulated at
    ``timestep`` s: its mode coupled to the carriage through the ball nut of the new axis,
    ω² ≤ (k_base + k_axial)/M, must keep ω·dt ≤ 1 for the explicit spring, i.e.
    M ≥ k_axial·dt²/(1 − (ω_b·dt)²) and ω_b·dt < 1."""
    k_axial = axis.screw.axial_stiffness(axis.screw.preload)
    wdt = 2.0 * math.pi * base.frequency * timestep / BASE_MODE_MAX_OMEGA_DT
    m_min = k_axial * (timestep / BASE_MODE_MAX_OMEGA_DT) ** 2 / max(1.0 - wdt**2, 1e-12)
    if base.mass <= 0 or wdt >= 1.0 or base.mass < m_min:
        raise ValueError(
            f"effects.base_modal_mass_kg = {base.mass:g} with effects.base_frequency_hz = "
            f"{base.frequency:g} cannot be simulated at a {timestep:g} s step: the base "
            f"mode coupled to the ball nut (k = {k_axial:.3g} N/m) needs a modal mass >= "
            f"{m_min:.3g} kg and 2π·f·dt < {BASE_MODE_MAX_OMEGA_DT:g} (explicit spring); use a "
            "heavier base or a smaller time step")


def build_mjcf(axis: Axis, timestep: float, base: BaseMode | None = None) -> str:
    """MJCF text of the axis in its new (healthy, zero-backlash) state, a complete model that
    holds still when loaded on its own; other states are written into the compiled model by
    :func:`apply_state`. ``timestep`` in s. ``base``: a compliant machine base (one more DOF,
    ``base_x``, see the module docstring); None = rigid base, the 8-DOF model.

    Raises ValueError when the base is too light for the time step (:func:`check_base_mode`)."""
    c, s = axis.carriage, axis.screw
    new = state_fields(axis, MechanicalState(preload=s.preload), ballnut_invweight0(axis, base))
    base_body, base_wrap = "", ""
    if base is not None:
        check_base_mode(axis, timestep, base)
        base_body = (
            f'    <body name="base">\n'
            f'      <joint name="base_x" type="slide" axis="1 0 0" springref="0" '
            f'stiffness="{_fmt(base.stiffness)}" damping="{_fmt(base.damping)}"/>\n'
            f'      <inertial pos="0 0 0" mass="{_fmt(base.mass)}" diaginertia="1 1 1"/>\n'
            f'    </body>\n')
        base_wrap = '      <joint joint="base_x" coef="-1"/>\n'

    def spring(i: int) -> str:
        lo, hi = new.tendon_lengthspring[i]
        return (f'springlength="{_fmt(lo)} {_fmt(hi)}" stiffness="{_fmt(new.tendon_stiffness[i])}" '
                f'damping="{_fmt(new.tendon_damping[i])}"')
    lo, hi = new.ballnut_range
    contact = (f'limited="{str(new.ballnut_limited).lower()}" range="{_fmt(lo)} {_fmt(hi)}" '
               f'solreflimit="{" ".join(map(_fmt, new.ballnut_solreflimit))}" '
               f'solimplimit="{" ".join(map(_fmt, new.ballnut_solimplimit))}"')
    r = s.radius_per_rad
    layout = TruckLayout.of(axis)
    zn = c.nut_height - c.com_height  # nut axis relative to the centre of mass (m, negative)
    zi = c.imu_height - c.com_height
    kp, ki, kd = axis.servo_gains()
    fric = axis.friction_solver_attributes()
    half_travel = axis.travel / 2.0
    flank_kp = FLANK_MASS * (0.5 / timestep) ** 2
    flank_kv = 2.0 * math.sqrt(flank_kp * FLANK_MASS)

    truck_tendons = []
    for i in range(len(TRUCKS)):
        xi, yi, h = layout.x[i], layout.y[i], layout.height_below_com
        truck_tendons.append(
            f'    <fixed name="truck_v{i}" {spring(1 + 2 * i)}>\n'
            f'      <joint joint="carriage_z" coef="1"/>\n'
            f'      <joint joint="carriage_roll" coef="{_fmt(yi)}"/>\n'
            f'      <joint joint="carriage_pitch" coef="{_fmt(-xi)}"/>\n'
            f'    </fixed>\n'
            f'    <fixed name="truck_l{i}" {spring(2 + 2 * i)}>\n'
            f'      <joint joint="carriage_y" coef="1"/>\n'
            f'      <joint joint="carriage_yaw" coef="{_fmt(xi)}"/>\n'
            f'      <joint joint="carriage_roll" coef="{_fmt(h)}"/>\n'
            f'    </fixed>\n')
    truck_motors = "".join(
        f'    <motor name="rail_v{i}" tendon="truck_v{i}" gear="1"/>\n' for i in range(4))
    truck_motors += "".join(
        f'    <motor name="rail_l{i}" tendon="truck_l{i}" gear="1"/>\n' for i in range(4))
    truck_sites = "".join(
        f'      <site name="truck_{n}" pos="{_fmt(layout.x[i])} {_fmt(layout.y[i])} '
        f'{_fmt(-layout.height_below_com)}" size="0.01"/>\n' for i, n in enumerate(TRUCKS))
    ix, iy, iz = c.inertia

    return f"""<mujoco model="ballscrew_linear_axis">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{_fmt(timestep)}" integrator="implicitfast" gravity="0 0 {_fmt(-GRAVITY)}">
    <flag contact="disable"/>
  </option>
  <worldbody>
    <geom name="base" type="box" pos="{_fmt(half_travel)} 0 -0.06" size="{_fmt(half_travel + 0.1)} 0.2 0.02"
          contype="0" conaffinity="0" rgba="0.5 0.5 0.5 1"/>
    <body name="screw" pos="0 0 {_fmt(c.nut_height)}">
      <joint name="screw" type="hinge" axis="1 0 0" armature="{_fmt(axis.servo.motor_inertia)}"
             damping="{_fmt(s.drag_viscous)}" frictionloss="{_fmt(s.drag_torque(s.preload))}"{fric}/>
      <inertial pos="{_fmt(half_travel)} 0 0" mass="{_fmt(s.screw_mass)}"
                diaginertia="{_fmt(s.screw_inertia)} 0.05 0.05"/>
      <geom type="cylinder" fromto="0 0 0 {_fmt(axis.travel)} 0 0" size="{_fmt(s.root_diameter / 2)}"
            contype="0" conaffinity="0" mass="0" rgba="0.7 0.7 0.75 1"/>
    </body>
    <body name="carriage" pos="0 0 {_fmt(c.com_height)}">
      <joint name="carriage_x" type="slide" axis="1 0 0" frictionloss="{_fmt(c.rail_friction)}"{fric}/>
      <joint name="carriage_y" type="slide" axis="0 1 0"/>
      <joint name="carriage_z" type="slide" axis="0 0 1"/>
      <joint name="carriage_roll" type="hinge" axis="1 0 0"/>
      <joint name="carriage_pitch" type="hinge" axis="0 1 0"/>
      <joint name="carriage_yaw" type="hinge" axis="0 0 1"/>
      <inertial pos="0 0 0" mass="{_fmt(c.mass)}" diaginertia="{_fmt(ix)} {_fmt(iy)} {_fmt(iz)}"/>
      <geom type="box" size="0.1 0.13 0.02" pos="0 0 {_fmt(-c.com_height + 0.02)}" contype="0"
            conaffinity="0" mass="0" rgba="0.3 0.4 0.8 1"/>
      <geom type="box" size="0.08 0.08 0.06" pos="0 0 {_fmt(zi - 0.07)}" contype="0" conaffinity="0"
            mass="0" rgba="0.25 0.25 0.25 1"/>
      <site name="imu" pos="0 0 {_fmt(zi)}" size="0.01"/>
      <site name="nut" pos="0 0 {_fmt(zn)}" size="0.01"/>
      <site name="nut_acc1" pos="0.02 0.025 {_fmt(zn + 0.02)}" size="0.005"/>
      <site name="nut_acc2" pos="-0.02 -0.025 {_fmt(zn - 0.02)}" size="0.005"/>
{truck_sites}    </body>
    <body name="lead_flank">
      <joint name="lead_flank" type="slide" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="{_fmt(FLANK_MASS)}" diaginertia="1 1 1"/>
    </body>
{base_body}  </worldbody>
  <tendon>
    <fixed name="ballnut" {spring(0)}
           {contact}>
      <joint joint="carriage_x" coef="1"/>
      <joint joint="carriage_pitch" coef="{_fmt(zn)}"/>
      <joint joint="screw" coef="{_fmt(-r)}"/>
      <joint joint="lead_flank" coef="-1"/>
{base_wrap}    </fixed>
{''.join(truck_tendons)}  </tendon>
  <actuator>
    <pid name="servo" joint="screw" input="pos vel ff" kp="{_fmt(kp)}" kv="{_fmt(kd)}" ki="{_fmt(ki)}"
         forcerange="{_fmt(-axis.servo.torque_limit)} {_fmt(axis.servo.torque_limit)}"/>
    <motor name="ripple" joint="screw" gear="1"/>
    <pid name="lead_flank" joint="lead_flank" input="pos vel ff" kp="{_fmt(flank_kp)}"
         kv="{_fmt(flank_kv)}"/>
{truck_motors}    <motor name="runout_y" site="nut" gear="0 1 0 0 0 0"/>
    <motor name="runout_z" site="nut" gear="0 0 1 0 0 0"/>
    <motor name="nut_axial" site="nut" gear="1 0 0 0 0 0"/>
    <motor name="rail_stribeck" joint="carriage_x" gear="1"/>
  </actuator>
  <sensor>
    <accelerometer name="imu_acc" site="imu"/>
    <gyro name="imu_gyro" site="imu"/>
    <accelerometer name="nut1_acc" site="nut_acc1"/>
    <accelerometer name="nut2_acc" site="nut_acc2"/>
    <actuatorfrc name="servo_torque" actuator="servo"/>
    <actuatorfrc name="ripple_torque" actuator="ripple"/>
  </sensor>
</mujoco>
"""


def build_model(axis: Axis, timestep: float, base: BaseMode | None = None) -> mujoco.MjModel:
    """Compile the axis model; see :func:`build_mjcf`."""
    model = mujoco.MjModel.from_xml_string(build_mjcf(axis, timestep, base))
    ModelIndex.of(model)  # every element the simulator uses is there, with its width
    return model


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
            truck_v0, truck_l0, ..., truck_v3, truck_l3 (as in :func:`build_mjcf`). The ball
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
    """The fields of the model in ``state`` (one source for the MJCF and for
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
    # The screw is the third joint of the ball-nut tendon (see build_mjcf).
    wrap = model.tendon_adr[ballnut] + 2
    if model.wrap_objid[wrap] != model.joint("screw").id:
        raise ModelLayoutError("the third joint of the ball-nut tendon is not the screw hinge; "
                               "its coefficient (the lead) cannot be set")
    model.wrap_prm[wrap] = f.screw_coef


def initial_state(model: mujoco.MjModel, x0: float, theta0: float, flank0: float = 0.0,
                  pose: np.ndarray | None = None) -> np.ndarray:
    """Full physics state at rest: carriage at ``x0`` m, screw at ``theta0`` rad, lead flank at
    ``flank0`` m, and the carriage's (y, z, roll, pitch, yaw) ``pose`` (5,) m/rad (default 0)."""
    data = mujoco.MjData(model)
    data.joint("screw").qpos[0] = theta0
    data.joint("carriage_x").qpos[0] = x0
    data.joint("lead_flank").qpos[0] = flank0
    if pose is not None:
        data.qpos[ModelIndex.of(model).pose] = pose
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    mujoco.mj_forward(model, data)
    state = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, state, spec)
    return state


def accelerometer_implicit_correction(model: mujoco.MjModel, state: np.ndarray,
                                      ctrl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What turns MuJoCo's accelerometer readings into the acceleration the integrator applies.

    With the ``implicit`` and ``implicitfast`` integrators MuJoCo advances the velocity by
    v' = v + h·a_i with (M − h·D)·a_i = f, D the derivative of the passive and actuator forces
    with respect to the velocity (MuJoCo documentation, Computation chapter, "Numerical
    integration"; mujoco.readthedocs.io), while ``mjData.qacc``, from which the accelerometers
    are computed in ``mj_forward`` before the step, is the explicit a = M⁻¹·f. So
    a = a_i − h·M⁻¹·D·a_i, and an accelerometer reads −h·Sᵀ·J·M⁻¹·D·a_i more than a_i gives
    (S the site's orientation, J its translational Jacobian; MuJoCo keeps in D only the entries
    of its sparsity pattern ``D_rownnz``/``D_colind``, within a kinematic tree: a tendon's
    damping between the carriage and the screw enters a_i through its carriage entries alone).
    The integrated velocity differs from the integral of the reading by that amount: 0.65 % of
    the carriage's acceleration along the travel with the nut's passive damper (b = 0), the
    lever arm of the pitch acceleration 1.3 % long through the trucks' dampers.

    D is MuJoCo's own (``mjData.qDeriv`` after one step from ``state`` under ``ctrl``); M, J and S
    at ``state`` (the pose changes by µrad, the passive and actuator damping of the carriage's
    joints are linear). Returns (cols, G): the ``sensordata`` columns of every accelerometer and
    G (len(cols), nv) such that the reading of the applied acceleration a_i (n, nv) is
    ``sens[:, cols] + a_i @ G.T``.

    Raises ValueError for another integrator (the axis model uses implicitfast)."""
    if model.opt.integrator not in (mujoco.mjtIntegrator.mjINT_IMPLICIT,
                                    mujoco.mjtIntegrator.mjINT_IMPLICITFAST):
        raise ValueError(f"accelerometer_implicit_correction: integrator {model.opt.integrator}; "
                         "expected implicitfast or implicit (the correction is theirs)")
    acc = [i for i in range(model.nsensor) if model.sensor_type[i] == mujoco.mjtSensor.mjSENS_ACCELEROMETER]
    cols = np.concatenate([np.arange(model.sensor_adr[i], model.sensor_adr[i] + 3) for i in acc]
                          ) if acc else np.zeros(0, dtype=int)
    nv = model.nv
    gain = np.zeros((cols.size, nv))
    if not acc:
        return cols, gain
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    data = mujoco.MjData(model)
    mujoco.mj_setState(model, data, state, spec)
    data.ctrl[:] = ctrl
    mujoco.mj_step(model, data)  # fills qDeriv, the D of this step
    damping = np.zeros((nv, nv))
    for i in range(nv):
        a = model.D_rowadr[i]
        damping[i, model.D_colind[a:a + model.D_rownnz[i]]] = data.qDeriv[a:a + model.D_rownnz[i]]
    mujoco.mj_setState(model, data, state, spec)
    mujoco.mj_forward(model, data)
    minv_d = np.zeros((nv, nv))
    mujoco.mj_solveM(model, data, minv_d, np.ascontiguousarray(damping.T))  # rows: M⁻¹·(columns of D)
    minv_d = minv_d.T
    jac = np.zeros((3, nv))
    for k, i in enumerate(acc):
        site = model.sensor_objid[i]
        mujoco.mj_jacSite(model, data, jac, None, site)
        rot = data.site_xmat[site].reshape(3, 3)
        gain[3 * k:3 * k + 3] = model.opt.timestep * rot.T @ jac @ minv_d
    return cols, gain
