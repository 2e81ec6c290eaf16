"""Benchmark: wall time of the sim-to-real gap diagnosis (issue 6, check 7).

1. One diagnosis on the quick campaign: a "real" recording of ``scenarios/quick.toml`` with
   seed 4242 and a cogging torque of 0.05 N·m at 12 per revolution is simulated, then
   ``twin diagnose REAL --scenario scenarios/quick.toml`` runs with a fresh cache (8 twin seeds
   plus every candidate's grid simulated on all local cores).
2. ``twin diagnose-benchmark`` (the default plan: 86 cases on ``scenarios/diagnose-bench.toml``, the
   candidates of the three kinds), fresh.

Prints the wall times, the diagnosis's answer and the benchmark's summary.

Usage: .venv/bin/python benchmarks/bench_diagnose.py
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _twin(*args: str) -> tuple[float, subprocess.CompletedProcess]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "twin.cli", *args], cwd=REPO, env=env,
                          capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"twin {' '.join(args)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return wall, proc


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        real = Path(tmp) / "real"
        t_sim, _ = _twin("simulate", "scenarios/quick.toml", "-o", str(real), "--set", "seed=4242",
                         "--set", "effects.cogging_Nm=0.05", "--set", "effects.cogging_per_rev=12")
        (real / "truth.h5").unlink()
        t_diag, proc = _twin("diagnose", str(real), "--scenario", "scenarios/quick.toml",
                             "-o", str(Path(tmp) / "diagnosis"))
        res = json.loads((Path(tmp) / "diagnosis" / "diagnosis.json").read_text())
        n_sims = len(list((Path(tmp) / "diagnosis" / "cache").glob("*/signature.npz")))
        print(f"twin diagnose on the quick campaign, {os.cpu_count()} cores, fresh cache: "
              f"{t_diag:.0f} s wall ({n_sims} campaigns simulated; the recording itself took "
              f"{t_sim:.0f} s)")
        added = ", ".join(f"{a['effect']} {a['params']}" for a in res["added"]) or "none"
        print(f"  verdict: {res['verdict']}; added: {added}; held-out gap "
              f"{res['heldout_gap_before']:.0f} -> {res['heldout_gap_after']:.0f}")
        t_bench, proc = _twin("diagnose-benchmark", "-o", str(Path(tmp) / "bench"))
        b = json.loads((Path(tmp) / "bench" / "benchmark.json").read_text())
        print(f"twin diagnose-benchmark ({b['n_cases']} cases): {t_bench:.0f} s wall "
              f"(twin and candidates {b['wall_time_s']['twin_and_candidates']:.0f} s, recordings "
              f"{b['wall_time_s']['recordings']:.0f} s, diagnoses {b['wall_time_s']['diagnoses']:.0f} s)")
        for k in ("top1_accuracy", "median_heldout_shrink", "null_correct_fraction",
                  "open_set_correct_fraction", "pair_both_top3_fraction"):
            print(f"  {k}: {b[k]:.3f}")
        print("  " + "\n  ".join(proc.stdout.strip().splitlines()))


if __name__ == "__main__":
    main()
