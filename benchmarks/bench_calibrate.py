"""Time of ``twin calibrate`` on a paper-size recording (issue 30, item 4; prints figures; not a test).

The calibration reads a recording's layout from the parts' attributes and fits on its first
Phase I sample (up to 4 of its captures) and the first runs of its first Phase II session
(``twin/harness/calibration/``): what it costs is set by the paper's capture length, rates and
routine, not by the campaign's length. The benchmark therefore simulates the paper's campaign
(``scenarios/paper-rtf.toml``: ten 10-s captures per sample at 10 kHz, sessions of 90 IMU runs
over 450 mm at 20, 100 and 500 mm/s) cut after its first sample and session, calibrates it
with ``--workers W``, and prints:

- the calibration's wall time (the goal: at most 15 min on 2 cores) and its own estimate of
  its longest time after the first simulations;
- with ``--budget-minutes B``: the calibration's time against B (the goal: at most 1.2 B; the
  fit stops at the budget's deadline with the best point so far, or the verb refuses a budget
  below the least a fit needs, naming it);
- the machine: cores, load average, and MuJoCo's bare stepping rate of the model measured in the
  same run, so the time can be compared across machines as a ratio.

``--scenario foreign-16mm`` takes that axis's whole campaign instead (the round trip's recording).

Run: .venv/bin/python benchmarks/bench_calibrate.py [--workers 2] [--out DIR] [--budget-minutes B]
[--scenario NAME] [--record]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np
from mujoco import rollout

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from record import record, text  # noqa: E402

from twin.harness.calibration import CALIBRATE_VERSION, calibrate  # noqa: E402
from twin.sim import campaign as cp  # noqa: E402
from twin.sim.campaign import simulate_campaign  # noqa: E402
from twin.sim.scenario import from_dict, load  # noqa: E402
from twin.sim.simulate import Simulator, phase1_profile  # noqa: E402

#: Issue 30's goal for a paper-size recording on 2 cores, s.
GOAL_S = 15 * 60.0


def goal_verdict(calibrate_s: float) -> str:
    """"met" when the calibration took at most :data:`GOAL_S`, else "not met"."""
    return "met" if calibrate_s <= GOAL_S else "not met"



def bare_steps_per_s(s) -> float:
    """MuJoCo's bare stepping (mujoco.rollout over a Phase I capture's controls), steps per CPU s."""
    sim = Simulator(cp.make_world(s), s.phase1.timestep_s)
    cond = cp.condition_at(s, 100.0)
    cmd = phase1_profile(s.phase1, sim.fs, cp.rng_for(0, cp.KIND_PHASE1, 0))
    s0 = np.concatenate([[0.0], sim.run(cond, cmd, passes=1).qpos[0], np.zeros(sim.model.nv)])
    size = mujoco.mj_stateSize(sim.model, mujoco.mjtState.mjSTATE_FULLPHYSICS)
    s0 = np.concatenate([s0, np.zeros(size - s0.size)])
    ctrl = sim.controls(cond, cmd, cmd.x)
    data = mujoco.MjData(sim.model)
    c0 = time.process_time()
    rollout.rollout(sim.model, data, s0, ctrl)
    return ctrl.shape[0] / (time.process_time() - c0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None, help="keep the recording and the calibration here")
    ap.add_argument("--budget-minutes", type=float, default=None, help="calibrate with this budget")
    ap.add_argument("--scenario", default=None, help="a scenario's whole campaign (default: the paper's, cut)")
    ap.add_argument("--record", action="store_true", help="store the figures in docs/validation.json "
                    "(the paper's campaign, no budget, only)")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench-calibrate-"))
    shutil.rmtree(out, ignore_errors=True)
    if args.scenario:
        s = load(args.scenario)
        first_session = float(s.campaign.total_hours) - 1.0
    else:
        s = load(REPO / "scenarios/paper-rtf.toml")
        first = max(cp.session_hours(s)[0], cp.sample_hours(s)[0])
        d = s.model_dump(mode="json")
        d["campaign"].update(total_hours=first + 1.0, pauses=[])
        s = from_dict(d)
        first_session = first
    bare = bare_steps_per_s(s)
    load_avg = os.getloadavg()[0]  # at the start: other work then slows every step
    print(f"machine: {os.cpu_count()} cores, load average {load_avg:.1f}; bare stepping "
          f"{bare:,.0f} steps/s (mujoco {mujoco.__version__})", flush=True)
    t0 = time.perf_counter()
    simulate_campaign(s, out / "campaign", workers=args.workers)
    t_sim = time.perf_counter() - t0
    print(f"recording: {s.name}'s campaign to {first_session + 1:g} h simulated in {t_sim:.0f} s", flush=True)
    t1 = time.perf_counter()
    rec = calibrate(out / "campaign", out / "axis.toml", workers=args.workers, budget_minutes=args.budget_minutes,
                    progress=lambda t: print(f"  {t}", flush=True))
    wall = time.perf_counter() - t1
    est = rec.get("estimated_s")
    print(f"calibration: {wall / 60:.1f} min on {args.workers} workers ({rec['simulations']} twin evaluations); "
          f"its estimate of the longest {est / 60:.1f} min"
          if est else f"calibration: {wall / 60:.1f} min (no fit ran)")
    if args.budget_minutes:
        print(f"budget {args.budget_minutes:g} min: the calibration took {wall / 60 / args.budget_minutes:.2f} of it "
              f"(goal at most 1.2); {rec.get('stopped') or 'the fit converged'}")
    if args.record and not (args.scenario or args.budget_minutes):
        record("bench_calibrate", command=".venv/bin/python benchmarks/bench_calibrate.py --workers 2 --record",
               scale=(f"scenarios/paper-rtf.toml cut after its first Phase I sample and Phase II session, "
                      f"{args.workers} workers, CALIBRATE_VERSION {CALIBRATE_VERSION}"),
               figures={"calibrate_min": (round(wall / 60, 2), text(wall / 60, "{:.1f}")),
                        "estimated_min": (None if est is None else round(est / 60, 2),
                                          text(None if est is None else est / 60, "{:.1f}")),
                        "simulations": (float(rec["simulations"]), str(rec["simulations"])),
                        "simulate_min": (round(t_sim / 60, 2), text(t_sim / 60, "{:.1f}")),
                        "bare_steps_per_s": (round(bare), f"{bare:,.0f}".replace(",", " ")),
                        "load_average": (round(load_avg, 1), text(load_avg, "{:.1f}")),
                        "goal": (float(wall <= GOAL_S), goal_verdict(wall))})
    print(json.dumps({"calibrate_s": wall, "estimated_s": est, "simulations": rec["simulations"],
                      "budget_s": rec.get("budget_s"), "stopped": rec.get("stopped"),
                      "bare_steps_per_s": bare, "workers": args.workers, "load_average": os.getloadavg()[0]}))


if __name__ == "__main__":
    main()
