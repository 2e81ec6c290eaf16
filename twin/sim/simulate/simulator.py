"""The axis at one moment (:class:`Condition`), a rollout's motion (:class:`Trajectory`), and the
compiled MuJoCo model that produces it (:class:`Simulator`: one per time step; :meth:`Simulator.run`
rolls it out with ``mujoco.rollout`` under a commanded profile, :func:`run_many` several
(simulator, condition) pairs in one call).

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

from twin.sim import geometry as geo
from twin.sim.drive import Profile
from twin.sim.model import (
    FLANK_MASS,
    MechanicalState,
    ModelIndex,
    accelerometer_implicit_correction,
    apply_state,
    build_model,
    initial_state,
    stiffness_of,
)
from twin.sim.simulate.world import World, recirculation_force, stribeck_force

SETTLE_TIME = 0.1  # s of standstill simulated before t = 0 of every rollout


class SimulationDiverged(geo.RailRangeError):
    """A rollout diverged: MuJoCo found a NaN, Inf or huge acceleration and reset the state, so
    the rows after it are no motion. The axis's parameters are unstable at the model's time step
    (a stiffness too high for its mass: the semi-implicit Euler step is stable for ω·dt < 2,
    E. Hairer, C. Lubich and G. Wanner, Geometric Numerical Integration, 2nd ed., 2006, ch. I.5;
    or a loop too fast). A runaway like a carriage that leaves the rails: the handlers of
    :class:`~twin.sim.geometry.RailRangeError` take it. ``items``: the positions of the diverged
    (simulator, condition) pairs in :func:`run_many`'s list (or of the diverged scenarios in a
    batch of campaigns); ``t_s``: when the first one diverged, s."""

    def __init__(self, message: str, items: list[int], t_s: float):
        super().__init__(message)
        self.items, self.t_s = list(items), float(t_s)

    def __reduce__(self):  # across worker processes with its fields
        return type(self), (self.args[0], self.items, self.t_s)


def check_rollout(time_s: np.ndarray, start_s: np.ndarray, dt: float, what: str) -> None:
    """Raise :class:`SimulationDiverged` when a rollout's time column stops advancing by ``dt``
    (MuJoCo resets a diverged state, its time with it). ``time_s``: (n_items, n_rows) the time of
    the state after each step, s; ``start_s``: (n_items,) the initial states' time, s; ``what``:
    the rollout, for the message."""
    expected = start_s[:, None] + (np.arange(time_s.shape[1]) + 1) * dt
    bad = np.abs(time_s - expected) > 0.5 * dt
    items = np.flatnonzero(bad.any(axis=1))
    if items.size:
        first = min(float(expected[j, np.argmax(bad[j])] - dt - start_s[j]) for j in items)
        raise SimulationDiverged(
            f"the simulation diverged {first * 1e3:.4g} ms into {what} (MuJoCo found a NaN, Inf or huge "
            f"acceleration and reset the state): the axis is unstable at the time step of {dt * 1e3:g} ms, a "
            "stiffness too high for its mass or a loop too fast", [int(j) for j in items], first)


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
    check_rollout(settled[:, :, 0], np.stack(s0s)[:, 0], first.timestep, "the standstill before the command")
    s0s = list(settled[:, -1, :])
    for s0 in s0s:
        s0[0] = 0.0  # time
    phys = slice(1, 1 + nq + nv)  # qpos and qvel in MuJoCo's full physics state
    for k in range(max(passes, 1)):
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
        check_rollout(after[:, :, 0], np.zeros(len(items)), first.timestep,
                      f"the command of {cmd.t.size * first.timestep:.4g} s (pass {k + 1} of {max(passes, 1)})")
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
