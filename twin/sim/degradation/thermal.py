"""The screw's thermal transient after a (re)start: the first-order temperature rise over the hours
since the last resume (:func:`temperature_rise_K`, :func:`hours_since_resume`).

Sources ([Archard], [Hertz], [Catalogue], [Paper], [XJTU]) and units: :mod:`twin.sim.degradation`.
"""

from __future__ import annotations

import numpy as np

from twin.sim.degradation.wear import _hours_array


def temperature_rise_K(hours_since_resume, steady_rise_K: float, time_constant_hours: float) -> np.ndarray:
    """Warm-up after a cold restart, ΔT(t) = ΔT_ss · (1 − exp(−t/τ)) [K].

    First-order (lumped-capacitance) heating of the axis by its friction losses: C dT/dt =
    P − (T − T_amb)/R gives this exponential approach to the steady rise ΔT_ss = P R with
    τ = R C (Newton's law of cooling; e.g. Incropera, *Fundamentals of Heat and Mass Transfer*,
    lumped capacitance). After a pause the machine restarts cold [Paper, section III.C]; steady
    state is reached after a few τ (95 % at 3τ).

    Args:
        hours_since_resume: operating time since the restart t, any shape [h], >= 0.
        steady_rise_K: steady-state rise ΔT_ss [K].
        time_constant_hours: τ [h], > 0.

    Returns:
        Temperature rise, shape of ``hours_since_resume`` [K].
    """
    t = _hours_array(hours_since_resume, name="hours_since_resume")
    if not time_constant_hours > 0.0:
        raise ValueError(f"time_constant_hours = {time_constant_hours!r} is out of range; allowed: > 0")
    return steady_rise_K * -np.expm1(-t / time_constant_hours)


def hours_since_resume(hours, resume_hours) -> np.ndarray:
    """Operating hours since the most recent resume at or before ``hours``, or since start [h].

    Operating hours stop during a pause, so a pause and its resume share one operating-hour value
    (Table II of [Paper]: 855.5 h and 4033 h). At a resume the result is 0.

    Args:
        hours: operating hours, any shape [h], >= 0.
        resume_hours: operating hours of the resumes, any order [h].

    Returns:
        Hours since the last (re)start, shape of ``hours`` [h].
    """
    h = _hours_array(hours)
    starts = np.unique(np.concatenate([[0.0], np.asarray(list(resume_hours), dtype=float)]))
    idx = np.searchsorted(starts, h, side="right") - 1
    return h - starts[idx]
