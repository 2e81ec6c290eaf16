"""The paper's full campaign at reduced scale, measured end to end (prints figures; not a test).

``twin simulate scenarios/paper-rtf.toml --set campaign.scale=S`` (default S = 0.1: the full
8693-h timeline, 1 capture per Phase I sample instead of 10, 9 runs per Phase II session instead
of 90) on all local cores (or ``--workers N`` / ``--scheduler ADDR``), then ``twin backlash`` on
it; wall time of each, CPU time of the workers, size, and the peak memory of
the largest process. Long: about 10-20 min on a 2-core machine for S = 0.1.

Run: .venv/bin/python benchmarks/bench_campaign.py [--scale 0.1] [--out DIR] [--scheduler ADDR]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def twin(*args: str) -> float:
    """Run ``twin ARGS`` (wall seconds); stops the benchmark if it fails."""
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "twin.cli", *args], cwd=REPO, capture_output=True,
                       text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    if r.returncode != 0:
        sys.exit(f"twin {' '.join(args)} failed:\n{r.stdout}\n{r.stderr}")
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.1)
    ap.add_argument("--out", type=Path, default=None, help="campaign directory (default: temporary)")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--no-analysis", action="store_true", help="simulate only")
    args = ap.parse_args()
    where = (["--scheduler", args.scheduler] if args.scheduler else
             ["--workers", str(args.workers)] if args.workers else [])
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "paper"
        wall = twin("simulate", str(REPO / "scenarios/paper-rtf.toml"), "-o", str(out),
                    "--set", f"campaign.scale={args.scale}", *where)
        cpu = resource.getrusage(resource.RUSAGE_CHILDREN)
        size = sum(p.stat().st_size for p in out.glob("*.h5")) / 1e9
        print(f"paper campaign at campaign.scale={args.scale} on {os.cpu_count()} cores "
              f"(load average {os.getloadavg()[0]:.1f}): simulation {wall / 60:.1f} min wall, "
              f"{(cpu.ru_utime + cpu.ru_stime) / 60:.1f} min CPU, {size:.1f} GB of HDF5")
        if not args.no_analysis:
            wall_b = twin("backlash", str(out), "--no-plots", *where)
            print(f"  twin backlash {wall_b / 60:.1f} min wall (twin detect needs a reference set: "
                  "benchmarks/table3_phase1.py times it)")
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        print(f"  peak memory of the largest process: {peak:.0f} MB")


if __name__ == "__main__":
    main()
