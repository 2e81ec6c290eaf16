"""Benchmark: wall time of a 16-point sweep on a dask LocalCluster of 1 and of 2 worker processes,
and the speed-up (issue 5, check 8).

The sweep (``benchmarks/bench_sweep.toml``) is Phase II only (``scenarios/backlash-steps.toml``
reduced to 2 sessions of 2 runs at 100 mm/s over 450 mm): 4 backlash steps x 2 IMU noise levels
x 2 seeds = 16 campaigns, each simulated, analysed and scored by
:func:`twin.harness.chain.run_point` in a worker. Both runs go through ``twin sweep --workers N``
(a fresh output directory each, so nothing is reused); the times include starting the cluster
and the workers' imports. The two result tables are compared (they must be identical).
With ``--record`` the times go into docs/validation.json (:mod:`record`).

Usage: .venv/bin/python benchmarks/bench_sweep.py [--record]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402

SWEEP = REPO / "benchmarks" / "bench_sweep.toml"  # the 16 points (a sweep file, data)


def run(sweep: Path, out: Path, workers: int) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "twin.cli", "sweep", str(sweep), "-o", str(out),
                    "--workers", str(workers)], cwd=REPO, check=True, capture_output=True,
                   env=dict(os.environ, PYTHONPATH=str(REPO)))
    return time.perf_counter() - t0


def task_seconds(out: Path) -> list[float]:
    from twin.harness.sweep import read_log

    return [r["seconds"] for r in read_log(out) if r["event"] == "point"]


def main() -> None:
    import numpy as np
    import pandas as pd

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--record", action="store_true", help="store the figures in docs/validation.json")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        times, per_task, loads = {}, {}, {}
        for n in (1, 2):
            loads[n] = os.getloadavg()[0]
            times[n] = run(SWEEP, tmp / f"w{n}", n)
            per_task[n] = task_seconds(tmp / f"w{n}")
        a, b = (pd.read_parquet(tmp / f"w{n}" / "results.parquet") for n in (1, 2))
        pd.testing.assert_frame_equal(a, b, check_exact=True)
        print(f"sweep benchmark: 16 points (Phase II, 2 sessions x 2 runs at 100 mm/s over 450 mm), "
              f"{os.cpu_count()} cores")
        for n in (1, 2):
            t = np.asarray(per_task[n])
            print(f"  {n} worker{'s' if n > 1 else ' '}: {times[n]:6.1f} s wall "
                  f"(task {t.mean():.1f} s mean, {t.min():.1f}-{t.max():.1f} s; load average "
                  f"{loads[n]:.1f} before)")
        print(f"  speed-up 2 vs 1 workers: {times[1] / times[2]:.2f}x; result tables identical "
              f"({len(a)} rows)")
        print(json.dumps({"wall_s_1": round(times[1], 1), "wall_s_2": round(times[2], 1),
                          "speedup": round(times[1] / times[2], 2)}))
        if args.record:
            speedup = times[1] / times[2]
            record("bench_sweep", command=".venv/bin/python benchmarks/bench_sweep.py --record",
                   scale=f"twin sweep benchmarks/bench_sweep.toml ({len(a)} points) on 1 and on 2 workers",
                   figures={"times": (speedup, f"{times[1]:.0f} s on 1 worker, {times[2]:.0f} s on 2 "
                                               f"({speedup:.2f}×; {np.mean(per_task[2]):.1f} s per point), "
                                               "identical tables")})


if __name__ == "__main__":
    main()
