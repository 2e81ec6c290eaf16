"""The Fig. 13 analogue on the paper's campaign (docs/validation.md; prints figures, not a test).

The whole 8693-h timeline of ``scenarios/paper-rtf.toml`` with a session every 84 h as in the
paper (103 sessions) at ``campaign.scale=0.1`` (9 runs per session at 20/100/500 mm/s, 2-s
dwells, Phase I off), then ``twin backlash --process-noise ml`` and the same with
``--baseline-sessions 10`` (the first ten sessions, up to 840 h, share the initial backlash).
Scored against ``truth.h5`` (:func:`analysis.scoring.score_phase2`): per period of the timeline
the error of the change by shifts and the change by pitch (mean ± sd), the session nearest
8000 h, the prognosis's 10 µm crossing against the injected one, the observed pitch; the CPU
time of each command (its processes and theirs, ``resource.getrusage(RUSAGE_CHILDREN)``).
``--record`` (``make validate``) stores the figures and the table in docs/validation.json and
copies the Fig. 13 PNG ``twin backlash`` draws to docs/figures/fig13-paper-rtf.png.

Usage: .venv/bin/python benchmarks/fig13_paper.py [--out DIR] [--workers N] [--record]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from record import record, text  # noqa: E402

from analysis.dataset import open_truth  # noqa: E402
from analysis.scoring import score_phase2  # noqa: E402

SIMULATE = ["--set", "campaign.scale=0.1", "--set", "phase2.dwell_s=2", "--set", "campaign.phase1=false"]
PERIODS = ((0.0, 2500.0), (2500.0, 5000.0), (5000.0, 7000.0), (7000.0, None))
BASELINE_SESSIONS = 10


def twin(*args) -> float:
    """Run a ``twin`` command; the CPU time (s) of it and its child processes."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run([sys.executable, "-m", "twin.cli", *map(str, args)], cwd=REPO, capture_output=True,
                          text=True, env=dict(os.environ, PYTHONPATH=str(REPO)))
    if proc.returncode != 0:
        sys.exit(f"twin {' '.join(map(str, args))} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def mean_sd(values: list[float], digits: int) -> str:
    v = np.asarray([x for x in values if x is not None], dtype=float)
    return f"{text(float(v.mean()), f'{{:+.{digits}f}}')} ± {v.std(ddof=1):.{digits}f}"


def in_period(hours: float, lo: float, hi: float | None) -> bool:
    return hours >= lo and (hi is None or hours < hi)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="keep the campaign here (default: a temporary folder)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--record", action="store_true")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = a.out or Path(tmp) / "rtf"
        sim_cpu = twin("simulate", REPO / "scenarios/paper-rtf.toml", "-o", out, *SIMULATE, "--workers", a.workers)
        bl_cpu = twin("backlash", out, "--process-noise", "ml", "--workers", a.workers)
        twin("backlash", out, "--process-noise", "ml", "--baseline-sessions", BASELINE_SESSIONS,
             "-o", out / "backlash-baseline", "--no-plots", "--workers", a.workers)
        with open_truth(out / "truth.h5") as t:
            raw = score_phase2(out, t)
            base = score_phase2(out, t, out / "backlash-baseline")
        doc = json.loads((out / "backlash/backlash.json").read_text())
        doc_b = json.loads((out / "backlash-baseline/backlash.json").read_text())
        pitches = [r["observed_pitch_mm"] for r in doc["sessions"] if r.get("observed_pitch_mm") is not None]
        if a.record:
            (REPO / "docs/figures").mkdir(exist_ok=True)
            shutil.copyfile(out / "backlash/fig13_backlash.png", REPO / "docs/figures/fig13-paper-rtf.png")

    rows = ["| hours | sessions | injected Δbacklash (µm) | by shifts − injected (µm), mean ± sd | "
            "by pitch (µm), mean ± sd |", "|---|---|---|---|---|"]
    base_means = []
    for lo, hi in PERIODS:
        ses = [r for r in raw["sessions"] if in_period(r["hours"], lo, hi)]
        inj = [r["injected_delta_um"] for r in ses]
        span = f"{min(inj):.2f}" if max(inj) - min(inj) < 0.005 else f"{min(inj):.2f}–{max(inj):.1f}"
        end = f"{hi:.0f}" if hi is not None else f"{max(r['hours'] for r in ses):.0f}"
        rows.append(f"| {lo:.0f}–{end} | {len(ses)} | {span} | {mean_sd([r['error_um'] for r in ses], 2)} | "
                    f"{mean_sd([r['pitch_estimated_delta_um'] for r in ses], 1)} |")
        b = [r["error_um"] for r in base["sessions"] if in_period(r["hours"], lo, hi)]
        base_means.append(text(float(np.mean(b)), "{:+.2f}"))
    table = "\n".join(rows) + "\n"
    near = min(raw["sessions"], key=lambda r: abs(r["hours"] - 8000.0))
    near_b = next(r for r in base["sessions"] if r["session"] == near["session"])
    prog, prog_b = doc["prognosis"], doc_b["prognosis"]
    true_cross = raw["prognosis"]["true_crossing_hours"]
    inside = prog_b["band_hours"][0] <= true_cross <= prog_b["band_hours"][1]
    inside_raw = prog["band_hours"][0] <= true_cross <= prog["band_hours"][1]
    figures = {
        "sessions": (len(raw["sessions"]), f"{len(raw['sessions'])}"),
        "simulate_cpu_min": (round(sim_cpu / 60, 1), f"{sim_cpu / 60:.1f}"),
        "backlash_cpu_min": (round(bl_cpu / 60, 1), f"{bl_cpu / 60:.1f}"),
        "near_8000": (near["hours"], f"injected {near['injected_delta_um']:.1f} µm at {near['hours']:.0f} h; by "
                      f"shifts {near['estimated_delta_um']:.1f}, smoothed {near['smoothed_um']:.1f} µm"),
        "prognosis": (prog["crossing_hours"], f"the prognosis at {prog['at_hours']:.0f} h puts the 10 µm crossing "
                      f"at {prog['crossing_hours']:.0f} h (95 % band {prog['band_hours'][0]:.0f}–"
                      f"{prog['band_hours'][1]:.0f} h) against the injected {true_cross:.0f} h, "
                      f"{'inside' if inside_raw else 'outside'} the band"),
        "baseline": (None, f"the mean error becomes {' / '.join(base_means)} µm in the four periods of the table, "
                     f"{near_b['estimated_delta_um']:.1f} µm (smoothed {near_b['smoothed_um']:.1f}) at "
                     f"{near['hours']:.0f} h, and the crossing {prog_b['crossing_hours']:.0f} h (band "
                     f"{prog_b['band_hours'][0]:.0f}–{prog_b['band_hours'][1]:.0f} h), the injected "
                     f"{true_cross:.0f} h {'inside' if inside else 'outside'} the band"),
        "observed_pitch": (None, f"{min(pitches):.5f}–{max(pitches):.5f} mm"),
    }
    print(f"paper-rtf at scale 0.1 ({len(raw['sessions'])} sessions): simulate {sim_cpu / 60:.1f} min CPU, "
          f"backlash {bl_cpu / 60:.1f} min CPU ({a.workers} worker processes)")
    print(table)
    for key in ("near_8000", "prognosis", "baseline", "observed_pitch"):
        print(f"{key}: {figures[key][1]}")
    if a.record:
        record("fig13_paper", command=".venv/bin/python benchmarks/fig13_paper.py --record",
               scale="scenarios/paper-rtf.toml at campaign.scale=0.1, 2-s dwells, Phase I off, "
                     f"{a.workers} worker processes", figures=figures, tables={"table": table})


if __name__ == "__main__":
    main()
