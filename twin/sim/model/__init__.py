"""The MuJoCo model of the linear axis, built from :class:`twin.sim.axis.Axis` with MuJoCo's
model-editing API (``mujoco.MjSpec``: bodies, joints, tendons, actuators and sensors added in code
and compiled with ``spec.compile()``; MuJoCo documentation, Programming chapter, "Model Editing",
mujoco.readthedocs.io/en/4.0.0/programming/modeledit.html). The MJCF text (``twin export-model``)
is written from that spec, not the other way round.

The package (every public name is re-exported here, ``from twin.sim.model import X``):
- :mod:`~twin.sim.model.spec`: :func:`build_spec` (the ``MjSpec`` of the new axis),
  :func:`build_model` (compiled), :class:`TruckLayout`, :data:`TRUCKS`;
- :mod:`~twin.sim.model.machine_base`: :class:`BaseMode` (the optional compliant base) and
  :func:`check_base_mode`;
- :mod:`~twin.sim.model.state`: the degradation state in model fields, :class:`MechanicalState`,
  :func:`state_fields`, :func:`apply_state`, :func:`ballnut_invweight0`, :func:`stiffness_of`;
- :mod:`~twin.sim.model.index`: :class:`ModelIndex` (where controls, sensors and joints sit, by
  name) and :class:`ModelLayoutError`;
- :mod:`~twin.sim.model.runtime`: :func:`initial_state` and
  :func:`accelerometer_implicit_correction`;
- :mod:`~twin.sim.model.export`: :func:`build_mjcf`, the MJCF text of the spec, exact to the bit.

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

The servo is MuJoCo's PID actuator with position, velocity and feed-forward inputs (MJCF
``<pid input="pos vel ff">``, ``set_to_pid`` in the spec) on the screw hinge (see
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
  + 1/M_flank (+ 1/M_base with the compliant base), :func:`ballnut_invweight0`; the spec uses
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

from twin.sim.model.export import build_mjcf, spec_to_mjcf
from twin.sim.model.index import ModelIndex, ModelLayoutError
from twin.sim.model.machine_base import BASE_MODE_MAX_OMEGA_DT, BaseMode, check_base_mode
from twin.sim.model.runtime import accelerometer_implicit_correction, initial_state
from twin.sim.model.spec import TRUCKS, TruckLayout, build_model, build_spec
from twin.sim.model.state import (
    CONTACT_SOLIMP,
    FLANK_MASS,
    GRAVITY,
    MechanicalState,
    StateFields,
    apply_state,
    ballnut_invweight0,
    state_fields,
    stiffness_of,
)

__all__ = [
    "BASE_MODE_MAX_OMEGA_DT", "CONTACT_SOLIMP", "FLANK_MASS", "GRAVITY", "TRUCKS", "BaseMode",
    "MechanicalState", "ModelIndex", "ModelLayoutError", "StateFields", "TruckLayout",
    "accelerometer_implicit_correction", "apply_state", "ballnut_invweight0", "build_mjcf",
    "build_model", "build_spec", "check_base_mode", "initial_state", "spec_to_mjcf", "state_fields",
    "stiffness_of",
]
