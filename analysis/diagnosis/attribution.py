"""Which unmodelled effect explains the gap, and how far the gap shrinks once it is added.

Inputs are signatures only (this module never simulates): the real recording's two parts, the
twin's seed ensemble of both parts, and for each candidate effect its *response*: the change of
every statistic when the effect is added with parameter values on a grid, simulated with one seed
of the ensemble (common random numbers: the same rails, phases and noise with and without the
effect, so the difference is the effect's and not the seed's).

For each candidate:

1. **Fit on the calibration part.** The response is interpolated linearly between grid values
   (continuous parameters) or taken at grid values only (discrete ones, e.g. a cogging order),
   and the parameters minimise Σ_j t_j² over all statistics (t_j from :mod:`analysis.diagnosis.gap`)
   on a fine grid: a grid search, robust for non-smooth responses; the candidate added is
   searched again ten times finer around its best point. Uncertainty: the range of each
   parameter whose profile Σ t² stays within max(1, Σ t²_min / n) of the minimum (the Δχ² = 1
   rule, widened by the reduced χ² when the model does not fit to the noise); an added
   candidate states the hull of that and of three bootstraps, widened by the fit's dependence
   on the interpolation (:func:`stated_interval`).
2. **Measure on the held-out part.** The held-out gap G = Σ_{j∈S} t_j² over the statistics S
   that were significant on the calibration part, before and after adding the effect; the
   reduction 1 − G_after/G_before.

3. **Regions it makes worse.** A region (channel × band, phase, segment, …: a
   :attr:`Region.key` over all hours) is *made worse* when its held-out Σ t² over its m usable
   statistics rises by more than the χ²_m(1 − α) quantile once the candidate is added (more than
   a whole region of the twin's own spread would hold) and by at least ``WORSE_FRACTION`` (10 %)
   of its Σ t² before (a smaller relative rise in a region far beyond the spread is within the
   error of taking the response from one seed) (:func:`worse_regions`). The rise outside
   the statistics S (inside S it is already in G_after) is the candidate's *penalty*; its net
   gain is ΔG − penalty and its net reduction (ΔG − penalty)/G_before.
4. **At the edge of its grid.** A fitted value, or an end of its interval, on the first or last
   grid value is flagged ``"low"``/``"high"`` (``"both"``: the interval spans the whole grid, the
   data do not bound it): the true value may lie beyond the range tried (:func:`grid_edge`). A
   zero end of a grid without negative values is a physical floor (a magnitude), not flagged.

Selection is greedy forward: the candidate with the largest net held-out reduction is added
while its net gain is significant: it exceeds the χ²_k(1 − α) quantile (k fitted
parameters) plus three standard deviations of ΔG's noise, 2·√(Σ d_j²) with d_j the effect's
change of t_j (if the residual were noise ε_j, ΔG = Σ 2ε_j d_j − d_j² has that spread), and it
removes at least ``min_gain`` of the gap net of its penalty. Later candidates are fitted on top of the effects
already added, their responses added to them (the effects' responses are taken as additive).

**An explanation explains where it acts.** Once selected, each added candidate is checked on its
*footprint*, the statistics of S its response moves by at least one standard deviation of the
twin's spread (:func:`footprint_left`): with every added candidate in, the footprint's held-out
Σ t², less what the twin's noise and the error of the candidate's response allow (1 + v_j per
statistic, v_j from the response's seed-to-seed variation, :func:`response_error_var`), must be
no more than 1 − ``explained_fraction`` (10 %) of its Σ t² before: the verdict's 90 % rule
applied where the candidate acts. A candidate that leaves more approximates a gap whose shape it
does not have (a resonance standing in for a speed-locked line, a drifting bias for a
misalignment's constant offset): it is *refused* (``refused``, with the fraction it left) and the
selection runs again without it, until every added candidate passes; what it would have absorbed
stays unexplained (docs/gap-diagnosis.md gives the measured fractions of right and refused
candidates).

The verdict: "no significant gap" when no statistic is significant on the calibration part after
Holm's correction or the held-out gap over S does not exceed its χ²_|S|(1 − α) quantile;
otherwise "explained" when the residual held-out gap is within that quantile or the added
effects removed at least ``explained_fraction`` (90 %) of it, else "unexplained gap remains"
(with or without effects added). The 90 % rule: a large gap (G in the thousands) explained to
within a few per cent stays statistically significant because the effect's response from one
seed of the twin is not exactly the recording's; that is reported in ``residual`` as a
significant but small remainder, not as an unexplained gap.

**Not told apart.** Another candidate of the same round that passes the test too and whose net
gain falls short of the added one's by no more than ``TIE_SIGMAS`` (3) standard deviations of
the difference of the two gains (the twin's noise, 2·√Σ(d_a − d_b)² as for the gain test, and
the error of each candidate's response from its seed-to-seed variation, :func:`alternatives`)
or by no more than ``TIE_FRACTION`` (1 %) of the gap before is listed in the added entry's
``alternatives``: the data do not tell them apart (springs in series, a constant against a
viscous drag at one speed, a noisier sensor against noise added to its signal).

**Re-simulated shrink.** The shrink above is interpolated: one seed's responses, linear
between grid values and added. :func:`resimulated` measures it again on the twin re-simulated
with every added candidate at its fitted values (the simulation is the caller's: this module
never simulates) for the first n of the K seeds, the response taken as the mean paired
difference to the same seeds (common random numbers: Law, Simulation Modeling and Analysis,
5th ed., section 11.2), with the same statistic G over the same statistics S;
:func:`with_resimulation` makes the verdict follow it.

The ranking lists the added effects in the order they were added, then the others by their
net held-out reduction in the last round. ``worse_regions`` of the summary compares the twin
with all the added effects to the twin as it is.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy import stats
from scipy.interpolate import RegularGridInterpolator

from analysis.diagnosis import gap as g
from analysis.diagnosis.signature import Signature

NO_GAP, EXPLAINED, UNEXPLAINED = "no significant gap", "explained", "unexplained gap remains"


@dataclass(frozen=True)
class ParamAxis:
    """One parameter of a candidate: name (with its unit, e.g. ``rise_K``), the grid values at
    which the response was simulated (ascending, including the value that turns it off where
    there is one), whether it is discrete (no interpolation between grid values), and whether
    the grid is closed: it lists every value the parameter can take (the mains frequency and
    its harmonics), so that a fit on its first or last value is not "at the edge"; log: its
    prior is log-uniform (:attr:`log_scaled`)."""

    name: str
    values: tuple[float, ...]
    discrete: bool = False
    closed: bool = False
    log: bool = False

    @property
    def log_scaled(self) -> bool:
        """A scale whose prior is log-uniform (a factor on a twin parameter) and whose grid is
        positive: its response is also interpolated in log p for the interval."""
        return self.log and not self.discrete and min(self.values) > 0


@dataclass
class CandidateResponse:
    """The simulated response of one candidate effect.

    name: candidate name; params: its axes; delta: {"cal": array, "heldout": array}, each of
    shape (*[len(a.values) for a in params], n) with the change of every statistic on the grid;
    kind: "physical effect" (simulated) or "signal artefact" (applied to a simulated recording);
    spread: for a response that is the mean of its change over the twin's seeds, the standard
    deviation of that change from seed to seed, same shapes as ``delta`` (None: one seed's
    response): how far one recording's change may stand from the mean. per_seed: the change
    on each twin seed it was computed with, {"cal", "heldout"}: (seeds, *grid, n) (None: one
    seed), for the interval (:func:`seed_interval`).
    """

    name: str
    params: list[ParamAxis]
    delta: dict[str, np.ndarray]
    kind: str = "physical effect"
    spread: dict[str, np.ndarray] | None = None
    per_seed: dict[str, np.ndarray] | None = None

    def __post_init__(self) -> None:
        shape = tuple(len(a.values) for a in self.params)
        for part, d in self.delta.items():
            if d.shape[:-1] != shape:
                raise ValueError(f"{self.name}: {part} response has shape {d.shape}; expected "
                                 f"{shape} + (n,) for the grids of {[a.name for a in self.params]}")
            if self.per_seed is not None and self.per_seed[part].shape[1:] != d.shape:
                raise ValueError(f"{self.name}: {part} per-seed responses have shape "
                                 f"{self.per_seed[part].shape}; expected (seeds,) + {d.shape}")


def grid_edge(axis: ParamAxis, value: float, interval: tuple[float, float]) -> str | None:
    """Whether a fit sits on the edge of the grid it was searched on: "low" | "high" when the
    value or its interval reaches the first | last grid value, "both" when the interval reaches
    both, None inside. A zero first value of a grid without negative values (a magnitude: a
    torque, a mass, a spread) is a physical floor, not an edge."""
    v = np.asarray(axis.values, float)
    lo_g, hi_g = float(v.min()), float(v.max())
    if hi_g == lo_g:
        return None
    tol = 1e-9 * (hi_g - lo_g)
    if axis.closed:
        spans = interval[0] <= lo_g + tol and interval[1] >= hi_g - tol
        return "both" if spans else None
    floor = lo_g == 0.0
    low = not floor and min(value, interval[0]) <= lo_g + tol
    high = max(value, interval[1]) >= hi_g - tol
    return "both" if low and high else "low" if low else "high" if high else None


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
                   z_before: np.ndarray, z_after: np.ndarray, error_var: np.ndarray) -> tuple[int, float]:
    """What a candidate leaves of the gap where it acts, beyond what a right candidate leaves.

    Its footprint F: the statistics of ``sel`` (S, usable on the held-out part) whose t its
    response moves by at least :data:`FOOTPRINT_SIGMAS` (|Δ_j|/σ_j ≥ 1; ``delta_heldout``,
    ``sd_heldout`` (n,), the statistic's units). With a right candidate, the residual t_j there is
    the twin's own noise (variance 1) plus the error of its response (variance ``error_var`` v_j
    (n,), :func:`response_error_var`), so the excess Σ_F (t_after² − 1 − v_j), floored at 0, is
    what it leaves unexplained; returned as a fraction of Σ_F t_before² (``z_before``: the twin
    as it is, ``z_after``: with every added candidate; (n,) each). Returns (|F|, the fraction;
    0.0 for an empty footprint)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        moved = np.abs(delta_heldout / sd_heldout) >= FOOTPRINT_SIGMAS
    foot = sel & moved & np.isfinite(z_before) & np.isfinite(z_after)
    before = float(np.sum(z_before[foot] ** 2))
    excess = float(np.sum(z_after[foot] ** 2 - 1.0 - error_var[foot]))
    return int(foot.sum()), (max(0.0, excess) / before if before > 0 else 0.0)


def response_error_var(cand: CandidateResponse, params: dict[str, float], sd: np.ndarray,
                       part: str = "heldout") -> np.ndarray:
    """(n,) variance, in units of the twin's spread squared (``sd`` (n,)), of the error of
    taking ``cand``'s response at ``params`` (a fit's {name: value}) for the recording's on ``part``: the recording's
    machine is another draw than the seed the response was fitted with, so twice the variance
    of the response over its seeds (``per_seed``, sample variance), or its ``spread`` squared
    for a response averaged over the seeds; zeros for a one-seed response."""
    p = np.array([params[a.name] for a in cand.params])
    with np.errstate(divide="ignore", invalid="ignore"):
        if cand.per_seed is not None and cand.per_seed[part].shape[0] > 1:
            per = np.stack([_interpolator(cand.params, np.nan_to_num(d))(p[None, :])[0]
                            for d in cand.per_seed[part]])
            v = 2.0 * per.var(axis=0, ddof=1) / sd ** 2
        elif cand.spread is not None:
            v = (_interpolator(cand.params, np.nan_to_num(cand.spread[part]))(p[None, :])[0] / sd) ** 2
        else:
            v = np.zeros_like(sd)
    return np.nan_to_num(v)


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


def _fine_axes(params: list[ParamAxis], n_fine: int) -> list[np.ndarray]:
    out = []
    for a in params:
        v = np.asarray(a.values, float)
        if a.discrete or v.size == 1:
            out.append(v)
        else:
            # The grid values themselves plus an even subdivision between them.
            out.append(np.unique(np.concatenate([v, np.linspace(v[0], v[-1], n_fine)])))
    return out


def _interpolator(params: list[ParamAxis], delta: np.ndarray, method: str = "linear"):
    """The response ``delta`` (*grid, n) as a function of the parameters: points (m, k) ->
    (m, n). ``method``: "linear" (the fit's), or one of the interpolations the interval is
    checked with (:func:`interpolation_shift`): "pchip" (the shape-preserving cubic; an axis with
    fewer than four grid values is first given linearly interpolated midpoints), "log" (linear
    in log p on the :attr:`ParamAxis.log_scaled` axes, linear on the others). A single grid
    value gets a flat second one."""
    if not params:
        return lambda pts: np.broadcast_to(delta, (len(pts), delta.shape[-1]))
    axes = [np.asarray(a.values, float) for a in params]
    in_log = np.array([method == "log" and a.log_scaled for a in params])
    axes2, d = [], delta
    for i, ax in enumerate(axes):
        if ax.size == 1:
            # A single grid value cannot be interpolated over: repeat it as a flat axis.
            ax = np.array([ax[0], ax[0] + 1.0])
            d = np.concatenate([d, d], axis=i)
        while method == "pchip" and ax.size < 4:
            mid = 0.5 * (ax[1:] + ax[:-1])
            dm = 0.5 * (np.take(d, range(1, ax.size), axis=i) + np.take(d, range(ax.size - 1), axis=i))
            order = np.argsort(np.concatenate([ax, mid]), kind="stable")
            ax = np.concatenate([ax, mid])[order]
            d = np.take(np.concatenate([d, dm], axis=i), order, axis=i)
        axes2.append(np.log(ax) if in_log[i] else ax)
    f = RegularGridInterpolator(axes2, d, method="linear" if method == "log" else method)
    if not in_log.any():
        return f
    return lambda pts: f(np.where(in_log, np.log(np.where(in_log, pts, 1.0)), pts))


ZOOM_STEPS = 2.0  # half-width of the zoomed search, in steps of the fine grid
ZOOM_POINTS = 41  # points of each continuous parameter in the zoomed search


def _zoom_half_width(values: np.ndarray, n_fine: int) -> float:
    """Half the width of the zoomed search of a continuous parameter whose grid is ``values``:
    ZOOM_STEPS steps of the fine grid (its range in ``n_fine`` values)."""
    return ZOOM_STEPS * (values[-1] - values[0]) / max(n_fine - 1, 1)


def _zoom_axes(params: list[ParamAxis], fine: list[np.ndarray], p: np.ndarray, n_fine: int) -> list[np.ndarray]:
    """The zoomed search around the fine grid's best point ``p`` (k,): ZOOM_POINTS values of each
    continuous parameter within ± ZOOM_STEPS fine-grid steps of it (inside its grid), a discrete
    one (or a single-valued one) held at its value."""
    out = []
    for a, v, x in zip(params, fine, p, strict=True):
        if a.discrete or v.size == 1:
            out.append(np.array([x]))
            continue
        half = _zoom_half_width(v, n_fine)
        out.append(np.linspace(max(v[0], x - half), min(v[-1], x + half), ZOOM_POINTS))
    return out


def _points(axes: list[np.ndarray]) -> np.ndarray:
    """Every combination of the axes' values: (m, k)."""
    if not axes:
        return np.zeros((1, 0))
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))


def _calibration_residuals(cand: CandidateResponse, z_cal: np.ndarray, sd_cal: np.ndarray, n_fine: int,
                           method: str = "linear", zoom: bool = True):
    """The parameter values searched for ``cand`` and what is left of the calibration part at
    each: (points (m, k), the calibration response's interpolator, residual t (m, n), zero where
    a statistic is not finite). The points are the fine grid (every grid value and an even
    subdivision of each continuous parameter's range in ``n_fine`` values) and, with ``zoom``, a
    zoomed grid around its best point (:func:`_zoom_axes`, ten times finer): a fitted value is not
    rounded to the fine grid's step. ``method``: the response's interpolation (:func:`_interpolator`)."""
    fine = _fine_axes(cand.params, n_fine)
    ok = np.isfinite(z_cal)
    z = np.where(ok, z_cal, 0.0)[None, :]
    f_cal = _interpolator(cand.params, np.nan_to_num(cand.delta["cal"]), method)

    def resid(pts: np.ndarray) -> np.ndarray:
        return z - np.where(ok, f_cal(pts) / sd_cal, 0.0)  # (m, n)

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
    grid, f_cal, resid = _calibration_residuals(cand, z_cal, sd["cal"], n_fine, zoom=zoom)
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
    sel = select & np.isfinite(z_ho)
    before = float(np.sum(z_ho[sel] ** 2))
    dt = d_ho[sel] / sd["heldout"][sel]
    after = float(np.sum((z_ho[sel] - dt) ** 2))
    noise = 2.0 * float(np.sqrt(np.sum(dt ** 2)))
    threshold = chi2_quantile(1.0 - alpha, max(len(cand.params), 1)) + 3.0 * noise
    params = {a.name: float(v) for a, v in zip(cand.params, p_best, strict=True)}
    worse, penalty = [], 0.0
    if regions is not None:
        z_after = z_ho - d_ho / sd["heldout"]
        if cand.spread is not None:
            # A response averaged over the seeds: the recording's change is one seed's draw around
            # it, so a statistic is only made worse beyond that spread as well as the twin's.
            s_ho = _interpolator(cand.params, np.nan_to_num(cand.spread["heldout"]))(p_best[None, :])[0]
            z_after = z_after * sd["heldout"] / np.sqrt(sd["heldout"] ** 2 + s_ho ** 2)
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


def search_step(axis: ParamAxis, n_fine: int = 61) -> float:
    """The step of the zoomed search of a continuous parameter (0 for a discrete one): the
    resolution of its fitted value."""
    v = np.asarray(axis.values, float)
    if axis.discrete or v.size == 1:
        return 0.0
    return 2.0 * _zoom_half_width(v, n_fine) / (ZOOM_POINTS - 1)


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


def diagnose(real: dict[str, Signature], twin: dict[str, list[Signature]],
             candidates: list[CandidateResponse], *, alpha: float = 0.01,
             min_gain: float = 0.1, max_effects: int = 3, explained_fraction: float = 0.9
             ) -> tuple[dict, dict[str, np.ndarray]]:
    """The whole diagnosis on signatures.

    Returns (summary, t_heldout): a JSON-able dict (see ``twin diagnose``: verdict, statistics
    counts, regions with their held-out gap before/after, the ranking of every candidate, the
    effects added in order, and the residual) and the held-out t of every statistic against the
    twin as it is and with the added effects, {"before", "after"}: (n,) (for the gap maps)."""
    sp, z0, select, sel_ho, g_before, crit = _gap_setup(real, twin, alpha)
    sd = {p: sp[p].sd for p in sp}
    regions = real["cal"].regions
    n_sel = int(sel_ho.sum())
    out: dict = {
        "alpha": alpha, "min_gain": min_gain, "seeds": sp["cal"].k,
        "n_statistics": int(np.isfinite(z0["cal"]).sum()),
        "n_significant_calibration": int(select.sum()),
        "heldout_gap_before": g_before, "heldout_gap_critical": crit,
    }
    gaps_cal = g.region_gaps(z0["cal"], regions)
    sig_keys = {r.key for r, s in zip(regions, select, strict=True) if s}
    if n_sel == 0 or g_before <= crit:
        out.update(verdict=NO_GAP, ranking=[], added=[], heldout_gap_after=g_before,
                   heldout_shrink=0.0, worse_regions=[], regions=_regions(regions, z0, z0, select, sig_keys, gaps_cal),
                   hours=_hours(regions, z0, z0, select), residual={"significant": False})
        return out, {"before": z0["heldout"], "after": z0["heldout"]}
    # Each twin seed's deviation from the twin's mean, a recording's worth of the twin's own
    # variation (the parametric bootstrap of the intervals, noise_interval).
    k = sp["cal"].k
    with np.errstate(divide="ignore", invalid="ignore"):  # a statistic without spread: not finite, not used
        noise = (np.stack([t.values for t in twin["cal"]]) - sp["cal"].mean) / sp["cal"].sd * np.sqrt(k / (k - 1))
    pool = list(candidates)
    refused: list[dict] = []
    passes = 0
    # Select; then refuse every added candidate that leaves more than 1 − explained_fraction of
    # the gap where it acts (it approximates the gap, it does not explain it) and select again
    # without it, until every added candidate explains its footprint.
    while True:
        added, ranking, z = _select(pool, real, sp, z0, select, alpha, regions, noise, min_gain, max_effects)
        by_name = {c.name: c for c in pool}
        bad = []
        for f in added:
            err = response_error_var(by_name[f.name], f.params, sd["heldout"])
            f.footprint_statistics, f.footprint_gap_left = footprint_left(
                f.delta_heldout, sd["heldout"], sel_ho, z0["heldout"], z["heldout"], err)
            if f.footprint_gap_left > 1.0 - explained_fraction:
                bad.append(f)
        if not bad:
            break
        passes += 1
        refused += [{**f.as_dict(min_gain), "pass": passes} for f in bad]
        pool = [c for c in pool if c.name not in {f.name for f in bad}]
    g_after = float(np.sum(z["heldout"][sel_ho] ** 2))
    residual_sig = g_after > crit
    shrink = 1.0 - g_after / g_before if g_before > 0 else 0.0
    explained = not residual_sig or (added and shrink >= explained_fraction)
    ranking = [{**f.as_dict(min_gain), "round": i + 1} for i, f in enumerate(added)] + \
        [r for r in ranking if r["effect"] not in {f.name for f in added}]
    out.update(
        verdict=EXPLAINED if explained else UNEXPLAINED,
        ranking=ranking,
        added=[{**f.as_dict(min_gain), "step": i + 1} for i, f in enumerate(added)],
        refused=refused,
        heldout_gap_after=g_after,
        heldout_shrink=shrink, explained_fraction=explained_fraction,
        worse_regions=worse_regions(z0["heldout"], z["heldout"], regions, alpha),
        regions=_regions(regions, z0, z, select, sig_keys, gaps_cal),
        hours=_hours(regions, z0, z, select),
        residual={"significant": bool(residual_sig), "heldout_gap": g_after, "critical": crit,
                  "top_regions": [r for r in _regions(regions, z, z, select, sig_keys,
                                                      g.region_gaps(z["cal"], regions))
                                  if r["significant"]][:5]},
    )
    return out, {"before": z0["heldout"], "after": z["heldout"]}


def _select(pool: list[CandidateResponse], real: dict[str, Signature], sp: dict, z0: dict,
            select: np.ndarray, alpha: float, regions: list, noise: np.ndarray, min_gain: float,
            max_effects: int) -> tuple[list[Fit], list[dict], dict[str, np.ndarray]]:
    """Greedy forward selection among ``pool`` (steps 1–3 of the module's docstring): returns
    the added fits in order (zoomed, with their stated intervals and alternatives), the ranking
    of the last round and the t of both parts with the added candidates' responses."""
    sd = {p: sp[p].sd for p in sp}
    delta = {p: np.zeros_like(z0[p]) for p in z0}
    z = dict(z0)
    remaining = list(pool)
    added: list[Fit] = []
    ranking: list[dict] = []
    for step in range(max_effects):
        fits = [fit_candidate(c, z["cal"], z["heldout"], sd, select, alpha, regions=regions)
                for c in remaining]
        if not fits:
            break
        fits.sort(key=lambda f: -f.net_reduction)
        best = fits[0]
        ranking = [{**f.as_dict(min_gain), "round": step + 1} for f in fits]
        if not best.significant(min_gain):
            break
        by_name = {c.name: c for c in remaining}
        err = {f.name: response_error_var(by_name[f.name], f.params, sd["heldout"])
               for f in fits if f is best or f.significant(min_gain)}
        alt = alternatives(best, fits, select & np.isfinite(z["heldout"]), sd["heldout"], min_gain,
                           z["heldout"], err)
        cand = by_name[best.name]
        # The added candidate's value is not rounded to the fine grid: searched again, zoomed.
        best = fit_candidate(cand, z["cal"], z["heldout"], sd, select, alpha, regions=regions, zoom=True)
        best.alternatives = alt
        best.interval = stated_interval(best, cand, z["cal"], sd["cal"], regions, noise)
        best.at_grid_edge = {a.name: grid_edge(a, best.params[a.name], best.interval[a.name]) for a in cand.params}
        added.append(best)
        delta = {"cal": delta["cal"] + best.delta_cal, "heldout": delta["heldout"] + best.delta_heldout}
        z = {p: g.zscores(real[p], sp[p], delta[p]) for p in sp}
        remaining = [c for c in remaining if c.name != best.name]
    return added, ranking, z


def _gap_setup(real: dict[str, Signature], twin: dict[str, list[Signature]], alpha: float):
    """What every measure of the held-out gap shares: the spread of each part, the t of the
    twin as it is, the significant statistics S (calibration, Holm), S where the held-out t is
    usable, the held-out gap G over them and its χ²_|S|(1 − α) quantile."""
    for part in ("cal", "heldout"):
        for i, s in enumerate(twin[part]):
            g.check_same(real[part], s, f"the recording's {part} part", f"twin seed {i} ({part})")
    sp = {p: g.spread(twin[p]) for p in ("cal", "heldout")}
    z0 = {p: g.zscores(real[p], sp[p]) for p in sp}
    select = g.holm(g.pvalues(z0["cal"], sp["cal"]), alpha)
    sel_ho = select & np.isfinite(z0["heldout"])
    g_before = float(np.sum(z0["heldout"][sel_ho] ** 2))
    crit = chi2_quantile(1.0 - alpha, max(int(sel_ho.sum()), 1))
    return sp, z0, select, sel_ho, g_before, crit


def resimulated(real: dict[str, Signature], twin: dict[str, list[Signature]],
                resim: dict[str, list[Signature]], *, alpha: float = 0.01,
                explained_fraction: float = 0.9) -> dict:
    """The held-out gap with the added candidates **re-simulated** instead of interpolated.

    ``resim``: {part: [signature of twin seed k with every added candidate applied at its fitted
    values]} for the first n ≤ K seeds of ``twin`` (the same seeds, in order). The added
    candidates' response is then Δ_j = mean over those seeds of (resim_k,j − twin_k,j) (common
    random numbers, as for the grid: with all K seeds it is the mean of the re-simulated twin
    minus the mean of the twin), and the statistic is the interpolated one with Δ in place of
    the interpolated, additive response: G = Σ_{j∈S} ((r_j − μ_j − Δ_j)/σ_j)² over the same
    statistics S, with the twin's own spread σ_j (a statistic no re-simulated seed could compute
    gets Δ_j = 0, as a NaN of the grid's responses; ``n_statistics_resimulated`` counts the others).
    The verdict follows the rule of :func:`diagnose` on this G.

    Returns the ``resimulation`` entry of the result: done, seeds (n), heldout_gap_before,
    heldout_gap_after, heldout_shrink, n_statistics (of S), n_statistics_resimulated, verdict, residual (significant,
    heldout_gap, critical, top_regions) and worse_regions (against the twin as it is).
    """
    n = len(resim["heldout"])
    if n < 1 or n > len(twin["heldout"]):
        raise ValueError(f"re-simulation with {n} seeds; expected 1 to {len(twin['heldout'])}")
    for part in ("cal", "heldout"):
        for i, s in enumerate(resim[part]):
            g.check_same(twin[part][0], s, f"twin seed 0 ({part})", f"re-simulated seed {i} ({part})")
    sp, z0, select, sel_ho, g_before, crit = _gap_setup(real, twin, alpha)
    regions = real["cal"].regions
    diffs = {p: np.stack([r.values - t.values for r, t in zip(resim[p], twin[p][:n], strict=False)])
             for p in sp}
    finite = {p: np.isfinite(d).any(axis=0) for p, d in diffs.items()}
    # A statistic no re-simulated seed could compute gets no response, as a NaN of the grid's.
    delta = {p: np.where(finite[p], np.nanmean(np.where(finite[p], diffs[p], 0.0), axis=0), 0.0)
             for p in sp}
    z = {p: g.zscores(real[p], sp[p], delta[p]) for p in sp}
    g_after = float(np.sum(z["heldout"][sel_ho] ** 2))
    shrink = 1.0 - g_after / g_before if g_before > 0 else 0.0
    residual_sig = g_after > crit
    explained = not residual_sig or shrink >= explained_fraction
    sig_keys = {r.key for r, s in zip(regions, select, strict=True) if s}
    top = [r for r in _regions(regions, z, z, select, sig_keys, g.region_gaps(z["cal"], regions))
           if r["significant"]][:5]
    return {"done": True, "seeds": n, "heldout_gap_before": g_before, "heldout_gap_after": g_after,
            "heldout_shrink": shrink, "n_statistics": int(sel_ho.sum()),
            "n_statistics_resimulated": int((sel_ho & finite["heldout"]).sum()),
            "verdict": EXPLAINED if explained else UNEXPLAINED,
            "residual": {"significant": bool(residual_sig), "heldout_gap": g_after, "critical": crit,
                         "top_regions": top},
            "worse_regions": worse_regions(z0["heldout"], z["heldout"], regions, alpha)}


def with_resimulation(result: dict, resim: dict | None, reason: str = "") -> dict:
    """``result`` of :func:`diagnose` with its ``resimulation`` entry (:func:`resimulated`, or
    None: not re-simulated, for ``reason``): the verdict becomes the re-simulated one, the
    interpolated one stays in ``verdict_interpolated``; ``heldout_shrink_resimulated`` is the
    re-simulated shrink (None without a re-simulation)."""
    out = dict(result)
    out["verdict_interpolated"] = result.get("verdict_interpolated", result["verdict"])
    if resim is None:
        out["resimulation"] = {"done": False, "reason": reason}
        out["heldout_shrink_resimulated"] = None
        out["verdict"] = out["verdict_interpolated"]
    else:
        out["resimulation"] = resim
        out["heldout_shrink_resimulated"] = resim["heldout_shrink"]
        out["verdict"] = resim["verdict"] if result["verdict"] != NO_GAP else NO_GAP
    return out


def _regions(regions, z_before, z_after, select, sig_keys, gaps_cal) -> list[dict]:
    """Regions sorted by their calibration gap, with held-out gaps before and after."""
    before = g.region_gaps(z_before["heldout"], regions)
    after = g.region_gaps(z_after["heldout"], regions)
    n_sig: dict[tuple, int] = {}
    for r, s in zip(regions, select, strict=True):
        if s:
            n_sig[r.key] = n_sig.get(r.key, 0) + 1
    rows = []
    for key, gc in sorted(gaps_cal.items(), key=lambda kv: -kv[1]):
        rows.append({"domain": key[0], "channel": key[1], "family": key[2], "bin": key[3],
                     "calibration_gap": gc, "heldout_gap_before": before.get(key, float("nan")),
                     "heldout_gap_after": after.get(key, float("nan")),
                     "n_significant": n_sig.get(key, 0), "significant": key in sig_keys})
    return rows


def _hours(regions, z_before, z_after, select) -> list[dict]:
    b = g.hours_gaps(z_before["heldout"], regions, select)
    a = g.hours_gaps(z_after["heldout"], regions, select)
    return [{"hours": h, "heldout_gap_before": v, "heldout_gap_after": a.get(h, float("nan"))}
            for h, v in b.items()]
