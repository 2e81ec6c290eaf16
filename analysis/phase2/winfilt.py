"""``winfilt()`` of the paper (section V, Fig. 8): high-pass, mean removal, symmetric Hann window.

Steps, applied to an error motion sampled on a uniform position grid of step ``dx_m``:

1. high-pass: the signal minus its first-order Savitzky–Golay smoothing
   (``scipy.signal.savgol_filter(e, W, 1)``; Savitzky & Golay 1964, the paper's ref. [45]);
2. removal of the mean;
3. multiplication by a symmetric Hann window (``scipy.signal.windows.hann(n, sym=True)``).

Window length. A first-order Savitzky–Golay smoother is exactly a moving average of length W
(derived here; Savitzky & Golay, Anal. Chem. 36, 1964): its transmission at wavelength λ is
sinc(W·dx/λ) (normalised sinc), so the high-pass passes 1 − sinc(W·dx/λ). We read the paper's
"spatial cutoff wavelength of 0.5 mm" as a cutoff *wavelength* λc = 0.5 mm (not 0.5 cycles/mm)
with the ISO 16610 convention of 50 % transmission at λc, which gives W·dx = 0.603·λc
(ISO 16610-21 convention): features shorter than λc pass, longer ones are suppressed. The two
other definitions of the table are available through ``definition``. W is rounded to the nearest
odd number of samples (at least 3): 31 samples for λc = 0.5 mm on a 10 µm grid.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter
from scipy.signal.windows import hann

CUTOFF_WAVELENGTH_M = 0.5e-3
"""The paper's cutoff wavelength (section V), m."""

WINDOW_PER_CUTOFF = {"iso50": 0.603, "lowpass-3db": 0.443, "highpass-3db": 0.755}
"""Moving-average length W·dx per cutoff wavelength λc for each cutoff definition
(derived here): 50 % transmission (ISO 16610-21), low-pass −3 dB, high-pass −3 dB."""


def savgol_window(dx_m: float, cutoff_wavelength_m: float = CUTOFF_WAVELENGTH_M,
                  definition: str = "iso50") -> int:
    """Length W (odd number of samples, ≥ 3) of the first-order Savitzky–Golay smoother whose
    high-pass complement has its cutoff at ``cutoff_wavelength_m`` on a grid of step ``dx_m`` (m).

    W = 0.603·λc/dx for ``definition="iso50"`` (ISO 16610-21 convention), rounded to the nearest odd
    integer."""
    if definition not in WINDOW_PER_CUTOFF:
        raise ValueError(f"definition is {definition!r}; expected one of {sorted(WINDOW_PER_CUTOFF)}")
    if not (dx_m > 0 and cutoff_wavelength_m > 0):
        raise ValueError(f"dx_m = {dx_m!r} and cutoff_wavelength_m = {cutoff_wavelength_m!r}: "
                         "expected both > 0 m")
    w = WINDOW_PER_CUTOFF[definition] * cutoff_wavelength_m / dx_m
    return max(3, 2 * round((w - 1.0) / 2.0) + 1)


def highpass(e: np.ndarray, dx_m: float, cutoff_wavelength_m: float = CUTOFF_WAVELENGTH_M,
             definition: str = "iso50") -> np.ndarray:
    """First-order Savitzky–Golay high-pass along the last axis.

    Args:
        e: (..., n) samples on a uniform grid of step ``dx_m`` (any unit; returned in the same).
        dx_m: grid step, m. cutoff_wavelength_m: λc, m.
    Returns:
        (..., n) e − savgol_filter(e, W, 1) with W from :func:`savgol_window`.
    """
    e = np.asarray(e, dtype=float)
    w = savgol_window(dx_m, cutoff_wavelength_m, definition)
    if e.shape[-1] < w:
        raise ValueError(f"a trace of {e.shape[-1]} samples is shorter than the Savitzky–Golay "
                         f"window of {w} samples (λc = {cutoff_wavelength_m * 1e3:g} mm, "
                         f"dx = {dx_m * 1e6:g} µm)")
    return e - savgol_filter(e, w, 1, axis=-1, mode="interp")


def winfilt(e: np.ndarray, dx_m: float, cutoff_wavelength_m: float = CUTOFF_WAVELENGTH_M,
            definition: str = "iso50") -> np.ndarray:
    """The paper's ``winfilt()``: high-pass (:func:`highpass`), mean removal, symmetric Hann window.

    Args:
        e: (..., n) error motion(s) on a uniform grid of step ``dx_m``, m or rad.
        dx_m: grid step, m. cutoff_wavelength_m: λc, m (0.5 mm in the paper).
    Returns:
        (..., n) filtered and windowed signal in the unit of ``e``.
    """
    h = highpass(e, dx_m, cutoff_wavelength_m, definition)
    h = h - h.mean(axis=-1, keepdims=True)
    return h * hann(h.shape[-1], sym=True)
