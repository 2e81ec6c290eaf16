"""Simulation benchmark: the twin's speed as ratios to MuJoCo's bare stepping measured in the same
run, and what the paper's full campaign costs (prints figures; not a test).

Absolute times differ by 1.5-2x from one machine to the next (and with the load of a shared
one); the ratios to the bare stepping of the same model on the same machine in the same run do
not, so they are the figures that count, and every absolute time is printed with the machine's
bare rate beside it. All times are CPU time of this process (``time.process_time``), the best of
``--repeat`` calls, with the C allocator keeping freed memory as the campaign's workers do.

- MuJoCo's bare stepping of the model: ``mujoco.rollout`` over the precomputed controls of the
  unit's own command (no sensor models, no Python per step), per step, for Phase I's capture and
  for Phase II's session (one pass of its steps);
- the Phase I pipeline (one 10-s capture: command, rollout, eight sensor channels) and the Phase II
  pipeline (one 90-run session: the motion in the scenario's ``phase2.rail_passes`` passes, then
  the IMU models of every run), each as a ratio to the bare stepping of the steps it simulates;
- one dial-indicator unit, in bare steps;
- what a campaign adds per unit: writing its part (and a session's truth) and assembling it into
  ``measurements.h5`` and ``truth.h5``;
- the paper's full campaign (``scenarios/paper-rtf.toml``) projected from these unit costs, as
  a ratio to the bare stepping of all its steps and in minutes on 2 cores and on N Dask workers;
- the quick campaign on all cores (wall time; not in the baseline), and the peak memory.

Regression guard: ``--write-baseline FILE`` stores the ratios; ``--check FILE`` measures them
again and exits 1 if any is more than ``--tolerance`` (20 %) above the stored one (``make
bench-check``; ratios below the baseline are reported, not failed). A measured campaign at scale:
``benchmarks/bench_campaign.py``.

``--record`` stores the speed table the docs show (docs/validation.json, ``benchmarks/record.py``).

Run: make bench   (or .venv/bin/python benchmarks/bench_simulation.py [--runs 90] [--no-quick])
     make bench-check
     .venv/bin/python benchmarks/bench_simulation.py --no-quick --repeat 3 --record
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
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

import record  # noqa: E402  (benchmarks/record.py, beside this script)

from analysis.base.executors import keep_freed_memory  # noqa: E402
from twin.sim import campaign as cp  # noqa: E402
from twin.sim.campaign import units as campaign_units  # noqa: E402
from twin.sim.parts import PartStore  # noqa: E402
from twin.sim.scenario import load  # noqa: E402
from twin.sim.simulate import (  # noqa: E402
    Simulator,
    dial_indicator,
    phase1_measure,
    phase1_profile,
    phase2_command,
    phase2_measure_runs,
    phase2_trajectory,
)

#: The issue's goals for the ratios (printed beside them; the check compares with the baseline).
GOALS = {"phase1": 1.3, "phase2": 1.5}


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


def bare_step(sim: Simulator, ctrl: np.ndarray, qpos0: np.ndarray, repeat: int) -> float:
    """CPU seconds per step of ``mujoco.rollout`` over ``ctrl`` (n, nu) from rest at ``qpos0``."""
    size = mujoco.mj_stateSize(sim.model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    s0 = np.zeros(size)
    s0[1:1 + sim.model.nq] = qpos0
    data = mujoco.MjData(sim.model)
    cpu, _, _ = clock(lambda: rollout.rollout(sim.model, data, s0, ctrl), repeat)
    return cpu / ctrl.shape[0]


def best_pair(unit, bare, repeat: int) -> tuple[float, float]:
    """(CPU s of ``unit()``, what ``bare()`` returns), the smallest of each over ``repeat``
    alternating calls of the two."""
    cpu, per_step = math.inf, math.inf
    for _ in range(repeat):
        cpu = min(cpu, clock(unit)[0])
        per_step = min(per_step, bare())
    return cpu, per_step


def machine() -> str:
    """What the figures were measured on: CPU model, cores (:func:`record.machine`), load."""
    return f"{record.machine()}, load average {os.getloadavg()[0]:.1f}"


def measure(runs: int, repeat: int) -> dict:
    """Every figure of the benchmark: ratios (dimensionless) and absolute CPU seconds."""
    s = load(REPO / "scenarios/paper-rtf.toml")
    world = cp.make_world(s)
    f: dict = {}
    # --- Phase I: one capture, and the bare stepping of its command ---------------------------
    sim1 = Simulator(world, s.phase1.timestep_s)
    cond1 = cp.condition_at(s, 100.0)
    cmd1 = phase1_profile(s.phase1, sim1.fs, cp.rng_for(0, cp.KIND_PHASE1, 0))
    traj1 = sim1.run(cond1, cmd1, passes=1)
    ctrl1 = sim1.controls(cond1, cmd1, cmd1.x)
    # The unit and its bare stepping alternate, so that both see the same load; best of each.
    roll1, step1 = best_pair(lambda: sim1.run(cond1, cmd1, passes=1),
                             lambda: bare_step(sim1, ctrl1, traj1.qpos[0], 1), 3 * repeat)
    meas1, _, _ = clock(lambda: phase1_measure(sim1, s.phase1, traj1,
                                               cp.rng_for(0, cp.KIND_PHASE1, 0)), 3 * repeat)
    n1 = cmd1.t.size
    f.update(bare_steps_per_s=1.0 / step1, phase1_s=roll1 + meas1, phase1_sensors_s=meas1, phase1_steps=n1,
             phase1_simulated_s=n1 * s.phase1.timestep_s, phase1=(roll1 + meas1) / (step1 * n1),
             phase1_rollout=roll1 / (step1 * n1))
    # --- Phase II: one session, and the bare stepping of its steps (one pass) -----------------
    sim2 = Simulator(world, s.phase2.timestep_s)
    cond2 = cp.condition_at(s, 5000.0, cp.origin_offset(s, 0))
    cmd2 = phase2_command(sim2, s.phase2)
    traj2 = phase2_trajectory(sim2, s.phase2, cond2)
    n2 = cmd2.t.size
    ctrl2 = sim2.controls(cond2, cmd2, traj2.x)
    motion, step2 = best_pair(lambda: phase2_trajectory(sim2, s.phase2, cond2),
                              lambda: bare_step(sim2, ctrl2, traj2.qpos[0], 1), repeat)
    rngs = [cp.rng_for(s.seed, cp.KIND_PHASE2, 0, r) for r in range(runs)]
    imu, _, _ = clock(lambda: phase2_measure_runs(sim2, traj2, rngs), repeat)
    session = motion + imu * s.runs_per_session / runs  # the scenario's runs per session
    f.update(phase2_bare_steps_per_s=1.0 / step2, phase2_passes=s.phase2.rail_passes,
             phase2_steps=n2, phase2_runs=s.runs_per_session, phase2_s=session,
             phase2_motion_s=motion, phase2_imu_s=imu * s.runs_per_session / runs,
             phase2=session / (step2 * n2), phase2_motion=motion / (step2 * n2),
             phase2_imu=imu * s.runs_per_session / runs / (step2 * n2))
    # --- Dial indicator ---------------------------------------------------------------------
    dial, _, _ = clock(lambda: dial_indicator(sim2, s.dial_indicator, cp.condition_at(s, 5000.0),
                                              cp.rng_for(s.seed, cp.KIND_DIAL, 0)), repeat)
    f.update(dial_s=dial, dial_bare_steps=dial / step2 / 1000.0)
    # --- What a campaign adds per unit: its part (HDF5; Phase II: also the session's truth) and
    # its assembly into measurements.h5 and truth.h5 -------------------------------------------
    u1, u2 = cp.Unit("phase1", "c000000", 0, 100.0, 0), cp.Unit("phase2", "s0000", 0, 5000.0)
    sig1 = phase1_measure(sim1, s.phase1, traj1, cp.rng_for(0, cp.KIND_PHASE1, 0))
    with tempfile.TemporaryDirectory() as tmp:
        store = PartStore(tmp)
        part1, _, _ = clock(lambda: campaign_units._store_phase1(store, u1, sig1), 3 * repeat)
        part2, _, _ = clock(lambda: campaign_units._store_phase2(s, sim2, store, u2, cond2, traj2))
        part2 -= f["phase2_imu_s"]  # _store_phase2 measures the scenario's runs again
        # Less the assembly's own cost (the files, the truth timeline), once per campaign.
        asm0, _, _ = clock(lambda: cp.assemble(s, Path(tmp), []), repeat)
        asm1, _, _ = clock(lambda: cp.assemble(s, Path(tmp), [u1]), repeat)
        asm2, _, _ = clock(lambda: cp.assemble(s, Path(tmp), [u2]), repeat)
        asm1, asm2 = max(asm1 - asm0, 0.0), max(asm2 - asm0, 0.0)
    f.update(phase1_storage_s=part1 + asm1, phase2_storage_s=part2 + asm2, assembly_s=asm0,
             phase2_storage=(part2 + asm2) / (step2 * n2))
    # --- The paper's campaign, projected ------------------------------------------------------
    units = cp.plan(s)
    count = {k: sum(u.kind == k for u in units) for k in ("phase1", "phase2", "dial")}
    unit1, unit2 = f["phase1_s"] + f["phase1_storage_s"], session + f["phase2_storage_s"]
    total = count["phase1"] * unit1 + count["phase2"] * unit2 + count["dial"] * dial + asm0
    bare = count["phase1"] * n1 * step1 + count["phase2"] * n2 * step2
    f.update(campaign_counts=count, campaign_s=total, campaign=total / bare,
             campaign_phase1_s=count["phase1"] * unit1 + asm0,
             campaign_phase2_s=count["phase2"] * unit2 + count["dial"] * dial,
             campaign_longest_s=max(unit2, dial, unit1),
             # on 2 cores: half the CPU, or the longest unit if that is longer
             campaign_2cores_s=max(total / 2, unit2, dial, unit1),
             campaign_sensors=(count["phase1"] * meas1 + count["phase2"] * f["phase2_imu_s"]) / total,
             campaign_storage=(count["phase1"] * f["phase1_storage_s"]
                               + count["phase2"] * f["phase2_storage_s"]) / total)
    return f


#: The ratios the baseline holds and the check compares.
RATIOS = ("phase1", "phase1_rollout", "phase2", "phase2_motion", "phase2_imu", "phase2_storage",
          "dial_bare_steps", "campaign")


def report(f: dict) -> None:
    rate = f"bare {f['bare_steps_per_s']:,.0f} steps/s"
    print(f"bare stepping (0.2 ms step): {f['bare_steps_per_s']:,.0f} steps/s over the Phase I "
          f"capture's controls, {f['phase2_bare_steps_per_s']:,.0f} over the Phase II session's")
    print(f"Phase I capture: {f['phase1']:.2f}x bare stepping of its steps (goal <= "
          f"{GOALS['phase1']}; rollout {f['phase1_rollout']:.2f}x, sensors "
          f"{f['phase1_sensors_s'] / f['phase1_s']:.0%}); {f['phase1_s']:.3f} s CPU for "
          f"{f['phase1_simulated_s']:.1f} s simulated ({rate})")
    print(f"Phase II session ({f['phase2_runs']} runs, {f['phase2_steps']:,} steps, "
          f"{f['phase2_passes']} rollout pass{'es' if f['phase2_passes'] > 1 else ''}): "
          f"{f['phase2']:.2f}x bare stepping of its steps (goal <= {GOALS['phase2']}; motion "
          f"{f['phase2_motion']:.2f}x, IMU models {f['phase2_imu']:.2f}x); {f['phase2_s']:.1f} s "
          f"CPU ({f['phase2_bare_steps_per_s']:,.0f} bare steps/s)")
    print(f"dial-indicator unit: {f['dial_bare_steps']:.0f} thousand bare steps; {f['dial_s']:.2f} s "
          f"CPU ({rate})")
    print(f"a campaign's storage per unit (its part, and its assembly into measurements.h5 and "
          f"truth.h5): Phase I capture {f['phase1_storage_s'] * 1e3:.0f} ms, Phase II session "
          f"{f['phase2_storage_s']:.2f} s = {f['phase2_storage']:.2f}x its bare stepping ({rate})")
    c = f["campaign_counts"]
    print(f"paper campaign ({c['phase1']} captures, {c['phase2']} sessions, {c['dial']} dial "
          f"units), projected: {f['campaign']:.2f}x the bare stepping of all its steps, sensor "
          f"models {f['campaign_sensors']:.0%}, storage {f['campaign_storage']:.0%}; "
          f"{f['campaign_s'] / 60:.1f} min CPU ({rate})")
    print("  projected wall time: " + ", ".join(
        f"{n} {'cores' if n == 2 else 'Dask workers'} "
        f"{max(f['campaign_s'] / n, f['campaign_longest_s']) / 60:.1f} min"
        for n in (2, 8, 32, 128)) + f" ({rate}; goal <= 15 min on 2 cores)")


def speed_table(f: dict) -> str:
    """The docs' table of the ratios (Markdown), each with its CPU time and goal."""
    c = f["campaign_counts"]
    met = lambda ok: "met" if ok else "not met"  # noqa: E731
    two = f["campaign_2cores_s"] / 60
    rows = [
        "| unit | ratio to the bare stepping of its steps | CPU | goal |",
        "|---|---|---|---|",
        f"| Phase I capture ({f['phase1_simulated_s']:.1f} s simulated, eight sensors) | **{f['phase1']:.2f}×** "
        f"(rollout {f['phase1_rollout']:.2f}×, sensor models {f['phase1_sensors_s'] / f['phase1_s']:.0%}) | "
        f"{f['phase1_s']:.2f} s | ≤ {GOALS['phase1']}×: {met(f['phase1'] <= GOALS['phase1'])} |",
        f"| Phase II session ({f['phase2_runs']} runs, {f['phase2_steps']:,} steps, {f['phase2_passes']} rollout "
        f"pass{'es' if f['phase2_passes'] > 1 else ''}) | **{f['phase2']:.2f}×** (motion {f['phase2_motion']:.2f}×, "
        f"IMU models {f['phase2_imu']:.2f}×) | {f['phase2_s']:.1f} s | ≤ {GOALS['phase2']}×: "
        f"{met(f['phase2'] <= GOALS['phase2'])} |",
        f"| dial-indicator unit | {f['dial_bare_steps'] * 1000:,.0f} bare steps | {f['dial_s']:.2f} s | |",
        f"| storage per unit (its part, its assembly into `measurements.h5` and `truth.h5`) | Phase II session "
        f"{f['phase2_storage']:.2f}×; Phase I capture {f['phase1_storage_s'] * 1e3:.0f} ms | "
        f"{f['phase2_storage_s']:.2f} s | |",
        f"| the paper's campaign, projected from these units ({c['phase1']} captures, {c['phase2']} sessions, "
        f"{c['dial']} dial units) | **{f['campaign']:.2f}×** (sensor models {f['campaign_sensors']:.0%}, storage "
        f"{f['campaign_storage']:.0%}) | {f['campaign_s'] / 60:.1f} min; {two:.1f} min on 2 cores | ≤ 15 min on "
        f"2 cores: {met(two <= 15)} |"]
    return "\n".join(rows)


def check(f: dict, path: Path, tolerance: float) -> int:
    """Compare the ratios with the baseline at ``path``; 1 if any is above it by more than
    ``tolerance`` (relative), else 0."""
    base = json.loads(path.read_text())
    failed = []
    print(f"\ncheck against {path} (measured on {base['machine']}, bare "
          f"{base['bare_steps_per_s']:,.0f} steps/s; tolerance +{tolerance:.0%}):")
    for k in RATIOS:
        if k not in base["ratios"]:
            continue
        old, new = base["ratios"][k], f[k]
        change = new / old - 1.0
        verdict = "SLOWER" if change > tolerance else "ok"
        if verdict != "ok":
            failed.append(k)
        print(f"  {k:<16} {old:8.3f} -> {new:8.3f} ({change:+.0%}) {verdict}")
    if failed:
        print(f"FAILED: {', '.join(failed)} more than {tolerance:.0%} above the baseline")
        return 1
    print("passed")
    return 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=90, help="runs of the Phase II session (90)")
    ap.add_argument("--repeat", type=int, default=1, help="best of N calls (1; 3 with --check)")
    ap.add_argument("--no-quick", action="store_true", help="skip the quick campaign")
    ap.add_argument("--check", type=Path, default=None, metavar="BASELINE",
                    help="compare the ratios with BASELINE (JSON); exit 1 beyond --tolerance")
    ap.add_argument("--tolerance", type=float, default=0.2, help="relative slack of --check (0.2)")
    ap.add_argument("--write-baseline", type=Path, default=None, metavar="FILE",
                    help="store the measured ratios as the baseline FILE (JSON)")
    ap.add_argument("--record", action="store_true",
                    help="store the speed table in docs/validation.json (benchmarks/record.py)")
    args = ap.parse_args()
    repeat = args.repeat if args.repeat > 1 or args.check is None else 3
    keep_freed_memory()  # as the campaign's worker processes do (analysis/base/executors.py)
    where = machine()
    print(f"machine: {where}; mujoco {mujoco.__version__}, numpy {np.__version__}; "
          f"CPU time of one process, best of {repeat}")
    f = measure(args.runs, repeat)
    report(f)
    if args.record:
        two_cores = f["campaign_2cores_s"] / 60  # the projection on 2 cores, min
        record.record("bench_simulation", command=".venv/bin/python benchmarks/bench_simulation.py --no-quick "
               f"--repeat {repeat} --record", scale=f"scenarios/paper-rtf.toml: one Phase I capture, one "
               f"{args.runs}-run Phase II session, one dial unit; CPU time of one process, best of {repeat}",
               figures={"bare_steps_per_s": (round(f["bare_steps_per_s"]), f"{f['bare_steps_per_s']:,.0f}"),
                        "phase2_bare_steps_per_s": (round(f["phase2_bare_steps_per_s"]),
                                                    f"{f['phase2_bare_steps_per_s']:,.0f}"),
                        "phase1": (round(f["phase1"], 3), f"{f['phase1']:.2f}"),
                        "phase2": (round(f["phase2"], 3), f"{f['phase2']:.2f}"),
                        "phase2_imu": (round(f["phase2_imu"], 3), f"{f['phase2_imu']:.2f}"),
                        "campaign": (round(f["campaign"], 3), f"{f['campaign']:.2f}"),
                        "campaign_2cores_min": (round(two_cores, 1), f"{two_cores:.0f}")},
               tables={"speed": speed_table(f)})
    if args.write_baseline:
        args.write_baseline.write_text(json.dumps({
            "machine": where, "bare_steps_per_s": round(f["bare_steps_per_s"]),
            "command": " ".join(["benchmarks/bench_simulation.py", *sys.argv[1:]]),
            "ratios": {k: round(f[k], 4) for k in RATIOS}}, indent=2) + "\n")
        print(f"baseline written to {args.write_baseline}")
    if args.check:
        sys.exit(check(f, args.check, args.tolerance))
    if not args.no_quick:
        with tempfile.TemporaryDirectory() as tmp:
            q = load(REPO / "scenarios/quick.toml")
            t0 = time.perf_counter()
            summary = cp.simulate_campaign(q, tmp)
            wall_q = time.perf_counter() - t0
            size = sum(p.stat().st_size for p in Path(tmp).glob("*.h5")) / 1e6
        print(f"quick campaign ({summary['units']} units) on {summary['executor']}: {wall_q:.1f} s "
              f"wall, {size:.0f} MB of HDF5 (bare {f['bare_steps_per_s']:,.0f} steps/s)")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    peak_children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(f"peak memory: {peak:.0f} MB (this process), {peak_children:.0f} MB (largest worker)")


if __name__ == "__main__":
    main()
