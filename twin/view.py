"""The Rerun recording of a campaign directory (``twin view``); the only module that imports Rerun.

What the recording holds (entity paths; the blueprint arranges them in four tabs):

- ``/world/...``: the axis in 3D (z up, x along the travel, m): base, the two rails, the screw
  and, under ``/world/carriage``, the trucks, the carriage plate, the nut, the load and the IMU.
  ``/world/carriage`` carries one :class:`rerun.Transform3D` per pose on the ``sim_time``
  timeline (s from the start of the run) of one Phase II run: the carriage at the commanded
  position plus the six error motions multiplied by a stated factor (``exaggeration``, e.g.
  2000), placed so that the IMU point moves by the exaggerated translations and the carriage
  turns by the exaggerated angles. The error motions are the true ones of the session
  (``truth.h5``) when it exists, else the estimated ones (``backlash/error_motions.h5``, the
  forward or reverse profile by the direction of travel); the property ``view`` and the notes
  say which. With ``truth.h5`` the carriage is placed at its rail coordinate (commanded position
  plus the session's origin offset); without it, at the commanded position.
- ``/phase2/<session>/<run>/...``: that run's IMU channels and commanded position, and the error
  motions along the run (unexaggerated, µm and µrad), on ``sim_time``.
- ``/phase1/<capture>/...``: motor speed and torque and the two nut accelerometers of one or
  more Phase I captures, on ``sim_time`` (s from the start of the capture). Channels longer than
  ``max_points`` samples keep every k-th sample (stated in the series name).
- ``/hours/...`` on the ``hours`` timeline (operating hours, stored as a duration of
  hours·3600 s): the Phase I scores of every method of ``phase1/detection.json`` with their
  limits (values exactly those of the file), the injected onset (``truth.h5``) and the true
  preload; the backlash estimates of ``backlash/backlash.json`` (shift estimate, perceived-pitch
  estimate, Kalman smoothed value with ±2σ, dial-indicator change) against the injected change
  of backlash (``truth.h5``, relative to the mean of the baseline sessions as the estimates);
  ``/hours/events`` marks the onset and each method's first detection.
- Properties: ``scenario`` (the scenario of ``truth.h5``, flattened to dotted keys, plus the whole
  JSON as ``json``) or, without ``truth.h5``, ``measurements`` (the axis description of
  ``measurements.h5``); ``view`` (what was drawn and from what).
- ``/notes``: a Markdown document of the above, including what was left out and why.

A directory without ``truth.h5`` (a real machine) gives a recording without the truth parts;
missing ``phase1/`` or ``backlash/`` outputs are left out with a note naming the file and the
command that writes it.
"""

from __future__ import annotations

import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import quote

import numpy as np

from analysis.dataset import DOFS, DatasetError, open_measurements, open_truth
from analysis.phase2.workflow import read_error_motions
from analysis.scoring import injected_change_um
from twin.axis import Axis
from twin.scenario import Scenario, ScenarioError, from_dict, to_axis

__all__ = ["ENTITY_CARRIAGE", "EXAGGERATION", "MAX_POINTS", "POSE_RATE_HZ", "ViewError", "ViewSummary",
           "build", "carriage_poses", "hours_to_ns", "serve_recording", "write_recording"]

APP_ID = "ballscrew_twin"
#: Carriage poses logged per second of the run.
POSE_RATE_HZ = 100.0
#: Samples per sensor channel above which only every k-th sample is logged.
MAX_POINTS = 50_000
#: Default factor on the error motions in the 3D view.
EXAGGERATION = 2000.0
ENTITY_CARRIAGE = "/world/carriage"
DOF_LABELS = {"E_XX": ("positioning", "um"), "E_YX": ("horizontal straightness", "um"),
              "E_ZX": ("vertical straightness", "um"), "E_AX": ("roll", "urad"),
              "E_BX": ("pitch", "urad"), "E_CX": ("yaw", "urad")}
PHASE1_CHANNELS = (("speed", "rad/s", None), ("torque", "N*m", None),
                   ("acc1", "m/s^2", "xyz"), ("acc2", "m/s^2", "xyz"))
PHASE2_CHANNELS = (("imu_acc", "m/s^2", "xyz"), ("imu_gyro", "rad/s", "xyz"), ("position_cmd", "m", None))
RED, ORANGE, GREEN, BLUE, GREY, PURPLE = ((220, 40, 40), (240, 150, 20), (40, 160, 60),
                                          (40, 90, 220), (120, 120, 120), (150, 60, 200))


class ViewError(ValueError):
    """Bad input to ``twin view``: the message names the file, key or option and what was expected."""


@dataclass
class ViewSummary:
    """What :func:`build` put into the recording.

    Attributes:
        directory: the campaign directory.
        path: the ``.rrd`` written (None when served).
        session, run, hours: the Phase II run shown in 3D (None without Phase II data).
        error_motion_source: ``"truth.h5"``, ``"backlash/error_motions.h5"`` or ``"none"``.
        source_detail: one sentence saying where the error motions come from.
        exaggeration: factor on the error motions in the 3D view.
        n_poses: carriage poses logged on ``sim_time``.
        captures: Phase I captures logged.
        methods: Phase I methods logged from ``detection.json``.
        backlash_sessions: sessions of ``backlash.json`` logged.
        has_truth: whether ``truth.h5`` was used.
        notes: what was left out and why (printed by the CLI).
        seconds: wall time of :func:`build`.
        size_bytes: size of the written file (0 when served).
    """

    directory: Path
    path: Path | None = None
    session: str | None = None
    run: str | None = None
    hours: float | None = None
    error_motion_source: str = "none"
    source_detail: str = ""
    exaggeration: float = EXAGGERATION
    n_poses: int = 0
    captures: list[str] = field(default_factory=list)
    methods: list[str] = field(default_factory=list)
    backlash_sessions: int = 0
    has_truth: bool = False
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0
    size_bytes: int = 0


def hours_to_ns(hours) -> np.ndarray:
    """Operating hours as the ``hours`` timeline stores them: int64 ns of a duration of hours·3600 s."""
    return np.round(np.asarray(hours, dtype=np.float64) * 3600e9).astype(np.int64)


# ---------------------------------------------------------------------------------------------
# Inputs


def _read_json(path: Path, what: str) -> dict:
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ViewError(f"{path}: not valid JSON ({exc}); expected {what}; rerun the command that "
                        "writes it") from None
    except OSError as exc:
        raise ViewError(f"{path}: cannot read it ({exc.strerror})") from None
    if not isinstance(doc, dict):
        raise ViewError(f"{path}: JSON of type {type(doc).__name__}; expected {what}")
    return doc


def _number_list(path: Path, key: str, value: Any, n: int | None = None,
                 allow_none: bool = False) -> list:
    ok = isinstance(value, list) and all(
        (v is None and allow_none) or (isinstance(v, (int, float)) and not isinstance(v, bool)
                                       and math.isfinite(v)) for v in value)
    if not ok or (n is not None and len(value) != n):
        length = "" if n is None else f" of length {n}"
        raise ViewError(f"{path}: {key} is {str(value)[:80]}; expected a list{length} of finite numbers")
    return value


def _detection(path: Path) -> dict[str, dict]:
    """``detection.json``: method -> {hours, scores, threshold, detection_hours}, checked."""
    doc = _read_json(path, "the Phase I detection results of `twin detect`")
    methods = doc.get("methods")
    if not isinstance(methods, dict) or not methods:
        raise ViewError(f"{path}: 'methods' is {str(methods)[:80]}; expected an object of methods")
    out = {}
    for name, m in methods.items():
        key = f"methods.{name}"
        if not isinstance(m, dict):
            raise ViewError(f"{path}: {key} is {str(m)[:80]}; expected an object")
        hours = _number_list(path, f"{key}.hours", m.get("hours"))
        scores = _number_list(path, f"{key}.scores", m.get("scores"), len(hours))
        thr = m.get("threshold")
        if not isinstance(thr, (int, float)) or not math.isfinite(thr):
            raise ViewError(f"{path}: {key}.threshold is {thr!r}; expected a finite number")
        det = m.get("detection_hours")
        out[name] = {"hours": hours, "scores": scores, "threshold": float(thr),
                     "detection_hours": det if isinstance(det, (int, float)) else None}
    return out


def _backlash(path: Path) -> dict:
    doc = _read_json(path, "the Phase II backlash results of `twin backlash`")
    sessions = doc.get("sessions")
    if not isinstance(sessions, list):
        raise ViewError(f"{path}: 'sessions' is {str(sessions)[:80]}; expected a list of sessions")
    for i, rec in enumerate(sessions):
        if not isinstance(rec, dict) or not isinstance(rec.get("session"), str):
            raise ViewError(f"{path}: sessions[{i}] is {str(rec)[:80]}; expected an object with 'session'")
        _number_list(path, f"sessions[{i}].hours", [rec.get("hours")])
        for key in ("delta_backlash_um_shift", "delta_backlash_um_pitch", "smoothed_um",
                    "smoothed_std_um", "dial_delta_um"):
            if key in rec:
                _number_list(path, f"sessions[{i}].{key}", [rec[key]], allow_none=True)
    return doc


def _flatten(obj: Any, prefix: str = "") -> dict[str, Any]:
    """A JSON object as ``{"a.b.c": value}``: numbers, strings, booleans and non-empty lists of
    numbers or of strings as they are; anything else (null, empty or mixed lists, lists of
    objects) as its JSON text."""
    out: dict[str, Any] = {}
    if isinstance(obj, dict):
        for k, v in obj.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        return out
    key = prefix[:-1]
    if isinstance(obj, (bool, int, float, str)):
        out[key] = obj
    elif (isinstance(obj, list) and obj and
          (all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in obj)
           or all(isinstance(v, str) for v in obj))):
        out[key] = [float(v) for v in obj] if not isinstance(obj[0], str) else list(obj)
    else:
        out[key] = json.dumps(obj)
    return out


_AXIS_KEYS = ("travel_mm", "lead_mm", "rail_spacing_mm", "truck_spacing_mm", "carriage_mass_kg")


def _axis_from_measurements(desc: dict, notes: list[str], label: str) -> Axis:
    """The axis to draw from the nominal description of ``measurements.h5``: the few dimensions it
    names (``travel_mm`` or ``travel_m``, ...), the defaults of :class:`Scenario` for the rest."""
    given: dict[str, float] = {}
    for key in _AXIS_KEYS:
        unit = key.rsplit("_", 1)[1]
        if isinstance(desc.get(key), (int, float)):
            given[key] = float(desc[key])
        elif unit == "mm" and isinstance(desc.get(key[:-3] + "_m"), (int, float)):
            given[key] = float(desc[key[:-3] + "_m"]) * 1e3
    try:
        s = from_dict({"axis": given})
    except ScenarioError as exc:
        notes.append(f"{label}: /@axis gives dimensions the twin cannot draw ({exc}); the 3D view "
                     "uses the default axis")
        s = Scenario()
    missing = [k for k in _AXIS_KEYS if k not in given]
    if missing:
        notes.append(f"{label}: /@axis has no {', '.join(missing)}; the 3D view uses the twin's "
                     "defaults for them")
    return to_axis(s)


# ---------------------------------------------------------------------------------------------
# Geometry and poses (numpy only)


@dataclass(frozen=True)
class _Shape:
    path: str
    kind: str  # "box" or "cylinder_x"
    center: tuple[float, float, float]
    size: tuple[float, float, float]  # box: half sizes; cylinder along x: (half length, radius, 0)
    color: tuple[int, int, int]
    label: str


def _geometry(axis: Axis) -> tuple[list[_Shape], list[_Shape], dict[str, float]]:
    """Static shapes in the world frame and shapes in the carriage frame (origin at the carriage's
    centre of mass, ``com_height`` above the rail plane z = 0), m. Dimensions from the axis where
    it has them (travel, rail and truck spacing, screw diameters, heights of the nut, centre of
    mass and IMU); the rest is schematic."""
    c, s, L = axis.carriage, axis.screw, axis.travel
    w, a = c.rail_spacing / 2.0, c.truck_spacing / 2.0
    zc = c.com_height
    world = [
        _Shape("base", "box", (L / 2, 0.0, -0.06), (L / 2 + 0.1, max(0.2, w + 0.06), 0.02), GREY,
               "base"),
        _Shape("rails/left", "box", (L / 2, -w, -0.02), (L / 2 + 0.1, 0.01, 0.02), (90, 90, 100),
               f"rail (spacing {c.rail_spacing * 1e3:g} mm)"),
        _Shape("rails/right", "box", (L / 2, w, -0.02), (L / 2 + 0.1, 0.01, 0.02), (90, 90, 100),
               "rail"),
        _Shape("screw", "cylinder_x", (L / 2, 0.0, c.nut_height), (L / 2 + 0.05, s.root_diameter / 2, 0.0),
               (180, 180, 190), f"screw {s.pitch_diameter * 1e3:g}x{s.lead * 1e3:g}"),
    ]
    top = 0.035  # rail plane to the underside of the plate: the trucks
    plate_t = 0.02
    load_h = max(c.imu_height - top - plate_t, 0.02)
    carriage = [
        *[_Shape(f"trucks/{n}", "box", (x, y, top / 2 - zc), (0.03, 0.02, top / 2), (70, 70, 80),
                 f"truck {n}") for n, x, y in (("FL", a, -w), ("FR", a, w), ("RL", -a, -w), ("RR", -a, w))],
        _Shape("plate", "box", (0.0, 0.0, top + plate_t / 2 - zc), (a + 0.04, w + 0.03, plate_t / 2),
               (80, 100, 200), "carriage"),
        _Shape("nut", "cylinder_x", (0.0, 0.0, c.nut_height - zc), (0.04, s.pitch_diameter / 2 + 0.012, 0.0),
               (200, 160, 60), "ball nut"),
        _Shape("load", "box", (0.0, 0.0, top + plate_t + load_h / 2 - zc), (0.09, 0.09, load_h / 2),
               (60, 60, 60), f"steel load (carriage with load {c.mass:g} kg)"),
        _Shape("imu", "box", (0.0, 0.0, c.imu_height - zc + 0.005), (0.015, 0.015, 0.005), (220, 40, 40),
               "IMU"),
    ]
    frame = {"com_height": zc, "imu_offset": c.imu_height - zc, "travel": L}
    return world, carriage, frame


def _quat_xyzw(roll, pitch, yaw) -> np.ndarray:
    """Quaternions (n, 4) x, y, z, w of R = Rz(yaw)·Ry(pitch)·Rx(roll) (angles (n,) rad)."""
    cr, sr = np.cos(np.asarray(roll) / 2), np.sin(np.asarray(roll) / 2)
    cp, sp = np.cos(np.asarray(pitch) / 2), np.sin(np.asarray(pitch) / 2)
    cy, sy = np.cos(np.asarray(yaw) / 2), np.sin(np.asarray(yaw) / 2)
    return np.stack([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy], axis=1)


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate the vector v (3,) by each quaternion of q (n, 4) x, y, z, w; returns (n, 3)."""
    u, w = q[:, :3], q[:, 3:4]
    t = 2.0 * np.cross(u, np.broadcast_to(v, u.shape))
    return v + w * t + np.cross(u, t)


def carriage_poses(x_m: np.ndarray, errors: np.ndarray, exaggeration: float, com_height: float,
                   imu_offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Carriage frame poses: ``x_m`` (n,) carriage position along the rails in m; ``errors``
    (6, n) error motions at the IMU in DOFS order (m, m, m, rad, rad, rad). Returns translations
    (n, 3) in m and quaternions (n, 4) x, y, z, w of the carriage frame (origin at the centre of
    mass), such that the IMU point (``imu_offset`` above the origin) is at
    (x + k·E_XX, k·E_YX, com_height + imu_offset + k·E_ZX) and the carriage is turned by
    k·(E_AX, E_BX, E_CX) about x, y, z, with k = ``exaggeration``."""
    k = float(exaggeration)
    q = _quat_xyzw(k * errors[3], k * errors[4], k * errors[5])
    imu = np.stack([x_m + k * errors[0], k * errors[1],
                    np.full_like(x_m, com_height + imu_offset) + k * errors[2]], axis=1)
    return imu - _rotate(q, np.array([0.0, 0.0, imu_offset])), q


def _direction(x: np.ndarray) -> np.ndarray:
    """+1 moving forward (x increasing), −1 in reverse; a standstill keeps the last direction
    (forward before the first move)."""
    s = np.sign(np.diff(x, prepend=x[0]))
    idx = np.where(s != 0, np.arange(len(s)), 0)
    np.maximum.accumulate(idx, out=idx)
    d = s[idx]
    d[d == 0] = 1.0
    return d


def _estimated_error_motions(path: Path, session: str):
    """``(x_m (n,) m, forward (6, n), reverse (6, n))`` in DOFS order (m and rad) of ``session``
    in ``error_motions.h5`` (written by ``twin backlash``), or None if the session is absent."""
    try:
        return read_error_motions(path).get(session)
    except DatasetError as exc:
        raise ViewError(str(exc)) from None


def _stride(n: int, max_points: int) -> int:
    return max(1, -(-n // max_points))


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


def _blueprint(rrb, summary: ViewSummary, phase2_roots: list[str], phase1_roots: list[str],
               ranges: dict[str, tuple | None], travel: float, has_backlash: bool, has_truth: bool):
    tabs = []
    k = f"{summary.exaggeration:g}"
    eye = rrb.EyeControls3D(position=[travel / 2 + 0.35, -0.95, 0.55], look_target=[travel / 2, 0.0, 0.05],
                            eye_up=[0, 0, 1])
    view3d = rrb.Spatial3DView(origin="/world", eye_controls=eye,
                               name=f"axis, error motions ×{k} ({summary.error_motion_source})")
    if phase2_roots:
        plots = [rrb.TimeSeriesView(origin=p, name=p.rsplit("/", 1)[1] + f" ({summary.session}/{summary.run})")
                 for p in phase2_roots]
        tabs.append(rrb.Horizontal(view3d, rrb.Vertical(*plots), column_shares=[3, 2],
                                   name="Phase II run (sim_time)"))
    else:
        tabs.append(rrb.Horizontal(view3d, name="axis"))
    if phase1_roots:
        tabs.append(rrb.Grid(*[rrb.TimeSeriesView(origin=p, name=p.removeprefix("/phase1/"))
                               for p in phase1_roots], grid_columns=4, name="Phase I captures (sim_time)"))
    hours_views = []
    for name, rng in ranges.items():
        hours_views.append(rrb.TimeSeriesView(
            origin=f"/hours/phase1/{name}", name=f"{name} against operating hours",
            axis_y=rrb.ScalarAxis(range=rng) if rng is not None else None))
    if has_truth:
        hours_views.append(rrb.TimeSeriesView(origin="/hours/truth", name="injected preload (truth.h5)"))
    if has_backlash:
        hours_views.append(rrb.TimeSeriesView(origin="/hours/backlash", name="backlash change (µm)"))
    if hours_views:
        first = hours_views[:1] if ranges else []
        rest = hours_views[1:] if ranges else hours_views
        tabs.append(rrb.Vertical(*first, rrb.Grid(*rest, grid_columns=3), row_shares=[1, 1] if first else None,
                                 name="operating hours (timeline: hours)"))
    tabs.append(rrb.Vertical(rrb.TextDocumentView(origin="/notes", name="notes"),
                             rrb.TextLogView(origin="/hours/events", name="events (hours)"),
                             row_shares=[3, 1], name="notes"))
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), rrb.TimePanel(timeline="sim_time"))


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
