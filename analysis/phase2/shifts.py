"""Position shift of an error motion against a reference trace by correlation (paper section V,
Figs. 9–10, Eq. 3).

For two traces already passed through :func:`analysis.phase2.winfilt.winfilt` on grids of the
same step dx:

1. the normalised cross-correlation against position lag τ (``scipy.signal.correlate`` with
   ``correlation_lags``, scipy.signal documentation), c(τ) = Σ a(x)·b(x − τ) / sqrt(Σa²·Σb²), so that
   a peak at τ means trace(x) ≈ reference(x − τ): **a positive shift means the features of the
   trace appear at a larger commanded position than in the reference**;
2. γ = the largest correlation within ±``max_lag_m`` (Eq. 3); that peak is the main one (n = 0);
3. every local maximum of c above ``threshold``·γ (75 % in the paper) is a peak; a least-squares
   quadratic through the samples of its lobe that are positive and at least ``fit_fraction`` of
   the peak value gives its sub-sample position, the *local shift* (Fig. 9b);
4. the peaks are numbered n by their spacing (median distance of neighbours) and a least-squares
   line τ_n = s + n·p through the local shifts gives the overall shift s and the observed peak
   spacing p (the paper's Fig. 9c: lag_n = s + n·p_obs). With fewer than
   ``min_peaks`` peaks (a trace without periodic content has a single peak) s is the main peak's
   local shift and p is NaN.

Units: positions and lags in m; correlations dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.fft import next_fast_len
from scipy.signal import correlate, correlation_lags, find_peaks

THRESHOLD = 0.75
"""Peaks above this fraction of the maximum correlation are fitted (paper section V)."""


@dataclass(frozen=True)
class ShiftResult:
    """Outcome of one correlation (one session, DOF and direction against the reference).

    Attributes:
        shift_m: overall position shift s, m (trace(x) ≈ reference(x − s)).
        gamma: maximum correlation γ within the lag range (Eq. 3), dimensionless.
        spacing_m: observed spacing p of the correlation peaks (slope of the line), m; NaN when
            fewer than ``min_peaks`` peaks were found.
        peak_index: (k,) integer number n of each fitted peak (0 = main peak).
        local_shifts_m: (k,) sub-sample position of each fitted peak, m.
        peak_values: (k,) correlation at each fitted peak.
        comb_residual_m: rms distance of the local shifts from the fitted line, m (NaN without
            a line).
    """

    shift_m: float
    gamma: float
    spacing_m: float
    peak_index: np.ndarray = field(repr=False)
    local_shifts_m: np.ndarray = field(repr=False)
    peak_values: np.ndarray = field(repr=False)
    comb_residual_m: float = float("nan")

    @property
    def n_peaks(self) -> int:
        return int(self.peak_index.size)


def correlate_traces(trace: np.ndarray, reference: np.ndarray, dx_m: float,
                     x0_trace_m: float = 0.0, x0_reference_m: float = 0.0,
                     upsample: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Normalised cross-correlation against position lag.

    Computed through the FFT (the circular correlation of the zero-padded traces, i.e. the linear
    one, as ``scipy.signal.correlate(..., method="fft")``); with ``upsample`` > 1 the spectrum is
    zero-padded so that c(τ) comes on a lag grid ``upsample`` times finer than dx (band-limited
    interpolation of the correlation, exact for band-limited traces). The quadratic peak fits are
    then free of the bias that the coarse sampling of an asymmetric lobe gives (its size for
    rail-like traces at dx = 10 µm, with and without upsampling: docs/validation.md).

    Args:
        trace, reference: (n,) and (m,) signals on uniform grids of the same step ``dx_m`` (m),
            whose first samples are at ``x0_trace_m`` and ``x0_reference_m`` (m).
        upsample: integer refinement of the lag grid (1 = lags k·dx, as ``correlation_lags``).
    Returns:
        lags (upsample·(n + m − 2) + 1,) in m, ascending, and c of the same shape,
        c(τ) = Σ a(x)·b(x − τ) / sqrt(Σa²·Σb²) (1 for identical traces at τ = 0).
    """
    a = np.asarray(trace, dtype=float)
    b = np.asarray(reference, dtype=float)
    norm = np.sqrt(np.sum(a * a) * np.sum(b * b))
    if not np.isfinite(norm) or norm == 0.0:
        raise ValueError("cannot correlate a trace that is zero or not finite after winfilt")
    up = int(upsample)
    if up < 1:
        raise ValueError(f"upsample is {upsample!r}; expected an integer >= 1")
    if up == 1:
        c = correlate(a, b, mode="full", method="fft") / norm
        lags = correlation_lags(a.size, b.size, mode="full") * dx_m
        return lags + (x0_trace_m - x0_reference_m), c
    n_fft = next_fast_len(a.size + b.size - 1, real=True)
    spec = np.fft.rfft(a, n_fft) * np.conj(np.fft.rfft(b, n_fft))
    circ = np.fft.irfft(spec, up * n_fft)
    # the negative lags wrap to the end of the circular correlation: its two ends, in lag order
    neg, pos = (b.size - 1) * up, (a.size - 1) * up + 1
    c = np.concatenate((circ[circ.size - neg:], circ[:pos]))
    c *= up / norm
    return np.arange(-neg, pos) * (dx_m / up) + (x0_trace_m - x0_reference_m), c


def _fit_peak(lags: np.ndarray, c: np.ndarray, i: int, fit_fraction: float) -> tuple[float, float]:
    """Vertex (lag m, value) of a least-squares quadratic through the lobe around sample ``i``:
    the contiguous samples with c > 0 and c ≥ fit_fraction·c[i] (at least i−1..i+1)."""
    level = max(0.0, fit_fraction * c[i])
    lo = i
    while lo > 0 and c[lo - 1] > level and c[lo - 1] <= c[lo] + 1e-15:
        lo -= 1
    hi = i
    while hi < c.size - 1 and c[hi + 1] > level and c[hi + 1] <= c[hi] + 1e-15:
        hi += 1
    lo, hi = min(lo, max(i - 1, 0)), max(hi, min(i + 1, c.size - 1))
    if hi - lo < 2:
        return float(lags[i]), float(c[i])
    x = lags[lo:hi + 1] - lags[i]
    a2, a1, a0 = np.polyfit(x, c[lo:hi + 1], 2)
    if a2 >= 0:
        return float(lags[i]), float(c[i])
    v = -a1 / (2.0 * a2)
    if not (x[0] <= v <= x[-1]):
        return float(lags[i]), float(c[i])
    return float(lags[i] + v), float(a0 - a1 * a1 / (4.0 * a2))


def position_shift(lags: np.ndarray, c: np.ndarray, *, max_lag_m: float = 5e-3,
                   threshold: float = THRESHOLD, fit_fraction: float = 0.5,
                   min_peaks: int = 3) -> ShiftResult:
    """Overall shift, γ and peak spacing from a correlation curve (steps 2–4 of the module doc).

    Args:
        lags: (m,) lags in m, ascending, uniform; c: (m,) correlation.
        max_lag_m: the main peak is searched within |τ| ≤ max_lag_m (must cover the change of
            the origin between sessions plus the backlash: ±2 mm origins give up to 4 mm).
        threshold: fraction of γ above which peaks are fitted (0.75). fit_fraction: part of each
            peak's lobe used by the quadratic fit (samples ≥ fit_fraction·peak; 0 = the whole
            positive lobe as in the paper's Fig. 9b).
        min_peaks: fewest peaks for the line fit (otherwise the spacing is NaN).
    Returns:
        :class:`ShiftResult`.
    """
    lags = np.asarray(lags, dtype=float)
    c = np.asarray(c, dtype=float)
    inside = np.flatnonzero(np.abs(lags) <= max_lag_m)
    if inside.size == 0:
        raise ValueError(f"no lag within ±{max_lag_m * 1e3:g} mm: the traces do not overlap there")
    i_main = int(inside[np.argmax(c[inside])])
    gamma = float(c[i_main])
    main_lag, main_val = _fit_peak(lags, c, i_main, fit_fraction)
    if gamma <= 0:
        return ShiftResult(main_lag, gamma, float("nan"), np.array([0]), np.array([main_lag]),
                           np.array([gamma]))
    peaks, _ = find_peaks(c, height=threshold * gamma)
    peaks = peaks[peaks != i_main]
    fits = [(main_lag, main_val)] + [_fit_peak(lags, c, int(p), fit_fraction) for p in peaks]
    pos = np.array([f[0] for f in fits])
    val = np.array([f[1] for f in fits])
    if pos.size < min_peaks:
        return ShiftResult(main_lag, gamma, float("nan"), np.array([0]), np.array([main_lag]),
                           np.array([main_val]))
    order = np.argsort(pos)
    spacing = float(np.median(np.diff(pos[order])))
    n = np.round((pos - main_lag) / spacing).astype(int)
    # Keep one peak per number (the highest) and only peaks close to their place on the comb.
    keep = np.abs(pos - main_lag - n * spacing) <= 0.25 * spacing
    best: dict[int, int] = {}
    for k in np.flatnonzero(keep):
        if n[k] not in best or val[k] > val[best[n[k]]]:
            best[n[k]] = k
    sel = np.array(sorted(best.values(), key=lambda k: n[k]))
    if sel.size < min_peaks or 0 not in best:
        return ShiftResult(main_lag, gamma, float("nan"), np.array([0]), np.array([main_lag]),
                           np.array([main_val]))
    slope, intercept = np.polyfit(n[sel].astype(float), pos[sel], 1)
    resid = pos[sel] - (intercept + slope * n[sel])
    return ShiftResult(float(intercept), gamma, float(slope), n[sel], pos[sel], val[sel],
                       float(np.sqrt(np.mean(resid ** 2))))


def shift_between(trace: np.ndarray, reference: np.ndarray, dx_m: float,
                  x0_trace_m: float = 0.0, x0_reference_m: float = 0.0, upsample: int = 8,
                  **kw) -> ShiftResult:
    """:func:`correlate_traces` then :func:`position_shift` (other keywords go to the latter).

    Both inputs must already be winfiltered (:func:`analysis.phase2.winfilt.winfilt`)."""
    lags, c = correlate_traces(trace, reference, dx_m, x0_trace_m, x0_reference_m, upsample)
    return position_shift(lags, c, **kw)
