"""Baseline standardisation of a feature table (paper section IV: "normalized to a mean of zero and a
standard deviation of one"; the test data "normalized by the mean and standard deviation of the
training dataset").

The baseline is the first ``n_baseline`` samples (15 in the paper). Standard deviations use the
N - 1 denominator. A feature that is constant over the baseline (zero deviation) is left
unscaled (divided by 1) so it cannot produce infinities.
"""

from __future__ import annotations

import numpy as np

__all__ = ["BaselineScaler"]


class BaselineScaler:
    """Centre and scale features with the baseline's mean and standard deviation.

    fit(X_baseline (N, p)) stores ``mean_`` (p,) and ``scale_`` (p,); transform(X (n, p)) returns
    (n, p) ``(X - mean_) / scale_`` (dimensionless).
    """

    def fit(self, X: np.ndarray) -> BaselineScaler:
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[0] < 2:
            raise ValueError(f"baseline has shape {X.shape}; expected (N, p) with N >= 2 samples")
        self.mean_ = X.mean(axis=0)
        sd = X.std(axis=0, ddof=1)
        self.scale_ = np.where(sd > 0, sd, 1.0)
        return self

    def transform(self, X: np.ndarray) -> np.ndarray:
        return (np.asarray(X, dtype=float) - self.mean_) / self.scale_
