"""Simulation benchmarks (prints figures; not a test).

- Phase I capture with all sensors: simulated seconds per wall second on one core;
- MuJoCo's bare stepping rate for the same model (mj_step in a C loop via rollout with a
  precomputed control array, and mj_step called from Python), and the pipeline's share;
- wall time of one Phase II run (two rollout passes + IMU models) and of the sensor part alone;
- wall time of the quick campaign on all cores;
- peak memory of this process.

Run: make bench   (or .venv/bin/python benchmarks/bench_simulation.py)
"""

from __future__ import annotations

import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from twin import campaign as cp  # noqa: E402
from twin.scenario import load  # noqa: E402
from twin.simulate import Simulator, phase1_capture, phase2_measure, phase2_trajectory  # noqa: E402


def timed(fn, repeat=3):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    s = load(REPO / "scenarios/paper-rtf.toml")
    world = cp.make_world(s)
    cond = cp.condition_at(s, 100.0)
    print(f"machine: {os.cpu_count()} cores, mujoco {mujoco.__version__}, numpy {np.__version__}")

    # Phase I: one 10-s capture with the eight sensor channels, at the default simulation step
    # (nut accelerometers upsampled to their 10 kHz DAQ) and at a step equal to the DAQ period.
    from twin.model import initial_state
    for dt in (s.phase1.timestep_s, 1e-4):
        sim = Simulator(world, dt)
        p1 = s.phase1.model_copy(update={"timestep_s": dt})
        wall, _ = timed(lambda sim=sim, p1=p1: phase1_capture(sim, p1, cond, cp.rng_for(0, 1, 0)))
        sim_seconds = p1.capture_s + 0.3
        rtf_pipeline = sim_seconds / wall
        # Bare stepping of the same model: rollout in C, same number of steps, holding still.
        nstep = int(round(sim_seconds / dt))
        model, data = sim.model, mujoco.MjData(sim.model)
        theta = 0.11 / world.axis.screw.radius_per_rad
        s0 = initial_state(model, 0.11, theta)
        ctrl = np.zeros((nstep, model.nu))
        ctrl[:, sim.index.servo_pos] = theta
        wall_bare, _ = timed(lambda model=model, data=data, s0=s0, ctrl=ctrl: rollout.rollout(model, data, s0, ctrl))
        rtf_bare = nstep / wall_bare * dt
        print(f"Phase I capture, step {dt * 1e3:g} ms: pipeline {wall:.3f} s wall -> "
              f"{rtf_pipeline:.1f}x real time (one core); bare mj_step {nstep / wall_bare:,.0f} "
              f"steps/s = {rtf_bare:.1f}x real time; pipeline / bare = {rtf_bare / rtf_pipeline:.2f}")
    d2 = mujoco.MjData(model)
    n_py = 20000
    t0 = time.perf_counter()
    for _ in range(n_py):
        mujoco.mj_step(model, d2)
    print(f"mj_step called from Python: {n_py / (time.perf_counter() - t0):,.0f} steps/s "
          f"(targets: >= 20x real time, pipeline within 2x of bare stepping)")

    # Phase II: one run (motion simulated in two passes, then the IMU models).
    sim2 = Simulator(world, s.phase2.timestep_s)
    cond2 = cp.condition_at(s, 5000.0, cp.origin_offset(s, 0))
    wall_traj, traj = timed(lambda: phase2_trajectory(sim2, s.phase2, cond2), repeat=1)
    wall_meas, _ = timed(lambda: phase2_measure(sim2, traj, cp.rng_for(0, 2, 0, 0)))
    print(f"Phase II run ({traj.t[-1]:.0f} s of motion and dwell at {1/s.phase2.timestep_s:g} Hz): "
          f"motion {wall_traj:.2f} s wall (two passes), IMU models {wall_meas:.3f} s per run; "
          f"a 90-run session = {wall_traj + 90 * wall_meas:.1f} s")

    # The quick campaign on all cores.
    with tempfile.TemporaryDirectory() as tmp:
        q = load(REPO / "scenarios/quick.toml")
        t0 = time.perf_counter()
        summary = cp.simulate_campaign(q, tmp)
        wall_q = time.perf_counter() - t0
        size = sum(p.stat().st_size for p in Path(tmp).glob("*.h5")) / 1e6
    print(f"quick campaign ({summary['units']} units) on {os.cpu_count()} cores: {wall_q:.1f} s, "
          f"{size:.0f} MB of HDF5")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    peak_children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"peak memory: {peak:.0f} MB (this process), {peak_children:.0f} MB (largest worker)")


if __name__ == "__main__":
    main()
