"""Layer (b): the sensor chain measured from the recording's rests, then corrected for what the
twin's own instruments give at the values it was set to.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from analysis.calibration.sensor_chain import Measured, measure_instruments
from analysis.dataset import open_measurements
from twin.harness.calibration.values import (
    FIT_CAPTURES,
    FLOOR_SPAN,
    FLOOR_SPAN_DATASHEET,
    FLOORS,
    SENSOR_KEYS,
    T90,
    Z90,
    Value,
)
from twin.sim.scenario import Scenario

# ---------------------------------------------------------------------------------------------
# Layer (b): the sensor chain


def sensor_values(recording: Path, base: Scenario) -> tuple[dict[str, Measured], list[str]]:
    """Layer (b), as measured: the instruments from the rests (:func:`measure_instruments`) by
    scenario key, and notes on what is not a scenario key (the torque's resolution, the IMU's
    gravity)."""
    with open_measurements(recording / "measurements.h5") as m:
        caps = m.phase1_captures()[:2 * FIT_CAPTURES]
        sess = m.phase2_sessions()
        runs = [(s, r) for s in sess[:2] for r in m.phase2_runs(s)[:4]]
        meas = measure_instruments(m, caps, runs, base.sensors.imu_acc_bandwidth_hz,
                                   base.sensors.imu_gyro_bandwidth_hz)
    notes = []
    if "torque_resolution_Nm" in meas:
        notes.append(f"the torque signal's resolution is {meas['torque_resolution_Nm'].value:.4g} N·m (the "
                     "twin's is 0.001 N·m, not a scenario key)")
    if "imu_gravity_scale" in meas:
        g = meas["imu_gravity_scale"].value
        notes.append(f"the IMU reads gravity as {g:.5f} × 9.80665 m/s² at rest"
                     + (" (a sensitivity error or local gravity: check the IMU's unit and sensitivity)"
                        if abs(g - 1) > 0.003 else ""))
    return {k: v for k, v in meas.items() if k in SENSOR_KEYS}, notes


def datasheet_keys(recording: Path) -> set[str]:
    """The sensor keys (``sensors.…``) whose value the recording's ``/@axis`` gives (the
    instrument's data sheet: :data:`twin.sim.scenario_init.DATASHEET`)."""
    from analysis.dataset.axis import axis_of
    from twin.sim.scenario_init import DATASHEET

    with open_measurements(recording / "measurements.h5") as m:
        axis = axis_of(m)
        return {f"sensors.{k}" for k, path in DATASHEET.items() if axis.get(path) is not None}


def floors_beyond_span(measured: dict[str, Measured], base: Scenario,
                       datasheet: set[str] = frozenset()) -> dict[str, str]:
    """{key: why it keeps the scenario's value} for each noise floor of ``measured`` (layer b,
    scenario keys) more than :data:`FLOOR_SPAN` times the scenario ``base``'s
    (:data:`FLOOR_SPAN_DATASHEET` for the keys in ``datasheet``, whose scenario value is the
    instrument's data sheet), and the keys measured on the same spectra (:data:`FLOORS`): a
    noisier channel than its instrument, left for `twin diagnose` to name rather than written
    into the calibrated scenario."""
    from twin.sim.config import get_dotted

    data = base.model_dump(mode="json")
    out: dict[str, str] = {}
    for key, partners in FLOORS.items():
        v = measured.get(key)
        ref = float(get_dotted(data, key))
        sheet = key in datasheet
        span = FLOOR_SPAN_DATASHEET if sheet else FLOOR_SPAN
        if v is None or not ref > 0 or not v.value > span * ref:
            continue
        name = key.split(".")[-1]
        what = "the instrument's data sheet (/@axis)" if sheet else "the twin's default instrument"
        why = (f"the recording's floor measures {v.value:.4g} ({v.unit}), {v.value / ref:.3g} times the "
               f"scenario's {ref:g}, {what} (more than {span:g}): a channel noisier than its instrument "
               "(cable, connector, amplifier?); kept at the scenario's so that twin diagnose names the excess. "
               f"If the instrument is this noisy, set {name} to its data sheet's floor and calibrate again")
        out[key] = why
        for p in partners:
            if p in measured:
                out[p] = f"measured on the same rests as {name}, whose floor is not taken in: {why}"
    return out


def corrected_sensor_values(measured: dict[str, Measured], set_to: dict[str, float],
                            twin: dict[str, list[float]]) -> list[Value]:
    """Layer (b)'s values, each measurement corrected by the twin's own: the twin set to
    ``set_to[key]`` and measured the same way at each seed of the spread (``twin[key]``)
    reads mean(twin) where the recording reads ``measured``; the value is
    set · measured / mean(twin) (a step of indirect inference: the statistic is nearly
    proportional to the value; what the rests hold beside the noise and the estimator's own bias
    cancel). :func:`calibrate` takes two steps, the second from the first's values. The 90 %
    interval combines the recording's own error and the twin's scatter over the seeds (Student's
    t with the seeds' degrees of freedom). Without the twin's measurement the raw value and its
    own error."""
    out = []
    for key, v in measured.items():
        tw = np.array(twin.get(key, []), dtype=float)
        tw = tw[np.isfinite(tw)]
        if tw.size >= 2 and set_to.get(key):
            ratio = tw / set_to[key]
            r = float(np.mean(ratio))
            rel = math.sqrt(v.rel_se ** 2 + (float(np.std(ratio, ddof=1)) / r) ** 2 * (1 + 1 / tw.size))
            value = set_to[key] * v.value / float(np.mean(tw))
            note = f"{v.note}; corrected by the twin's own measurement (× {value / v.value:.4f})"
            w = T90 * rel
        else:
            value, note, w = v.value, v.note, Z90 * v.rel_se
        ok = np.isfinite(w)
        out.append(Value(key, float(f"{value:.6g}"), "measured", float(value * math.exp(-w)) if ok else None,
                         float(value * math.exp(w)) if ok else None, note))
    return out


