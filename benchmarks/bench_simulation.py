"""Simulation benchmark: where a campaign's time goes, and what the paper's full campaign costs
(prints figures; not a test).

One run, side by side (CPU time of this process, ``time.process_time``, and wall time; on a busy
machine trust the CPU figures):

- MuJoCo's bare stepping of the model (``mujoco.rollout`` over precomputed controls of the
  Phase I command, no sensor models, no Python per step);
- the Phase I pipeline (one 10-s capture: command, rollout, eight sensor channels) and the Phase II
  pipeline (one 90-run session: the motion in two passes, then the IMU models of every run), each
  as a ratio to the bare stepping of the steps it simulates, and the sensor models' share;
- one dial-indicator unit;
- the paper's full campaign (``scenarios/paper-rtf.toml``) projected from these unit costs on
  2 cores and on N Dask workers (never below its longest unit);
- the quick campaign on all cores, and the peak memory.

A measured full campaign at reduced scale: ``benchmarks/bench_campaign.py``.

Run: make bench   (or .venv/bin/python benchmarks/bench_simulation.py [--runs 90])
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import resource  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import mujoco  # noqa: E402
import numpy as np  # noqa: E402
from mujoco import rollout  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from twin import campaign as cp  # noqa: E402
from twin.scenario import load  # noqa: E402
from twin.simulate import (  # noqa: E402
    Simulator,
    dial_indicator,
    phase1_measure,
    phase1_profile,
    phase2_measure_runs,
    phase2_trajectory,
)


def clock(fn, repeat: int = 1):
    """(CPU s, wall s, result) of the fastest of ``repeat`` calls (by CPU time)."""
    best = None
    for _ in range(repeat):
        c0, w0 = time.process_time(), time.perf_counter()
        out = fn()
        c, w = time.process_time() - c0, time.perf_counter() - w0
        if best is None or c < best[0]:
            best = (c, w, out)
    return best


def bare_rate(sim: Simulator, ctrl: np.ndarray, s0: np.ndarray, repeat: int = 3) -> float:
    """CPU seconds per step of mujoco.rollout over ``ctrl`` (n, nu) from ``s0``."""
    data = mujoco.MjData(sim.model)
    cpu, _, _ = clock(lambda: rollout.rollout(sim.model, data, s0, ctrl), repeat)
    return cpu / ctrl.shape[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=90, help="runs of the Phase II session (90)")
    ap.add_argument("--no-quick", action="store_true", help="skip the quick campaign")
    args = ap.parse_args()
    s = load(REPO / "scenarios/paper-rtf.toml")
    world = cp.make_world(s)
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; mujoco "
          f"{mujoco.__version__}, numpy {np.__version__}; CPU time of one process")

    # --- Phase I: one capture, and the bare stepping of its command --------------------------
    sim1 = Simulator(world, s.phase1.timestep_s)
    cond1 = cp.condition_at(s, 100.0)
    cmd1 = phase1_profile(s.phase1, sim1.fs, cp.rng_for(0, cp.KIND_PHASE1, 0))
    s0 = np.concatenate([[0.0], sim1.run(cond1, cmd1, passes=1).qpos[0], np.zeros(sim1.model.nv)])
    state_size = mujoco.mj_stateSize(sim1.model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    s0 = np.concatenate([s0, np.zeros(state_size - s0.size)])
    step_cpu = bare_rate(sim1, sim1.controls(cond1, cmd1, cmd1.x), s0)
    n1 = cmd1.t.size
    bare1 = step_cpu * n1
    roll1, _, traj1 = clock(lambda: sim1.run(cond1, cmd1, passes=1), 3)
    meas1, _, _ = clock(lambda: phase1_measure(sim1, s.phase1, traj1,
                                               cp.rng_for(0, cp.KIND_PHASE1, 0)), 3)
    p1 = roll1 + meas1
    print(f"bare stepping (step {s.phase1.timestep_s * 1e3:g} ms): {1 / step_cpu:,.0f} steps/s = "
          f"{1 / step_cpu * s.phase1.timestep_s:.1f}x real time")
    print(f"Phase I capture ({n1 * s.phase1.timestep_s:.1f} s simulated): {p1:.3f} s CPU = "
          f"{p1 / bare1:.2f}x bare (rollout {roll1 / bare1:.2f}x, sensors {meas1:.3f} s = "
          f"{meas1 / p1:.0%}); {n1 * s.phase1.timestep_s / p1:.1f}x real time")

    # --- Phase II: one session ----------------------------------------------------------------
    sim2 = Simulator(world, s.phase2.timestep_s)
    cond2 = cp.condition_at(s, 5000.0, cp.origin_offset(s, 0))
    traj_cpu, traj_wall, traj2 = clock(lambda: phase2_trajectory(sim2, s.phase2, cond2))
    n2 = traj2.t.size
    # Same model and step as Phase I (0.2 ms by default): the same bare rate per step.
    bare2 = (step_cpu if sim2.timestep == sim1.timestep else
             bare_rate(sim2, sim2.controls(cond2, traj2.cmd, traj2.cmd.x), s0, 1)) * n2
    rngs = [cp.rng_for(s.seed, cp.KIND_PHASE2, 0, r) for r in range(args.runs)]
    sens_cpu, sens_wall, _ = clock(lambda: phase2_measure_runs(sim2, traj2, rngs))
    p2 = traj_cpu + sens_cpu
    print(f"Phase II session ({args.runs} runs of {traj2.t[-1]:.0f} s at "
          f"{1 / s.phase2.timestep_s:g} Hz): {p2:.1f} s CPU ({traj_wall + sens_wall:.1f} s wall) "
          f"= {p2 / bare2:.2f}x bare stepping of one pass; motion (two passes) {traj_cpu:.1f} s "
          f"= {traj_cpu / bare2:.2f}x, IMU models {sens_cpu:.1f} s ({sens_cpu / args.runs * 1e3:.0f} "
          f"ms per run) = {sens_cpu / p2:.0%}")

    # --- Dial indicator ---------------------------------------------------------------------
    prof_cpu, _, _ = clock(lambda: sim2.controls(cond2, traj2.cmd, traj2.x))
    print(f"  where the motion's time goes: {n2:,} steps x 2 passes + settle in mujoco.rollout "
          f"({(traj_cpu - 2 * prof_cpu) / traj_cpu:.0%}), control arrays (rails, screw) "
          f"{2 * prof_cpu:.2f} s ({2 * prof_cpu / traj_cpu:.0%})")
    dial_cpu, _, _ = clock(lambda: dial_indicator(sim2, s.dial_indicator, cp.condition_at(s, 5000.0),
                                                  cp.rng_for(s.seed, cp.KIND_DIAL, 0)))
    print(f"dial-indicator unit: {dial_cpu:.1f} s CPU")

    # --- The paper's campaign, projected ------------------------------------------------------
    units = cp.plan(s)
    count = {k: sum(u.kind == k for u in units) for k in ("phase1", "phase2", "dial")}
    session_cpu = traj_cpu + sens_cpu * s.runs_per_session / args.runs
    total = count["phase1"] * p1 + count["phase2"] * session_cpu + count["dial"] * dial_cpu
    longest = max(session_cpu, dial_cpu, p1)
    sens_total = count["phase1"] * meas1 + count["phase2"] * sens_cpu * s.runs_per_session / args.runs
    print(f"paper campaign ({count['phase1']} captures, {count['phase2']} sessions x "
          f"{s.runs_per_session} runs, {count['dial']} dial units): {total / 60:.0f} min CPU, "
          f"sensor models {sens_total / total:.0%}")
    print("  projected wall time: " + ", ".join(
        f"{n} {'cores' if n == 2 else 'Dask workers'} {max(total / n, longest) / 60:.1f} min"
        for n in (2, 8, 32, 128)) + " (goal: <= 15 min on 2 cores)")

    # --- The quick campaign on all cores ------------------------------------------------------
    if not args.no_quick:
        with tempfile.TemporaryDirectory() as tmp:
            q = load(REPO / "scenarios/quick.toml")
            t0 = time.perf_counter()
            summary = cp.simulate_campaign(q, tmp)
            wall_q = time.perf_counter() - t0
            size = sum(p.stat().st_size for p in Path(tmp).glob("*.h5")) / 1e6
        print(f"quick campaign ({summary['units']} units) on {summary['executor']}: {wall_q:.1f} s "
              f"wall, {size:.0f} MB of HDF5")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    peak_children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"peak memory: {peak:.0f} MB (this process), {peak_children:.0f} MB (largest worker)")


if __name__ == "__main__":
    main()
