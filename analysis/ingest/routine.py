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
#: The part of each ramp a measured speed's slope is fitted on, as fractions of the cruise speed:
#: the servo's transient at the ramp's corners is left out (the loop follows a constant
#: acceleration with a constant lag once the transient has settled, so the slope there is the
#: commanded acceleration).
MEASURED_RAMP = (0.4, 0.8)
#: The same for a commanded position's increments, which are exact: every increment inside the
#: ramp (the first and last, which may straddle a corner of the profile, left out).
COMMAND_RAMP = (0.0, 1.0)
#: A stretch above the moving threshold that travels less than this fraction of the longest
#: move's distance is the servo settling, not a move.
SETTLE_FRACTION = 0.01
#: Significant digits of the measured routine values (a fit, not a rounding to 3 digits).
DIGITS = 7


def _segments(moving: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index ranges where ``moving`` is true."""
    d = np.diff(np.concatenate(([0], moving.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def _round(v: float) -> float:
    return float(f"{v:.{DIGITS}g}")


def _ramp_line(t: np.ndarray, s: np.ndarray, idx: np.ndarray) -> tuple[float, float, int] | None:
    """(slope, time where the line crosses zero speed, samples) of a least-squares line through
    ``s[idx]`` against ``t[idx]``; the first and last sample of the run are left out (they may
    straddle a corner of the profile). None when fewer than 3 samples are left."""
    idx = idx[1:-1]
    if idx.size < 3:
        return None
    slope, icpt = np.polyfit(t[idx], s[idx], 1)
    if slope == 0:
        return None
    return float(slope), float(-icpt / slope), int(idx.size)


def fit_moves(v: np.ndarray, fs_hz: float, ramp: tuple[float, float] = MEASURED_RAMP,
              smooth_s: float = 0.0) -> list[dict]:
    """The trapezoidal moves of a velocity signal, each fitted.

    Args:
        v: (n,) velocity, mm/s (a measured speed, or a commanded position's increments × fs).
        fs_hz: its rate, Hz.
        ramp: the fractions of the cruise speed between which each ramp's slope is fitted
            (:data:`MEASURED_RAMP`, :data:`COMMAND_RAMP`).
        smooth_s: moving-average window used only to find the moves and their plateaus, s.
    Returns:
        one dict per move, in time order (a move cut by the record's start or end has no ramp,
        start or distance there): ``speed`` (mean of the plateau's middle half, mm/s; None for a triangular move that
        never cruises), ``accel`` and ``decel`` (the ramps' fitted slopes, mm/s²; None when the
        ramp has too few samples), ``t_start`` and ``t_stop`` (where the fitted ramps cross zero
        speed, s: a servo's constant lag shifts both alike, so the dwell between two moves is
        exact; None where not fitted), ``distance`` (the integral of ``|v|`` over the move, mm), ``direction`` (±1),
        ``samples`` (the ramps' fitted samples, for weighting)."""
    v = np.asarray(v, dtype=float)
    t = np.arange(v.size) / fs_hz
    k = max(1, int(round(smooth_s * fs_hz)))
    sm = np.convolve(v, np.ones(k) / k, mode="same") if k > 1 else v
    peak = float(np.percentile(np.abs(sm), 99.5)) if v.size else 0.0
    if not peak > 0:
        return []
    moving = np.abs(sm) > 0.02 * peak
    lo, hi = ramp
    moves = []
    segs = [(a, b) for a, b in _segments(moving) if b - a >= 8]
    # a servo settling after a stop (a heavy carriage, a soft loop) can cross the threshold for a
    # few samples: a "move" of a fraction of a millimetre, which is no move of the routine
    if segs:
        travel = [float(np.sum(np.abs(v[a:b]))) / fs_hz for a, b in segs]
        segs = [sg for sg, d in zip(segs, travel, strict=True) if d >= SETTLE_FRACTION * max(travel)]
    for j, (a, b) in enumerate(segs):
        # the distance is integrated out to the middle of the rests on either side (the tails
        # below the moving threshold belong to the move)
        ia = (segs[j - 1][1] + a) // 2 if j > 0 else 0
        ib = (b + segs[j + 1][0]) // 2 if j + 1 < len(segs) else v.size
        cut_start, cut_end = a == 0, b >= v.size  # a move cut by the record: its ramp there is not fitted
        sign = 1.0 if np.median(v[a:b]) >= 0 else -1.0
        s, ss = sign * v[a:b], sign * sm[a:b]
        n = s.size
        top = float(np.median(s[n // 3: 2 * n // 3]))
        on = np.flatnonzero(ss > 0.99 * top)
        p0, p1 = (int(on[0]), int(on[-1])) if on.size else (n // 2, n // 2)
        cruise = p1 - p0 > max(8, 0.05 * n)
        speed = float(np.mean(s[p0 + (p1 - p0) // 4: p1 - (p1 - p0) // 4 + 1])) if cruise else float(ss.max())
        # the ramps: the accelerating samples before the plateau, the decelerating after it
        lo_v, hi_v = max(lo * speed, 1e-12), hi * speed
        up = np.flatnonzero((s[:p0] > lo_v) & (s[:p0] < hi_v) & (ss[:p0] > 0.5 * lo_v))
        down = p1 + np.flatnonzero((s[p1:] > lo_v) & (s[p1:] < hi_v) & (ss[p1:] > 0.5 * lo_v))
        tt = t[a:b]
        acc = None if cut_start else _ramp_line(tt, s, up)
        dec = None if cut_end else _ramp_line(tt, s, down)
        moves.append({
            "speed": speed if cruise else None, "direction": sign,
            "accel": acc[0] if acc else None, "decel": -dec[0] if dec else None,
            "t_start": acc[1] if acc else None, "t_stop": dec[1] if dec else None,
            "distance": None if cut_start or cut_end else abs(float(np.sum(v[ia:ib]))) / fs_hz,
            "samples": (acc[2] if acc else 0) + (dec[2] if dec else 0)})
    return moves


def _trapezoid_position(t: np.ndarray, t0: float, accel: float, speed: float, dist: float) -> np.ndarray:
    """Distance travelled (mm) at times ``t`` (s) by a trapezoidal move of ``dist`` mm starting
    at ``t0`` with ``accel`` (mm/s²) up to ``speed`` (mm/s); a triangular one when ``dist`` is
    shorter than speed²/accel."""
    ta = min(speed / accel, math.sqrt(dist / accel))
    vpk = accel * ta
    tm = 2 * ta + max(dist - vpk * ta, 0.0) / vpk
    tau = np.clip(t - t0, 0.0, tm)
    up = 0.5 * accel * np.minimum(tau, ta) ** 2
    cruise = vpk * np.clip(tau - ta, 0.0, tm - 2 * ta)
    rem = np.clip(tm - tau, 0.0, ta)
    down = np.where(tau > tm - ta, 0.5 * accel * ta ** 2 - 0.5 * accel * rem ** 2, 0.0)
    return up + cruise + down


def fit_command(x: np.ndarray, fs_hz: float) -> list[dict]:
    """The moves of a commanded position ``x`` (n,) mm at ``fs_hz``, each fitted as a whole:
    the trapezoid (start time, acceleration, cruise speed; the distance between the rests
    fixed) least-squares fitted to the position samples of the move and half of each rest
    around it (``scipy.optimize.least_squares``), started from :func:`fit_moves` on the
    increments. Position samples of a trapezoid are exact wherever the sampling falls, where
    the increments across a corner of the profile are not: this fit is exact for a command
    sampled at any phase. Returns :func:`fit_moves`'s dicts with the fitted values."""
    from scipy import optimize

    x = np.asarray(x, dtype=float)
    moves = fit_moves(np.diff(x) * fs_hz, fs_hz, COMMAND_RAMP)
    t = np.arange(x.size) / fs_hz
    starts = [m["t_start"] for m in moves]
    out = []
    for j, m in enumerate(moves):
        if m["t_start"] is None or m["t_stop"] is None or m["speed"] is None or m["accel"] is None:
            out.append(m)
            continue
        lo = 0.5 * (moves[j - 1]["t_stop"] + m["t_start"]) if j > 0 and moves[j - 1]["t_stop"] else m["t_start"] - 0.05
        hi = (0.5 * (m["t_stop"] + starts[j + 1]) if j + 1 < len(moves) and starts[j + 1] is not None
              else m["t_stop"] + 0.05)
        sel = (t >= lo) & (t <= hi)
        tt, xx = t[sel], x[sel]
        if tt.size < 8:
            out.append(m)
            continue
        x0, x1 = float(xx[0]), float(xx[-1])
        dist, sign = abs(x1 - x0), (1.0 if x1 >= x0 else -1.0)

        def resid(p: np.ndarray, tt=tt, xx=xx, x0=x0, dist=dist, sign=sign) -> np.ndarray:
            return x0 + sign * _trapezoid_position(tt, p[0], p[1], p[2], dist) - xx

        p0 = np.array([m["t_start"], 0.5 * (m["accel"] + (m["decel"] or m["accel"])), m["speed"]])
        sol = optimize.least_squares(resid, p0, x_scale=np.array([1.0 / fs_hz, 0.01 * p0[1], 0.001 * p0[2]]),
                                     bounds=([-np.inf, 0.5 * p0[1], 0.5 * p0[2]], [np.inf, 2 * p0[1], 2 * p0[2]]),
                                     xtol=1e-12, ftol=1e-12)
        t0, acc, speed = (float(v) for v in sol.x)
        tm = float(_move_time(acc, speed, dist))
        out.append({**m, "speed": speed, "accel": acc, "decel": acc, "t_start": t0, "t_stop": t0 + tm,
                    "distance": dist})
    return out


def _move_time(accel: float, speed: float, dist: float) -> float:
    ta = min(speed / accel, math.sqrt(dist / accel))
    vpk = accel * ta
    return 2 * ta + max(dist - vpk * ta, 0.0) / vpk


def routine_of_moves(moves: list[list[dict]]) -> dict:
    """The routine of the moves of several records (lists of :func:`fit_moves` dicts): distinct
    cruise ``speeds_mm_s`` (ascending; a speed within 1 % of another is the same), ``accel_mm_s2``
    (the ramps' slopes averaged, weighted by their samples), ``dwell_s`` (median time between the
    fitted end of a move and the fitted start of the next), ``stroke_mm`` (median distance of a
    move), ``moves`` (how many were fitted); keys whose value cannot be measured are left out."""
    out: dict = {}
    flat = [m for rec in moves for m in rec]
    if not flat:
        return out
    speeds = sorted(m["speed"] for m in flat if m["speed"] is not None)
    groups: list[list[float]] = []
    for sp in speeds:
        if groups and sp <= 1.01 * groups[-1][0]:
            groups[-1].append(sp)
        else:
            groups.append([sp])
    if groups:
        out["speeds_mm_s"] = [_round(float(np.mean(g))) for g in groups]
    slopes = [(m[k], m["samples"]) for m in flat for k in ("accel", "decel") if m[k] is not None]
    if slopes:
        w = np.array([n for _, n in slopes], dtype=float)
        out["accel_mm_s2"] = _round(float(np.average([sl for sl, _ in slopes], weights=w)))
    dwells = [b["t_start"] - a["t_stop"] for rec in moves for a, b in zip(rec, rec[1:], strict=False)
              if a["t_stop"] is not None and b["t_start"] is not None]
    if dwells:
        out["dwell_s"] = _round(float(np.median(dwells)))
    dist = [m["distance"] for m in flat if m["distance"] is not None]
    if dist:
        out["stroke_mm"] = _round(float(np.median(dist)))
    out["moves"] = len(flat)
    return out


def motion_profile(v: np.ndarray, fs_hz: float, smooth_s: float = 0.0,
                   ramp: tuple[float, float] = MEASURED_RAMP) -> dict:
    """Speeds, acceleration, dwell and stroke of one velocity signal ``v`` (n,) in mm/s at
    ``fs_hz``: :func:`routine_of_moves` of its :func:`fit_moves`."""
    return routine_of_moves([fit_moves(v, fs_hz, ramp, smooth_s)])


def _spacing(hours: list[float]) -> float | None:
    return float(np.median(np.diff(hours))) if len(hours) > 1 else None


def measure_recording(path: str | os.PathLike, *, runs_to_measure: int = 3, captures_to_measure: int = 6) -> dict:
    """Layout and routines of ``path`` (campaign directory or ``measurements.h5``); see the module."""
    path = Path(path)
    if path.is_dir() or path.suffix != ".h5":
        path = path / "measurements.h5"
    out: dict = {"file": str(path)}
    with open_measurements(path) as m:
        axis = AxisDescription.from_dict(m.axis(), m.label)
        out["axis"] = axis
        names = m.phase1_captures()
        if names:
            # the layout from the headers (no array read: a paper-size recording has 1040
            # captures); the durations and the routine from the first captures
            heads = {n: m.phase1_header(n) for n in names}
            by_sample: dict[int, list[float]] = {}
            for hours, sample, _ in heads.values():
                by_sample.setdefault(sample, []).append(hours)
            counts = sorted({len(v) for v in by_sample.values()})
            first = [min(v) for _, v in sorted(by_sample.items())]
            within = [h for v in by_sample.values() for h in np.diff(sorted(v))]
            caps = [m.phase1(n) for n in names[:captures_to_measure]]
            p1 = {"samples": len(by_sample), "captures_per_sample": counts,
                  "fs_hz": sorted({fs for _, _, fs in heads.values()}),
                  "capture_s": float(np.median([len(c.speed) / c.fs_hz for c in caps])),
                  "first_hours": first[0], "last_hours": max(h for h, _, _ in heads.values()),
                  "sample_interval_hours": _spacing(first),
                  "capture_interval_minutes": float(np.median(within)) * 60 if within else None}
            lead = axis.lead_mm
            if lead is not None:
                # every capture's moves (up to ``captures_to_measure``), the ramps pooled
                p1["routine"] = routine_of_moves([
                    fit_moves(c.speed * lead / (2 * math.pi), c.fs_hz, MEASURED_RAMP, SPEED_SMOOTH_S)
                    for c in caps])
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
                recs, lo, hi = [], [], []
                for r in runs[sessions[0]][:runs_to_measure]:
                    run = m.phase2(sessions[0], r)
                    x = run.position_cmd * 1e3
                    fs = run.position_cmd_fs_hz
                    recs.append(fit_command(x, fs))
                    lo.append(float(x.min()))
                    hi.append(float(x.max()))
                prof = routine_of_moves(recs)
                prof["start_mm"] = _round(float(np.median(lo)))
                prof["end_mm"] = _round(float(np.median(hi)))
                p2["routine"] = prof
            out["phase2"] = p2
    return out
