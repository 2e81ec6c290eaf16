"""Running the MuJoCo axis through the paper's routines and turning the motion into sensor streams.

- :class:`World`: what is fixed for a whole campaign (the axis, its rails, its screw) drawn once
  from the scenario seed.
- :class:`Condition`: the axis at one moment of the campaign (preload, backlash, temperature,
  origin set by the operator).
- :class:`Simulator`: one compiled model per time step; :meth:`Simulator.run` rolls it out with
  ``mujoco.rollout`` under a commanded profile.
- :func:`phase1_capture`, :func:`phase2_session`, :func:`dial_indicator`: the three measurement
  procedures of the paper (section III).

Rail waviness follows the carriage's TRUE position. The carriage's travel depends on the rail
forces only weakly (through the pitch of the carriage, since the nut sits below its centre of
mass), so a first rollout with the rails looked up at the commanded position shifted by the
known backlash lag gives the true travel x(t), and a second rollout with the rails looked up at
that x(t) is the fixed point: at steady speed a third pass changes x by far less than a nm, and
passes 1 and 2 differ by a fraction of a nm rms (asserted in ``tests/test_twin_physics.py``;
figures in docs/validation.md). The residual error of the first pass's rail input is (slope of
the rail) × (following error) ≈ 2π·0.5 µm/60 mm × 1 µm ≈ 0.05 nm at steady speed. Phase I does
that one pass. Phase II does both unless the scenario's ``phase2.rail_passes`` asks for one,
which then looks the rails up where the nut's flank contact puts the carriage
(:func:`flank_contact_position`: the flank that pushes, its compression, the lead error). The
lag alone misses the compression, which Phase II measures as part of the lost motion, and the
flank the carriage coasts to at a stop; where it comes to rest in the clearance can still move
by a micrometre with one pass (a preloaded nut with a wide clearance,
``scenarios/backlash-steps.toml``). On the paper's routine and wear law the travels move by
less than 0.1 µm and the backlash estimates by a few hundredths of a µm, and
``scenarios/paper-rtf.toml`` does one pass (``benchmarks/bench_rail_passes.py``;
``tests/test_campaign.py::test_one_rail_pass_keeps_the_paper_figures``).
"""

from __future__ import annotations

import copy
import math
import os
from dataclasses import dataclass, replace

import mujoco
import numpy as np
from mujoco import rollout
from scipy import signal

from twin.sim import geometry as geo
from twin.sim.axis import Axis
from twin.sim.drive import Move, Profile, command_profile, reciprocating
from twin.sim.model import (
    FLANK_MASS,
    BaseMode,
    MechanicalState,
    ModelIndex,
    accelerometer_implicit_correction,
    apply_state,
    build_model,
    initial_state,
    stiffness_of,
)
from twin.sim.sensors import instruments as ins

SETTLE_TIME = 0.1  # s of standstill simulated before t = 0 of every rollout


@dataclass(frozen=True)
class World:
    """Everything fixed over a campaign.

    Attributes:
        axis: physical parameters (SI).
        rails: rail deviation profiles (rail coordinate = world X, m).
        carriage: carriage layout for the kinematic error motions.
        screw: lead error, runout and ball-pass geometry with their (seeded) phases.
        ripple_torque: amplitude of the motor torque ripple, N·m; ripple_per_rev: its order;
        ripple_phase: rad.
        thermal_expansion: screw expansion coefficient, 1/K.
        sensors: instrument specifications.

    Unmodelled effects (scenario section ``[effects]``; the defaults are off and leave every
    array of the nominal twin unchanged):
        cogging_torque: motor cogging amplitude, N·m, added to the ripple motor as
            cogging·sin(cogging_per_rev·θ + cogging_phase) (PM-motor cogging has the period
            LCM(slots, poles) per revolution: Zhu & Howe, IEEE Trans. Energy Conversion 15(4),
            2000); cogging_phase: rad.
        recirculation_impulse: peak axial force on the nut of the ball re-entry impulses, N;
            recirculation_width: pulse width as a fraction of the ball-pass period (see
            :func:`recirculation_force`).
        stribeck_excess: static rail friction in excess of the Coulomb friction ΔF, N;
            stribeck_velocity: Stribeck velocity v_s, m/s (see :func:`stribeck_force`).
        base_modal_mass: modal mass of the machine base's X mode, kg (0 = rigid base);
            base_frequency: its natural frequency, Hz; base_damping_ratio: ζ (see
            :class:`twin.sim.model.BaseMode`).
    """

    axis: Axis
    rails: geo.RailProfiles
    carriage: geo.CarriageGeometry
    screw: geo.ScrewSpec
    ripple_torque: float
    ripple_per_rev: int
    ripple_phase: float
    thermal_expansion: float
    drag_temperature_coefficient: float
    imu_acc: ins.AnalogAccelerometerSpec
    imu_gyro: ins.DigitalGyroSpec
    nut_acc: ins.NutAccelerometerSpec
    controller_fs: float
    encoder_counts_per_rev: int
    torque_noise: float
    position_cmd_fs: float
    cogging_torque: float
    cogging_per_rev: int
    cogging_phase: float
    recirculation_impulse: float
    recirculation_width: float
    stribeck_excess: float
    stribeck_velocity: float
    base_modal_mass: float
    base_frequency: float
    base_damping_ratio: float
    torque_resolution: float = 0.001

    @property
    def base_mode(self) -> BaseMode | None:
        """The compliant machine base of the model, None for a rigid base (modal mass 0)."""
        if self.base_modal_mass <= 0.0:
            return None
        return BaseMode(mass=self.base_modal_mass, frequency=self.base_frequency,
                        damping_ratio=self.base_damping_ratio)


def recirculation_force(theta: np.ndarray, v_cmd: np.ndarray, world: World) -> np.ndarray:
    """Axial force of the ball re-entry impulses on the nut, (n,) N, for the commanded screw
    angles ``theta`` (n,) rad and carriage velocities ``v_cmd`` (n,) m/s at the simulation
    steps (n ≥ 2).

    When balls re-enter the loaded zone through the return/deflector they strike the nut: one
    impulse per ball-pass period, at the ball-pass phase u = (N_bp·θ + φ_bp)/2π of
    :func:`twin.sim.geometry.ball_pass` (pulse centred where u is an integer). Each is a raised
    cosine p(d) = ½(1 + cos(2πd/w)) for |d| < w/2 (d = u − round(u), w the width as a fraction
    of the period), of peak F, opposing the motion: F·p·(−sign v). The mean, F·w/2, is kept
    (a one-sided contact force: it is a real drag of the recirculation). Zero at standstill.

    The control is held over a step, so each step carries the pulse's mean over the step,
    (C(u_{k+1}) − C(u_k))/(u_{k+1} − u_k) with C the integral of p: the impulse is delivered
    exactly even when the pulse is shorter than a step (w·T = 0.28 ms at 400 mm/s for w = 0.1),
    and the sampling does not alias its harmonics through the pulse's phase jitter."""
    w = world
    n_bp = geo.ball_pass_per_rev(w.screw)
    width = w.recirculation_width
    u = (n_bp * theta + w.screw.ball_pass_phase_rad) / (2.0 * math.pi)

    def pulse(u):
        d = u - np.round(u)
        return np.where(np.abs(d) < width / 2, 0.5 * (1.0 + np.cos(2.0 * np.pi * d / width)), 0.0)

    def integral(u):
        k = np.floor(u + 0.5)
        d = np.clip(u - k, -width / 2, width / 2)
        return k * width / 2 + 0.5 * (d + width / 2) + width / (4.0 * np.pi) * np.sin(2.0 * np.pi * d / width)

    # The last step continues the motion.
    u_next = np.append(u[1:], 2.0 * u[-1] - u[-2] if u.size > 1 else u[-1])
    du = u_next - u
    small = np.abs(du) < 1e-9
    mean = np.where(small, pulse(u),
                    (integral(u_next) - integral(u)) / np.where(small, 1.0, du))
    return -w.recirculation_impulse * mean * np.sign(v_cmd)


def stribeck_force(v_cmd: np.ndarray, world: World) -> np.ndarray:
    """Stribeck friction of the rails in excess of their Coulomb friction, (n,) N, on
    ``carriage_x``: F = −ΔF·exp(−(v/v_s)²)·sign(v) (Stribeck curve: Armstrong-Hélouvry, Dupont,
    Canudas de Wit, Automatica 30(7), 1994), of magnitude ΔF at the start of a motion and at
    reversals, vanishing in the cruise.

    Approximation: v is the COMMANDED carriage velocity ``v_cmd`` (n,) m/s, so the force is an
    open-loop input (the model's Coulomb part, ``frictionloss``, is the true-velocity one). The
    carriage follows the command within µm; its velocity differs from the commanded one by a
    fraction of a mm/s over the Phase I routine, with transients of a few mm/s at the
    acceleration steps (where the axial mode rings; see docs/validation.md).
    For v_s of a few mm/s the force is therefore the Stribeck friction of the ideal motion, not
    the flicker the ringing would give; a true stick phase (a carriage held by static friction
    while the servo winds up) is not modelled."""
    v = np.asarray(v_cmd, dtype=float)
    return -world.stribeck_excess * np.exp(-(v / world.stribeck_velocity) ** 2) * np.sign(v)


@dataclass(frozen=True)
class Condition:
    """The axis at one moment of a campaign.

    Attributes:
        mech: preload (N), backlash (m) and truck preload.
        temperature_rise: screw temperature above its reference, K (thermal growth of the lead).
        origin_offset: rail coordinate of the controller's zero, m (set by the operator).
    """

    mech: MechanicalState
    temperature_rise: float = 0.0
    origin_offset: float = 0.0


@dataclass(frozen=True)
class Trajectory:
    """A rollout, row k at t_k = k·dt (state and sensors). t (n,) s;
    qpos (n, 8) [screw rad, x y z m, roll pitch yaw rad, lead flank m] or
    (n, 9) with a compliant base (``base_x`` m last); qvel likewise;
    sens (n, 14) MuJoCo sensors (see :mod:`twin.sim.model`); cmd: the commanded profile (controller
    frame); theta_cmd (n,) rad; index: the columns of qpos and sens by name."""

    t: np.ndarray
    qpos: np.ndarray
    qvel: np.ndarray
    sens: np.ndarray
    cmd: Profile
    theta_cmd: np.ndarray
    index: ModelIndex

    @property
    def x(self) -> np.ndarray:
        """True carriage position (rail coordinate), m."""
        return self.qpos[:, self.index.x]

    @property
    def angular_velocity_imu(self) -> np.ndarray:
        """(n, 3) angular velocity of the IMU frame at t_k, rad/s.

        MuJoCo's (semi-)implicit Euler step computes q_{k+1} = q_k + dt·v_{k+1}, so the velocity
        of row k, v_k = (q_k − q_{k−1})/dt, is the mean rate over [t_{k−1}, t_k], centred half a
        step late; the accelerometer rows, (v_{k+1} − v_k)/dt, are centred at t_k. The mean of
        consecutive rows centres the gyro at t_k (last row repeated)."""
        g = self.sens[:, self.index.imu_gyro]
        out = g.copy()
        out[:-1] = 0.5 * (g[:-1] + g[1:])
        return out


class Simulator:
    """A compiled axis model at one time step, reused for every rollout of a worker."""

    def __init__(self, world: World, timestep: float):
        self.world = world
        self.timestep = timestep
        self.model = build_model(world.axis, timestep, world.base_mode)
        self.index = ModelIndex.of(self.model)
        self.data = mujoco.MjData(self.model)
        self._state_size = mujoco.mj_stateSize(self.model, mujoco.mjtState.mjSTATE_FULLPHYSICS)

    def lead_stretch(self, cond: Condition) -> float:
        """Relative lead deviation: cumulative lead error + thermal growth α·ΔT (m/m)."""
        w = self.world
        return w.screw.cumulative_lead_error_m_per_m + w.thermal_expansion * cond.temperature_rise

    def drag_scale(self, cond: Condition) -> float:
        """Nut drag torque relative to the cold screw: exp(−β·ΔT), β the lubricant's viscosity
        temperature coefficient (Reynolds' viscosity relation)."""
        return math.exp(-self.world.drag_temperature_coefficient * cond.temperature_rise)

    def flank_motion(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Prescribed flank displacement ε (n,) m, its velocity and acceleration, for the screw
        angles ``theta`` (n,) rad sampled at the simulation rate: cyclic lead error + ball pass."""
        w = self.world
        r = w.axis.screw.radius_per_rad
        eps = geo.nut_axial_deviation(theta, w.screw) - w.screw.cumulative_lead_error_m_per_m * r * theta
        # Exact for MuJoCo's semi-implicit step: target velocity = the one step k must reach
        # (forward difference), feed-forward = second difference (tests/test_twin_physics.py).
        vel = np.diff(eps, append=eps[-1]) / self.timestep
        return eps, vel, np.diff(eps, 2, prepend=eps[0], append=eps[-1]) / self.timestep**2

    @property
    def fs(self) -> float:
        return 1.0 / self.timestep

    def controls(self, cond: Condition, cmd: Profile, x_rail: np.ndarray) -> np.ndarray:
        """(n, nu) control array: servo set-points, torque ripple (+ cogging), the prescribed
        lead flank, the rail and runout errors as force pairs K·e (see :mod:`twin.sim.model`), rails
        looked up at ``x_rail`` (n,) m, and the recirculation and Stribeck forces of the
        world's effects (zero when off)."""
        w, ax = self.world, self.world.axis
        r = ax.screw.radius_per_rad
        k = stiffness_of(ax, cond.mech)
        theta = (cmd.x + cond.origin_offset) / r
        ix = self.index
        ctrl = np.zeros((cmd.t.size, ix.nu))
        ctrl[:, ix.servo_pos] = theta
        ctrl[:, ix.servo_vel] = cmd.v / r
        ctrl[:, ix.servo_ff] = ax.servo.torque_feedforward * ax.total_inertia() * cmd.a / r
        ctrl[:, ix.ripple] = w.ripple_torque * np.sin(w.ripple_per_rev * theta + w.ripple_phase)
        if w.cogging_torque > 0.0:
            ctrl[:, ix.ripple] += w.cogging_torque * np.sin(w.cogging_per_rev * theta
                                                              + w.cogging_phase)
        if w.recirculation_impulse > 0.0:
            ctrl[:, ix.nut_axial] = recirculation_force(theta, cmd.v, w)
        if w.stribeck_excess > 0.0:
            ctrl[:, ix.stribeck] = stribeck_force(cmd.v, w)
        # Cyclic lead error and ball pass move the nut's flanks (the lead_flank coordinate);
        # the cumulative and thermal parts are in the tendon's lead coefficient.
        flank, flank_v, flank_a = self.flank_motion(theta)
        ctrl[:, ix.flank_pos] = flank
        ctrl[:, ix.flank_vel] = flank_v
        ctrl[:, ix.flank_ff] = FLANK_MASS * flank_a
        disp = geo.truck_displacements(w.rails, w.carriage, x_rail)
        ctrl[:, ix.truck_v] = k["truck_vertical"] * disp["vertical"].T
        ctrl[:, ix.truck_l] = k["truck_lateral"] * disp["lateral"].T
        ctrl[:, ix.runout] = ax.screw.radial_stiffness * geo.runout(theta, w.screw)
        return ctrl

    def run(self, cond: Condition, cmd: Profile, passes: int = 2,
            contact_guess: bool = False) -> Trajectory:
        """Roll the model out under ``cmd`` in condition ``cond``.

        ``passes`` = 2 looks the rails up at the true carriage position of a first pass (see the
        module docstring); 1 looks them up at the commanded position shifted by the backlash lag.
        """
        return self.run_batch([cond], cmd, passes, contact_guess=contact_guess)[0]

    def rest_pose(self, x: float) -> np.ndarray:
        """Resting pose of the carriage on the rails at rail position ``x`` m: joint coordinates
        (y, z, roll, pitch, yaw) of its centre of mass, (5,) in m and rad (quasi-static truck
        fit, :func:`twin.sim.geometry.error_motions_from_trucks`)."""
        w = self.world
        t_y, t_z, e_ax, e_bx, e_cx = geo.error_motions_from_trucks(
            geo.truck_displacements(w.rails, w.carriage, np.array([x])), w.carriage)[:, 0]
        # The trucks' lateral contacts are com_height below the centre of mass.
        return np.array([t_y - w.axis.carriage.com_height * e_ax, t_z, e_ax, e_bx, e_cx])

    def run_batch(self, conds: list[Condition], cmd: Profile, passes: int = 2,
                  nthread: int | None = None, contact_guess: bool = False) -> list[Trajectory]:
        """Roll out several conditions under one command in one ``mujoco.rollout`` call
        (:func:`run_many` with this simulator for every condition)."""
        return run_many([(self, c) for c in conds], cmd, passes, nthread, contact_guess)

    def structure(self) -> tuple:
        """What must agree for models to share one ``mujoco.rollout`` call."""
        m = self.model
        return (m.nq, m.nv, m.nu, m.na, m.nsensordata, self.timestep)


def held_sign(values: np.ndarray, before: float) -> np.ndarray:
    """(n,) sign of ``values`` (n,), the last nonzero sign held through zeros, ``before`` until
    the first nonzero value."""
    sign = np.sign(values)
    held = np.maximum.accumulate(np.where(sign != 0, np.arange(sign.size), -1))
    return np.where(held >= 0, sign[np.maximum(held, 0)], before)


def flank_contact_position(sim: Simulator, cond: Condition, cmd: Profile, x_cmd: np.ndarray,
                           before: float) -> np.ndarray:
    """First guess of the carriage's true position (n,) m at the command ``cmd`` (rail
    coordinate of the command ``x_cmd`` (n,) m), for the rails' lookup of a first rollout pass:
    the carriage rides on the flank of the ball nut that pushes it, compressed by that push,

        x = (1 + s)·x_c + ε(θ) − σ·b/2 − F/K,   F = m·a + F_f·sign(v),

    s the lead stretch, ε the cyclic lead error and ball pass of the nut's flank
    (:meth:`Simulator.flank_motion`), b the clearance, F the force the nut must exert on the
    carriage of mass m to give it the commanded acceleration a against the rails' Coulomb
    friction F_f, K the nut's axial stiffness, σ the sign of F held while F = 0 (at rest the
    carriage stays on the flank it came to; ``before``: the flank before the first push). At a
    stop that decelerates harder than the friction does, the carriage crosses to the other flank
    (instantly here; in the rollout within a few ms). Quasi-static: the servo's following error
    and the axial mode's ringing are the residual (a second pass looks the rails up at the
    rolled-out position instead)."""
    ax = sim.world.axis
    r = ax.screw.radius_per_rad
    push = ax.carriage.mass * cmd.a + ax.carriage.rail_friction * np.sign(cmd.v)
    k = stiffness_of(ax, cond.mech)["axial"]
    eps = sim.flank_motion(x_cmd / r)[0]
    return ((1.0 + sim.lead_stretch(cond)) * x_cmd + eps
            - 0.5 * cond.mech.backlash * held_sign(push, before) - push / k)


def run_many(items: list[tuple[Simulator, Condition]], cmd: Profile, passes: int = 2,
             nthread: int | None = None, contact_guess: bool = False) -> list[Trajectory]:
    """Roll out several (simulator, condition) pairs under one command in one
    ``mujoco.rollout`` call.

    The simulators may hold different worlds (rails, effects, servo, sensors: anything but the
    model's structure, see :meth:`Simulator.structure`); the models of different conditions
    differ only in float fields (see :func:`twin.sim.model.apply_state`), so they batch; ``nthread``
    threads share the work (the GIL is released). A simulator's own model serves its first
    item, copies the others. Each item's trajectory is the one a rollout of it alone gives.

    Row k of a trajectory is the state at t_k = k·dt, before step k, which is also when
    MuJoCo evaluates the sensors of step k (``sens`` row k). The accelerometers' rows are the
    acceleration that step k applies, (v_{k+1} − v_k)/dt at the sensor
    (:func:`twin.sim.model.accelerometer_implicit_correction`)."""
    first = items[0][0]
    for sim, _ in items[1:]:
        if sim.structure() != first.structure():
            raise ValueError(f"run_many: models of different structure {sim.structure()} and "
                             f"{first.structure()} (nq, nv, nu, na, nsensordata, timestep) "
                             "cannot share a rollout")
    x_cmd = [cmd.x + c.origin_offset for _, c in items]
    # Direction of the last motion at every instant: the flank the carriage rests on.
    moving = np.flatnonzero(cmd.v)
    direction = held_sign(cmd.v, cmd.rest_direction
                          or (np.sign(cmd.v[moving[0]]) if moving.size else 1.0))
    models, s0s, x_rails, used = [], [], [], set()
    for (sim, cond), xc in zip(items, x_cmd, strict=True):
        model = sim.model if id(sim) not in used else copy.deepcopy(sim.model)
        used.add(id(sim))
        ax = sim.world.axis
        r = ax.screw.radius_per_rad
        zn = ax.carriage.nut_height - ax.carriage.com_height
        mech = replace(cond.mech, lead_stretch=sim.lead_stretch(cond),
                       drag_scale=sim.drag_scale(cond))
        apply_state(model, ax, mech)
        stretch = 1.0 + mech.lead_stretch
        # Start at rest on the rails, in contact on the flank of the first motion; first guess
        # of the true position: the carriage trails the screw by half the clearance.
        theta0 = xc[0] / r
        x0 = stretch * xc[0] - 0.5 * cond.mech.backlash * direction[0]
        pose = sim.rest_pose(x0)
        flank0 = sim.flank_motion(np.array([theta0, theta0]))[0][0]
        models.append(model)
        s0s.append(initial_state(model, x0 + flank0 - zn * pose[3], theta0, flank0, pose))
        x_rails.append(flank_contact_position(sim, cond, cmd, xc, direction[0]) if contact_guess
                       else stretch * xc - 0.5 * cond.mech.backlash * direction)
    nthread = nthread or min(len(items), os.cpu_count() or 1)
    datas = [first.data] + [mujoco.MjData(first.model) for _ in range(nthread - 1)]
    nq, nv = first.model.nq, first.model.nv
    # Let the small transient of the analytic rest pose (the x–pitch coupling of the nut,
    # ~25 nm) ring out before t = 0, holding the first command, so that no instrument
    # starts from a disturbed first sample.
    n_settle = int(round(SETTLE_TIME / first.timestep))
    hold = Profile(t=np.arange(n_settle) * first.timestep, x=np.full(n_settle, cmd.x[0]),
                   v=np.zeros(n_settle), a=np.zeros(n_settle))
    ctrl = np.stack([sim.controls(c, hold, np.full(n_settle, xr[0]))
                     for (sim, c), xr in zip(items, x_rails, strict=True)])
    settled, _ = rollout.rollout(models, datas, np.stack(s0s), ctrl)
    s0s = list(settled[:, -1, :])
    for s0 in s0s:
        s0[0] = 0.0  # time
    phys = slice(1, 1 + nq + nv)  # qpos and qvel in MuJoCo's full physics state
    for _ in range(max(passes, 1)):
        ctrls = [sim.controls(c, cmd, xr) for (sim, c), xr in zip(items, x_rails, strict=True)]
        # Rollout row k is the state after step k; with the initial state before it, row k
        # is the state at t_k, the one step k (its rails, its sensors) sees.
        if len(items) == 1:  # the rollout writes after the initial state: no copy
            ctrl = ctrls[0][None]
            full = np.empty((1, cmd.t.size + 1, s0s[0].size))
            full[0, 0] = s0s[0]
            sens = np.empty((1, cmd.t.size, first.model.nsensordata))
            rollout.rollout(models, datas, full[:, 0], ctrl, state=full[:, 1:], sensordata=sens)
            after, state = full[:, 1:], full[:, :-1, phys]
        else:
            ctrl = np.stack(ctrls)
            after, sens = rollout.rollout(models, datas, np.stack(s0s), ctrl)
            state = np.concatenate([np.stack(s0s)[:, None, phys], after[:, :-1, phys]], axis=1)
        x_rails = [st[:, sim.index.x] for st, (sim, _) in zip(state, items, strict=True)]
    # The accelerometers read the acceleration of step k that the integrator applies,
    # (v_{k+1} − v_k)/dt, not MuJoCo's explicit qacc (see accelerometer_implicit_correction).
    for j, model in enumerate(models):
        cols, gain = accelerometer_implicit_correction(model, s0s[j], ctrl[j, 0])
        applied = (after[j, :, 1 + nq:1 + nq + nv] - state[j, :, nq:]) / first.timestep
        sens[j][:, cols] += applied @ gain.T
    t = np.arange(cmd.t.size) * first.timestep
    return [Trajectory(t=t, qpos=st[:, :nq], qvel=st[:, nq:], sens=se,
                       cmd=cmd, theta_cmd=xc / sim.world.axis.screw.radius_per_rad, index=sim.index)
            for st, se, xc, (sim, _) in zip(state, sens, x_cmd, items, strict=True)]


# ---------------------------------------------------------------------------------------------
# Phase I: ten 10-s captures of the 400 mm/s reciprocating routine per sample


PHASE1_LEAD_IN = 0.3  # s of standstill simulated (and discarded) before a capture starts
PHASE1_LEAD_OUT = 0.005  # s simulated (and discarded) after a capture ends


def phase1_profile(cfg, fs: float, rng: np.random.Generator) -> Profile:
    """Command of one Phase I capture: the reciprocating routine of Table I entered at a random
    moment of a dwell (captures are taken every 30 min of continuous operation, at no particular
    phase of the motion). ``cfg`` is a :class:`twin.sim.scenario.Phase1Config`."""
    start, end = cfg.start_mm * 1e-3, cfg.end_mm * 1e-3
    one = Move(start, end, cfg.speed_mm_s * 1e-3, cfg.accel_mm_s2 * 1e-3, cfg.dwell_s)
    cycles = int(math.ceil(cfg.capture_s / (2.0 * one.duration))) + 1
    moves = reciprocating(start, end, one.speed, one.accel, one.dwell, cycles)
    lead_in = PHASE1_LEAD_IN + float(rng.uniform(0.0, cfg.dwell_s))
    # A few ms past the capture so that instruments resampling to their own clock have samples
    # on both sides of the last instant.
    return command_profile(moves, fs, lead_in=lead_in,
                           duration=PHASE1_LEAD_IN + cfg.capture_s + PHASE1_LEAD_OUT)


def phase1_capture(sim: Simulator, cfg, cond: Condition, rng: np.random.Generator) -> dict:
    """Simulate one Phase I capture and measure it.

    Returns a dict of the eight signals at the controller/DAQ rate: ``speed`` (n,) rad/s,
    ``torque`` (n,) N·m, ``acc1``/``acc2`` (n, 3) m/s² (float32), and ``fs_hz``."""
    cmd = phase1_profile(cfg, sim.fs, rng)
    return phase1_measure(sim, cfg, sim.run(cond, cmd, passes=1), rng)


def phase1_measure(sim: Simulator, cfg, traj: Trajectory, rng: np.random.Generator) -> dict:
    """The eight Phase I signals of a simulated capture (see :func:`phase1_capture`; ``rng``
    continues the capture's generator after :func:`phase1_profile`)."""
    w = sim.world
    fs = sim.fs
    nut = traj.sens[:, np.r_[traj.index.nut1_acc, traj.index.nut2_acc]]
    fs_nut = fs
    if fs < w.nut_acc.fs_hz:
        # A coarser simulation step (phase1.timestep_s > 1/10 kHz) is band-limited upsampled to
        # the DAQ rate: the motion then has no content above fs/2.
        up = int(math.ceil(w.nut_acc.fs_hz / fs))
        nut = signal.resample_poly(nut, up, 1, axis=0)
        fs_nut = fs * up
    # Both nut accelerometers in one call; their noise is drawn from ``rng`` in order (acc1's,
    # then acc2's), as two calls would.
    _, (acc1, acc2) = ins.measure_nut_accelerometer_runs([nut[:, :3], nut[:, 3:]], fs_nut,
                                                         w.nut_acc, [rng, rng])
    _, speed = ins.measure_speed(traj.qpos[:, traj.index.screw], fs, w.encoder_counts_per_rev,
                                 w.controller_fs, rng)
    _, torque = ins.measure_torque(traj.sens[:, traj.index.servo_torque], fs, w.torque_noise,
                                   w.torque_resolution, w.controller_fs, rng)
    skip = int(round(PHASE1_LEAD_IN * w.controller_fs))
    n = int(round(cfg.capture_s * w.controller_fs))
    sl = slice(skip, skip + n)
    return {"speed": speed[sl].astype(np.float32), "torque": torque[sl].astype(np.float32),
            "acc1": acc1[sl].astype(np.float32), "acc2": acc2[sl].astype(np.float32),
            "fs_hz": float(w.controller_fs)}


# ---------------------------------------------------------------------------------------------
# Phase II: IMU runs over the full stroke at three speeds


PHASE2_LEAD_IN = 2.0  # s of standstill before the first move (bias estimation needs it)


def phase2_moves(cfg) -> list[Move]:
    """One Phase II run (Table I): forward and back at each speed, dwell after each motion."""
    start, end = cfg.start_mm * 1e-3, cfg.end_mm * 1e-3
    acc = cfg.accel_mm_s2 * 1e-3
    moves = []
    for v in cfg.speeds_mm_s:
        moves += reciprocating(start, end, v * 1e-3, acc, cfg.dwell_s, 1)
    return moves


def phase2_command(sim: Simulator, cfg) -> Profile:
    """The commanded profile of one Phase II run at the simulation rate. With
    ``cfg.start_flank`` = "last" the carriage rests before the run on the flank of the run's last
    motion, as it does when the run follows an identical one."""
    moves = phase2_moves(cfg)
    cmd = command_profile(moves, sim.fs, lead_in=PHASE2_LEAD_IN)
    if cfg.start_flank == "last" and moves:
        cmd = replace(cmd, rest_direction=math.copysign(1.0, moves[-1].end - moves[-1].start))
    return cmd


def phase2_trajectory(sim: Simulator, cfg, cond: Condition) -> Trajectory:
    """The deterministic motion of one Phase II run (``cfg.rail_passes`` passes, 2 by default;
    see the module docstring): one pass looks the rails up at
    :func:`flank_contact_position`, the first of two at the command shifted by the clearance's
    lag (as Phase I does), so that two passes give what they always gave."""
    return sim.run(cond, phase2_command(sim, cfg), passes=cfg.rail_passes,
                   contact_guess=cfg.rail_passes == 1)


def phase2_measure(sim: Simulator, traj: Trajectory, rng: np.random.Generator) -> dict:
    """Sensor streams of one run from the motion ``traj``: ``imu_acc`` (n,3) m/s², ``imu_gyro``
    (m,3) rad/s, ``position_cmd`` (k,) m, each with its rate ``*_fs_hz``.

    The runs of a session share the mechanical state, and the simulator is deterministic, so the
    90 runs of a session share one simulated motion and differ by their sensor noise (drawn
    independently per run from ``rng``), exactly as 90 simulations would."""
    return phase2_measure_runs(sim, traj, [rng])[0]


def phase2_measure_runs(sim: Simulator, traj: Trajectory, rngs: list[np.random.Generator],
                        position_cmd_lead_s: float = 0.0) -> list[dict]:
    """:func:`phase2_measure` for the runs of a session at once, run j from ``rngs[j]``: the
    motion's sensor-frame signals, the filter designs and the spline factorisation are computed
    once, the noise of each run is drawn from its own generator (accelerometer, then gyroscope,
    as :func:`phase2_measure`), so every array is bit for bit the one-run result.
    ``position_cmd_lead_s``: the recorded ``position_cmd`` at t is the command at t + this, s (a
    controller clock running ahead of the IMU's)."""
    w = sim.world
    fs = sim.fs
    force = traj.sens[:, traj.index.imu_acc]
    rate = traj.angular_velocity_imu
    n_cmd = int(math.floor(traj.cmd.t[-1] * w.position_cmd_fs)) + 1
    pos = traj.cmd.position_at(w.position_cmd_fs, n_cmd, position_cmd_lead_s)
    # All runs in one call per instrument: the motion's part once, the noise in blocks of runs,
    # each run's samples cast to float32 as its block is done. Run j's generator draws its
    # accelerometer noise, then its gyroscope noise, as run by run.
    _, accs = ins.measure_imu_accelerometer_runs([force] * len(rngs), fs, w.imu_acc, rngs,
                                                 dtype=np.float32)
    _, gyros = ins.measure_gyroscope_runs([rate] * len(rngs), fs, w.imu_gyro, rngs,
                                          dtype=np.float32)
    return [{"imu_acc": acc, "imu_acc_fs_hz": float(w.imu_acc.fs_hz),
             "imu_gyro": gyro, "imu_gyro_fs_hz": float(w.imu_gyro.fs_hz),
             "position_cmd": pos, "position_cmd_fs_hz": float(w.position_cmd_fs)}
            for acc, gyro in zip(accs, gyros, strict=True)]


def stroke_travels(world: World, traj: Trajectory, rest_fraction: float = 0.5) -> dict[str, np.ndarray]:
    """The true rest-to-rest travels of one run, per move in time order: what the paper's Eq. 9
    assumes (a carriage that travels L − b between rests when it stops on the driving flank).

    A rest is a standstill of the command; its position is the mean over the last
    ``rest_fraction`` of the standstill (the carriage has stopped ringing). Returns (moves,) arrays:
    ``speed_m_s`` (signed commanded speed of the move), ``carriage_m`` (the carriage's travel,
    signed, m), ``screw_m`` (the screw's, its angle times lead/2π, signed, m), ``command_m`` (the
    commanded travel, signed, m).
    """
    t, v = traj.cmd.t, traj.cmd.v
    moving = np.abs(v) > 1e-12
    edges = np.flatnonzero(np.diff(moving.astype(np.int8)))  # last index before each change
    starts, stops = list(edges[moving[edges + 1]] + 1), list(edges[~moving[edges + 1]] + 1)
    rests = []  # (i0, i1) index ranges of the standstills between moves
    bounds = [0, *stops]
    ends = [*starts, t.size]
    for a, b in zip(bounds, ends, strict=False):
        if b > a:
            rests.append((a + int((1.0 - rest_fraction) * (b - a)), b))
    x = traj.x
    screw = traj.qpos[:, traj.index.screw] * world.axis.screw.radius_per_rad
    sim_t = traj.t

    def at(sig, ab):
        i0, i1 = (int(np.searchsorted(sim_t, t[k])) for k in (ab[0], ab[1] - 1))
        return float(np.mean(sig[i0:i1 + 1]))

    out = {"speed_m_s": [], "carriage_m": [], "screw_m": [], "command_m": []}
    for k, i in enumerate(starts):
        if k + 1 >= len(rests):
            break
        r0, r1 = rests[k], rests[k + 1]
        j = i + int(np.argmax(np.abs(v[i:r1[0]])))
        out["speed_m_s"].append(float(v[j]))
        out["carriage_m"].append(at(x, r1) - at(x, r0))
        out["screw_m"].append(at(screw, r1) - at(screw, r0))
        out["command_m"].append(at(traj.cmd.x, r1) - at(traj.cmd.x, r0))
    return {k: np.asarray(a) for k, a in out.items()}


def true_error_motions(world: World, cfg, cond: Condition, dx: float = 0.05e-3
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Kinematic truth of a session: grid x_m (n,) of true carriage positions over the stroke
    and E (6, n) (E_XX, E_YX, E_ZX m; E_AX, E_BX, E_CX rad) at the IMU, quasi-static, including
    the thermal lead growth of the condition."""
    start = cfg.start_mm * 1e-3 + cond.origin_offset
    end = cfg.end_mm * 1e-3 + cond.origin_offset
    x = np.arange(start, end + 0.5 * dx, dx)
    r = world.axis.screw.radius_per_rad
    theta = x / r
    e = geo.true_error_motions(world.rails, world.carriage, world.screw, x, theta)
    e[0] += world.thermal_expansion * cond.temperature_rise * x
    return x, e


# ---------------------------------------------------------------------------------------------
# The dial indicator: first contact forward, last contact in reverse, 1 µm steps


@dataclass(frozen=True)
class DialResult:
    """backlash_um: the reading a technician reports (mean over repeats), µm; elastic_um: the
    largest elastic part of the lost motion, 2·F_rail/K_axial, µm (the rail friction fully
    loading the nut in both directions). In the simulation the reading lands slightly *below*
    the clearance (docs/validation.md) rather than up to elastic_um above it: MuJoCo's Coulomb
    friction is a soft constraint, so the settled carriage slowly relaxes the nut's load at each
    30 ms step.
    repeats_um: the single readings, µm."""

    backlash_um: float
    elastic_um: float
    repeats_um: tuple[float, ...]


def dial_indicator(sim: Simulator, cfg, cond: Condition, rng: np.random.Generator,
                   position: float = 0.225, settle: float = 0.03) -> DialResult:
    """The paper's dial-indicator procedure (section III.C), simulated.

    The lever tip is fixed against the steel load at rail coordinate ``position``. The screw is
    commanded in steps of ``cfg.step_um`` (held ``settle`` s each, quasi-static) through the
    contact point forward, then back. The technician reads the dial by eye: reading = true tip
    deflection + N(0, reading_noise), rounded to a tenth of the gradation, and takes the first
    step with a non-zero reading forward and the last one in reverse. The difference of the two
    displayed (encoder) positions, averaged over ``cfg.repeats`` repetitions (each from a random sub-step
    starting point), is the "experimental" backlash. ``cfg`` is a DialConfig."""
    step = cfg.step_um * 1e-6
    margin = 8e-6 + 4.0 * cfg.reading_noise_um * 1e-6
    b = cond.mech.backlash
    # Steps through the clearance and a margin on each side, then back (2·(b + margin) of
    # travel); the tip is set where the carriage will touch it half-way up.
    nsteps = int(math.ceil(2.0 * (b + margin) / step)) + 1
    per = max(int(round(settle * sim.fs)), 2)
    k_axial = stiffness_of(sim.world.axis, cond.mech)["axial"]
    elastic = 2.0 * sim.world.axis.carriage.rail_friction / k_axial
    resolution = cfg.gradation_um * 1e-6 / 10.0
    stretch = 1.0 + sim.lead_stretch(cond)
    results = []
    for _ in range(cfg.repeats):
        base = position - cond.origin_offset + float(rng.uniform(0.0, step))
        # The technician brings the lever to the load with the carriage parked on its forward
        # flank at ``base``; the tip ends up b + margin ahead of the load.
        tip = stretch * (base + cond.origin_offset) - b / 2.0 + b + margin
        up = base + step * np.arange(nsteps)
        stair = np.concatenate([up, up[::-1]])
        x_cmd = np.concatenate([np.full(per * 4, base), np.repeat(stair, per)])
        t = np.arange(x_cmd.size) / sim.fs
        # A vanishing first velocity tells the simulator which flank the carriage starts on.
        v = np.zeros_like(x_cmd)
        v[0] = 1e-12
        cmd_start = Profile(t=t, x=x_cmd, v=v, a=np.zeros_like(x_cmd))
        traj = sim.run(cond, cmd_start, passes=1)
        ends = per * 4 + per * (np.arange(2 * nsteps) + 1) - 1
        x_true = traj.x[ends]
        deflection = np.maximum(x_true - tip, 0.0)
        # A needle at rest reads exactly zero; once the tip is pushed, the by-eye estimate of
        # the sub-gradation deflection carries the reading error.
        noise = rng.normal(0.0, cfg.reading_noise_um * 1e-6, size=deflection.size)
        reading = np.where(deflection > 0.0, np.maximum(deflection + noise, 0.0), 0.0)
        reading = np.round(reading / resolution) * resolution
        touched = reading > 0.0
        fwd, rev = touched[:nsteps], touched[nsteps:]
        # The technician notes the position display: the encoder's actual position (nominal
        # lead), not the command, which the stiction of the drive leaves a fraction of a µm away.
        shown = traj.qpos[ends, traj.index.screw] * sim.world.axis.screw.radius_per_rad - cond.origin_offset
        cmd_steps_fwd, cmd_steps_rev = shown[:nsteps], shown[nsteps:]
        if not fwd.any() or not rev.any():
            raise RuntimeError("dial indicator: no contact within the stepped range")
        first_fwd = cmd_steps_fwd[np.argmax(fwd)]
        # Reverse: the last step (in time) at which the tip is still touched.
        last_rev = cmd_steps_rev[len(rev) - 1 - np.argmax(rev[::-1])]
        results.append((first_fwd - last_rev) * 1e6)
    return DialResult(backlash_um=float(np.mean(results)), elastic_um=elastic * 1e6,
                      repeats_um=tuple(results))
