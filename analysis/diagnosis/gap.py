"""Where the twin and the machine differ: each statistic of the signature judged against the
twin's own spread from seed to seed, with the multiple comparisons corrected for.

For statistic j, the twin is simulated with K seeds (new rails, screw phases, noise each time):
mean μ_j, and a standard deviation pooled over the statistics of the same region (the same
channel and band or phase at every hour; :attr:`Region.pool_key`), σ_R, with ν degrees of
freedom between K − 1 and Σ (K − 1): the statistics of a region share their seeds, and what a
seed draws once moves them alike (:func:`pooled_dof`). A recording
that the twin describes is one more draw, so

    t_j = (r_j − μ_j − Δ_j) / (σ_R √(1 + 1/K))

follows Student's t with ν degrees of freedom (the prediction interval of a new observation,
e.g. Montgomery & Runger, Applied Statistics and Probability for Engineers, 6th ed., section
8.4). Δ_j is the response of the added effects (zero for the twin as it is). Two-sided p-values
are corrected with Holm's step-down method (Holm, Scand. J. Statist. 6, 1979), which keeps the
family-wise error rate at α for any dependence between the statistics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from analysis.diagnosis.signature import Region, Signature


class GapError(ValueError):
    """Signatures that cannot be compared (different statistics); the message names them."""


@dataclass
class Spread:
    """The twin's seed-to-seed spread of one part. mean (n,), sd (n,) the pooled prediction
    standard deviation σ_R·√(1 + 1/K), dof (n,) its degrees of freedom, k the number of seeds,
    valid (n,) statistics finite in every seed."""

    mean: np.ndarray
    sd: np.ndarray
    dof: np.ndarray
    k: int
    valid: np.ndarray


def check_same(a: Signature, b: Signature, what_a: str, what_b: str) -> None:
    """Raise :class:`GapError` unless the two signatures hold the same statistics."""
    if len(a.regions) != len(b.regions) or any(
            ra.key != rb.key for ra, rb in zip(a.regions, b.regions, strict=True)):
        ka = {r.key for r in a.regions}
        kb = {r.key for r in b.regions}
        only_a = sorted(" ".join(k) for k in ka - kb)[:5]
        only_b = sorted(" ".join(k) for k in kb - ka)[:5]
        raise GapError(
            f"{what_a} has {len(a.regions)} statistics and {what_b} {len(b.regions)}; they must "
            f"describe the same captures, sessions, speeds and channels (only in {what_a}: "
            f"{only_a or 'none'}; only in {what_b}: {only_b or 'none'})")


def pooled_dof(v: np.ndarray) -> float:
    """Effective degrees of freedom of the variance pooled over the m statistics of one region,
    v (K, m): the values of each statistic in each of K seeds.

    The m statistics (one region at m hours) are measured on the same K simulated machines, so
    they are not m independent replicates: what a seed draws once (its rails, the phases of its
    screw's errors) moves all of them alike. The pooled variance is the two-way decomposition
    MS_seed/m + (1 − 1/m)·MS_res, MS_seed = m·Σ_k (ē_k − ē)²/(K − 1) from the seeds' means over
    the m statistics (K − 1 degrees of freedom) and MS_res the seed × statistic residual
    ((K − 1)(m − 1)); Satterthwaite's approximation (Satterthwaite, Biometrics Bull. 2, 1946;
    Montgomery, Design and Analysis of Experiments, 8th ed., section 13.6) gives its degrees of
    freedom: m(K − 1) when the statistics vary independently from seed to seed, down to K − 1
    when each seed moves them all alike.
    """
    k, m = v.shape
    if m == 1:
        return float(k - 1)
    d = v - v.mean(axis=0)  # (K, m) deviations from each statistic's mean
    seed = d.mean(axis=1)  # (K,) what each seed shares over the m statistics
    ms_seed = m * np.sum(seed ** 2) / (k - 1)
    ms_res = np.sum((d - seed[:, None]) ** 2) / ((k - 1) * (m - 1))
    a, b = ms_seed / m, (1.0 - 1.0 / m) * ms_res
    den = a ** 2 / (k - 1) + b ** 2 / ((k - 1) * (m - 1))
    if not den > 0.0:  # constant over the seeds: nothing to pool, the floor of `spread` applies
        return float(m * (k - 1))
    return float(np.clip((a + b) ** 2 / den, k - 1, m * (k - 1)))


def spread(signatures: list[Signature]) -> Spread:
    """The spread of K ≥ 3 twin signatures of the same part (identical statistics)."""
    if len(signatures) < 3:
        raise GapError(f"the twin's spread needs at least 3 seeds; got {len(signatures)}")
    for i, s in enumerate(signatures[1:], 1):
        check_same(signatures[0], s, "twin seed 0", f"twin seed {i}")
    v = np.stack([s.values for s in signatures])  # (K, n)
    k = v.shape[0]
    valid = np.all(np.isfinite(v), axis=0)
    w = np.where(valid, v, 0.0)
    mean = np.where(valid, w.mean(axis=0), np.nan)
    var = np.where(valid, w.var(axis=0, ddof=1), np.nan)
    keys = [r.pool_key for r in signatures[0].regions]
    pooled = np.full(len(keys), np.nan)
    dof = np.zeros(len(keys))
    groups: dict[tuple, list[int]] = {}
    for j, key in enumerate(keys):
        if valid[j]:
            groups.setdefault(key, []).append(j)
    for idx in groups.values():
        pooled[idx] = np.mean(var[idx])
        dof[idx] = pooled_dof(v[:, idx])
    floor = 1e-9 * np.maximum(1.0, np.abs(np.nan_to_num(mean)))
    sd = np.sqrt(np.maximum(np.nan_to_num(pooled), floor ** 2)) * np.sqrt(1.0 + 1.0 / k)
    return Spread(mean=mean, sd=sd, dof=np.maximum(dof, 1.0), k=k, valid=valid)


def zscores(real: Signature, sp: Spread, delta: np.ndarray | None = None) -> np.ndarray:
    """(n,) standardised differences t_j (NaN where the statistic is not usable)."""
    pred = sp.mean if delta is None else sp.mean + delta
    z = (real.values - pred) / sp.sd
    return np.where(sp.valid & np.isfinite(real.values), z, np.nan)


def pvalues(z: np.ndarray, sp: Spread) -> np.ndarray:
    """Two-sided p-values of t_j with the spread's degrees of freedom (NaN stays NaN)."""
    return np.where(np.isfinite(z), 2.0 * stats.t.sf(np.abs(np.nan_to_num(z)), sp.dof), np.nan)


def holm(p: np.ndarray, alpha: float) -> np.ndarray:
    """Boolean (n,): the hypotheses Holm's step-down procedure rejects at family-wise level α
    (NaN p-values are not tested)."""
    ok = np.flatnonzero(np.isfinite(p))
    out = np.zeros(p.shape, bool)
    order = ok[np.argsort(p[ok])]
    m = order.size
    for rank, j in enumerate(order):
        if p[j] > alpha / (m - rank):
            break
        out[j] = True
    return out


def region_gaps(z: np.ndarray, regions: list[Region], select: np.ndarray | None = None
                ) -> dict[tuple, float]:
    """Mean z² per region key over the statistics in ``select`` (all finite ones by default)."""
    acc: dict[tuple, list[float]] = {}
    for j, r in enumerate(regions):
        if np.isfinite(z[j]) and (select is None or select[j]):
            acc.setdefault(r.key, []).append(z[j] ** 2)
    return {k: float(np.mean(v)) for k, v in acc.items()}


def hours_gaps(z: np.ndarray, regions: list[Region], select: np.ndarray | None = None
               ) -> dict[float, float]:
    """Mean z² per operating hours (statistics of one sample or session) over ``select``."""
    acc: dict[float, list[float]] = {}
    for j, r in enumerate(regions):
        if np.isfinite(z[j]) and np.isfinite(r.hours) and (select is None or select[j]):
            acc.setdefault(round(r.hours, 3), []).append(z[j] ** 2)
    return {k: float(np.mean(v)) for k, v in sorted(acc.items())}
