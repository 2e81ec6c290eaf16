"""Benchmark: wall time of ``twin demo`` (what ``make demo`` runs) on all local cores.

Runs ``twin demo -o TMP`` in a fresh directory (nothing reused), reports the total wall time,
the time of each stage from the demo's own log lines, and the peak resident memory of the
command and its children (``resource.getrusage(RUSAGE_CHILDREN)``, the largest single process).

Usage: .venv/bin/python benchmarks/bench_demo.py
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "demo"
        env = dict(os.environ, PYTHONPATH=str(REPO))
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "twin.cli", "demo", "-o", str(out)], cwd=REPO,
                              env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            sys.exit(f"twin demo failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        size_mb = sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) / 1e6
        print(f"twin demo on {os.cpu_count()} cores: {wall:.1f} s wall "
              f"(issue 5 budget: 600 s); peak RSS of one process {peak_mb:.0f} MB; "
              f"output {size_mb:.0f} MB")
        for line in proc.stderr.splitlines():
            if line.startswith(("scenario", "demo done")) or "units simulated" in line:
                print("  " + line.strip())


if __name__ == "__main__":
    main()
