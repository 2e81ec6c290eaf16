"""Eq. 9 on the IMU axis on ``scenarios/backlash-slow-reversal.toml``, where the carriage does
travel D = L − b: the stroke timing and the pitch estimate, old and new (prints figures; not a
test).

Three campaigns of that scenario with the same origins: two without IMU noise and with one run per
session (one with the scenario's backlash steps, one without backlash), and the scenario as it is
(the paper's IMU noise, 4 runs per session, what ``test_eq9_on_the_imu_axis_where_d_is_l_minus_b``
gates). Printed:

1. per session of the noise-free pair, how much shorter the backlash makes the forward and reverse
   cruise of the first run on the IMU axis (:func:`analysis.phase2.strokes.imu_run_segments`), ms,
   for each stroke timing (``half_velocity``: the earlier one; ``travel``: the default), against
   b/v, which D = L − b requires; then, for every timing (``centroid`` too), how much the cruise
   without backlash spreads over the sessions (the origin alone) and its run-to-run scatter with
   the IMU's noise;
2. per campaign, stroke timing and pitch method (``comb``: the spacing of the comb's line fit,
   the earlier one; ``harmonic``: the default), the observed pitch (Eq. 8) relative to the first
   session, µm, and Eq. 9's change of backlash, µm. Without backlash the pitch's change is the
   scatter the origin alone causes.

Run: ``python benchmarks/bench_eq9_stretch.py [--record]`` (about 3 minutes on one core;
``--record``: the three tables into docs/validation.json, :mod:`record`).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from analysis.dataset import open_measurements, open_truth
from analysis.phase2.backlash import BacklashEstimator
from analysis.phase2.error_motions import session_error_motions
from analysis.phase2.strokes import imu_run_segments

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from record import record, text  # noqa: E402

SCENARIO = REPO / "scenarios/backlash-slow-reversal.toml"
NOISE_FREE = ("sensors.imu_acc_noise_ug_per_rthz=0.0", "sensors.imu_gyro_noise_urad_s_per_rthz=0.0",
              "phase2.runs_per_session=1")
TIMINGS = ("half_velocity", "travel")
ALL_TIMINGS = ("half_velocity", "centroid", "travel")
PITCH_METHODS = ("comb", "harmonic")


def simulate(out: Path, *sets: str) -> Path:
    subprocess.run([sys.executable, "-m", "twin.cli", "simulate", str(SCENARIO), "-o", str(out),
                    "--workers", "1", *[a for s in sets for a in ("--set", s)]],
                   check=True, cwd=REPO, capture_output=True)
    return out


def cruises(path: Path, all_runs: bool = False) -> dict:
    """{(session, timing): (runs, 2) forward and reverse cruise durations, s} (the first run only
    unless ``all_runs``)."""
    out = {}
    with open_measurements(path / "measurements.h5") as m:
        abw = m.axis()["sensors"]["imu_accelerometer"]["bandwidth_hz"]
        for s in m.phase2_sessions():
            runs = m.phase2_runs(s) if all_runs else m.phase2_runs(s)[:1]
            for timing in ALL_TIMINGS:
                out[(s, timing)] = np.array([[mo.t1_s - mo.t0_s for mo in
                                              imu_run_segments(m.phase2(s, r), abw, timing=timing)[0].motions]
                                             for r in runs])
    return out


def eq9(path: Path) -> dict:
    """{(timing, method): [(session, pitch − first µm, Eq. 9 µm)]} on the IMU axis (Eq. 9 unbounded:
    the estimator withholds a value beyond its bound, docs/import.md)."""
    out = {}
    with open_measurements(path / "measurements.h5") as m:
        for timing in TIMINGS:
            ems = [session_error_motions(m, s, position_reference="imu", stroke_timing=timing)
                   for s in m.phase2_sessions()]
            for method in PITCH_METHODS:
                est = BacklashEstimator(pitch_method=method).fit(ems[0])
                rows = [est.estimate(e) for e in ems]
                out[(timing, method)] = [(r.session, (r.observed_pitch_m - est.reference_pitch_m_) * 1e6,
                                          r.delta_backlash_pitch_raw_m * 1e6) for r in rows]
    return out


def injected(path: Path) -> dict:
    with open_truth(path / "truth.h5") as t:
        return {s: t.session(s)[2]["backlash_um"] for s in t.sessions()}


def _fr(pair) -> str:
    """'forward \\| reverse' of a pair (ms or µm already), for a Markdown cell."""
    return " \\| ".join(text(v, "{:+.3f}") for v in pair)


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        steps = simulate(Path(tmp) / "steps", *NOISE_FREE)
        none = simulate(Path(tmp) / "none", *NOISE_FREE, "degradation.table_backlash_um=[0.0, 0.0, 0.0, 0.0]")
        noisy = simulate(Path(tmp) / "noisy")
        b = injected(steps)
        cw, cn = cruises(steps), cruises(none)
        shortened = ["| session | b (µm) | b/v (ms) | " + " | ".join(f"`{t}`" for t in TIMINGS) + " |",
                     "|---" * (3 + len(TIMINGS)) + "|"]
        for s in sorted(b)[1:]:
            cells = [_fr([(n - w) * 1e3 for w, n in zip(cw[(s, t)][0], cn[(s, t)][0], strict=True)])
                     for t in TIMINGS]
            shortened.append(f"| {s} | {b[s]:g} | {b[s] * 1e-6 / 0.02 * 1e3:.2f} | " + " | ".join(cells) + " |")
        cq = cruises(noisy, all_runs=True)
        spread = ["| stroke timing | spread over the sessions, noise-free (ms) "
                  "| run-to-run sd with the IMU's noise (ms) |", "|---|---|---|"]
        for t in ALL_TIMINGS:
            sp = np.ptp(np.array([cn[(s, t)][0] for s in sorted(b)]), axis=0)
            resid = np.concatenate([cq[(s, t)] - cq[(s, t)].mean(axis=0) for s in sorted(b)])
            dof = resid.size - 2 * len(b)
            spread.append(f"| `{t}` | {_fr(sp * 1e3)} | {np.sqrt(np.sum(resid ** 2) / dof) * 1e3:.3f} |")
        pitch = ["| campaign | stroke timing + pitch method | observed pitch − the first session's (µm) | Eq. 9 (µm) |",
                 "|---|---|---|---|"]
        for name, path in (("noise-free, backlash steps", steps), ("noise-free, no backlash", none),
                           ("the scenario (IMU noise, 4 runs)", noisy)):
            for (timing, method), rows in eq9(path).items():
                pitches = ", ".join(text(p, "{:+.4f}") for _, p, _ in rows[1:])
                pitch.append(f"| {name} | `{timing}` + `{method}` | {pitches} | "
                             + ", ".join(text(e, "{:+.2f}") for _, _, e in rows[1:]) + " |")
        tables = {"cruise_shortened": "\n".join(shortened) + "\n", "cruise_spread": "\n".join(spread) + "\n",
                  "pitch": "\n".join(pitch) + "\n"}
        for v in tables.values():
            print(v)
        if "--record" in sys.argv[1:]:
            record("bench_eq9_stretch", command=".venv/bin/python benchmarks/bench_eq9_stretch.py --record",
                   scale="scenarios/backlash-slow-reversal.toml three times with the same origins: noise-free "
                         "with 1 run per session, with and without its backlash steps; as it is (4 runs)",
                   figures={"injected_um": (None, ", ".join(f"{b[s]:g}" for s in sorted(b)[1:]))}, tables=tables)


if __name__ == "__main__":
    main()
