"""Why Eq. 9 on the IMU axis misses the backlash on ``scenarios/backlash-slow-reversal.toml``,
where the carriage does travel D = L − b (prints figures; not a test).

Two noise-free campaigns of that scenario, one run per session, with the same origins: one
with the scenario's backlash steps, one without backlash. For each session it prints:

- the forward start pulse found from the IMU alone (:func:`analysis.phase2.strokes.imu_run_segments`,
  the half-velocity instant that places the IMU axis): its change with backlash, ms;
- the centroid ∫t·a dt / ∫a dt of the same pulse in the accelerometer's x axis: its change
  with backlash, ms (a carriage that travels b less during the pulse has it b/v later);
- the observed pitch of Eq. 8 (``observed_pitch_mm`` of ``twin backlash --position-reference
  imu``) relative to the first session, µm, and Eq. 9's change of backlash, µm, in both
  campaigns.

Run: ``python benchmarks/bench_eq9_stretch.py`` (about a minute on one core).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from analysis.dataset import open_measurements, open_truth
from analysis.phase2.strokes import imu_run_segments

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "scenarios/backlash-slow-reversal.toml"
NOISE_FREE = ("sensors.imu_acc_noise_ug_per_rthz=0.0", "sensors.imu_gyro_noise_urad_s_per_rthz=0.0",
              "phase2.runs_per_session=1")


def twin(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "twin.cli", *args], check=True, cwd=REPO, capture_output=True)


def campaign(out: Path, *sets: str) -> dict:
    """Simulate, analyse; per session: backlash µm, start instant s, centroid s, pitch mm, Eq. 9 µm."""
    twin("simulate", str(SCENARIO), "-o", str(out), "--workers", "1",
         *[a for s in (*NOISE_FREE, *sets) for a in ("--set", s)])
    twin("backlash", str(out), "-o", str(out / "bl"), "--no-plots", "--position-reference", "imu")
    doc = {r["session"]: r for r in json.loads((out / "bl" / "backlash.json").read_text())["sessions"]}
    rows = {}
    with open_measurements(out / "measurements.h5") as m, open_truth(out / "truth.h5") as t:
        abw = m.axis()["sensors"]["imu_accelerometer"]["bandwidth_hz"]
        for s in m.phase2_sessions():
            run = m.phase2(s, m.phase2_runs(s)[0])
            seg, moves = imu_run_segments(run, abw)
            a = run.imu_acc[:, 0].astype(float)
            a -= np.median(a)
            tt = np.arange(a.size) / run.imu_acc_fs_hz
            t0, t1 = moves[0][0], seg.motions[0].t0_s
            sel = (tt > t0 - 0.05) & (tt < t1 + 0.05)
            rows[s] = {"b_um": t.session(s)[2]["backlash_um"], "start_s": seg.motions[0].t0_s,
                       "centroid_s": float(np.sum(tt[sel] * a[sel]) / np.sum(a[sel])),
                       "pitch_mm": doc[s]["observed_pitch_mm"], "eq9_um": doc[s]["delta_backlash_um_pitch"]}
    return rows


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        steps = campaign(Path(tmp) / "steps")
        none = campaign(Path(tmp) / "none", "degradation.table_backlash_um=[0.0, 0.0, 0.0, 0.0]")
    ref = min(steps)
    print("session  b (µm)  Δ start, half-velocity (ms)  Δ centroid (ms)  b/v (ms)  "
          "pitch − first, with b | without (µm)  Eq. 9 with b | without (µm)")
    for s in sorted(steps):
        w, n = steps[s], none[s]
        print(f"{s}  {w['b_um']:6.1f}  {(w['start_s'] - n['start_s']) * 1e3:+8.3f}  "
              f"{(w['centroid_s'] - n['centroid_s']) * 1e3:+8.3f}  {w['b_um'] * 1e-6 / 0.02 * 1e3:6.3f}  "
              f"{(w['pitch_mm'] - steps[ref]['pitch_mm']) * 1e3:+7.3f} | "
              f"{(n['pitch_mm'] - none[ref]['pitch_mm']) * 1e3:+7.3f}  "
              f"{w['eq9_um']:+7.2f} | {n['eq9_um']:+7.2f}")


if __name__ == "__main__":
    main()
