"""Phase I features of the paper (section IV, Fig. 3): 46 per sample.

Signals: the six nut-accelerometer channels ``acc1_x ... acc2_z`` (m/s^2) and the motor torque
(N*m), seven in all. Torque is *oriented*: multiplied by the direction of motion (sign of the
speed) so that forward and reverse moves have the same sign.

Per Phase I sample (all captures of one sample together):

===========================  =====  ========================================================
feature                      count  definition
===========================  =====  ========================================================
``amp{1,2,3}x_<sig>``        21     amplitude of the line at 1x, 2x, 3x the rotational
                                    frequency in the averaged PSD, 7 signals (paper: "PSD
                                    amplitudes at the rotational frequency and first two
                                    harmonics")
``band_<sig>``               7      energy of the averaged PSD from 0 Hz to the 10th harmonic,
                                    6 accelerometer channels (paper) + torque (ours)
``skew_<sig>``/``kurt_<sig>``  14   skewness / kurtosis of the steady segments, 7 signals
``skew_tr_torque``/
``kurt_tr_torque``           2      skewness / kurtosis of the transient torque segments
``corr_tr_torque_{fwd,rev}`` 2      correlation of the transient torque with the first sample's
                                    average transient, forward and reverse starts separately
===========================  =====  ========================================================

The paper's enumeration gives 21 + 6 + 16 + 1 = 44; it counts 46. We reach 46 with the torque's
band energy and by splitting the correlation by direction: a forward and a reverse start are
different transients (each is compared with the first sample's average of its own direction).

Definitions and units (checked against analytical values in ``tests/test_phase1_features.py``):

- PSD: Welch's method with a Hann window [scipy.signal.welch docs], one-sided density
  (unit^2/Hz), segment mean removed, averaged over all steady segments of the sample (paper: "the
  PSDs of all ten segments are averaged").
- Line amplitude at frequency f: ``sqrt(2 * sum(PSD[|f_k - f| <= 2.5 df]) * df)``: the power of
  the line (Parseval) expressed as the amplitude of a sinusoid, in the signal's unit; the Hann
  main lobe (+-2 bins) holds the line's power whatever the line's position between bins.
- Band energy: ``sum(PSD[0 < f_k <= 10 f_rot]) * df`` (unit^2), the mean-square of the signal in
  that band.
- Skewness ``m3/m2^1.5`` and (Pearson) kurtosis ``m4/m2^2`` (3 for a Gaussian) with biased
  central moments [scipy.stats.skew/kurtosis, ``fisher=False``], averaged over segments.
- Correlation: Pearson correlation of a transient's torque, resampled to ``TRANSIENT_POINTS``
  points over its duration, with the template (the average resampled transient of the same
  direction in the first sample).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from analysis.phase1.segmentation import Segmentation, segment_capture

__all__ = [
    "ACC_SIGNALS",
    "AE_RATE_HZ",
    "AE_WINDOW_S",
    "FEATURE_NAMES",
    "PSD_SEGMENT_S",
    "SIGNALS",
    "TRANSIENT_POINTS",
    "CaptureSummary",
    "FeatureError",
    "band_energy",
    "kurtosis",
    "line_amplitude",
    "sample_features",
    "skewness",
    "summarise_capture",
    "transient_templates",
    "welch_psd",
]

ACC_SIGNALS = tuple(f"acc{i}_{ax}" for i in (1, 2) for ax in "xyz")
SIGNALS = (*ACC_SIGNALS, "torque")
TRANSIENT_POINTS = 200
PSD_SEGMENT_S = 0.2  # Welch segment length (s): 5 Hz resolution
AE_WINDOW_S = 0.3  # torque window for the autoencoder from the start of each acceleration (s)
AE_RATE_HZ = 1000.0  # the autoencoder's torque windows are block-averaged to this rate

FEATURE_NAMES: tuple[str, ...] = (
    *(f"amp{k}x_{s}" for s in SIGNALS for k in (1, 2, 3)),
    *(f"band_{s}" for s in SIGNALS),
    *(f"{m}_{s}" for s in SIGNALS for m in ("skew", "kurt")),
    "skew_tr_torque",
    "kurt_tr_torque",
    "corr_tr_torque_fwd",
    "corr_tr_torque_rev",
)
if len(FEATURE_NAMES) != 46:  # the paper's section IV count; a new feature must say why
    raise RuntimeError(f"FEATURE_NAMES has {len(FEATURE_NAMES)} entries; the paper's feature set has 46")


class FeatureError(ValueError):
    """A capture or sample yields no usable segment (message names the capture)."""


def welch_psd(x: np.ndarray, fs_hz: float, segment_s: float = PSD_SEGMENT_S) -> tuple[np.ndarray, np.ndarray]:
    """Hann-windowed Welch PSD along axis 0.

    x: (n,) or (n, c) signal; returns ``(f (m,) Hz, P (m,) or (m, c) unit^2/Hz)``, one-sided,
    50 % overlap, constant detrend [scipy.signal.welch].
    """
    nper = int(round(segment_s * fs_hz))
    return signal.welch(x, fs=fs_hz, window="hann", nperseg=nper, noverlap=nper // 2,
                        detrend="constant", scaling="density", axis=0)


def line_amplitude(f: np.ndarray, psd: np.ndarray, f_line: float) -> np.ndarray:
    """Amplitude of a spectral line at ``f_line`` (Hz) from a density PSD (module docstring).

    f: (m,) Hz; psd: (m,) or (m, c); returns scalar or (c,) in the signal's unit.
    """
    df = f[1] - f[0]
    sel = np.abs(f - f_line) <= 2.5 * df
    return np.sqrt(2.0 * psd[sel].sum(axis=0) * df)


def band_energy(f: np.ndarray, psd: np.ndarray, f_high: float) -> np.ndarray:
    """Mean-square in ``0 < f <= f_high`` from a density PSD: ``sum(P) df``; unit^2."""
    df = f[1] - f[0]
    sel = (f > 0) & (f <= f_high)
    return psd[sel].sum(axis=0) * df


def _central_moments(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centred x, the biased second moment m2 along axis 0, and where the column is degenerate.

    The moments are formed as scipy.stats forms them (mean removed, products of squares), so
    that ordinary columns give scipy's values to the last bit, without its per-call overhead.
    Degenerate: constant to within 10 machine epsilons of its mean (where scipy warns of
    catastrophic cancellation, or returns NaN), e.g. a clipped channel.
    """
    x = np.asarray(x, dtype=float)
    mean = np.mean(x, axis=0, keepdims=True)
    d = x - mean
    m2 = np.mean(d ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        spread = np.max(np.abs(d), axis=0) / np.abs(mean[0])
        degenerate = (spread < 10.0 * np.finfo(float).eps) | (m2 <= (np.finfo(float).eps * mean[0]) ** 2)
    return d, m2, degenerate


def skewness(x: np.ndarray) -> np.ndarray:
    """Skewness m3 / m2^1.5 along axis 0 (biased moments) [scipy.stats.skew, ``bias=True``];
    NaN for a degenerate (constant) column. x: (n,) or (n, c) → scalar or (c,)."""
    d, m2, degenerate = _central_moments(x)
    m3 = np.mean(d ** 2 * d, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(degenerate, np.nan, m3 / m2 ** 1.5)[()]


def kurtosis(x: np.ndarray) -> np.ndarray:
    """Pearson kurtosis m4 / m2^2 along axis 0 (3 for a Gaussian) [scipy.stats.kurtosis,
    ``fisher=False, bias=True``]; NaN for a degenerate (constant) column. x: (n,) or (n, c)."""
    d, m2, degenerate = _central_moments(x)
    m4 = np.mean((d ** 2) ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(degenerate, np.nan, m4 / m2 ** 2.0)[()]


@dataclass
class CaptureSummary:
    """What one capture contributes to its sample's features.

    name, hours, sample: from the file; f_rot_hz: rotational frequency (Hz); freqs (m,) Hz;
    psd_sum (m, 7): sum of the steady segments' PSDs (unit^2/Hz) over ``n_steady`` segments;
    skew_sum, kurt_sum (7,): sums over the steady segments; tr_skew, tr_kurt: per transient;
    transients: {+1 or -1: list of (TRANSIENT_POINTS,) oriented torque (N*m)};
    ae_windows: list of (AE points,) oriented torque windows (N*m) for the autoencoder.
    """

    name: str
    hours: float
    sample: int
    f_rot_hz: float
    freqs: np.ndarray
    psd_sum: np.ndarray
    n_steady: int
    skew_sum: np.ndarray
    kurt_sum: np.ndarray
    tr_skew: list[float] = field(default_factory=list)
    tr_kurt: list[float] = field(default_factory=list)
    transients: dict[int, list[np.ndarray]] = field(default_factory=lambda: {1: [], -1: []})
    ae_windows: list[np.ndarray] = field(default_factory=list)


def _stack(capture) -> np.ndarray:
    """(n, 7) matrix of acc1 x/y/z, acc2 x/y/z, oriented torque."""
    direction = np.sign(capture.speed)
    return np.column_stack([capture.acc1, capture.acc2, capture.torque * direction])


def summarise_capture(capture, label: str = "") -> CaptureSummary:
    """Segment one capture and compute its per-segment quantities.

    capture: an :class:`analysis.dataset.Phase1Capture` (or any object with ``speed`` (n,),
    ``torque`` (n,), ``acc1``/``acc2`` (n, 3), ``fs_hz``, ``name``, ``hours``, ``sample``).
    Raises :class:`FeatureError` if the capture has no steady segment long enough for the PSD.
    """
    fs = float(capture.fs_hz)
    seg: Segmentation = segment_capture(capture.speed, fs)
    nper = int(round(PSD_SEGMENT_S * fs))
    steady = [s for s in seg.steady if len(s) >= nper]
    where = f"{label}: /phase1/{capture.name}" if label else f"capture {capture.name}"
    if not steady:
        raise FeatureError(
            f"{where}/speed has no constant-speed segment of at least {PSD_SEGMENT_S} s "
            f"(plateau {seg.plateau_rad_s:.3g} rad/s); expected the reciprocating Phase I routine")
    sig = _stack(capture)
    freqs, psd_sum = None, 0.0
    skew_sum, kurt_sum = np.zeros(7), np.zeros(7)
    for s in steady:
        x = sig[s.slice]
        freqs, p = welch_psd(x, fs)
        psd_sum = psd_sum + p
        skew_sum += skewness(x)
        kurt_sum += kurtosis(x)
    out = CaptureSummary(capture.name, float(capture.hours), int(capture.sample), seg.f_rot_hz,
                         freqs, psd_sum, len(steady), skew_sum, kurt_sum)
    torque = sig[:, 6]
    block = max(1, int(round(fs / AE_RATE_HZ)))
    ae_len = int(round(AE_WINDOW_S * fs)) // block * block
    for t in seg.transient:
        x = torque[t.slice]
        if len(x) < 8:
            continue
        out.tr_skew.append(float(skewness(x)))
        out.tr_kurt.append(float(kurtosis(x)))
        grid = np.linspace(0.0, len(x) - 1.0, TRANSIENT_POINTS)
        out.transients[t.direction].append(np.interp(grid, np.arange(len(x)), x))
        w = torque[t.start:t.start + ae_len]
        if len(w) == ae_len and np.all(np.sign(capture.speed[t.start:t.start + ae_len]) == t.direction):
            out.ae_windows.append(w.reshape(-1, block).mean(axis=1))
    return out


def transient_templates(first_sample: list[CaptureSummary]) -> dict[int, np.ndarray]:
    """Average resampled transient torque per direction over the first sample's captures.

    Returns {+1: (TRANSIENT_POINTS,), -1: (TRANSIENT_POINTS,)}; a direction without transients is
    missing from the dict.
    """
    out = {}
    for d in (1, -1):
        rows = [x for c in first_sample for x in c.transients[d]]
        if rows:
            out[d] = np.mean(rows, axis=0)
    return out


def sample_features(captures: list[CaptureSummary], templates: dict[int, np.ndarray]) -> np.ndarray:
    """The 46 features (``FEATURE_NAMES`` order) of one sample from its captures' summaries.

    PSDs are averaged over all steady segments of the sample first, then the line amplitudes and
    band energies are read off the average at the sample's mean rotational frequency. Statistics
    are averaged over segments. A missing transient gives NaN for the transient features.
    """
    n = sum(c.n_steady for c in captures)
    psd = sum(c.psd_sum for c in captures) / n
    f = captures[0].freqs
    f_rot = float(np.mean([c.f_rot_hz for c in captures]))
    amps = np.stack([line_amplitude(f, psd, k * f_rot) for k in (1, 2, 3)], axis=1)  # (7, 3)
    band = band_energy(f, psd, 10.0 * f_rot)
    skew = sum(c.skew_sum for c in captures) / n
    kurt = sum(c.kurt_sum for c in captures) / n
    tr_skew = [v for c in captures for v in c.tr_skew]
    tr_kurt = [v for c in captures for v in c.tr_kurt]
    corr = []
    for d in (1, -1):
        rows = [x for c in captures for x in c.transients[d]]
        if d in templates and rows:
            with np.errstate(divide="ignore", invalid="ignore"):  # a flat (clipped) transient: NaN
                corr.append(float(np.mean([np.corrcoef(x, templates[d])[0, 1] for x in rows])))
        else:
            corr.append(np.nan)
    stats_ = np.column_stack([skew, kurt]).ravel()
    return np.concatenate([
        amps.ravel(), band, stats_,
        [np.mean(tr_skew) if tr_skew else np.nan, np.mean(tr_kurt) if tr_kurt else np.nan],
        corr,
    ])
