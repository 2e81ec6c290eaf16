"""Control limits and smoothing for the Phase I detectors (NIST/SEMATECH e-Handbook §6.5.4.3).

N: baseline samples; a: retained principal components (or dimensions); alpha: false-alarm rate.

- :func:`t2_limit_new`: Hotelling T^2 of a *new* observation scored against a baseline of N
  [NIST/SEMATECH e-Handbook 6.5.4.3; SAS MVPMONITOR]:
  ``a (N-1)(N+1) / (N (N-a)) * F_{1-alpha}(a, N-a)``. Exact for Gaussian data.
- :func:`t2_limit_train`: T^2 of the baseline observations themselves [same sources]:
  ``(N-1)^2 / N * Beta_{1-alpha}(a/2, (N-a-1)/2)``.
- :func:`t2_limit_paper`: the paper's Eq. 2, ``a (N-1) / (N-a) * F_{1-alpha}(a, N-a)``; it lacks the
  (N+1)/N factor of the new-observation limit, so it alarms slightly more often than alpha.
- :func:`md2_beta_limit`: squared Mahalanobis distance with the *maximum-likelihood* covariance
  (divisor N, as ``sklearn.mixture.GaussianMixture`` fits it) of a baseline point:
  ``MD^2 / (N-1) ~ Beta(a/2, (N-a-1)/2)`` [Gnanadesikan & Kettenring 1972],
  so the limit is ``(N-1) * Beta_{1-alpha}(a/2, (N-a-1)/2)``. Exact on the baseline only.
- :func:`md2_limit_new`: the same MD^2 of a *new* observation: MD^2 = N/(N-1) T^2, so
  ``a (N+1) / (N-a) * F_{1-alpha}(a, N-a)`` [Tracy, Young & Mason 1992, J. Quality Technology
  24, 88-95, with the T^2 limit above]. Exact for Gaussian data.
- :func:`three_sigma`: mean + 3 standard deviations (N-1) of baseline scores (paper, SOM and AE).
- :func:`moving_average`: trailing moving average over the time order of samples (paper: "moving
  window average with a sample width of 4"); the first w-1 samples average what is available.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

__all__ = [
    "md2_beta_limit",
    "md2_limit_new",
    "moving_average",
    "t2_limit_new",
    "t2_limit_paper",
    "t2_limit_train",
    "three_sigma",
]


def _check(n: int, a: int) -> None:
    if not (1 <= a < n):
        raise ValueError(f"a limit needs 1 <= a < N; got a = {a} dimensions and N = {n} samples")


def t2_limit_new(n: int, a: int, alpha: float = 0.01) -> float:
    """UCL of T^2 for new observations: a(N-1)(N+1)/(N(N-a)) F_{1-alpha}(a, N-a)."""
    _check(n, a)
    return a * (n - 1) * (n + 1) / (n * (n - a)) * float(stats.f.ppf(1 - alpha, a, n - a))


def t2_limit_train(n: int, a: int, alpha: float = 0.01) -> float:
    """UCL of T^2 for the baseline observations: (N-1)^2/N Beta_{1-alpha}(a/2, (N-a-1)/2)."""
    _check(n, a + 1)
    return (n - 1) ** 2 / n * float(stats.beta.ppf(1 - alpha, a / 2, (n - a - 1) / 2))


def t2_limit_paper(n: int, a: int, alpha: float = 0.01) -> float:
    """The paper's Eq. 2: a(N-1)/(N-a) F_{1-alpha}(a, N-a)."""
    _check(n, a)
    return a * (n - 1) / (n - a) * float(stats.f.ppf(1 - alpha, a, n - a))


def md2_beta_limit(n: int, a: int, alpha: float = 0.01) -> float:
    """UCL of MD^2 (MLE covariance) for baseline points: (N-1) Beta_{1-alpha}(a/2, (N-a-1)/2)."""
    _check(n, a + 1)
    return (n - 1) * float(stats.beta.ppf(1 - alpha, a / 2, (n - a - 1) / 2))


def md2_limit_new(n: int, a: int, alpha: float = 0.01) -> float:
    """UCL of MD^2 (MLE covariance, divisor N) for new observations: a(N+1)/(N-a) F_{1-alpha}(a, N-a)."""
    _check(n, a)
    return a * (n + 1) / (n - a) * float(stats.f.ppf(1 - alpha, a, n - a))


def three_sigma(baseline_scores: np.ndarray) -> float:
    """mean + 3 * std (N-1 denominator) of the baseline scores."""
    s = np.asarray(baseline_scores, dtype=float)
    return float(s.mean() + 3.0 * s.std(ddof=1))


def moving_average(x: np.ndarray, width: int) -> np.ndarray:
    """Trailing moving average of a (n,) series; element i averages x[max(0, i-w+1) : i+1]."""
    x = np.asarray(x, dtype=float)
    if width <= 1 or x.size == 0:
        return x.copy()
    c = np.concatenate(([0.0], np.cumsum(x)))
    i = np.arange(1, x.size + 1)
    lo = np.maximum(0, i - width)
    return (c[i] - c[lo]) / (i - lo)
