"""Fisher-score feature selection (paper section IV, Eq. 1 and Fig. 5).

Two-class Fisher score of feature j [paper Eq. 1]:

    F_j = (mu_H - mu_F)^2 / (sigma_H^2 + sigma_F^2)

with the class means and (biased, N denominator) variances of the healthy (H) and faulty (F)
samples of the reference data set. The general form (the multi-class Fisher score,
``sum_c n_c (mu_c - mu)^2 / sum_c n_c sigma_c^2``) ranks features the same way for two classes of
equal size. Features are ranked by decreasing score and the smallest leading set whose cumulative
score reaches ``fraction`` (0.9) of the total is kept.
"""

from __future__ import annotations

import numpy as np

__all__ = ["fisher_scores", "select_cumulative"]


def fisher_scores(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Fisher score of every column.

    X: (n, p) features; y: (n,) labels, 0 healthy and 1 faulty (both present).
    Returns (p,) non-negative scores; a feature with zero within-class variance and different
    means scores +inf, one with equal means 0.
    """
    X = np.asarray(X, dtype=float)
    y = np.asarray(y)
    if X.ndim != 2 or len(y) != len(X):
        raise ValueError(f"X has shape {X.shape} and y {y.shape}; expected (n, p) and (n,)")
    h, f = X[y == 0], X[y == 1]
    if len(h) < 2 or len(f) < 2:
        raise ValueError(f"need at least 2 healthy and 2 faulty samples; got {len(h)} and {len(f)}")
    num = (h.mean(axis=0) - f.mean(axis=0)) ** 2
    den = h.var(axis=0) + f.var(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.where(num > 0, np.inf, 0.0))
    return out


def select_cumulative(scores: np.ndarray, fraction: float = 0.9) -> np.ndarray:
    """Indices (k,) of the highest-scoring features whose cumulative score first reaches
    ``fraction`` of the total, in decreasing score order (paper Fig. 5, 90 % threshold).

    Infinite scores (perfect separation) are all kept; NaN scores count as 0.
    """
    s = np.nan_to_num(np.asarray(scores, dtype=float), nan=0.0, posinf=np.inf)
    order = np.argsort(-s, kind="stable")
    n_inf = int(np.isinf(s).sum())
    if n_inf:
        return order[:n_inf]
    total = s.sum()
    if total <= 0:
        return order[:1]
    cum = np.cumsum(s[order]) / total
    k = int(np.searchsorted(cum, fraction - 1e-12) + 1)
    return order[:k]
