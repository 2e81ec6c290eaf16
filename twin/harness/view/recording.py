"""Logging a campaign directory into a Rerun recording (:func:`build`): which run and captures are
shown, the streams of each part, the properties, the notes and the blueprint.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from analysis.dataset import open_measurements, open_truth
from twin.harness.view.base import (
    ENTITY_CARRIAGE,
    EXAGGERATION,
    MAX_POINTS,
    ORANGE,
    POSE_RATE_HZ,
    ViewError,
    ViewSummary,
)
from twin.harness.view.blueprint import _blueprint
from twin.harness.view.inputs import _axis_from_measurements, _backlash, _detection, _flatten
from twin.harness.view.poses import _geometry, carriage_poses
from twin.harness.view.recorder import _Recorder
from twin.harness.view.streams import _log_backlash, _log_detection, _log_phase1, _log_phase2
from twin.sim.scenario import Scenario, ScenarioError, from_dict, to_axis


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
