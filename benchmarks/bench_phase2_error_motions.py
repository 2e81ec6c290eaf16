"""Error-motion benchmark (issue 4, check 7; prints figures, not a test).

Wall time per session of :func:`analysis.phase2.error_motions.session_error_motions` on one
core (BLAS/FFT threads pinned to 1), for a session of the paper's size (90 runs, 20/100/500 mm/s,
full 450 mm stroke, 10 s dwells scaled to 1 s to save simulation time: the dwells only feed the
bias estimate) and for 10 runs, with the time split into reading + gridding per run and the
fusion. Also the peak memory of the process.

Run: make bench   (or .venv/bin/python benchmarks/bench_phase2_error_motions.py [RUNS ...])
A campaign directory given with --campaign DIR is used instead of simulating one. ``--record``
stores the 90-run session's figures, which docs/validation.md quotes, in docs/validation.json
(benchmarks/record.py); it refuses --campaign (the figures are those of the stated session).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from analysis.dataset import open_measurements
from analysis.phase2 import error_motions as em

sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402


def simulate(out: Path, runs: int) -> None:
    cmd = [sys.executable, "-m", "twin.cli", "simulate", str(REPO / "scenarios/quick.toml"),
           "-o", str(out), "--set", "campaign.phase1=false",
           "--set", f"phase2.runs_per_session={runs}", "--set", "phase2.session_hours=[50.0]"]
    subprocess.run(cmd, cwd=REPO, check=True, capture_output=True,
                   env=dict(os.environ, PYTHONPATH=str(REPO)))


def bench(path: Path) -> dict[str, float]:
    """Times of the first session of the campaign at ``path``: {runs, total_s (the faster of two
    passes), read_grid_ms (reading and gridding per run), fusion_s (per session)}."""
    with open_measurements(path / "measurements.h5") as m:
        session = m.phase2_sessions()[0]
        runs = len(m.phase2_runs(session))
        # Split: fusion alone = total − (reading + gridding), measured by patching the fusion.
        t0 = time.perf_counter()
        r = em.session_error_motions(m, session)
        total = time.perf_counter() - t0
        fuse = em._fuse
        spent = [0.0]

        def timed_fuse(*a, **k):
            t = time.perf_counter()
            out = fuse(*a, **k)
            spent[0] += time.perf_counter() - t
            return out

        em._fuse = timed_fuse
        try:
            t0 = time.perf_counter()
            em.session_error_motions(m, session)
            total2 = time.perf_counter() - t0
        finally:
            em._fuse = fuse
    per_run = (total2 - spent[0]) / runs
    print(f"session {session}: {runs} runs; combined {r.combined.x_m.size} points "
          f"(step {r.combined.dx_m * 1e3:.2f} mm), slow {r.slow.x_m.size} points "
          f"(step {r.slow.dx_m * 1e6:.0f} µm)")
    print(f"  wall time per session, one core: {min(total, total2):.2f} s "
          f"(reading + gridding {per_run * 1e3:.0f} ms per run, fusion {spent[0]:.2f} s)")
    return {"runs": runs, "total_s": min(total, total2), "read_grid_ms": per_run * 1e3, "fusion_s": spent[0]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="*", type=int, default=[10, 90])
    ap.add_argument("--campaign", type=Path, default=None)
    ap.add_argument("--record", action="store_true",
                    help="store the 90-run session's figures in docs/validation.json")
    args = ap.parse_args()
    if args.record and (args.campaign is not None or 90 not in args.runs):
        ap.error("--record measures the 90-run session it simulates: without --campaign, with 90 among RUNS")
    print(f"machine: {os.cpu_count()} cores; error motions on one core")
    found = {}
    if args.campaign is not None:
        bench(args.campaign)
    else:
        for runs in args.runs:
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                simulate(Path(tmp), runs)
                print(f"simulated a {runs}-run session in {time.perf_counter() - t0:.0f} s "
                      "(all cores)")
                found[runs] = bench(Path(tmp))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak memory of this process: {peak:.0f} MB")
    if args.record:
        f = found[90]
        per_run = f["total_s"] / f["runs"] * 1e3
        record("bench_phase2_error_motions",
               command=".venv/bin/python benchmarks/bench_phase2_error_motions.py --record",
               scale="one session of scenarios/quick.toml with 90 runs (20/100/500 mm/s, the full stroke), "
                     "one core", figures={
                   "session_s": (round(f["total_s"], 2), f"{f['total_s']:.2f}"),
                   "per_run_ms": (round(per_run, 1), f"{per_run:.0f}"),
                   "read_grid_ms": (round(f["read_grid_ms"], 1), f"{f['read_grid_ms']:.0f}"),
                   "fusion_s": (round(f["fusion_s"], 2), f"{f['fusion_s']:.2f}"),
                   "peak_mb": (round(peak), f"{peak:.0f}")})


if __name__ == "__main__":
    main()
