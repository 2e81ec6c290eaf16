"""Phase I benchmarks (issue 3, check 7; prints figures, not a test).

- feature extraction rate: captures per second on one core (one process, BLAS limited to one
  thread), reading ``measurements.h5`` included, for the 4-s captures of
  ``scenarios/phase1-quick.toml`` and the paper's 10-s captures;
- wall time of ``twin detect`` on the quick Phase I campaign (``scenarios/phase1-quick.toml``, 24
  samples of 2 x 4 s) with a reduced reference set (15 samples of 2 x 4 s), as a subprocess.

Simulation (not timed) goes to a temporary directory. Run: make bench (or
.venv/bin/python benchmarks/bench_phase1.py); ``--record`` stores the figures docs/validation.md
quotes in docs/validation.json (``make validate``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from threadpoolctl import threadpool_limits

from analysis.phase1.pipeline import extract

sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402

TWIN = [sys.executable, "-m", "twin.cli"]
ENV = dict(os.environ, PYTHONPATH=str(REPO))


def twin(*args: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([*TWIN, *map(str, args)], cwd=REPO, env=ENV, check=True, capture_output=True)
    return time.perf_counter() - t0


def rate(path: Path) -> tuple[float, int]:
    with threadpool_limits(1):
        t0 = time.perf_counter()
        table = extract(path)
        dt = time.perf_counter() - t0
    n = int(table.n_captures.sum())
    return n / dt, n


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        ref, camp, long = tmp / "ref", tmp / "camp", tmp / "long"
        twin("simulate", REPO / "scenarios/paper-reference.toml", "-o", ref, "--set",
             "phase1.captures_per_sample=2", "--set", "phase1.capture_s=4.0", "--set",
             "phase1.sample_interval_hours=20")
        twin("simulate", REPO / "scenarios/phase1-quick.toml", "-o", camp)
        twin("simulate", REPO / "scenarios/phase1-quick.toml", "-o", long, "--set",
             "phase1.capture_s=10.0", "--set", "campaign.total_hours=60")
        r4, n4 = rate(camp / "measurements.h5")
        r10, n10 = rate(long / "measurements.h5")
        print(f"feature extraction, one core: {r4:.1f} captures/s (4-s captures, {n4}), "
              f"{r10:.1f} captures/s (10-s captures at 10 kHz, {n10})")
        wall = twin("detect", camp, "--reference", ref, "-o", tmp / "out")
        print(f"twin detect on the quick Phase I campaign (24 samples, 6 methods, reference of 15 "
              f"samples): {wall:.1f} s wall")
        if "--record" in sys.argv[1:]:
            record("bench_phase1", command=".venv/bin/python benchmarks/bench_phase1.py --record",
                   scale="scenarios/phase1-quick.toml (4-s captures), the same with 10-s captures up to 60 h, "
                         "paper-reference reduced to 15 samples of 2 × 4 s", figures={
                       "extract_4s_per_s": (round(r4, 1), f"{r4:.0f}"),
                       "extract_10s_per_s": (round(r10, 1), f"{r10:.0f}"),
                       "detect_wall_s": (round(wall, 1), f"{wall:.1f}")})


if __name__ == "__main__":
    main()
