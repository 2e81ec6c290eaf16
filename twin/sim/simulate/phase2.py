"""Phase II of the paper (section III, Table I): IMU runs over the full stroke at three speeds,
simulated (the deterministic motion of a run, shared by the runs of a session) and measured (the
IMU's accelerometer and gyroscope and the commanded position, one noise draw per run); and the
session's truths: the rest-to-rest travels of a run and the quasi-static error motions at the IMU.
SI units.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from twin.sim import geometry as geo
from twin.sim.drive import Move, Profile, command_profile, reciprocating
from twin.sim.sensors import instruments as ins
from twin.sim.simulate.simulator import Condition, Simulator, Trajectory
from twin.sim.simulate.world import World

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
    see :mod:`twin.sim.simulate.simulator`): one pass looks the rails up at
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
