"""Benchmark: `twin diagnose --budget-minutes` on a recording of the paper's full layout
(issue 15, item 3). Prints figures; not a test.

A recording of ``scenarios/paper-rtf.toml`` (104 Phase I samples of 10 captures, 103 Phase II
sessions of 90 runs: about 46 GB) is not simulated: the diagnosis reads only the parts of the
subset it chooses, and simulates only the subset's layout. So:

1. the recording's layout is taken from the scenario's campaign plan (:func:`twin.sim.campaign.plan`:
   the capture and session names, sample indices and hours a recording of it holds, what
   :func:`analysis.diagnosis.subset.inventory` reads from its attributes);
2. the unit costs are measured as ``twin diagnose`` measures them at its start
   (:func:`twin.harness.diagnosis.budget.measure_unit_costs`, kept in ``OUT/cache``);
3. for each budget, the subset chosen and its estimated time on ``--workers`` workers, and the
   estimate of the chosen subset on N workers;
4. a file of the paper's layout with one-sample arrays is written and its inventory timed
   (what the diagnosis reads of every part of a full recording);
5. with ``--measure``: a "real" recording holding exactly the parts of the subset chosen for
   ``--budget-minutes`` (the paper's scenario with the subset's layout at the same hours,
   another seed) is simulated, and ``twin diagnose REAL --scenario scenarios/paper-rtf.toml
   --budget-minutes B --workers W`` is timed on it (the same cache: the calibration is reused,
   and the subset of this recording within the same budget is all of it, the same
   simulations as for the full recording).

``--record`` (with ``--measure``) stores the figures and the table of docs/gap-diagnosis.md's
"The paper's layout" in docs/validation.json (``benchmarks/record.py`` writes them into the doc).

Usage: .venv/bin/python benchmarks/bench_diagnose_campaign.py [--out DIR] [--workers 1]
       [--budget-minutes 60] [--measure [--record]]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

from analysis.dataset import assemble_measurements  # noqa: E402
from analysis.diagnosis import subset  # noqa: E402
from twin.harness.diagnosis.budget import measure_unit_costs, subset_scenario, workload  # noqa: E402
from twin.harness.diagnosis.cache import with_seed  # noqa: E402
from twin.sim.campaign import plan, simulate_campaign  # noqa: E402
from twin.sim.scenario import load  # noqa: E402

PAPER = REPO / "scenarios" / "paper-rtf.toml"
BUDGETS_MIN = (15, 30, 60, 120, 240, 480, 960, 1920)
WORKERS = (1, 2, 4, 8, 16, 32, 64)


def layout_of(s) -> subset.Inventory:
    """The inventory a recording of ``s`` has (names, sample indices, hours), from its plan."""
    samples: dict[int, list] = {}
    sessions = []
    for u in plan(s):
        if u.kind == "phase1":
            samples.setdefault(u.sample, []).append((u.hours, u.name))
        elif u.kind == "phase2":
            sessions.append((u.name, u.hours, [f"r{r:04d}" for r in range(s.runs_per_session)]))
    return subset.Inventory([(k, c[0][0], [n for _, n in c]) for k, c in sorted(samples.items())], sessions)


def skeleton(path: Path, s, inv: subset.Inventory) -> Path:
    """A ``measurements.h5`` with the layout of ``inv`` (every capture, session and run group
    with its attributes) but one-sample arrays: what :func:`analysis.diagnosis.subset.inventory`
    reads of a full recording (attributes only) at a size that fits a disk."""
    from twin.sim.scenario import nominal_axis_description

    one, tri = np.zeros(1), np.zeros((1, 3))
    p1 = ((n, {"hours": h + j * s.phase1.capture_interval_minutes / 60, "sample": k, "fs_hz": s.phase1.fs_hz},
           {"speed": one, "torque": one, "acc1": tri, "acc2": tri})
          for k, h, names in inv.samples for j, n in enumerate(names))
    se = s.sensors
    rates = {"imu_acc": {"fs_hz": se.imu_acc_fs_hz}, "imu_gyro": {"fs_hz": se.imu_gyro_fs_hz},
             "position_cmd": {"fs_hz": se.position_cmd_fs_hz}}
    p2 = ((name, {"hours": h}, ((r, {}, {"imu_acc": tri, "imu_gyro": tri, "position_cmd": one}, rates)
                                for r in runs)) for name, h, runs in inv.sessions)
    return assemble_measurements(path, nominal_axis_description(s), p1, p2)


def describe(sub: subset.Subset) -> str:
    return (f"{len(sub.samples)} samples × {sub.captures} captures, {len(sub.sessions)} sessions × "
            f"{sub.runs} runs")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=REPO / "runs" / "bench-diagnose-campaign")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--budget-minutes", type=float, default=60.0)
    ap.add_argument("--measure", action="store_true")
    ap.add_argument("--record", action="store_true",
                    help="store the measured figures in docs/validation.json (needs --measure)")
    ap.add_argument("--response-seeds", type=int, default=3,
                    help="twin seeds of each candidate's response (twin diagnose --response-seeds)")
    a = ap.parse_args()
    if a.record and not a.measure:
        ap.error("--record needs --measure: the docs quote the measured diagnosis beside the projection")
    cache = a.out / "cache"
    paper = load(PAPER)
    inv = layout_of(paper)
    print(f"paper layout: {len(inv.samples)} samples × {inv.captures} captures, {len(inv.sessions)} "
          f"sessions × {inv.runs} runs")
    costs, spent = measure_unit_costs(paper, inv, cache)
    print(f"calibration: {spent:.1f} s (0: from the cache); unit costs (s, one worker): {costs}")
    report: dict = {"unit_costs_s": costs.__dict__, "calibration_s": spent, "budgets": []}
    for w in sorted({a.workers, 2}):
        work = workload(paper, 8, None, None, None, w, a.response_seeds)
        print(f"workload (default kinds, 8 seeds, {a.response_seeds} response seeds, 8 re-simulation seeds) "
              f"on {w} worker(s): {work}")
        for b in BUDGETS_MIN:
            sub = subset.choose(inv, costs, work, b * 60.0)
            print(f"  budget {b:5d} min: {describe(sub)}, estimated {sub.estimated_s / 60:.1f} min"
                  + ("" if sub.fits else " (the minimum: does not fit)"))
            report["budgets"].append({"workers": w, "budget_minutes": b, "size": describe(sub),
                                      "estimated_minutes": sub.estimated_s / 60, "fits": sub.fits})
        whole = subset.ladder(inv)[-1]
        print(f"  the whole recording: estimated {subset.cost_s(whole, costs, work) / 3600:.1f} h")
    work = workload(paper, 8, None, None, None, a.workers, a.response_seeds)
    chosen = subset.choose(inv, costs, work, a.budget_minutes * 60.0)
    size = subset.Size(len(chosen.samples), chosen.captures, len(chosen.sessions), chosen.runs)
    print(f"chosen for {a.budget_minutes:g} min on {a.workers} worker(s): {describe(chosen)}; on N workers "
          "it takes, and within the same budget N workers diagnose:")
    for n in WORKERS:
        wn = workload(paper, 8, None, None, None, n, a.response_seeds)
        est = subset.cost_s(size, costs, wn)
        more = subset.choose(inv, costs, wn, a.budget_minutes * 60.0)
        whole = subset.cost_s(subset.ladder(inv)[-1], costs, wn)
        print(f"  N = {n:3d}: {est / 60:.1f} min; {describe(more)} ({more.estimated_s / 60:.1f} min); "
              f"the whole recording {whole / 3600:.1f} h")
        report.setdefault("workers", []).append({"n": n, "chosen_minutes": est / 60, "within_budget": describe(more),
                                                 "within_budget_minutes": more.estimated_s / 60,
                                                 "whole_hours": whole / 3600})
    t0 = time.perf_counter()
    sk = skeleton(a.out / "skeleton" / "measurements.h5", paper, inv)
    print(f"a file of the paper's layout with one-sample arrays: written in {time.perf_counter() - t0:.0f} s")
    t0 = time.perf_counter()
    got = subset.inventory(sk)
    t_inv = time.perf_counter() - t0
    assert [(k, h) for k, h, _ in got.samples] == [(k, h) for k, h, _ in inv.samples]
    print(f"its inventory (the attributes of {sum(len(c) for _, _, c in got.samples)} captures and "
          f"{len(got.sessions)} sessions, the names of {sum(len(r) for _, _, r in got.sessions)} runs): "
          f"{t_inv:.2f} s")
    report["inventory_s"] = t_inv
    (a.out / "bench.json").write_text(json.dumps(report, indent=1))
    if not a.measure:
        return
    real = a.out / "real"
    s_real = with_seed(subset_scenario(paper, chosen), paper.seed + 101)
    t0 = time.perf_counter()
    simulate_campaign(s_real, real, workers=1)
    (real / "truth.h5").unlink(missing_ok=True)
    print(f"the recording of the subset's parts: {time.perf_counter() - t0:.0f} s")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "twin.cli", "diagnose", str(real), "--scenario", str(PAPER),
                           "--budget-minutes", f"{a.budget_minutes:g}", "--workers", str(a.workers),
                           "--response-seeds", str(a.response_seeds),
                           "--cache", str(cache), "-o", str(a.out / "diagnosis")],
                          cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"twin diagnose failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    res = json.loads((a.out / "diagnosis" / "diagnosis.json").read_text())
    sub = res["subset"]
    print(proc.stdout[-2500:])
    print(f"twin diagnose: {wall / 60:.1f} min wall (estimated {sub['estimated_minutes']:.1f} min, "
          f"diagnosis.json's actual {sub['actual_minutes']:.1f} min); verdict {res['verdict']}")
    # The subset writer reads only the chosen parts: the same from a full recording.
    print(f"writing the subset: {sub['subset_write_s']:.1f} s")
    report["workload"] = work.__dict__
    report.update(measured={"budget_minutes": a.budget_minutes, "workers": a.workers, "size": describe(chosen),
                            "wall_minutes": wall / 60, "estimated_minutes": sub["estimated_minutes"],
                            "actual_minutes": sub["actual_minutes"], "verdict": res["verdict"],
                            "subset_write_s": sub["subset_write_s"]})
    (a.out / "bench.json").write_text(json.dumps(report, indent=1))
    if a.record:
        record_figures(report, res, a)


def record_figures(report: dict, res: dict, a: argparse.Namespace) -> None:
    """Store the measured run's figures and the projection over N workers in docs/validation.json
    (docs/gap-diagnosis.md, "The paper's layout")."""
    sys.path.insert(0, str(REPO / "benchmarks"))
    from record import record

    c, m, w = report["unit_costs_s"], report["measured"], report["workload"]
    ratio = m["wall_minutes"] / m["estimated_minutes"]
    worst = [f"{r['domain']} {r['channel']} {r['family']} {r['bin']}" for r in res["regions"]
             if r["significant"]][:2]  # sorted by their calibration gap
    verdict = (f"\"{res['verdict']}\", {len(res['added'])} added: {res['n_significant_calibration']} of "
               f"{res['n_statistics']} statistics beyond the spread"
               + (f" ({'; '.join(worst)})" if worst else "")
               + f", held-out gap {res['heldout_gap_before']:.1f} against its critical "
                 f"{res['heldout_gap_critical']:.1f}")
    rows = [f"| workers N | the subset chosen for {a.workers} worker(s) | within {a.budget_minutes:g} min "
            "| the whole recording |",
            "|---|---|---|---|"]
    for r in report["workers"]:
        rows.append(f"| {r['n']} | {r['chosen_minutes']:.1f} min | {r['within_budget']} "
                    f"({r['within_budget_minutes']:.1f} min) | {r['whole_hours']:.1f} h |")
    figures = {
        "workload": (float(w["campaigns"]), f"{w['campaigns']} campaigns, {w['phase1_signatures']} Phase I and "
                                            f"{w['phase2_signatures']} Phase II post-processings"),
        "unit_costs": (c["capture"], f"Phase I capture {c['capture']:.2f} s (its statistics "
                                     f"{c['capture_signature']:.2f} s of it); Phase II session's motion "
                                     f"{c['session']:.1f} s; each run {c['run']:.2f} s (its statistics "
                                     f"{c['run_signature']:.2f} s)"),
        "calibration_s": (report["calibration_s"], f"{report['calibration_s']:.0f} s"),
        "inventory_s": (report["inventory_s"], f"{report['inventory_s']:.1f} s"),
        "subset_write_s": (m["subset_write_s"], f"{m['subset_write_s']:.1f} s"),
        "chosen": (m["budget_minutes"], f"{m['size']} for {m['budget_minutes']:g} min on {m['workers']} worker(s)"),
        "diagnosis": (m["wall_minutes"], f"{m['estimated_minutes']:.1f} / {m['wall_minutes']:.1f} min (measured / "
                                         f"estimated {ratio:.2f}; goal within 20 %: "
                                         f"{'met' if abs(ratio - 1) <= 0.2 else 'not met'})"),
        "verdict": (float(res["n_significant_calibration"]), verdict),
    }
    record("bench_diagnose_campaign", scale=f"scenarios/paper-rtf.toml's layout, {a.budget_minutes:g} min on "
           f"{a.workers} worker(s), {a.response_seeds} response seeds",
           command=(f".venv/bin/python benchmarks/bench_diagnose_campaign.py --out {a.out} "
                    f"--budget-minutes {a.budget_minutes:g} --workers {a.workers} "
                    f"--response-seeds {a.response_seeds} --measure --record"),
           figures=figures, tables={"workers": "\n".join(rows) + "\n"})


if __name__ == "__main__":
    main()
