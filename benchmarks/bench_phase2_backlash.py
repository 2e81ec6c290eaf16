"""Benchmark: wall time per session of the Phase II backlash estimate, on one core.

Simulates ``scenarios/backlash-steps.toml`` (6 sessions x 10 runs at 100 mm/s; or uses the
campaign directory given as the first argument) and times, per session, the error motions
(:func:`analysis.phase2.error_motions.session_error_motions`, for reference) and the backlash
estimate (:meth:`analysis.phase2.backlash.BacklashEstimator.estimate`: winfilt, 12 correlations
against the reference, 12 autocorrelations for the pitch, Eqs. 4–9). Also the 20 mm/s slow grid
(``--set phase2.speeds_mm_s=[20.0]``), whose traces are 5x longer in time but the same length in
position.

``--record`` (``make validate``) stores the figures docs/validation.md quotes in
docs/validation.json.

Usage: .venv/bin/python benchmarks/bench_phase2_backlash.py [CAMPAIGN_DIR] [--record]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from analysis.dataset import open_measurements
from analysis.phase2.backlash import BacklashEstimator
from analysis.phase2.error_motions import session_error_motions

sys.path.insert(0, str(REPO / "benchmarks"))
from record import record  # noqa: E402


def campaign(tmp: Path) -> Path:
    out = tmp / "steps"
    subprocess.run([sys.executable, "-m", "twin.cli", "simulate", str(REPO / "scenarios/backlash-steps.toml"),
                    "-o", str(out), "--workers", "1"], cwd=REPO, check=True, capture_output=True,
                   env=dict(os.environ, PYTHONPATH=str(REPO)))
    return out


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        given = [a for a in sys.argv[1:] if not a.startswith("--")]
        if given and "--record" in sys.argv[1:]:
            sys.exit("--record stores the figures of the shipped backlash-steps campaign: give no CAMPAIGN_DIR")
        d = Path(given[0]) if given else campaign(Path(tmp))
        with open_measurements(d / "measurements.h5") as m:
            names = m.phase2_sessions()
            t_em, ems = [], []
            for s in names:
                t0 = time.perf_counter()
                ems.append(session_error_motions(m, s))
                t_em.append(time.perf_counter() - t0)
            runs = len(m.phase2_runs(names[0]))
        est = BacklashEstimator()
        t0 = time.perf_counter()
        est.fit(ems[0])
        t_fit = time.perf_counter() - t0
        t_est = []
        for e in ems[1:]:
            t0 = time.perf_counter()
            est.estimate(e)
            t_est.append(time.perf_counter() - t0)
        n = ems[0].slow.x_m.size
        print(f"Phase II backlash benchmark ({d}, {len(names)} sessions x {runs} runs, one core)")
        print(f"  slow grid: {n} samples of {ems[0].slow.dx_m * 1e6:g} µm per trace")
        print(f"  error motions per session: {np.mean(t_em):.2f} s (min {np.min(t_em):.2f}, "
              f"max {np.max(t_em):.2f}), {np.mean(t_em) / runs:.3f} s per run")
        print(f"  backlash estimate per session: {np.mean(t_est):.2f} s (min {np.min(t_est):.2f}, "
              f"max {np.max(t_est):.2f}); fit on the reference {t_fit:.2f} s")
        if "--record" in sys.argv[1:]:
            record("bench_phase2_backlash", command=".venv/bin/python benchmarks/bench_phase2_backlash.py --record",
                   scale=f"scenarios/backlash-steps.toml: {len(names)} sessions of {runs} runs at 100 mm/s, one core",
                   figures={
                       "estimate_s": (round(float(np.mean(t_est)), 2),
                                      f"{np.min(t_est):.2f}–{np.max(t_est):.2f}"),
                       "fit_s": (round(t_fit, 2), f"{t_fit:.2f}"),
                       "error_motions_s": (round(float(np.mean(t_em)), 2), f"{np.mean(t_em):.2f}"),
                       "slow_grid_samples": (n, f"{n:,}")})


if __name__ == "__main__":
    main()
