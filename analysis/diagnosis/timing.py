"""The timing of one channel against another: how late a recorded signal is against a reference
that moves with it, from the phase of their cross-spectrum.

A clock offset between the channels of an acquisition (the nut accelerometers recorded on another
card than the controller's speed and torque) shifts every sample of one channel by the same time.
The band powers and the RMS per operating phase of :mod:`analysis.diagnosis.signature` barely see
it (a few samples of a burst move across the edge of an operating phase), while the shift of the
axial acceleration against the motor speed's derivative, which the same motion makes in both, is
measured directly: below the drive's resonances the carriage follows the screw rigidly, so the
phase of their cross-spectrum falls by 2π·f·τ for a delay τ. τ is the slope of that phase over
a low band, weighted by the coherence (the weights γ²/(1 − γ²) of a phase's variance), so the
frequencies the motion fills count and the empty ones do not (time delay from the cross-spectrum's
phase and its coherence weighting: Carter, "Coherence and time delay estimation", Proc. IEEE
75(2), 1987; Bendat & Piersol, "Random Data", 4th ed., Wiley 2010, ch. 9).
"""

from __future__ import annotations

import numpy as np
from scipy import signal

#: The band whose cross-spectrum phase gives the delay, Hz: filled by the moves' ramps, below the
#: velocity loop's and the drive's modes.
TIMING_BAND_HZ = (2.0, 40.0)
#: Welch segment of the cross-spectrum, s (at most half the signal): bins of 2 Hz.
TIMING_SEGMENT_S = 0.5
#: Least mean coherence over the band for a delay to be read (below it the two are not one motion).
TIMING_MIN_COHERENCE = 0.5
#: The signals are averaged over blocks down to about this rate before their spectra, Hz (the band
#: is far below it; the same block average on both delays both alike).
TIMING_RATE_HZ = 1000.0


def _block_mean(x: np.ndarray, q: int) -> np.ndarray:
    """x (n,) averaged over consecutive blocks of ``q`` samples (the last partial block dropped)."""
    m = x.size // q
    return x[: m * q].reshape(m, q).mean(axis=1)


def lag_s(reference: np.ndarray, x: np.ndarray, fs: float, band_hz: tuple[float, float] = TIMING_BAND_HZ) -> float:
    """How late ``x`` is against ``reference`` (both (n,), sampled together at ``fs`` Hz, any
    units), s; negative when ``x`` leads. The coherence-weighted slope of the unwrapped phase of
    their cross-spectrum (Welch, Hann segments of :data:`TIMING_SEGMENT_S` or half the signal,
    after both are averaged over blocks down to about :data:`TIMING_RATE_HZ`) over ``band_hz``;
    an inverted axis (the phase starting near ±π) reads as the same delay. NaN when the band
    holds fewer than 4 bins, or the mean coherence over it is below :data:`TIMING_MIN_COHERENCE`
    (no common motion: a capture at rest)."""
    reference = np.asarray(reference, float)
    x = np.asarray(x, float)
    if reference.shape != x.shape or reference.ndim != 1:
        return float("nan")
    q = max(1, int(fs // TIMING_RATE_HZ))
    if q > 1:
        reference, x, fs = _block_mean(reference, q), _block_mean(x, q), fs / q
    nper = int(min(round(TIMING_SEGMENT_S * fs), x.size // 2))
    if nper < 8:
        return float("nan")
    f, pxy = signal.csd(reference, x, fs=fs, nperseg=nper)
    _, pxx = signal.welch(reference, fs=fs, nperseg=nper)
    _, pyy = signal.welch(x, fs=fs, nperseg=nper)
    sel = (f >= band_hz[0]) & (f <= band_hz[1])
    if sel.sum() < 4:
        return float("nan")
    den = pxx[sel] * pyy[sel]
    coh = np.where(den > 0, np.abs(pxy[sel]) ** 2 / np.where(den > 0, den, 1.0), 0.0)
    if not np.mean(coh) >= TIMING_MIN_COHERENCE:
        return float("nan")
    phase = np.unwrap(np.angle(pxy[sel]))
    if abs(phase[0]) > 0.5 * np.pi:  # the accelerometer's axis against the motion
        phase = phase - np.pi * np.sign(phase[0])
    w = coh / np.maximum(1.0 - coh, 1e-6)
    ff = f[sel]
    return float(-np.sum(w * ff * phase) / (2.0 * np.pi * np.sum(w * ff ** 2)))


def acceleration_lag_ms(speed: np.ndarray, acc_axial: np.ndarray, fs: float) -> float:
    """How late an accelerometer's axial column ``acc_axial`` (n,) is against the motor speed
    ``speed`` (n,) of the same Phase I capture (any speed unit), ms: :func:`lag_s` of the axial
    acceleration against the speed's derivative (the carriage's acceleration as the controller
    sees it, up to the lead). NaN for a capture without motion."""
    return 1e3 * lag_s(np.gradient(np.asarray(speed, float)) * fs, acc_axial, fs)
