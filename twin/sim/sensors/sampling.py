"""Reading a simulated signal at an instrument's own instants, and quantising it as its output
stage or DAQ does: :func:`decimate_to` (an exact pick or a not-a-knot cubic spline; no
anti-alias filter), :func:`quantise` and the DAQ's ADC model.

Sample ``i`` of a simulated signal is at ``t0 + i / fs_in``; output sample ``k`` at
``t0 + k / fs_out``. SI units (s, Hz); values in any unit.
"""

from __future__ import annotations

import math

import numpy as np

from analysis.resample import not_a_knot_cubic_rows


def quantise(values: np.ndarray, step: float, limit: float = math.inf) -> np.ndarray:
    """Round to the nearest multiple of ``step`` and clip to ``[-limit, limit]``.

    Args:
        values: array of any shape, in any unit.
        step: quantisation step in that unit (0 = no rounding).
        limit: clipping level in that unit (inf = none).

    Returns:
        Array of the same shape.
    """
    out = np.asarray(values, dtype=float)
    if step > 0:
        out = np.round(out / step) * step
    if np.isfinite(limit):
        out = np.clip(out, -limit, limit)
    return out


def _daq_quantise(
    values: np.ndarray, sensitivity: float, daq_range: float, bits: int
) -> np.ndarray:
    """Voltage = sensitivity·value, quantised by a ``bits``-bit ADC over ±daq_range, converted back.

    Codes run from ``-2**(bits-1)`` to ``2**(bits-1) - 1`` with LSB ``2·daq_range / 2**bits``, V;
    readings outside the range clip to the end codes.
    """
    if bits == 0:
        return np.asarray(values, dtype=float)
    lsb = 2.0 * daq_range / 2.0**bits
    half = 2.0 ** (bits - 1)
    # In one buffer, operation by operation as codes = clip(round(v·S/lsb)), codes·lsb/S.
    out = np.multiply(values, sensitivity, dtype=float)
    np.divide(out, lsb, out=out)
    np.round(out, out=out)
    np.clip(out, -half, half - 1, out=out)
    np.multiply(out, lsb, out=out)
    return np.divide(out, sensitivity, out=out)


def _output_count(n_in: int, fs_in: float, fs_out: float) -> int:
    """Number of instants ``k / fs_out`` inside ``[0, (n_in - 1) / fs_in]``."""
    span = (n_in - 1) / fs_in
    return int(math.floor(span * fs_out * (1.0 + 1e-12))) + 1


def decimate_to(values: np.ndarray, fs_in: float, fs_out: float, t0: float = 0.0,
                kind: str = "cubic") -> tuple[np.ndarray, np.ndarray]:
    """Sample a uniformly sampled signal at the instants ``t0 + k / fs_out``.

    This is a pure resampler: it applies **no** anti-alias filter. Callers (the instrument models
    below) pass a signal that their own low-pass has already band-limited, so this reads the value
    of that filtered signal at the instrument's sampling instants, which need not fall on the
    simulation grid (1613 Hz from 10 kHz). Any aliasing that results is the instrument's own.

    Accuracy: the cubic spline (not-a-knot) reproduces a sinusoid of frequency f with relative error
    about ``(5/384)·(2π f / fs_in)**4``: 2e-5 at 300 Hz from 10 kHz, 3e-4 at 300 Hz from 5 kHz.
    Linear interpolation errs by up to ``(π f / fs_in)**2 / 2`` (0.4 % at 300 Hz from 10 kHz); it is
    meant for smooth, slowly varying signals (motor angle, torque at the controller rate). When
    ``fs_out`` equals ``fs_in`` or divides it, samples are picked from the grid, exactly.

    Args:
        values: (n,) or (n, c) signal at ``fs_in``, sample i at ``t0 + i / fs_in``.
        fs_in: input sampling rate, Hz.
        fs_out: output sampling rate, Hz (may be above fs_in: then it interpolates).
        t0: time of the first input sample, s.
        kind: "cubic" or "linear".

    Returns:
        t_out: (m,) sample instants, s, all within the input's time span.
        out: (m,) or (m, c) signal at those instants.
    """
    values = np.asarray(values, dtype=float)
    if values.ndim not in (1, 2) or values.shape[0] < 2:
        raise ValueError(f"signal must have shape (n,) or (n, c) with n >= 2, got {values.shape}")
    if not (fs_in > 0 and fs_out > 0 and np.isfinite(fs_in) and np.isfinite(fs_out)):
        raise ValueError(f"sampling rates must be positive, got fs_in={fs_in!r}, fs_out={fs_out!r}")
    if kind not in ("cubic", "linear"):
        raise ValueError(f"kind must be 'cubic' or 'linear', got {kind!r}")
    n_in = values.shape[0]
    t_out, step, position = _sampling_plan(n_in, fs_in, fs_out, t0)
    if step:
        return t_out, values[: (t_out.size - 1) * step + 1 : step].copy()
    if kind == "linear":
        grid = np.arange(n_in, dtype=float)
        if values.ndim == 1:
            return t_out, np.interp(position, grid, values)
        return t_out, np.column_stack([np.interp(position, grid, col) for col in values.T])
    if values.ndim == 1:
        return t_out, not_a_knot_cubic_rows(values[None, :], position)[0]
    return t_out, not_a_knot_cubic_rows(values.T, position).T


def _sampling_plan(n_in: int, fs_in: float, fs_out: float, t0: float
                   ) -> tuple[np.ndarray, int, np.ndarray | None]:
    """Output instants (m,) s of :func:`decimate_to`, and either the grid step of an exact pick
    (``fs_out`` divides ``fs_in``; position None) or 0 and the fractional input indices (m,)."""
    m = _output_count(n_in, fs_in, fs_out)
    t_out = t0 + np.arange(m) / fs_out
    ratio = fs_in / fs_out
    step = round(ratio)
    if step >= 1 and abs(ratio - step) <= 1e-12 * ratio:
        return t_out, step, None
    position = np.arange(m) * ratio  # fractional index into the input grid
    return t_out, 0, np.minimum(position, n_in - 1)


def _sample_rows(rows: np.ndarray, fs_sim: float, fs_out: float, t0: float) -> np.ndarray:
    """Rows (c, n) of a signal at ``fs_sim`` read at the instants of :func:`decimate_to`:
    (c, m), by an exact pick or the cubic spline (:func:`analysis.resample.not_a_knot_cubic_rows`)."""
    t_out, step, position = _sampling_plan(rows.shape[1], fs_sim, fs_out, t0)
    if step:
        return rows[:, : (t_out.size - 1) * step + 1: step]
    return not_a_knot_cubic_rows(rows, position)
