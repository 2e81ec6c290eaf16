"""Phase I of the paper (section III, Table I): ten 10-s captures of the 400 mm/s reciprocating
routine per sample, simulated and measured as the controller and the 10 kHz DAQ record them (motor
speed and torque, the two nut accelerometers). SI units.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import signal

from twin.sim.drive import Move, Profile, command_profile, reciprocating
from twin.sim.sensors import instruments as ins
from twin.sim.simulate.simulator import Condition, Simulator, Trajectory

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
