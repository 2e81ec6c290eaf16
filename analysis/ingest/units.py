"""Conversion of a laboratory's units to the dataset's SI units, at the edge of the import.

Each target channel of the format has a quantity (acceleration, motor speed, torque, angular
rate, position). :func:`to_si` multiplies the samples by the factor of the given unit; a few
units need a figure of the axis or sensor (``mV`` and ``V`` need the accelerometer's
sensitivity in mV/g, carriage speed ``mm/s`` needs the screw's lead).
"""

from __future__ import annotations

import math

import numpy as np

G = 9.80665  # m/s² per g (standard gravity)

#: The quantity of each format channel.
QUANTITY = {"speed": "motor speed", "torque": "torque", "acc1": "acceleration", "acc2": "acceleration",
            "imu_acc": "acceleration", "imu_gyro": "angular rate", "position_cmd": "position"}

#: unit -> factor to SI, per quantity; None marks units that need a figure (see :func:`factor`).
UNITS: dict[str, dict[str, float | None]] = {
    "acceleration": {"m/s^2": 1.0, "m/s2": 1.0, "g": G, "mg": G * 1e-3, "mV": None, "V": None},
    "motor speed": {"rad/s": 1.0, "rpm": 2 * math.pi / 60, "rev/s": 2 * math.pi, "deg/s": math.pi / 180,
                    "mm/s": None},
    "torque": {"N*m": 1.0, "Nm": 1.0, "mN*m": 1e-3, "mNm": 1e-3, "N*cm": 1e-2},
    "angular rate": {"rad/s": 1.0, "mrad/s": 1e-3, "deg/s": math.pi / 180, "rpm": 2 * math.pi / 60},
    "position": {"m": 1.0, "mm": 1e-3, "um": 1e-6, "in": 0.0254},
}


def factor(channel: str, unit: str, *, sensitivity_mV_per_g: float | None = None,
           lead_mm: float | None = None) -> float:
    """The factor that turns ``unit`` into the SI unit of ``channel``; ValueError naming the
    allowed units, or the figure a unit needs when it is not given."""
    q = QUANTITY[channel]
    units = UNITS[q]
    if unit not in units:
        raise ValueError(f"unit {unit!r} is not a unit of {q}; expected one of {', '.join(units)}")
    f = units[unit]
    if f is not None:
        return f
    if unit in ("mV", "V"):
        if sensitivity_mV_per_g is None:
            raise ValueError(f"unit {unit!r} needs the accelerometer's sensitivity: give "
                             "sensitivity_mV_per_g on the channel or in the axis's sensors")
        return (1000.0 if unit == "V" else 1.0) * G / sensitivity_mV_per_g
    if lead_mm is None:  # carriage speed mm/s -> motor speed rad/s
        raise ValueError("unit 'mm/s' of the motor speed needs the screw's lead: give [axis] lead_mm")
    return 2 * math.pi / lead_mm


def to_si(x: np.ndarray, scale: float, offset: float, f: float) -> np.ndarray:
    """``(x * scale + offset) * f`` as float64."""
    return (np.asarray(x, dtype=np.float64) * scale + offset) * f
