"""``twin scenario init``: a scenario that reproduces a recording's layout and routine.

The layout (Phase I samples, captures, rates and durations, Phase II sessions, runs and rates,
the hours) and the routines are measured from the recording
(:func:`analysis.ingest.routine.measure_recording`), the axis values come from its axis
contract (``/@axis``), and every other value is the twin's default. Each line of the written
TOML says which of the three it is, so the owner knows what to check. The text is validated by
:func:`twin.sim.scenario.load` before it is written.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from analysis.base.files import write_text
from analysis.ingest.routine import measure_recording
from twin.sim.scenario import (
    AxisConfig,
    CampaignConfig,
    DegradationConfig,
    Phase1Config,
    Phase2Config,
    ScenarioError,
    SensorsConfig,
    load,
)

MEASURED, AXIS, DEFAULT, FITTED = "measured", "axis description", "twin default", "fitted"


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(float(f"{v:.6g}"))
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    if isinstance(v, str):
        return json.dumps(v)
    return str(v)


class _Table:
    """One TOML table; ``section`` (a scenario section's model) gives the meaning of a key whose
    value is a twin default, so the owner knows what to check."""

    def __init__(self, name: str, section: type[BaseModel] | None = None,
                 calibrated: dict[str, tuple[Any, str, str]] | None = None, defaults: dict[str, str] | None = None):
        self.name, self.section, self.rows = name, section, []
        self.calibrated, self.defaults = calibrated or {}, defaults or {}

    def add(self, key: str, value: Any, source: str, note: str = "") -> None:
        full = f"{self.name}.{key}"
        if full in self.calibrated:  # twin calibrate: measured or fitted, with its note
            value, source, note = self.calibrated[full]
        elif full in self.defaults and source == DEFAULT:
            note = "the recording cannot inform it: " + self.defaults[full]
        elif full in self.defaults:  # e.g. a data sheet's floor the calibration did not replace, and why
            note = (f"{note}; " if note else "") + "kept: " + self.defaults[full]
        if not note and source == DEFAULT and self.section is not None and key in self.section.model_fields:
            note = self.section.model_fields[key].description or ""
        self.rows.append((key, value, source + (f": {note}" if note else "")))

    def text(self) -> str:
        """The table as TOML; a key whose value is None (unset: TOML has no null) is written as a
        comment, so that the author sees it and the twin's own default applies."""
        lines = [f"[{self.name}]"] if self.name else []
        shown = [(f"{k} = {_fmt(v)}" if v is not None else f"# {k} = (unset)", c) for k, v, c in self.rows]
        width = max((len(kv) for kv, _ in shown), default=0)
        lines += [f"{kv:<{width}}  # {c}" for kv, c in shown]
        return "\n".join(lines)


def _calibration_table(record: dict) -> str:
    """The ``[calibration]`` table: which values ``twin calibrate`` measured or fitted (with
    their 90 % intervals) and which it left at the twin's default, from what recording."""
    lines = ["[calibration]", f"version = {int(record['version'])}", f"recording = {json.dumps(record['recording'])}"]
    for v in record["values"]:
        iv = f", low = {_fmt(v['low'])}, high = {_fmt(v['high'])}" if v["low"] is not None else ""
        src = json.dumps(v["source"])
        lines.append(f"{json.dumps(v['key'])} = {{ value = {_fmt(v['value'])}, source = {src}{iv} }}")
    lines.append("defaults = [" + ", ".join(json.dumps(d["key"]) for d in record["defaults"]) + "]")
    misfit = record.get("misfit")
    if misfit:  # layer (c) did not match the recording (twin diagnose says so)
        named = ", ".join(f"{{ statistic = {json.dumps(m['statistic'])}, residual_se = {_fmt(m['residual_se'])} }}"
                          for m in misfit["statistics"])
        lines.append(f"misfit = {{ chi2 = {_fmt(misfit['chi2'])}, dof = {int(misfit['dof'])}, "
                     f"critical = {_fmt(misfit['critical'])}, p = {_fmt(misfit['p'])}, statistics = [{named}] }}")
    cov = record.get("covariance")
    if cov:  # the calibrated values' joint covariance in log space (twin diagnose draws from it)
        rows = ", ".join("[" + ", ".join(f"{x:.6g}" for x in row) + "]" for row in cov["log"])
        lines.append(f"covariance = {{ keys = {json.dumps(cov['keys'])}, log = [{rows}] }}")
    return "\n".join(lines)


#: Sensor keys of the scenario an owner's ``/@axis`` gives (the instrument's data sheet): key ->
#: its dotted ``/@axis`` path.
DATASHEET = {"imu_acc_bandwidth_hz": "sensors.imu_accelerometer.bandwidth_hz",
             "imu_acc_noise_ug_per_rthz": "sensors.imu_accelerometer.noise_ug_per_rthz",
             "imu_gyro_bandwidth_hz": "sensors.imu_gyroscope.bandwidth_hz",
             "imu_gyro_noise_urad_s_per_rthz": "sensors.imu_gyroscope.noise_urad_s_per_rthz"}


def scenario_text(recording: str | os.PathLike, name: str | None = None, *,
                  calibrated: dict[str, tuple[Any, str, str]] | None = None,
                  defaults: dict[str, str] | None = None,
                  calibration: dict | None = None) -> tuple[str, list[str]]:
    """The scenario TOML for ``recording`` and the notes on what could not be measured.
    ``calibrated`` ({"section.key": (value, source, note)}) overrides what is measured or
    defaulted here (``twin calibrate``'s layers b and c), ``defaults`` ({"section.key": why})
    says why a default is kept, ``calibration`` (the record of ``twin calibrate``) is written
    as the ``[calibration]`` table."""
    cal = {"calibrated": calibrated, "defaults": defaults}
    meas = measure_recording(recording)
    axis = meas["axis"]
    notes: list[str] = []
    p1, p2 = meas.get("phase1"), meas.get("phase2")
    title = name or Path(meas["file"]).resolve().parent.name
    head = _Table("")
    head.add("name", title, MEASURED, "the recording's directory")
    head.add("description", f"the layout and routine of {meas['file']}", MEASURED)
    head.add("seed", 0, DEFAULT, "the seed of the twin's random draws")

    ax = _Table("axis", AxisConfig, **cal)
    d_axis = AxisConfig()
    for key in ("travel_mm", "lead_mm", "carriage_mass_kg", "truck_spacing_mm", "rail_spacing_mm"):
        v = getattr(axis, key, None)
        if v is not None:
            ax.add(key, float(v), AXIS)
        else:
            ax.add(key, getattr(d_axis, key), DEFAULT, "not in /@axis")
            if key in ("travel_mm", "lead_mm"):
                notes.append(f"/@axis.{key} is missing: the scenario uses the twin's {getattr(d_axis, key):g} mm")
    travel = float(axis.travel_mm or d_axis.travel_mm)
    if d_axis.shaft_length_mm < travel + 50:
        ax.add("shaft_length_mm", travel + 80.0, DEFAULT, "the travel plus the nut and bearings")
    for key, value in d_axis.model_dump().items():
        if key not in {r[0] for r in ax.rows}:
            ax.add(key, value, DEFAULT)

    sens = _Table("sensors", SensorsConfig, **cal)
    d_sens = SensorsConfig()
    if p2:
        for ch in ("imu_acc", "imu_gyro", "position_cmd"):
            if ch in p2["fs_hz"]:
                sens.add(f"{ch}_fs_hz", p2["fs_hz"][ch], MEASURED)
    for key, path in DATASHEET.items():
        v = axis.get(path)
        sens.add(key, float(v) if v is not None else getattr(d_sens, key), AXIS if v is not None else DEFAULT)
    for key, value in d_sens.model_dump().items():
        if key not in {r[0] for r in sens.rows}:
            sens.add(key, value, DEFAULT)

    camp = _Table("campaign", CampaignConfig)
    ph1 = _Table("phase1", Phase1Config, **cal)
    d1 = Phase1Config()
    last_hours = 0.0
    if p1:
        r1 = p1.get("routine", {})
        cps = max(p1["captures_per_sample"])
        if len(p1["captures_per_sample"]) > 1:
            notes.append(f"Phase I samples hold {p1['captures_per_sample']} captures; the scenario gives each {cps}")
        ph1.add("fs_hz", p1["fs_hz"][0], MEASURED)
        ph1.add("capture_s", p1["capture_s"], MEASURED)
        ph1.add("captures_per_sample", cps, MEASURED)
        step_min = p1["capture_interval_minutes"] or d1.capture_interval_minutes
        ph1.add("capture_interval_minutes", step_min, MEASURED if p1["capture_interval_minutes"] else DEFAULT)
        interval = p1["sample_interval_hours"] or d1.sample_interval_hours
        ph1.add("sample_interval_hours", interval, MEASURED if p1["sample_interval_hours"] else DEFAULT)
        if "speeds_mm_s" in r1:
            ph1.add("speed_mm_s", r1["speeds_mm_s"][-1], MEASURED, "from the motor speed and the lead")
        if "accel_mm_s2" in r1:
            ph1.add("accel_mm_s2", r1["accel_mm_s2"], MEASURED, "from the motor speed and the lead")
        pr = axis.phase1_routine
        stroke = r1.get("stroke_mm")
        if pr is not None and pr.start_mm is not None and pr.end_mm is not None:
            ph1.add("start_mm", pr.start_mm, AXIS)
            ph1.add("end_mm", pr.end_mm, AXIS)
        elif stroke is not None:
            if stroke >= travel:
                raise ScenarioError(
                    f"{meas['file']}: the Phase I stroke measured from the motor speed through /@axis.lead_mm "
                    f"= {axis.lead_mm:g} mm is {stroke:.4g} mm, not within the travel /@axis.travel_mm = "
                    f"{travel:g} mm; expected a stroke shorter than the travel (is the lead right?)")
            start = round((travel - stroke) / 2, 3)
            ph1.add("start_mm", start, MEASURED, "stroke measured; its place assumed centred in the travel")
            ph1.add("end_mm", round(start + stroke, 3), MEASURED, "stroke measured")
        elif d1.end_mm > travel:
            ph1.add("start_mm", round(0.25 * travel, 3), DEFAULT, "a half-travel stroke, centred")
            ph1.add("end_mm", round(0.75 * travel, 3), DEFAULT, "a half-travel stroke, centred")
        if "dwell_s" in r1:
            ph1.add("dwell_s", r1["dwell_s"], MEASURED)
        n = p1["samples"]
        first = p1["first_hours"]
        total = first + (n - 1) * interval + (cps - 1) * step_min / 60.0 + 0.5 * min(interval, 1.0)
        camp.add("warmup_hours", first, MEASURED, "the first Phase I sample")
        last_hours = total
        camp.add("phase1", True, MEASURED)
    else:
        camp.add("phase1", False, MEASURED, "no Phase I capture")
    for key, value in d1.model_dump().items():
        if key not in {r[0] for r in ph1.rows}:
            ph1.add(key, value, DEFAULT, "not measurable from the recording" if key == "dwell_s" else "")

    ph2 = _Table("phase2", Phase2Config, **cal)
    d2 = Phase2Config()
    if p2:
        r2 = p2.get("routine", {})
        pr = axis.phase2_routine
        for key in ("speeds_mm_s", "accel_mm_s2", "start_mm", "end_mm", "dwell_s"):
            if key in r2:
                ph2.add(key, r2[key], MEASURED, "from position_cmd")
            elif pr is not None and getattr(pr, key) is not None:
                ph2.add(key, getattr(pr, key), AXIS)
        if len(p2["runs_per_session"]) > 1:
            notes.append(f"Phase II sessions hold {p2['runs_per_session']} runs; the scenario gives each "
                         f"{max(p2['runs_per_session'])}")
        ph2.add("runs_per_session", max(p2["runs_per_session"]), MEASURED)
        ph2.add("session_hours", p2["session_hours"], MEASURED)
        camp.add("phase2", True, MEASURED)
        last_hours = max(last_hours, max(p2["session_hours"]))
    else:
        camp.add("phase2", False, MEASURED, "no Phase II session")
    for key, value in d2.model_dump().items():
        if key not in {r[0] for r in ph2.rows}:
            ph2.add(key, value, DEFAULT)
    camp.add("total_hours", float(last_hours or 1.0), MEASURED, "covers every sample and session")
    camp.add("pauses", [], DEFAULT, "none known")

    deg = _Table("degradation", DegradationConfig)
    hours = sorted({0.0, float(last_hours or 1.0)})
    deg.add("law", "table", DEFAULT, "a nominal machine: no preload loss, no backlash growth")
    deg.add("table_hours", hours, DEFAULT)
    deg.add("table_preload_fraction", [1.0] * len(hours), DEFAULT)
    deg.add("table_backlash_um", [0.0] * len(hours), DEFAULT)

    verb = "twin calibrate" if calibration else "twin scenario init"
    header = ("# Scenario of the recording " + meas["file"] + f", written by `{verb}`.\n"
              f"# Each value says where it comes from: '{MEASURED}' (the recording's signals and layout),\n"
              f"# '{FITTED}' (the twin fitted to the recording, with its 90 % interval: `twin calibrate`),\n"
              f"# '{AXIS}' (its /@axis), or '{DEFAULT}' (not in the recording: check it).\n")
    if not calibration:
        header += ("# The drive's physical parameters and the sensor chain are the twin's defaults here: "
                   "`twin calibrate` fits them.\n")
    tables = [t.text() for t in (head, ax, sens, ph1, ph2, deg, camp)]
    if calibration:
        tables.append(_calibration_table(calibration))
    body = "\n\n".join(tables)
    notes_text = "".join(f"# note: {n}\n" for n in notes)
    return header + notes_text + "\n" + body + "\n", notes


def write_scenario(recording: str | os.PathLike, out: str | os.PathLike, name: str | None = None) -> list[str]:
    """Write the scenario of ``recording`` to ``out`` after checking that it loads; the notes."""
    text, notes = scenario_text(recording, name)
    with tempfile.TemporaryDirectory() as tmp:
        probe = Path(tmp) / "scenario.toml"
        probe.write_text(text, encoding="utf-8")
        load(probe)  # ScenarioError if the measured values are outside the twin's ranges
    write_text(out, text)
    return notes


__all__ = ["scenario_text", "write_scenario"]
