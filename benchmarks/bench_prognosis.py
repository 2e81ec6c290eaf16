"""Error of the prognosis (hour at which the change of backlash reaches 10 µm) and of the smoothed
value, per choice of the Kalman trend's process noise, on synthetic per-session estimates with a
known growth law (prints figures; not a test).

Growth laws (truth, m, over operating hours, h), with Gaussian estimate noise:

- ``linear``: 10 µm at 8000 h from 0 h, a session every 84 h (the paper's interval), noise 0.5 µm
  (the setting of check 5, tests/test_phase2_prognosis.py);
- ``onset``: nothing until 2500 h, then quadratic to 10 µm at 8000 h (the shape of the paper's
  Fig. 13), every 84 h, noise 0.5 µm;
- ``steps``: the six sessions of scenarios/backlash-steps.toml (0, 0, 2, 5, 10, 20 µm every
  100 h; linear between them, so 10 µm at 500 h), noise 0.25 µm.

For each law, seed and session from the one where the truth passes 5 µm up to the last before
the crossing, the prognosis is made from the sessions so far (:func:`prognosis_history`'s
procedure) and its error is predicted − true crossing hour. Printed: the median and 90th
percentile of |error| in h and as a fraction of the hours still to go, and the fraction of cases
whose 95 % band holds the truth; then |smoothed − truth| at the last session.

``--record`` (``make validate``) stores the table docs/import.md quotes in docs/validation.json.

Run: .venv/bin/python benchmarks/bench_prognosis.py [--seeds 20] [--record]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from analysis.phase2.prognosis import BacklashTrend, prognosis  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from record import record  # noqa: E402

LIMIT = 10e-6


def laws() -> dict[str, tuple[np.ndarray, np.ndarray, float, float, str]]:
    """name -> (hours (n,), truth (n,) m, true crossing h, noise m, the law in docs/import.md's words)."""
    h84 = np.arange(42.0, 8693.0, 84.0)
    onset = np.where(h84 < 2500.0, 0.0, LIMIT * ((h84 - 2500.0) / 5500.0) ** 2)
    h6 = np.arange(100.0, 700.0, 100.0)
    return {"linear": (h84, LIMIT * h84 / 8000.0, 8000.0, 0.5e-6, "linear to 10 µm at 8000 h, every 84 h"),
            "onset": (h84, onset, 8000.0, 0.5e-6, "nothing until 2500 h, then quadratic to 10 µm at 8000 h"),
            "steps": (h6, np.array([0, 0, 2, 5, 10, 20]) * 1e-6, 500.0, 0.25e-6, "backlash-steps' six sessions")}


def run(seeds: int) -> str:
    """Print the figures; returns docs/import.md's table of them (Markdown)."""
    rows = ["| growth law | q | prognoses | median \\|error\\| | 90 % \\|error\\| | median of the hours to go "
            "| truth in the 95 % band |", "|---|---|---|---|---|---|---|"]
    for name, (hours, truth, crossing, noise, words) in laws().items():
        print(f"{name}: {hours.size} sessions, 10 µm at {crossing:g} h, noise {noise * 1e6:g} µm, {seeds} seeds")
        for q in ("auto", 1e-23, "ml"):
            model = BacklashTrend(process_noise=q)
            errs, frac, inside, last = [], [], [], []
            for seed in range(seeds):
                z = truth + noise * np.random.default_rng(seed).standard_normal(truth.size)
                for i in np.flatnonzero((truth >= 0.5 * LIMIT - 1e-12) & (hours < crossing)):
                    p = prognosis(model.fit(hours[:i + 1], z[:i + 1]))
                    e = p.crossing_hours - crossing
                    errs.append(abs(e))
                    frac.append(abs(e) / (crossing - hours[i]))
                    inside.append(p.band_hours[0] <= crossing <= p.band_hours[1])
                tr = model.fit(hours, z)
                last.append(abs(tr.smoothed[-1] - truth[-1]))
            errs, frac = np.array(errs), np.array(frac)
            print(f"  q {q!s:>6}: {errs.size:4d} prognoses; |error| median {np.median(errs):7.0f} h, 90 % "
                  f"{np.percentile(errs, 90):7.0f} h; of the hours to go median {100 * np.median(frac):5.1f} %, "
                  f"90 % {100 * np.percentile(frac, 90):6.1f} %; in the 95 % band {100 * np.mean(inside):5.1f} %; "
                  f"|smoothed - truth| at the last session median {np.median(last) * 1e6:.2f} µm, "
                  f"max {np.max(last) * 1e6:.2f} µm")
            law = f"{words}, noise {noise * 1e6:g} µm" if q == "auto" else ""
            rows.append(f"| {law} | {q} | {errs.size} | {np.median(errs):.0f} h | {np.percentile(errs, 90):.0f} h | "
                        f"{100 * np.median(frac):.1f} % | {100 * np.mean(inside):.1f} % |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--record", action="store_true", help="store the table in docs/validation.json")
    args = ap.parse_args()
    table = run(args.seeds)
    if args.record:
        record("bench_prognosis", scale=f"three growth laws, {args.seeds} seeds", figures={}, tables={"errors": table},
               command=f".venv/bin/python benchmarks/bench_prognosis.py --seeds {args.seeds} --record")
