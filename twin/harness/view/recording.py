"""Logging a campaign directory into a Rerun recording, saving it or serving it."""

from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np

from analysis.dataset import DOFS, open_measurements, open_truth
from analysis.injected import injected_change_um
from twin.harness.view.base import (
    APP_ID,
    BLUE,
    DOF_LABELS,
    ENTITY_CARRIAGE,
    EXAGGERATION,
    GREEN,
    GREY,
    MAX_POINTS,
    ORANGE,
    PHASE1_CHANNELS,
    PHASE2_CHANNELS,
    POSE_RATE_HZ,
    PURPLE,
    RED,
    ViewError,
    ViewSummary,
    hours_to_ns,
)
from twin.harness.view.blueprint import _blueprint
from twin.harness.view.inputs import _axis_from_measurements, _backlash, _detection, _flatten
from twin.harness.view.poses import _direction, _estimated_error_motions, _geometry, _Shape, _stride, carriage_poses
from twin.sim.scenario import Scenario, ScenarioError, from_dict, to_axis

# ---------------------------------------------------------------------------------------------
# The recording


class _Recorder:
    """Everything that calls Rerun."""

    def __init__(self, rec, rr):
        self.rec, self.rr = rec, rr

    def static(self, path: str, archetype) -> None:
        self.rec.log(path, archetype, static=True)

    def series(self, path: str, t_s, values, *, timeline: str = "sim_time", name: str | None = None,
               color=None, points: bool = False) -> None:
        rr = self.rr
        if name is not None or color is not None:
            style = (rr.SeriesPoints(names=name, colors=color, marker_sizes=4.0) if points else
                     rr.SeriesLines(names=name, colors=color))
            self.static(path, style)
        index = (rr.TimeColumn(timeline, duration=np.asarray(t_s, dtype=np.float64)) if timeline == "sim_time"
                 else rr.TimeColumn(timeline, duration=hours_to_ns(t_s).astype("timedelta64[ns]")))
        self.rec.send_columns(path, indexes=[index],
                              columns=rr.Scalars.columns(scalars=np.asarray(values, dtype=np.float64)))

    def shapes(self, root: str, shapes: list[_Shape]) -> None:
        rr = self.rr
        for sh in shapes:
            if sh.kind == "box":
                arch = rr.Boxes3D(centers=[sh.center], half_sizes=[sh.size], colors=[sh.color],
                                  labels=[sh.label], fill_mode="solid")
            else:
                arch = rr.Cylinders3D(centers=[sh.center], lengths=[2 * sh.size[0]], radii=[sh.size[1]],
                                      rotation_axis_angles=[rr.RotationAxisAngle(axis=[0, 1, 0], degrees=90.0)],
                                      colors=[sh.color], labels=[sh.label], fill_mode="solid")
            self.static(f"{root}/{sh.path}", arch)

    def events(self, hours: list[float], texts: list[str], levels: list[str]) -> None:
        rr = self.rr
        order = np.argsort(hours, kind="stable")
        self.rec.send_columns(
            "/hours/events",
            indexes=[rr.TimeColumn("hours", duration=hours_to_ns(np.asarray(hours)[order]).astype("timedelta64[ns]"))],
            columns=rr.TextLog.columns(text=[texts[i] for i in order], level=[levels[i] for i in order]))


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


def _notes_markdown(summary: ViewSummary, directory: Path) -> str:
    lines = [f"# `twin view` of {directory}", ""]
    if summary.session is not None:
        lines += [(f"**3D**: Phase II session {summary.session}, run {summary.run} "
                   f"({summary.hours:g} h), {summary.n_poses} carriage poses on the `sim_time` timeline. "
                   f"Error motions exaggerated **×{summary.exaggeration:g}**; source: "
                   f"{summary.source_detail}."), ""]
    lines += [("**Timelines**: the 3D view, the Phase II run and the Phase I captures play on `sim_time` "
               "(s from the start of the run or capture); the Phase I scores, the backlash and the truth "
               "are on `hours` (operating hours): select that timeline in the time panel for the "
               "'operating hours' tab."), ""]
    truth = ("truth.h5 (simulated campaign): the injected onset, preload and backlash are shown."
             if summary.has_truth else
             "no truth.h5 (a real machine's directory?): the injected onset, preload and backlash and "
             "the true error motions are left out.")
    lines += [f"**Truth**: {truth}", ""]
    if summary.notes:
        lines += ["**Left out**:", ""] + [f"- {n}" for n in summary.notes]
    return "\n".join(lines) + "\n"


def _choose(m, session: str | None, run: str | None, captures: list[str] | None,
            notes: list[str]) -> tuple[str | None, str | None, list[str]]:
    """The Phase II run and the Phase I captures to show (defaults: the last session's first run;
    the first and the last capture); raises :class:`ViewError` naming an unknown one."""
    mpath = m.label
    sessions = m.phase2_sessions()
    if session is not None and session not in sessions:
        raise ViewError(f"--session {session}: {mpath} has no such Phase II session; expected one of "
                        f"{', '.join(sessions) or '(none)'}")
    if sessions:
        session = session or sessions[-1]
        runs = m.phase2_runs(session)
        if run is not None and run not in runs:
            raise ViewError(f"--run {run}: session {session} of {mpath} has no such run; expected "
                            f"one of {', '.join(runs) or '(none)'}")
        run = run or (runs[0] if runs else None)
        if run is None:
            notes.append(f"{mpath}: session {session} has no runs: no carriage motion")
    elif run is not None:
        raise ViewError(f"--run {run}: {mpath} has no Phase II sessions")
    else:
        notes.append(f"{mpath} has no Phase II session: the carriage is shown at rest and no "
                     "Phase II streams are logged")
    all_caps = m.phase1_captures()
    unknown = [c for c in captures or [] if c not in all_caps]
    if unknown:
        shown = ", ".join(all_caps if len(all_caps) <= 4 else [*all_caps[:3], "...", all_caps[-1]]) or "(none)"
        raise ViewError(f"--capture {', '.join(unknown)}: {mpath} has no such Phase I capture; "
                        f"expected one of {shown}")
    if not captures:
        captures = list(dict.fromkeys([all_caps[0], all_caps[-1]])) if all_caps else []
    if not all_caps:
        notes.append(f"{mpath} has no Phase I capture: no Phase I streams")
    return session, run, captures


def build(rec, directory: str | Path, *, session: str | None = None, run: str | None = None,
          captures: list[str] | None = None, exaggeration: float = EXAGGERATION,
          max_points: int = MAX_POINTS) -> ViewSummary:
    """Log the recording of campaign ``directory`` into the Rerun ``rec`` (a ``RecordingStream``
    already given its sink).

    Args:
        session, run: the Phase II run shown (default: the last session's first run).
        captures: Phase I captures shown (default: the first and the last).
        exaggeration: factor on the error motions in the 3D view (> 0).
        max_points: per sensor channel; longer channels keep every k-th sample.

    Raises:
        FileNotFoundError: no ``measurements.h5``.
        ViewError: unknown session, run or capture; unreadable ``detection.json`` /
            ``backlash.json`` (all name the file or option and what was expected).
        analysis.dataset.DatasetError: an invalid ``measurements.h5`` / ``truth.h5``.
    """
    import rerun as rr
    import rerun.blueprint as rrb

    t0 = time.perf_counter()
    directory = Path(directory)
    if not (exaggeration > 0 and math.isfinite(exaggeration)):
        raise ViewError(f"--exaggeration {exaggeration!r}: expected a finite factor > 0 (e.g. 2000)")
    if max_points < 1:
        raise ViewError(f"max_points {max_points!r}: expected an integer >= 1")
    mpath = directory / "measurements.h5"
    if not mpath.is_file():
        raise FileNotFoundError(f"{mpath}: no such file; expected the campaign's measurements.h5 "
                                "(`twin simulate SCENARIO -o DIR` writes one)")
    summary = ViewSummary(directory=directory, exaggeration=float(exaggeration))
    r = _Recorder(rec, rr)
    tpath = directory / "truth.h5"
    truth = open_truth(tpath) if tpath.is_file() else None
    summary.has_truth = truth is not None
    try:
        with open_measurements(mpath) as m:
            # Choices first, so that a bad option fails before anything is logged.
            session, run, captures = _choose(m, session, run, captures, summary.notes)

            det_path = directory / "phase1" / "detection.json"
            det = _detection(det_path) if det_path.is_file() else None
            if det is None:
                summary.notes.append(f"{det_path} not found: the Phase I scores (T² and the others) are "
                                     f"left out (`twin detect {directory} --reference REF` writes it)")
            bl_path = directory / "backlash" / "backlash.json"
            bl = _backlash(bl_path) if bl_path.is_file() else None
            if bl is None:
                summary.notes.append(f"{bl_path} not found: the backlash estimates are left out "
                                     f"(`twin backlash {directory}` writes it)")
            if truth is None:
                summary.notes.append(f"no {tpath} (a real machine's directory?): the injected onset, "
                                     "preload and backlash and the true error motions are left out")

            # Scenario and axis.
            if truth is not None:
                sdict = truth.scenario()
                try:
                    axis = to_axis(from_dict(sdict, source=f"{tpath}: /@scenario"))
                except ScenarioError as exc:
                    summary.notes.append(f"{exc}; the 3D view uses the default axis")
                    axis = to_axis(Scenario())
                rec.send_property("scenario", rr.AnyValues(**_flatten(sdict), json=json.dumps(sdict, sort_keys=True)))
            else:
                desc = m.axis()
                axis = _axis_from_measurements(desc, summary.notes, str(mpath))
                rec.send_property("measurements", rr.AnyValues(**_flatten({"axis": desc}),
                                                               json=json.dumps(desc, sort_keys=True)))

            world, carriage, frame = _geometry(axis)
            r.static("/world", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
            r.shapes("/world", world)
            r.shapes(ENTITY_CARRIAGE, carriage)
            phase2_roots: list[str] = []
            if session is not None and run is not None:
                phase2_roots = _log_phase2(r, m, truth, directory, session, run, exaggeration, frame,
                                           max_points, summary)
            else:  # at rest at mid-stroke
                trans, quat = carriage_poses(np.array([axis.travel / 2]), np.zeros((6, 1)), exaggeration,
                                             frame["com_height"], frame["imu_offset"])
                r.static(ENTITY_CARRIAGE, rr.Transform3D(translation=trans[0], quaternion=quat[0]))
            phase1_roots = _log_phase1(r, m, captures, max_points)
            summary.captures = list(captures)

        onset = truth.onset_hours if truth is not None else None
        ranges: dict[str, tuple | None] = {}
        if det is not None:
            ranges = _log_detection(r, det, onset)
            summary.methods = list(det)
        elif onset is not None:
            r.events([onset], [f"injected fault onset at {onset:g} h (truth.h5)"], ["WARN"])
        if truth is not None:
            tl = truth.timeline()
            r.series("/hours/truth/preload_N", tl["hours"], tl["preload_N"], timeline="hours",
                     name="injected preload (N)", color=ORANGE)
        if bl is not None:
            _log_backlash(r, bl, truth, summary.notes, str(tpath))
            summary.backlash_sessions = len(bl["sessions"])
    finally:
        if truth is not None:
            truth.close()

    rec.send_property("view", rr.AnyValues(
        exaggeration=summary.exaggeration, error_motion_source=summary.error_motion_source,
        error_motion_detail=summary.source_detail, session=summary.session or "",
        run=summary.run or "", session_hours=float("nan") if summary.hours is None else summary.hours,
        n_poses=summary.n_poses, pose_rate_hz=POSE_RATE_HZ, max_points_per_channel=max_points,
        captures=summary.captures or [""], truth=summary.has_truth,
        left_out=summary.notes or [""]))
    r.static("/notes", rr.TextDocument(_notes_markdown(summary, directory), media_type=rr.MediaType.MARKDOWN))
    rec.send_blueprint(_blueprint(rrb, summary, phase2_roots, phase1_roots, ranges, axis.travel,
                                  bl is not None, summary.has_truth))
    summary.seconds = time.perf_counter() - t0
    return summary


def _stream(directory: Path):
    import rerun as rr

    rec = rr.RecordingStream(APP_ID)
    rec.send_recording_name(f"twin view {directory.resolve().name}")
    return rec


def write_recording(directory: str | Path, out: str | Path | None = None, **options) -> ViewSummary:
    """Write the recording of ``directory`` to ``out`` (default ``directory/view.rrd``), through a
    temporary file renamed into place; options as :func:`build`. Returns the summary with
    ``path``, ``size_bytes`` and ``seconds`` (logging and writing)."""
    directory = Path(directory)
    out = Path(out) if out is not None else directory / "view.rrd"
    if not (directory / "measurements.h5").is_file():  # before creating anything
        raise FileNotFoundError(f"{directory / 'measurements.h5'}: no such file; expected the campaign's "
                                "measurements.h5 (`twin simulate SCENARIO -o DIR` writes one)")
    t0 = time.perf_counter()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".partial")
    rec = _stream(directory)
    rec.save(tmp)
    try:
        summary = build(rec, directory, **options)
        rec.flush()
    except BaseException:
        rec.disconnect()
        tmp.unlink(missing_ok=True)
        raise
    rec.disconnect()
    os.replace(tmp, out)
    summary.path, summary.size_bytes = out, out.stat().st_size
    summary.seconds = time.perf_counter() - t0
    return summary


def _check_port(port: int, option: str) -> None:
    """Raise :class:`ViewError` if TCP ``port`` cannot be bound (Rerun's gRPC server only logs it)."""
    import socket

    if not 0 < port < 65536:
        raise ViewError(f"{option} {port}: expected a TCP port 1-65535")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError as exc:
            raise ViewError(f"{option} {port}: the port is not free ({exc.strerror}); choose another") from None


def serve_recording(directory: str | Path, *, web_port: int = 9090, grpc_port: int = 9876,
                    open_browser: bool = False, **options) -> tuple[ViewSummary, str, Any]:
    """Serve the recording of ``directory`` over gRPC with a web viewer on ``web_port``. Returns
    (summary, viewer URL, the recording stream); the servers live as long as the stream (the CLI
    keeps it until Ctrl-C)."""
    import rerun as rr

    directory = Path(directory)
    if not (directory / "measurements.h5").is_file():
        raise FileNotFoundError(f"{directory / 'measurements.h5'}: no such file; expected the campaign's "
                                "measurements.h5 (`twin simulate SCENARIO -o DIR` writes one)")
    for port, option in ((grpc_port, "--grpc-port"), (web_port, "--web-port")):
        _check_port(port, option)
    rec = _stream(directory)
    uri = rec.serve_grpc(grpc_port=grpc_port)
    summary = build(rec, directory, **options)
    rec.flush()
    try:
        rr.serve_web_viewer(web_port=web_port, open_browser=open_browser, connect_to=uri)
    except RuntimeError as exc:
        rec.disconnect()
        raise ViewError(f"--web-port {web_port}: the web viewer could not start ({exc})") from None
    return summary, f"http://localhost:{web_port}/?url={quote(uri, safe='')}", rec
