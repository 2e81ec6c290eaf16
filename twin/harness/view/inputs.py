"""What the view reads: ``twin detect`` and ``twin backlash`` outputs, the axis of a recording."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from analysis.base.files import read_json
from twin.harness.view.base import ViewError
from twin.sim.axis import Axis
from twin.sim.scenario import Scenario, ScenarioError, from_dict, to_axis

# ---------------------------------------------------------------------------------------------
# Inputs



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
    doc = read_json(path, error=ViewError, what="the Phase I detection results of `twin detect`")
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
    doc = read_json(path, error=ViewError, what="the Phase II backlash results of `twin backlash`")
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
    """The axis to draw from the nominal description of ``measurements.h5`` (the axis contract,
    :class:`analysis.dataset.axis.AxisDescription`): the few dimensions it names, the defaults of
    :class:`Scenario` for the rest."""
    from analysis.dataset.axis import AxisDescription

    axis = AxisDescription.from_dict(desc, label)
    given = {key: float(getattr(axis, key)) for key in _AXIS_KEYS if getattr(axis, key) is not None}
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
