"""The stated interval of an added candidate's parameters: the profile's, three bootstraps (the
regions, the response's seeds, the twin's noise) and the fit's dependence on the
interpolation, their hull (:func:`stated_interval`).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from analysis.diagnosis.fit import Fit, _calibration_residuals
from analysis.diagnosis.response import CandidateResponse, ParamAxis, _interpolator, search_step

BOOTSTRAP_DRAWS = 200  # resamples of the regions for an added candidate's interval
INTERVAL_LEVEL = 0.9  # the stated interval's nominal coverage


def bootstrap_interval(cand: CandidateResponse, z_cal: np.ndarray, sd_cal: np.ndarray, regions: list,
                       level: float = INTERVAL_LEVEL, draws: int = BOOTSTRAP_DRAWS, n_fine: int = 61,
                       seed: int = 0) -> dict[str, tuple[float, float]]:
    """The ``level`` interval of each parameter of ``cand`` by a block bootstrap over the regions.

    The statistics of one region (:attr:`Region.key`, all hours) move together, and where the
    candidate's one-seed, interpolated response is not exactly the recording's, different regions
    prefer different parameter values; the Δχ² profile sees neither. Resampling whole regions
    with replacement (the block bootstrap: Efron & Tibshirani, *An Introduction to the
    Bootstrap*, 1993, ch. 8.6; Künsch, Ann. Statist. 17(3), 1989) and refitting on the same fine
    grid gives the spread of the fitted value both cause: the interval is the (1 − level)/2 and
    (1 + level)/2 quantiles of the ``draws`` refits (percentile interval). Deterministic (the
    resamples come from ``seed``). z_cal: (n,) standardised differences from the current model;
    sd_cal: (n,) prediction standard deviations; regions: (n,) the statistics' regions.
    """
    if not cand.params:
        return {}
    grid, _, resid = _calibration_residuals(cand, z_cal, sd_cal, n_fine)
    r2 = resid ** 2  # (m, n)
    keys: dict = {}
    block = np.array([keys.setdefault(r.key, len(keys)) for r in regions])
    order = np.argsort(block, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(block[order]) != 0])
    per_block = np.add.reduceat(r2[:, order], starts, axis=1)  # (m, nb): Σ t² of each region
    rng = np.random.default_rng(seed)
    counts = rng.multinomial(len(keys), np.full(len(keys), 1.0 / len(keys)), size=draws)  # (draws, nb)
    best = np.argmin(per_block @ counts.T, axis=0)  # (draws,)
    q = ((1.0 - level) / 2.0, (1.0 + level) / 2.0)
    return {a.name: tuple(float(v) for v in np.quantile(grid[best, i], q)) for i, a in enumerate(cand.params)}


def seed_interval(cand: CandidateResponse, z_cal: np.ndarray, sd_cal: np.ndarray,
                  level: float = INTERVAL_LEVEL, n_fine: int = 61) -> dict[str, tuple[float, float]]:
    """The ``level`` interval of each continuous parameter of ``cand`` from its responses on the
    twin's seeds (a bootstrap over the seeds; {} without :attr:`CandidateResponse.per_seed`).

    A candidate's response is simulated with one of the twin's seeds (its rails, its screw's
    phases); the recording's machine is another draw, and its response differs: the fitted value
    moves with it by more than the noise of the statistics. The candidate is fitted
    again with the response of each of its R seeds, p_1 … p_R; the recording's own response is
    one more draw, so the interval is the prediction interval of a new observation,
    p̄ ± t_{R−1}((1 + level)/2) · s · √(1 + 1/R) (Montgomery & Runger, Applied Statistics and
    Probability for Engineers, 6th ed., section 8.4). A discrete parameter gets the range of its
    refits. z_cal, sd_cal: (n,) as for :func:`fit_candidate`."""
    if cand.per_seed is None or not cand.params:
        return {}
    fits = np.array([_best_point(CandidateResponse(cand.name, cand.params, {p: d[k] for p, d in cand.per_seed.items()},
                                                   cand.kind), z_cal, sd_cal, n_fine)
                     for k in range(len(cand.per_seed["cal"]))])  # (R, k)
    return _prediction_interval(cand.params, fits, fits.mean(axis=0), level)


def _best_point(cand: CandidateResponse, z_cal: np.ndarray, sd_cal: np.ndarray, n_fine: int,
                method: str = "linear") -> np.ndarray:
    """The parameter values (k,) of the zoomed search's least Σ t² (:func:`_calibration_residuals`)."""
    grid, _, resid = _calibration_residuals(cand, z_cal, sd_cal, n_fine, method)
    return grid[int(np.argmin(np.sum(resid ** 2, axis=1)))]


def _prediction_interval(params: list[ParamAxis], fits: np.ndarray, center: np.ndarray,
                         level: float) -> dict[str, tuple[float, float]]:
    """The ``level`` prediction interval of one more draw of the refits ``fits`` (n, k) around
    ``center`` (k,): center ± t_{n−1}((1 + level)/2) · s · √(1 + 1/n) (Montgomery & Runger,
    Applied Statistics and Probability for Engineers, 6th ed., section 8.4); a discrete
    parameter gets the range of the refits and the center."""
    n = len(fits)
    half = stats.t.ppf(0.5 + level / 2.0, n - 1) * fits.std(axis=0, ddof=1) * np.sqrt(1.0 + 1.0 / n)
    return {a.name: ((float(min(fits[:, i].min(), center[i])), float(max(fits[:, i].max(), center[i])))
                     if a.discrete else (float(center[i] - half[i]), float(center[i] + half[i])))
            for i, a in enumerate(params)}


def noise_interval(cand: CandidateResponse, z_cal: np.ndarray, sd_cal: np.ndarray, noise: np.ndarray,
                   level: float = INTERVAL_LEVEL, n_fine: int = 61,
                   p_hat: np.ndarray | None = None) -> dict[str, tuple[float, float]]:
    """The ``level`` interval of each parameter of ``cand`` from the twin's own seed-to-seed
    variation (a parametric bootstrap over the twin's seeds).

    The recording is one draw of its machine: whatever a seed draws once (the rails' waviness,
    the noise of a whole channel) moves many statistics alike, and may lean the same way as the
    candidate's response (a machine that vibrates a little less on acc2 against a gain error of
    acc2); the bootstrap over the regions sees no such common part. Each twin seed's deviation
    from the mean, ``noise`` (K, n) in units of sd_cal, plus the fitted response gives a
    recording the fit should return; the K refits give the prediction interval
    p̂ ± t_{K−1}((1 + level)/2) · s · √(1 + 1/K) of the fitted value (Efron & Tibshirani, *An
    Introduction to the Bootstrap*, 1993, ch. 6: the parametric bootstrap). A discrete parameter
    gets the range of its refits. z_cal, sd_cal: (n,) as for :func:`fit_candidate`; p_hat: (k,)
    the fitted values when known (the zoomed fit's), else searched for."""
    if not cand.params or len(noise) < 2:
        return {}
    ok = np.isfinite(z_cal)
    p_hat = _best_point(cand, z_cal, sd_cal, n_fine) if p_hat is None else p_hat
    d_hat = _interpolator(cand.params, np.nan_to_num(cand.delta["cal"]))(p_hat[None, :])[0] / sd_cal
    fits = np.array([_best_point(cand, np.where(ok, e + d_hat, np.nan), sd_cal, n_fine) for e in noise])
    return _prediction_interval(cand.params, fits, p_hat, level)


INTERPOLATIONS = ("pchip", "log")  # the interpolations of a response the interval is checked with


def interpolation_shift(cand: CandidateResponse, z_cal: np.ndarray, sd_cal: np.ndarray,
                        n_fine: int = 61, p_hat: np.ndarray | None = None) -> dict[str, tuple[float, float]]:
    """How far each fitted parameter of ``cand`` moves when its response is interpolated between
    grid values otherwise than linearly: by a shape-preserving piecewise cubic (PCHIP: Fritsch &
    Carlson, SIAM J. Numer. Anal. 17(2), 1980), and linearly in log p for a scale factor whose
    prior is log-uniform. Returns {name: (the most negative shift, the most positive; 0 when
    none moves it that way)}.

    The grid holds the simulated responses only; between them the response is unknown, and a
    response that curves (a band power growing with the square of an amplitude, a noise floor's
    log power with the log of its factor) is misjudged between two grid values by the straight
    line. Neither the Δχ² profile nor the bootstraps see this error; the stated interval is
    widened by the shifts to hold every fit. z_cal, sd_cal: (n,) as for :func:`fit_candidate`;
    p_hat: (k,) the linear fit's values when known (the zoomed fit's), else searched for."""
    best = {} if p_hat is None else {"linear": p_hat}
    for method in ("linear", *INTERPOLATIONS):
        if method in best:
            continue
        if method == "log" and not any(a.log_scaled for a in cand.params):
            continue
        best[method] = _best_point(cand, z_cal, sd_cal, n_fine, method)
    out = {}
    for i, a in enumerate(cand.params):
        shifts = [float(best[m][i] - best["linear"][i]) for m in best if m != "linear"]
        out[a.name] = (min(shifts + [0.0]), max(shifts + [0.0]))
    return out


def stated_interval(fit: Fit, cand: CandidateResponse, z_cal: np.ndarray, sd_cal: np.ndarray,
                    regions: list, noise: np.ndarray | None = None) -> dict[str, tuple[float, float]]:
    """The ``INTERVAL_LEVEL`` interval stated for each parameter of an added candidate: the hull
    of the Δχ² profile interval of ``fit``, the block bootstrap over the regions
    (:func:`bootstrap_interval`), the bootstrap over the seeds of the candidate's response
    (:func:`seed_interval`) and over the twin's own seed-to-seed variation (:func:`noise_interval`,
    with ``noise`` (K, n)), widened by the shifts of the fit under other interpolations of the
    response (:func:`interpolation_shift`) and never narrower than ± one step of the search:
    each covers a source of error the others do not see. ``fit``: the candidate's zoomed fit
    (``fit_candidate(..., zoom=True)``) on the same z_cal, sd_cal."""
    p_hat = np.array([fit.params[a.name] for a in cand.params])  # the zoomed fit's, not searched again
    parts = [fit.interval, bootstrap_interval(cand, z_cal, sd_cal, regions), seed_interval(cand, z_cal, sd_cal)]
    if noise is not None:
        parts.append(noise_interval(cand, z_cal, sd_cal, noise, p_hat=p_hat))
    shift = interpolation_shift(cand, z_cal, sd_cal, p_hat=p_hat)
    out = {}
    for a in cand.params:
        (down, up), step = shift[a.name], search_step(a)
        ends = [iv[a.name] for iv in parts if a.name in iv]
        lo = min(min(e[0] for e in ends) + down, fit.params[a.name] - step)
        hi = max(max(e[1] for e in ends) + up, fit.params[a.name] + step)
        out[a.name] = (lo, hi)
    return out


