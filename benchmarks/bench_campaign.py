"""The paper's full campaign at reduced scale, measured end to end (prints figures; not a test).

``twin simulate scenarios/paper-rtf.toml --set campaign.scale=S`` (default S = 0.1: the full
8693-h timeline, 1 capture per Phase I sample instead of 10, 9 runs per Phase II session instead
of 90; S = 1 is the paper's campaign) on all local cores (or ``--workers N`` / ``--scheduler
ADDR``), then ``twin backlash`` on it, then ``twin detect`` against the reference set
(``scenarios/paper-reference.toml`` at the same scale, simulated too). For each step: wall time,
CPU time of its processes and the peak memory of its largest process; the size of the HDF5
files. Long: about 10-20 min on a 2-core machine for S = 0.1; S = 1 writes about 46 GB and as
much again in resumable parts before they are assembled (about 100 GB of free disk).

Run: .venv/bin/python benchmarks/bench_campaign.py [--scale 0.1] [--out DIR] [--scheduler ADDR]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def twin(*args: str) -> tuple[float, float, float]:
    """Run ``twin ARGS``: (wall s, CPU s of it and the processes it waited for, peak RSS MB of the
    largest of them); stops the benchmark if it fails."""
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "twin.cli", *args], cwd=REPO, stdout=subprocess.PIPE,
                         stderr=subprocess.STDOUT, text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    out = p.stdout.read()
    _, status, usage = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        sys.exit(f"twin {' '.join(args)} failed:\n{out}")
    return time.perf_counter() - t0, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", type=float, default=0.1)
    ap.add_argument("--out", type=Path, default=None, help="work directory (default: temporary)")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--no-analysis", action="store_true", help="simulate only")
    args = ap.parse_args()
    where = (["--scheduler", args.scheduler] if args.scheduler else
             ["--workers", str(args.workers)] if args.workers else [])
    scale = ["--set", f"campaign.scale={args.scale}"]
    print(f"paper campaign at campaign.scale={args.scale} on {os.cpu_count()} cores "
          f"(load average {os.getloadavg()[0]:.1f} at the start)")

    def show(step: str, figures: tuple[float, float, float], extra: str = "") -> None:
        wall, cpu, peak = figures
        print(f"  {step:<34} {wall / 60:5.1f} min wall, {cpu / 60:5.1f} min CPU, "
              f"peak {peak:5.0f} MB{extra}", flush=True)

    with tempfile.TemporaryDirectory() as tmp:
        work = args.out or Path(tmp)
        rtf, ref = work / "rtf", work / "reference"
        step = twin("simulate", str(REPO / "scenarios/paper-rtf.toml"), "-o", str(rtf), *scale, *where)
        size = sum(p.stat().st_size for p in rtf.glob("*.h5")) / 1e9
        show("twin simulate paper-rtf", step, f", {size:.1f} GB of HDF5")
        if args.no_analysis:
            return
        show("twin backlash", twin("backlash", str(rtf), "--no-plots", *where))
        show("twin simulate paper-reference", twin(
            "simulate", str(REPO / "scenarios/paper-reference.toml"), "-o", str(ref), *scale, *where))
        show("twin detect (all six methods)",
             twin("detect", str(rtf), "--reference", str(ref), "-o", str(work / "detect")))


if __name__ == "__main__":
    main()
