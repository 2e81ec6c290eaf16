"""One candidate fitted on the calibration part and measured on the held-out part (:class:`Fit`,
:func:`fit_candidate`), with the regions it makes worse, its footprint and the candidates its
gain does not tell apart from it; the rules are those of :mod:`analysis.diagnosis.attribution`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy import stats

from analysis.diagnosis.response import CandidateResponse, _fine_axes, _interpolator, _points, _zoom_axes, grid_edge

#: The least relative rise of a region's Σ t² that makes it "worse" (with the χ² criterion).
WORSE_FRACTION = 0.1
#: Two candidates are not told apart when their net gains differ by no more than this many
#: standard deviations of the difference, or by no more than this fraction of the gap.
TIE_SIGMAS = 3.0
TIE_FRACTION = 0.01


@lru_cache(maxsize=4096)
def chi2_quantile(q: float, dof: int) -> float:
    """The χ²_dof quantile q (scipy.stats.chi2.ppf), remembered: a diagnosis asks for the same
    few (q, dof) pairs for every candidate and region."""
    return float(stats.chi2.ppf(q, dof))


def worse_regions(z_before: np.ndarray, z_after: np.ndarray, regions: list,
                  alpha: float) -> list[dict]:
    """The regions whose held-out Σ t² over their m usable statistics rises by more than the
    χ²_m(1 − α) quantile and by at least :data:`WORSE_FRACTION` of its value from ``z_before``
    to ``z_after`` ((n,) each; ``regions`` (n,)), worst first: domain, channel, family, bin,
    n_statistics, heldout_gap_before/after (mean t²),
    increase (of Σ t²) and threshold (the quantile)."""
    group: dict[tuple, int] = {}
    index = np.array([group.setdefault(r.key, len(group)) for r in regions], dtype=np.intp)
    ok = np.isfinite(z_before) & np.isfinite(z_after)
    m_of = np.bincount(index[ok], minlength=len(group))
    sb_of = np.bincount(index[ok], weights=np.asarray(z_before, float)[ok] ** 2, minlength=len(group))
    sa_of = np.bincount(index[ok], weights=np.asarray(z_after, float)[ok] ** 2, minlength=len(group))
    out = []
    for key, k in group.items():
        m, sb, sa = int(m_of[k]), float(sb_of[k]), float(sa_of[k])
        if m == 0:
            continue
        thr = chi2_quantile(1.0 - alpha, m)
        if sa - sb > thr and sa - sb >= WORSE_FRACTION * sb:
            out.append({"domain": key[0], "channel": key[1], "family": key[2], "bin": key[3],
                        "n_statistics": m, "heldout_gap_before": sb / m, "heldout_gap_after": sa / m,
                        "increase": sa - sb, "threshold": thr})
    return sorted(out, key=lambda d: -d["increase"])


def _penalty(z_before, z_after, regions, select, worse: list[dict]) -> float:
    """The rise of Σ t² in the ``worse`` regions over the statistics outside ``select``."""
    keys = {(w["domain"], w["channel"], w["family"], w["bin"]) for w in worse}
    if not keys:
        return 0.0
    m = np.array([r.key in keys for r in regions]) & ~select & np.isfinite(z_before) \
        & np.isfinite(z_after)
    return max(0.0, float(np.sum(z_after[m] ** 2 - z_before[m] ** 2)))


#: A statistic is in a candidate's footprint when the candidate's response moves its t by this much.
FOOTPRINT_SIGMAS = 1.0


def footprint_left(delta_heldout: np.ndarray, sd_heldout: np.ndarray, sel: np.ndarray,
                   z_before: np.ndarray, z_after: np.ndarray) -> tuple[int, float]:
    """What a candidate leaves of the gap where it acts, beyond what a right candidate leaves.

    Its footprint F: the statistics of ``sel`` (S, usable on the held-out part) whose t its
    response moves by at least :data:`FOOTPRINT_SIGMAS` (|Δ_j|/σ_j ≥ 1; ``delta_heldout``,
    ``sd_heldout`` (n,), the statistic's units). ``z_after``: the held-out t with every added
    candidate, each statistic standardised by the twin's spread and the error of the added
    responses (:func:`response_error_var`), so that with right candidates it is noise of
    variance 1; the excess Σ_F (t_after² − 1), floored at 0, is what the candidate leaves
    unexplained; returned as a fraction of Σ_F t_before² (``z_before``: the twin as it is;
    (n,) each). Returns (|F|, the fraction; 0.0 for an empty footprint)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        moved = np.abs(delta_heldout / sd_heldout) >= FOOTPRINT_SIGMAS
    foot = sel & moved & np.isfinite(z_before) & np.isfinite(z_after)
    before = float(np.sum(z_before[foot] ** 2))
    excess = float(np.sum(z_after[foot] ** 2 - 1.0))
    return int(foot.sum()), (max(0.0, excess) / before if before > 0 else 0.0)


def response_error_var(cand: CandidateResponse, params: dict[str, float], sd: np.ndarray,
                       part: str = "heldout") -> np.ndarray:
    """(n,) variance, in units of the twin's spread squared (``sd`` (n,)), of the error of
    taking ``cand``'s response at ``params`` (a fit's {name: value}) for the recording's on ``part``: the recording's
    machine is another draw than the seed the response was fitted with, so twice the variance
    of the response over its seeds (``per_seed``, sample variance), or its ``spread`` squared
    for a response averaged over the seeds; zeros for a one-seed response, and where the
    response moves the statistic by less than :data:`FOOTPRINT_SIGMAS` σ: where the candidate
    does not act, the scatter of its seeds is not what explains a gap (a mains line of the least
    amplitude scatters a transient's correlation by several σ from seed to seed without moving
    it)."""
    return _error_var_at(cand, np.array([[params[a.name] for a in cand.params]]), sd, part)[0]


def _error_var_at(cand: CandidateResponse, points: np.ndarray, sd: np.ndarray, part: str,
                  response: np.ndarray | None = None) -> np.ndarray:
    """(m, n) :func:`response_error_var` at each of the parameter ``points`` (m, k); ``response``:
    the candidate's response (``part``) at those points when the caller has it (m, n)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        if cand.per_seed is not None and cand.per_seed[part].shape[0] > 1:
            per = np.stack([_interpolator(cand.params, np.nan_to_num(d))(points) for d in cand.per_seed[part]])
            v = 2.0 * per.var(axis=0, ddof=1) / sd ** 2
        elif cand.spread is not None:
            v = (_interpolator(cand.params, np.nan_to_num(cand.spread[part]))(points) / sd) ** 2
        else:
            v = np.zeros((len(points), sd.size))
        if response is None:
            response = _interpolator(cand.params, np.nan_to_num(cand.delta[part]))(points)
        acts = np.abs(response / sd) >= FOOTPRINT_SIGMAS
    return np.where(acts, np.nan_to_num(v), 0.0)


def response_dof(cand: CandidateResponse) -> int | None:
    """The degrees of freedom of :func:`response_error_var`'s estimate for ``cand``: its response
    seeds less one (None: a one-seed response, no error estimated)."""
    k = cand.per_seed["heldout"].shape[0] if cand.per_seed is not None else 1
    return k - 1 if k > 1 else None


def error_scale(t: np.ndarray, error_var: np.ndarray, alpha: float, dof: int | None) -> np.ndarray:
    """(n,) what each t of a model with added candidates is divided by: √(1 + v_j) (``error_var``
    v_j (n,), the added responses' error, :func:`response_error_var`, estimated with ``dof``
    degrees of freedom) where what is left is within the responses' seed-to-seed variation, else 1.

    The recording's change is another draw than the response's seeds (a mains line of random
    phase moves a transient's correlation by hundreds of σ from seed to seed): within that
    variation when t_j/√(1 + v_j) lies within the two-sided 1 − α quantile of Student's t with
    ``dof`` degrees of freedom (v_j is itself estimated from a few seeds; the normal quantile
    without them). Beyond it the response's error does not account for what is left: a candidate
    that is only random where the gap is does not explain the gap. ``t`` (n,): the t with the
    responses, standardised by the twin's spread."""
    q = float(stats.t.ppf(1.0 - alpha / 2.0, dof)) if dof else float(stats.norm.ppf(1.0 - alpha / 2.0))
    s = np.sqrt(1.0 + error_var)
    with np.errstate(invalid="ignore"):
        within = np.abs(t / s) <= q
    return np.where(within, s, 1.0)


@dataclass
class Fit:
    """A candidate fitted on the calibration part and measured on the held-out part."""

    name: str
    params: dict[str, float]
    interval: dict[str, tuple[float, float]]
    cal_chi2: float
    heldout_before: float
    heldout_after: float
    gain_noise_sd: float
    gain_threshold: float
    delta_cal: np.ndarray = field(repr=False)
    delta_heldout: np.ndarray = field(repr=False)
    grid: dict[str, tuple[float, float]] = field(default_factory=dict)
    at_grid_edge: dict[str, str | None] = field(default_factory=dict)
    worse: list[dict] = field(default_factory=list)
    penalty: float = 0.0
    kind: str = "physical effect"
    alternatives: list[dict] = field(default_factory=list)
    footprint_statistics: int = 0
    footprint_gap_left: float | None = None

    @property
    def reduction(self) -> float:
        return 1.0 - self.heldout_after / self.heldout_before if self.heldout_before > 0 else 0.0

    @property
    def gain(self) -> float:
        return self.heldout_before - self.heldout_after

    @property
    def net_gain(self) -> float:
        """The gain less the rise of the gap in the regions it makes worse, outside S."""
        return self.gain - self.penalty

    @property
    def net_reduction(self) -> float:
        return self.net_gain / self.heldout_before if self.heldout_before > 0 else 0.0

    def significant(self, min_gain: float) -> bool:
        return self.net_gain > self.gain_threshold and self.net_reduction >= min_gain

    def as_dict(self, min_gain: float) -> dict:
        return {"effect": self.name, "kind": self.kind, "params": self.params,
                "interval": {k: list(v) for k, v in self.interval.items()},
                "grid": {k: list(v) for k, v in self.grid.items()},
                "at_grid_edge": self.at_grid_edge,
                "calibration_chi2": self.cal_chi2,
                "heldout_gap_before": self.heldout_before, "heldout_gap_after": self.heldout_after,
                "heldout_reduction": self.reduction, "gain": self.gain,
                "worse_regions": self.worse, "worse_penalty": self.penalty,
                "net_reduction": self.net_reduction,
                "gain_threshold": self.gain_threshold, "significant": self.significant(min_gain),
                "alternatives": self.alternatives,
                "footprint_statistics": self.footprint_statistics,
                "footprint_gap_left": self.footprint_gap_left}


def alternatives(best: Fit, fits: list[Fit], sel: np.ndarray, sd_ho: np.ndarray,
                 min_gain: float, z_ho: np.ndarray | None = None,
                 error_var: dict[str, np.ndarray] | None = None) -> list[dict]:
    """The candidates of ``fits`` (one round, ``best`` among them) the data do not tell apart
    from ``best``: they pass the test and their net gain falls short of best's by at most
    :data:`TIE_SIGMAS` standard deviations of the difference of the gains or by at most
    :data:`TIE_FRACTION` of the gap before.

    The difference of the gains G(a) − G(b), G(x) = Σ_S (z_j − d_x,j)² (z ``z_ho`` the held-out t
    of the current model, d_x the change of t by candidate x; (n,) each, over the statistics
    ``sel``), varies with the twin's noise on z (variance 4·Σ(d_a − d_b)²) and with the error of
    each candidate's response (variance 4·Σ(z − d_x)²·v_x, v_x from ``error_var`` {name: (n,)},
    :func:`response_error_var`; none without ``z_ho``): first-order propagation of both. Each:
    effect, kind, params, interval, net_reduction, gain_difference, difference_sd."""
    out = []
    err = error_var or {}
    for f in fits:
        if f is best or not f.significant(min_gain):
            continue
        dd = (best.delta_heldout - f.delta_heldout)[sel] / sd_ho[sel]
        var = float(np.sum(dd ** 2))
        if z_ho is not None:
            for x in (best, f):
                if x.name in err:
                    r = z_ho[sel] - x.delta_heldout[sel] / sd_ho[sel]
                    var += float(np.sum(r ** 2 * err[x.name][sel]))
        sd = 2.0 * float(np.sqrt(var))
        diff = best.net_gain - f.net_gain
        if diff <= max(TIE_SIGMAS * sd, TIE_FRACTION * best.heldout_before):
            out.append({"effect": f.name, "kind": f.kind, "params": f.params,
                        "interval": {k: list(v) for k, v in f.interval.items()},
                        "net_reduction": f.net_reduction, "gain_difference": diff, "difference_sd": sd})
    return out


def _calibration_residuals(cand: CandidateResponse, z_cal: np.ndarray, sd_cal: np.ndarray, n_fine: int,
                           method: str = "linear", zoom: bool = True, alpha: float = 0.01):
    """The parameter values searched for ``cand`` and what is left of the calibration part at
    each: (points (m, k), the calibration response's interpolator, residual t (m, n), zero where
    a statistic is not finite, each divided by :func:`error_scale` at its point with ``alpha``:
    a statistic the recording moves within the response's seed-to-seed variation does not pull
    the fit to the one seed's or the seeds' mean response there). The points are the fine grid
    (every grid value and an even subdivision of each continuous parameter's range in ``n_fine``
    values) and, with ``zoom``, a zoomed grid around its best point (:func:`_zoom_axes`, ten times
    finer): a fitted value is not rounded to the fine grid's step. ``method``: the response's
    interpolation (:func:`_interpolator`)."""
    fine = _fine_axes(cand.params, n_fine)
    ok = np.isfinite(z_cal)
    z = np.where(ok, z_cal, 0.0)[None, :]
    f_cal = _interpolator(cand.params, np.nan_to_num(cand.delta["cal"]), method)
    dof = response_dof(cand)

    def resid(pts: np.ndarray) -> np.ndarray:
        d = f_cal(pts)  # (m, n)
        r = z - np.where(ok, d / sd_cal, 0.0)
        if dof is None and cand.spread is None:
            return r
        # where the candidate acts is judged on its linear response (the fit's) whatever ``method``
        return r / error_scale(r, _error_var_at(cand, pts, sd_cal, "cal", d if method == "linear" else None),
                               alpha, dof)

    coarse = _points(fine)
    r = resid(coarse)
    if not cand.params or not zoom:
        return coarse, f_cal, r
    zoom = _points(_zoom_axes(cand.params, fine, coarse[int(np.argmin(np.sum(r ** 2, axis=1)))], n_fine))
    return np.concatenate([coarse, zoom]), f_cal, np.concatenate([r, resid(zoom)])


def fit_candidate(cand: CandidateResponse, z_cal: np.ndarray, z_ho: np.ndarray,
                  sd: dict[str, np.ndarray], select: np.ndarray, alpha: float,
                  n_fine: int = 61, regions: list | None = None, zoom: bool = False) -> Fit:
    """Fit ``cand`` on top of the current model.

    z_cal, z_ho: (n,) standardised differences of the real parts from the current model;
    sd: {"cal", "heldout"} (n,) prediction standard deviations; select: (n,) the statistics S;
    regions: (n,) the statistics' regions (for the regions the candidate makes worse; none
    looked for without them); zoom: search ten times finer around the fine grid's best point
    (the added candidate's final fit; the ranking compares the candidates on the fine grid).
    """
    grid, f_cal, resid = _calibration_residuals(cand, z_cal, sd["cal"], n_fine, zoom=zoom, alpha=alpha)
    ok_cal = np.isfinite(z_cal)
    chi2 = np.sum(resid ** 2, axis=1)
    best = int(np.argmin(chi2))
    p_best = grid[best]
    n_ok = int(ok_cal.sum())
    tol = max(1.0, chi2[best] / max(n_ok, 1))
    interval = {}
    for i, a in enumerate(cand.params):
        # The profile: the least Σ t² at each value searched of this parameter.
        vals, inv = np.unique(grid[:, i], return_inverse=True)
        profile = np.full(len(vals), np.inf)
        np.minimum.at(profile, inv, chi2)
        inside = vals[profile <= chi2[best] + tol]
        lo, hi = float(inside.min()), float(inside.max())
        k = int(inv[best])
        if not a.discrete and 0 < k < len(vals) - 1 and lo == hi:
            # Narrower than the search's step: the parabola through the profile's three points
            # around the minimum gives the Δχ² = tol half-width.
            x0, x1, x2 = vals[k - 1:k + 2]
            y0, y1, y2 = profile[k - 1:k + 2]
            curv = 2.0 * ((y2 - y1) / (x2 - x1) - (y1 - y0) / (x1 - x0)) / (x2 - x0)
            if curv > 0:
                half = float(np.sqrt(2.0 * tol / curv))
                lo, hi = float(vals[k]) - half, float(vals[k]) + half
        interval[a.name] = (lo, hi)
    d_cal = f_cal(p_best[None, :])[0]
    f_ho = _interpolator(cand.params, np.nan_to_num(cand.delta["heldout"]))
    d_ho = f_ho(p_best[None, :])[0]
    params = {a.name: float(v) for a, v in zip(cand.params, p_best, strict=True)}
    # The recording's change is another draw than the response's seeds (error_scale).
    z_after = z_ho - d_ho / sd["heldout"]
    z_after = z_after / error_scale(z_after, response_error_var(cand, params, sd["heldout"]), alpha,
                                    response_dof(cand))
    sel = select & np.isfinite(z_ho)
    before = float(np.sum(z_ho[sel] ** 2))
    dt = d_ho[sel] / sd["heldout"][sel]
    after = float(np.sum(z_after[sel] ** 2))
    noise = 2.0 * float(np.sqrt(np.sum(dt ** 2)))
    threshold = chi2_quantile(1.0 - alpha, max(len(cand.params), 1)) + 3.0 * noise
    worse, penalty = [], 0.0
    if regions is not None:
        worse = worse_regions(z_ho, z_after, regions, alpha)
        penalty = _penalty(z_ho, z_after, regions, select, worse)
    return Fit(name=cand.name, params=params,
               interval=interval, cal_chi2=float(chi2[best]), heldout_before=before,
               heldout_after=after, gain_noise_sd=noise, gain_threshold=threshold,
               delta_cal=d_cal, delta_heldout=d_ho,
               grid={a.name: (float(min(a.values)), float(max(a.values))) for a in cand.params},
               at_grid_edge={a.name: grid_edge(a, params[a.name], interval[a.name])
                             for a in cand.params},
               worse=worse, penalty=penalty, kind=cand.kind)


