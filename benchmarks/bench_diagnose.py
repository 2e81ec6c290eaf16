"""Benchmark: the sim-to-real gap diagnosis, its blind benchmark's figures and its wall time.

1. ``twin diagnose-benchmark --resim-seeds 2`` (the default plan: 86 cases on
   ``scenarios/diagnose-bench.toml``, the candidates of the three kinds, every case with something
   added re-simulated with 2 twin seeds) from an empty cache in ``--out`` (default
   runs/validate/diagnose-benchmark, emptied first): the per-kind table, the nulls, the
   out-of-everything cases, the pairs, the false attributions, the misses and the times.
2. With ``--quick``, also one diagnosis on the quick campaign: a "real" recording of
   ``scenarios/quick.toml`` with seed 4242 and a cogging torque of 0.05 N·m at 12 per revolution
   is simulated, then ``twin diagnose REAL --scenario scenarios/quick.toml`` runs with a fresh
   cache (8 twin seeds plus every candidate's grid of a longer campaign: most of half an hour).

With ``--record`` (what ``make validate`` runs) the figures the docs quote go into
docs/validation.json (:mod:`record`); ``make validate`` then runs the ``validate`` tests
(tests/test_diagnosis_benchmark.py) on this run's cache.

Usage: .venv/bin/python benchmarks/bench_diagnose.py [--out DIR] [--record] [--quick]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402

from analysis.base.executors import default_processes  # noqa: E402

KINDS = ("physical effect", "signal artefact", "parameter")


def _twin(*args: str) -> tuple[float, subprocess.CompletedProcess]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "twin.cli", *args], cwd=REPO, env=env,
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"twin {' '.join(args)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return wall, proc


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def _of(rows: list[dict], kind: str, key: str = "correct") -> str:
    sel = [r for r in rows if r["kind"] == kind]
    return f"{sum(bool(r[key]) for r in sel)} of {len(sel)}"


def kinds_table(b: dict) -> str:
    """The per-kind table of benchmark.json ``b`` (Markdown)."""
    rows = b["cases"]
    case_kind = {"physical effect": "single", "signal artefact": "artefact", "parameter": "parameter"}
    cov = b["interval_coverage"]

    def cell_top1(k):
        return f"{_pct(b['per_kind_top1'][k])} ({_of(rows, case_kind[k])})"

    def cell_shrink(k):
        a, r = b["per_kind_median_heldout_shrink"][k], b["per_kind_median_heldout_shrink_resimulated"][k]
        return "-" if a is None else f"{100 * a:.1f} / " + ("-" if r is None else f"{100 * r:.1f} %")

    lines = ["| figure | physical effect | signal artefact | parameter | issue 15's target |",
             "|---|---|---|---|---|",
             "| top-1 (`per_kind_top1`) | " + " | ".join(cell_top1(k) for k in KINDS) + " | ≥ 90 % each |",
             "| first or not told apart from the first | "
             + " | ".join(_pct(b["per_kind_top1_or_not_told_apart"][k]) for k in KINDS) + " | |",
             "| seen at all (`per_kind_detected`) | "
             + " | ".join(_pct(b["per_kind_detected"][k]) for k in KINDS) + " | |",
             f"| median held-out shrink, interpolated / re-simulated ({b['resim_seeds']} seeds) | "
             + " | ".join(cell_shrink(k) for k in KINDS) + " | ≥ 80 % |",
             "| stated 90 % interval holding the injected value | "
             + " | ".join(f"{_pct(cov['per_kind'][k])} ({cov['n'][k]})" for k in KINDS) + " | ≥ 85 % |"]
    return "\n".join(lines) + "\n"


def misses_table(b: dict) -> str:
    """The confusion of benchmark.json ``b``: every case whose first added candidate is not the
    injected one (Markdown)."""
    lines = ["| case | kind | injected | named first | verdict when none |", "|---|---|---|---|---|"]
    for g in b["confusion"]:
        for case in g["cases"]:
            lines.append(f"| {case} | {g['kind']} | {g['injected']} | {g['named'] or '-'} | {g['verdict'] or ''} |")
    if len(lines) == 2:
        lines.append("| - | | | | |")
    return "\n".join(lines) + "\n"


def response_seed_cost() -> tuple[float, str]:
    """What the response seeds cost on ``scenarios/diagnose-bench.toml`` with the default kinds
    (:func:`twin.harness.diagnosis.budget.workload`: the twin's 8 seeds and every candidate's grid
    points; the post-processings of both phases), with 1 response seed and with the default."""
    from twin.harness.diagnosis import DEFAULT_RESPONSE_SEEDS, DEFAULT_SEEDS
    from twin.harness.diagnosis.budget import workload
    from twin.harness.diagnosis.library import DEFAULT_KINDS
    from twin.sim.scenario import load

    nominal = load(REPO / "scenarios" / "diagnose-bench.toml")
    one, default = (workload(nominal, DEFAULT_SEEDS, None, DEFAULT_KINDS, 0, 1, r)
                    for r in (1, DEFAULT_RESPONSE_SEEDS))
    post = [w.phase1_signatures + w.phase2_signatures for w in (one, default)]
    return (default.campaigns - one.campaigns,
            f"{default.campaigns - one.campaigns} more campaigns ({one.campaigns} → {default.campaigns}, the "
            f"{DEFAULT_SEEDS} twin seeds' included) and {post[1] - post[0]} more post-processings "
            f"({post[0]} → {post[1]})")


def benchmark_figures(b: dict, wall_s: float, workers: int) -> dict[str, tuple[float | None, str]]:
    rows = b["cases"]
    n_stats = sorted({r["n_statistics"] for r in rows if r["kind"] == "null"})
    ooe = [r for r in rows if r["kind"] in ("open_set", "edit")]
    t = b["wall_time_s"]
    n_false = sum(bool(r["false_attribution"]) for r in rows)
    changed = b["verdict_changed_by_resimulation"]
    return {
        "n_cases": (b["n_cases"], str(b["n_cases"])),
        "n_statistics": (n_stats[-1], "–".join(dict.fromkeys(str(n) for n in (n_stats[0], n_stats[-1])))),
        "response_seed_cost": response_seed_cost(),
        "nulls": (b["null_correct_fraction"], f"{_pct(b['null_correct_fraction'])} ({_of(rows, 'null')})"),
        "out_of_everything": (b["out_of_everything_unexplained_fraction"],
                              f"{_pct(b['out_of_everything_unexplained_fraction'])} "
                              f"({sum(bool(r['correct']) for r in ooe)} of {len(ooe)})"),
        "pairs": (b["pair_both_top3_fraction"], f"{_pct(b['pair_both_top3_fraction'])} ({_of(rows, 'pair')})"),
        "false_attributions": (b["false_attribution_rate"],
                               f"{100 * b['false_attribution_rate']:.2g} % ({n_false} of {len(rows)})"),
        "verdicts_changed_by_resimulation": (len(changed), ", ".join(changed) or "none"),
        "n_resimulated": (b["n_resimulated"], str(b["n_resimulated"])),
        "time_total_min": (wall_s / 60, f"{wall_s / 60:.1f} min on {workers} processes"),
        "time_grids_s": (t["twin_and_candidates"], f"{t['twin_and_candidates']:.0f} s"),
        "time_recordings_s": (t["recordings"], f"{t['recordings']:.0f} s"),
        "time_diagnoses_s": (t["diagnoses"], f"{t['diagnoses']:.0f} s"),
        "time_resimulations_s": (t["resimulations"], f"{t['resimulations']:.0f} s"),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "runs" / "validate" / "diagnose-benchmark")
    ap.add_argument("--record", action="store_true", help="store the figures in docs/validation.json")
    ap.add_argument("--quick", action="store_true", help="also diagnose a recording of the quick campaign")
    args = ap.parse_args()
    workers = default_processes()
    figures: dict[str, tuple[float | None, str]] = {}
    if args.quick:
        with tempfile.TemporaryDirectory() as tmp:
            real = Path(tmp) / "real"
            t_sim, _ = _twin("simulate", "scenarios/quick.toml", "-o", str(real), "--set", "seed=4242",
                             "--set", "effects.cogging_Nm=0.05", "--set", "effects.cogging_per_rev=12")
            (real / "truth.h5").unlink()
            t_diag, _ = _twin("diagnose", str(real), "--scenario", "scenarios/quick.toml",
                              "-o", str(Path(tmp) / "diagnosis"))
            res = json.loads((Path(tmp) / "diagnosis" / "diagnosis.json").read_text())
            n_sims = len(list((Path(tmp) / "diagnosis" / "cache").glob("*/signature.npz")))
        added = ", ".join(f"{a['effect']} {a['params']}" for a in res["added"]) or "none"
        print(f"twin diagnose on the quick campaign, {workers} processes, fresh cache: {t_diag:.0f} s wall "
              f"({n_sims} campaigns simulated; the recording itself took {t_sim:.0f} s)\n"
              f"  verdict: {res['verdict']}; added: {added}; held-out gap "
              f"{res['heldout_gap_before']:.0f} -> {res['heldout_gap_after']:.0f}")
        figures["quick_diagnosis_s"] = (t_diag, f"{t_diag:.0f} s")
    shutil.rmtree(args.out, ignore_errors=True)
    args.out.mkdir(parents=True)
    wall, proc = _twin("diagnose-benchmark", "-o", str(args.out), "--workers", str(workers), "--resim-seeds", "2")
    b = json.loads((args.out / "benchmark.json").read_text())
    t = b["wall_time_s"]
    print(f"twin diagnose-benchmark ({b['n_cases']} cases, {workers} processes, empty cache): {wall:.0f} s wall "
          f"(twin and candidates {t['twin_and_candidates']:.0f} s, recordings {t['recordings']:.0f} s, "
          f"diagnoses {t['diagnoses']:.0f} s, re-simulations {t['resimulations']:.0f} s)")
    print(kinds_table(b) + "\n" + misses_table(b))
    figures.update(benchmark_figures(b, wall, workers))
    for k, (_, text) in figures.items():
        print(f"  {k}: {text}")
    if args.record:
        record("bench_diagnose", command=".venv/bin/python benchmarks/bench_diagnose.py --record",
               scale=f"twin diagnose-benchmark, default plan (seed 2026, {b['n_cases']} cases, 8 twin seeds, "
                     f"3 response seeds, --resim-seeds 2) from an empty cache on {workers} processes",
               figures=figures, tables={"kinds": kinds_table(b), "misses": misses_table(b)})


if __name__ == "__main__":
    main()
