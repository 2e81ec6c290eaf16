"""What one part of a campaign directory logs into a recording: a Phase II run (its IMU channels,
commanded position, error motions and the carriage poses), Phase I captures, the Phase I scores
of ``phase1/detection.json`` and the backlash estimates of ``backlash/backlash.json`` against the
truth (entity paths: :mod:`twin.harness.view`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from analysis.dataset import DOFS
from analysis.injected import injected_change_um
from twin.harness.view.base import (
    BLUE,
    DOF_LABELS,
    ENTITY_CARRIAGE,
    GREEN,
    GREY,
    ORANGE,
    PHASE1_CHANNELS,
    PHASE2_CHANNELS,
    POSE_RATE_HZ,
    PURPLE,
    RED,
    ViewSummary,
)
from twin.harness.view.poses import _direction, _estimated_error_motions, _stride, carriage_poses
from twin.harness.view.recorder import _Recorder


def _log_phase2(r: _Recorder, m, truth, directory: Path, session: str, run: str, exaggeration: float,
                frame: dict, max_points: int, summary: ViewSummary) -> list[str]:
    """The run's streams and the carriage poses; returns the entity roots of its plots."""
    rr = r.rr
    data = m.phase2(session, run)
    root = f"/phase2/{session}/{run}"
    for ch, unit, cols in PHASE2_CHANNELS:
        arr = getattr(data, ch)
        fs = getattr(data, f"{ch}_fs_hz")
        if arr is None:  # an optional channel the run does not have (a stand-alone IMU)
            continue
        k = _stride(len(arr), max_points)
        t = np.arange(0, len(arr), k) / fs
        every = "" if k == 1 else f", every {k}th sample"
        if cols is None:
            r.series(f"{root}/{ch}", t, arr[::k], name=f"{ch} ({unit}{every})")
        else:
            for j, col in enumerate(cols):
                r.series(f"{root}/{ch}/{col}", t, arr[::k, j], name=f"{ch} {col} ({unit}{every})",
                         color=(RED, GREEN, BLUE)[j])

    # Poses at POSE_RATE_HZ from the commanded position.
    fs = data.position_cmd_fs_hz
    step = max(1, round(fs / POSE_RATE_HZ))
    idx = np.arange(0, len(data.position_cmd), step)
    x_cmd = data.position_cmd
    t = idx / fs
    offset = 0.0
    errors = np.zeros((6, len(idx)))
    source, detail = "none", ""
    sessions_truth = truth.sessions() if truth is not None else []
    if truth is not None and session in sessions_truth:
        xt, et, attrs = truth.session(session)
        offset = float(attrs["origin_offset_m"])
        xr = x_cmd[idx] + offset
        errors = np.array([np.interp(xr, xt, et[i]) for i in range(6)])
        source = "truth.h5"
        detail = (f"true error motions of session {session} (truth.h5), at the carriage's rail "
                  f"coordinate = commanded position + the session's origin offset {offset * 1e3:.3f} mm")
    else:
        em_path = directory / "backlash" / "error_motions.h5"
        why = ("no truth.h5" if truth is None else f"{directory / 'truth.h5'} has no session {session}")
        if em_path.is_file():
            est = _estimated_error_motions(em_path, session)
            if est is not None:
                xe, fwd, rev = est
                d = _direction(x_cmd)[idx]
                xr = x_cmd[idx]
                ef = np.array([np.interp(xr, xe, fwd[i]) for i in range(6)])
                er = np.array([np.interp(xr, xe, rev[i]) for i in range(6)])
                errors = np.where(d > 0, ef, er)
                source = "backlash/error_motions.h5"
                detail = (f"estimated error motions of session {session} ({em_path}; {why}): the "
                          "forward or reverse profile by the direction of travel, over the commanded "
                          f"position (held at the ends of the estimated range {xe[0] * 1e3:.1f}–"
                          f"{xe[-1] * 1e3:.1f} mm)")
            else:
                summary.notes.append(f"{em_path} has no session {session} (skipped by `twin "
                                     f"backlash`?) and {why}: the carriage moves without error motions")
        else:
            summary.notes.append(f"{em_path} not found and {why}: the carriage moves without error "
                                 f"motions (`twin backlash {directory}` writes it)")
    if source == "none":
        detail = "none: the carriage follows the commanded position without error motions"
    x_rail = x_cmd[idx] + offset
    trans, quat = carriage_poses(x_rail, errors, exaggeration, frame["com_height"], frame["imu_offset"])
    r.rec.send_columns(ENTITY_CARRIAGE, indexes=[rr.TimeColumn("sim_time", duration=t)],
                       columns=rr.Transform3D.columns(translation=trans, quaternion=quat))
    for i, dof in enumerate(DOFS):
        what, unit = DOF_LABELS[dof]
        r.series(f"{root}/error_motion/{dof}", t, errors[i] * 1e6,
                 name=f"{dof} {what} ({unit}, not exaggerated)")
    summary.n_poses = len(idx)
    summary.error_motion_source, summary.source_detail = source, detail
    summary.session, summary.run, summary.hours = session, run, data.hours
    return [f"{root}/imu_acc", f"{root}/imu_gyro", f"{root}/position_cmd", f"{root}/error_motion"]


def _log_phase1(r: _Recorder, m, captures: list[str], max_points: int) -> list[str]:
    roots = []
    for name in captures:
        c = m.phase1(name)
        root = f"/phase1/{name}"
        for ch, unit, cols in PHASE1_CHANNELS:
            arr = getattr(c, ch)
            k = _stride(len(arr), max_points)
            t = np.arange(0, len(arr), k) / c.fs_hz
            every = "" if k == 1 else f", every {k}th sample"
            label = f"{name} at {c.hours:g} h"
            if cols is None:
                r.series(f"{root}/{ch}", t, arr[::k], name=f"{ch} ({unit}, {label}{every})")
            else:
                for j, col in enumerate(cols):
                    r.series(f"{root}/{ch}/{col}", t, arr[::k, j],
                             name=f"{ch} {col} ({unit}, {label}{every})", color=(RED, GREEN, BLUE)[j])
            roots.append(f"{root}/{ch}")
    return roots


def _log_detection(r: _Recorder, det: dict[str, dict], onset: float | None) -> dict[str, tuple]:
    """Scores and limits per method; returns method -> y range for its plot (or None)."""
    ranges = {}
    events_h, events_t, events_l = [], [], []
    for name, d in det.items():
        h = d["hours"]
        r.series(f"/hours/phase1/{name}/score", h, d["scores"], timeline="hours",
                 name=f"{name} score", color=BLUE, points=False)
        r.series(f"/hours/phase1/{name}/limit", h, [d["threshold"]] * len(h), timeline="hours",
                 name=f"{name} limit {d['threshold']:.4g}", color=RED)
        thr, sc = d["threshold"], d["scores"]
        top = 5.0 * thr if thr > 0 and max(sc) > 20 * thr else None
        ranges[name] = None if top is None else (min(0.0, min(sc)), top)
        if onset is not None:
            hi = top if top is not None else max(max(sc), thr)
            lo = ranges[name][0] if top is not None else min(min(sc), thr)
            r.series(f"/hours/phase1/{name}/onset", [onset, onset], [lo, hi], timeline="hours",
                     name=f"injected onset {onset:g} h", color=ORANGE)
        if d["detection_hours"] is not None:
            events_h.append(float(d["detection_hours"]))
            events_t.append(f"{name}: detection at {d['detection_hours']:g} h (detection.json)")
            events_l.append("INFO")
    if onset is not None:
        events_h.append(onset)
        events_t.append(f"injected fault onset at {onset:g} h (truth.h5)")
        events_l.append("WARN")
    if events_h:
        r.events(events_h, events_t, events_l)
    return ranges


def _log_backlash(r: _Recorder, doc: dict, truth, notes: list[str], truth_label: str) -> None:
    recs = doc["sessions"]

    def col(key):
        pts = [(float(s["hours"]), float(s[key])) for s in recs if s.get(key) is not None]
        return [p[0] for p in pts], [p[1] for p in pts]

    for key, name, color, points in (
            ("delta_backlash_um_shift", "Δbacklash, signal shifts (µm)", BLUE, True),
            ("delta_backlash_um_pitch", "Δbacklash, perceived pitch (µm)", PURPLE, True),
            ("smoothed_um", "Kalman smoothed (µm)", GREEN, False),
            ("dial_delta_um", "dial indicator change (µm)", GREY, True)):
        h, v = col(key)
        if h:
            r.series(f"/hours/backlash/{key}", h, v, timeline="hours", name=name, color=color, points=points)
    sm = [(float(s["hours"]), s["smoothed_um"], s["smoothed_std_um"]) for s in recs
          if s.get("smoothed_um") is not None and s.get("smoothed_std_um") is not None]
    if sm:
        h = [p[0] for p in sm]
        r.series("/hours/backlash/smoothed_band/upper", h, [p[1] + 2 * p[2] for p in sm], timeline="hours",
                 name="smoothed +2σ (µm)", color=(150, 210, 150))
        r.series("/hours/backlash/smoothed_band/lower", h, [p[1] - 2 * p[2] for p in sm], timeline="hours",
                 name="smoothed −2σ (µm)", color=(150, 210, 150))
    prog = doc.get("prognosis")
    if isinstance(prog, dict) and isinstance(prog.get("limit_um"), (int, float)) and recs:
        h = [float(recs[0]["hours"]), float(recs[-1]["hours"])]
        r.series("/hours/backlash/limit", h, [float(prog["limit_um"])] * 2, timeline="hours",
                 name=f"limit {prog['limit_um']:g} µm", color=RED)
    if truth is None:
        return
    k = int((doc.get("parameters") or {}).get("baseline_sessions") or 1)
    have = set(truth.sessions())
    base = [s["session"] for s in recs[:k]]
    if not recs or not set(base) <= have:
        notes.append(f"{truth_label} lacks the reference session(s) {', '.join(base) or '-'} of "
                     "backlash.json: the injected backlash is left out")
        return
    shown = [s for s in recs if s["session"] in have]  # the baseline sessions lead the list
    change = injected_change_um(truth, [s["session"] for s in shown], k)
    r.series("/hours/backlash/injected_delta_um", [float(s["hours"]) for s in shown], list(change),
             timeline="hours", name="injected change (truth.h5, µm)", color=ORANGE, points=True)
