"""The layout and the motion routine of a recording, measured from its signals (for
``twin scenario init``).

:func:`measure_recording` returns what a scenario needs to reproduce a recording: the Phase I
samples, captures, rates and durations and the Phase II sessions, runs and rates (the layout the
gap diagnosis compares), and the routines: the Phase I move from the controller's motor speed
(through the lead, ``/@axis.lead_mm``), the Phase II moves from ``position_cmd``. Every value
is reported with where it came from (``measured``, ``axis`` for the axis contract).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from analysis.dataset import open_measurements
from analysis.dataset.axis import AxisDescription

#: Moving-average window of the controller's measured motor speed before the moves are found, s.
SPEED_SMOOTH_S = 0.005


def _segments(moving: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index ranges where ``moving`` is true."""
    d = np.diff(np.concatenate(([0], moving.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def motion_profile(v: np.ndarray, fs_hz: float, smooth_s: float = 0.0) -> dict:
    """Speeds, acceleration, dwell and stroke of a velocity signal ``v`` (n,) in mm/s at ``fs_hz``.

    Returns ``speeds_mm_s`` (distinct cruise speeds, ascending), ``accel_mm_s2`` (median of the
    ramps' slopes), ``dwell_s`` (median standstill between moves), ``stroke_mm`` (median distance of
    a move); keys whose value cannot be measured are left out. ``smooth_s``: moving-average
    window applied first (for a noisy measured speed; 0 for a commanded position's derivative)."""
    out: dict = {}
    k = max(1, int(round(smooth_s * fs_hz)))
    v = np.convolve(v, np.ones(k) / k, mode="same") if k > 1 else v
    smooth = v
    peak = float(np.percentile(np.abs(smooth), 99.5))
    if not peak > 0:
        return out
    moving = np.abs(smooth) > 0.02 * peak
    # whole moves only: a move cut by the start or the end of the recording is left out
    segs = [(a, b) for a, b in _segments(moving) if b - a >= 5 and a > 0 and b < len(v)]
    speeds, accels, strokes = [], [], []
    for a, b in segs:
        seg = v[a:b]
        mid = seg[len(seg) // 4: 3 * len(seg) // 4]
        cruise = float(np.median(np.abs(mid)))
        speeds.append(cruise)
        strokes.append(abs(float(np.sum(seg))) / fs_hz)
        slope = np.abs(np.diff(v[max(a - 1, 0):b + 1])) * fs_hz
        accels.append(float(np.median(slope[slope > 0.5 * slope.max()])))  # the ramps' samples
    levels: list[float] = []
    for s in sorted(speeds):
        if not levels or s > 1.03 * levels[-1]:
            levels.append(s)
    out["speeds_mm_s"] = [float(f"{s:.3g}") for s in levels]
    if accels:
        out["accel_mm_s2"] = float(f"{np.median(accels):.3g}")
    if strokes:
        out["stroke_mm"] = float(f"{np.median(strokes):.4g}")
    still = [(b - a) / fs_hz for a, b in _segments(~moving) if a > 0 and b < len(v)]
    if still:
        out["dwell_s"] = float(f"{np.median(still):.3g}")
    return out


def _spacing(hours: list[float]) -> float | None:
    return float(np.median(np.diff(hours))) if len(hours) > 1 else None


def measure_recording(path: str | os.PathLike, *, runs_to_measure: int = 3) -> dict:
    """Layout and routines of ``path`` (campaign directory or ``measurements.h5``); see the module."""
    path = Path(path)
    if path.is_dir() or path.suffix != ".h5":
        path = path / "measurements.h5"
    out: dict = {"file": str(path)}
    with open_measurements(path) as m:
        axis = AxisDescription.from_dict(m.axis(), m.label)
        out["axis"] = axis
        caps = [m.phase1(c) for c in m.phase1_captures()]
        if caps:
            by_sample: dict[int, list] = {}
            for c in caps:
                by_sample.setdefault(c.sample, []).append(c)
            counts = sorted({len(v) for v in by_sample.values()})
            first = [min(c.hours for c in v) for _, v in sorted(by_sample.items())]
            within = [h for v in by_sample.values() for h in np.diff(sorted(c.hours for c in v))]
            p1 = {"samples": len(by_sample), "captures_per_sample": counts,
                  "fs_hz": sorted({c.fs_hz for c in caps}),
                  "capture_s": float(np.median([len(c.speed) / c.fs_hz for c in caps])),
                  "first_hours": first[0], "last_hours": max(c.hours for c in caps),
                  "sample_interval_hours": _spacing(first),
                  "capture_interval_minutes": float(np.median(within)) * 60 if within else None}
            lead = axis.lead_mm
            if lead is not None:
                c = caps[0]
                prof = motion_profile(c.speed * lead / (2 * math.pi), c.fs_hz, SPEED_SMOOTH_S)
                p1["routine"] = prof
            out["phase1"] = p1
        sessions = m.phase2_sessions()
        if sessions:
            runs = {s: m.phase2_runs(s) for s in sessions}
            r0 = m.phase2(sessions[0], runs[sessions[0]][0])
            p2 = {"sessions": len(sessions), "runs_per_session": sorted({len(v) for v in runs.values()}),
                  "session_hours": [m.session_hours(s) for s in sessions],
                  "fs_hz": {ch: getattr(r0, f"{ch}_fs_hz") for ch in ("imu_acc", "imu_gyro", "position_cmd")
                            if getattr(r0, f"{ch}_fs_hz", None) is not None},
                  "run_s": len(r0.imu_acc) / r0.imu_acc_fs_hz}
            pos = getattr(r0, "position_cmd", None)
            if pos is not None:
                profs, lo, hi = [], [], []
                for r in runs[sessions[0]][:runs_to_measure]:
                    run = m.phase2(sessions[0], r)
                    x = run.position_cmd * 1e3
                    profs.append(motion_profile(np.gradient(x) * run.position_cmd_fs_hz, run.position_cmd_fs_hz))
                    lo.append(float(x.min()))
                    hi.append(float(x.max()))
                prof = profs[0]
                for key in ("accel_mm_s2", "dwell_s"):
                    vals = [p[key] for p in profs if key in p]
                    if vals:
                        prof[key] = float(f"{np.median(vals):.3g}")
                prof["start_mm"] = float(f"{np.median(lo):.4g}")
                prof["end_mm"] = float(f"{np.median(hi):.4g}")
                p2["routine"] = prof
            out["phase2"] = p2
    return out
