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
Σ t² (each t with the responses' error allowed for, below), less the twin's noise (1 per
statistic), must be no more than 1 − ``explained_fraction`` (10 %) of its Σ t² before: the verdict's 90 % rule
applied where the candidate acts. A candidate that leaves more approximates a gap whose shape it
does not have (a resonance standing in for a speed-locked line, a drifting bias for a
misalignment's constant offset): it is *refused* (``refused``, with the fraction it left) and the
selection runs again without it, until every added candidate passes; what it would have absorbed
stays unexplained (docs/gap-diagnosis.md gives the measured fractions of right and refused
candidates).

**The response's own error.** The recording's machine is another draw than the seeds a response
was computed with (a mains line's phase at each transient moves a transient's correlation by
hundreds of σ from seed to seed). Where a candidate acts (its response moves the statistic by at
least ``FOOTPRINT_SIGMAS`` σ), its error variance v_j is twice its response's variance over the
response seeds (:func:`response_error_var`); a t_j it leaves within that variation (Student's t
with R − 1 degrees of freedom, :func:`error_scale`) counts as t_j/√(1 + v_j) in the fit (step 1),
in G after it (step 2), in the regions it makes worse, in the footprint and in the verdict;
beyond it, or where the candidate does not act, t_j counts whole (a candidate only random where
the gap is does not explain the gap).

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
:func:`merge_resimulation` makes the verdict follow it.

The ranking lists the added effects in the order they were added, then the others by their
net held-out reduction in the last round. ``worse_regions`` of the summary compares the twin
with all the added effects to the twin as it is.
"""

from __future__ import annotations

import numpy as np

from analysis.diagnosis import gap as g
from analysis.diagnosis.fit import (
    FOOTPRINT_SIGMAS,
    TIE_FRACTION,
    TIE_SIGMAS,
    WORSE_FRACTION,
    Fit,
    alternatives,
    chi2_quantile,
    error_scale,
    fit_candidate,
    footprint_left,
    response_dof,
    response_error_var,
    worse_regions,
)
from analysis.diagnosis.intervals import (
    BOOTSTRAP_DRAWS,
    INTERVAL_LEVEL,
    bootstrap_interval,
    interpolation_shift,
    noise_interval,
    seed_interval,
    stated_interval,
)
from analysis.diagnosis.response import CandidateResponse, ParamAxis, grid_edge, search_step
from analysis.diagnosis.signature import Signature

NO_GAP, EXPLAINED, UNEXPLAINED = "no significant gap", "explained", "unexplained gap remains"
#: Raised when the rules of the attribution change (a benchmark's recorded diagnoses are keyed on it).
ATTRIBUTION_VERSION = 3  # 3: twin check's clipped or flat channels left out and named (flagged.py)


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
        bad = []
        for f in added:
            f.footprint_statistics, f.footprint_gap_left = footprint_left(
                f.delta_heldout, sd["heldout"], sel_ho, z0["heldout"], z["heldout"])
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
    sd0 = {p: sp[p].sd for p in sp}
    sd = dict(sd0)  # the current model's spread: the twin's and the added responses' errors
    delta = {p: np.zeros_like(z0[p]) for p in z0}
    added_responses: list[tuple[CandidateResponse, dict[str, float]]] = []
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
        added_responses.append((cand, best.params))
        err_added, dof_added = _summed_error(added_responses, sd0)
        z = {p: g.zscores(real[p], sp[p], delta[p]) for p in sp}
        scale = {p: error_scale(z[p], err_added[p], alpha, dof_added) for p in sp}
        sd = {p: sd0[p] * scale[p] for p in sp}
        z = {p: z[p] / scale[p] for p in sp}
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


def _summed_error(responses: list[tuple[CandidateResponse, dict[str, float]]],
                  sd: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], int | None]:
    """({part: (n,)} the summed :func:`response_error_var` of the candidates at their parameters
    ``responses`` [(candidate, {name: value})], in units of ``sd`` {part: (n,)} squared; the least
    degrees of freedom of those estimates, :func:`response_dof`)."""
    err = {p: sum((response_error_var(c, params, sd[p], p) for c, params in responses), np.zeros_like(sd[p]))
           for p in sd}
    return err, min((d for c, _ in responses if (d := response_dof(c))), default=None)


def added_error_var(candidates: list[CandidateResponse], added: list[dict],
                    twin: dict[str, list[Signature]]) -> tuple[dict[str, np.ndarray], int | None]:
    """:func:`_summed_error` of the ``added`` candidates (entries of the result's ``added``: effect,
    params) against the twin's spread: how far the recording's change by them may stand from the
    twin's response to them, and the degrees of freedom of that estimate."""
    by_name = {c.name: c for c in candidates}
    return _summed_error([(by_name[a["effect"]], a["params"]) for a in added],
                         {p: g.spread(twin[p]).sd for p in ("cal", "heldout")})


def resimulated_gap(real: dict[str, Signature], twin: dict[str, list[Signature]],
                resim: dict[str, list[Signature]], *, alpha: float = 0.01,
                explained_fraction: float = 0.9,
                error_var: tuple[dict[str, np.ndarray], int | None] | None = None) -> dict:
    """The held-out gap with the added candidates **re-simulated** instead of interpolated.

    ``resim``: {part: [signature of twin seed k with every added candidate applied at its fitted
    values]} for the first n ≤ K seeds of ``twin`` (the same seeds, in order). The added
    candidates' response is then Δ_j = mean over those seeds of (resim_k,j − twin_k,j) (common
    random numbers, as for the grid: with all K seeds it is the mean of the re-simulated twin
    minus the mean of the twin), and the statistic is the interpolated one with Δ in place of
    the interpolated, additive response: G = Σ_{j∈S} (r_j − μ_j − Δ_j)²/(σ_j²(1 + v_j)) over the
    same statistics S, with the twin's own spread σ_j and the error variance v_j of the added
    responses where what is left is within it (``error_var``, :func:`added_error_var`: the
    variances and their degrees of freedom; none when None; :func:`error_scale`), as for the
    interpolated G (a statistic no re-simulated seed could compute
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
    if error_var is not None:
        z = {p: z[p] / error_scale(z[p], error_var[0][p], alpha, error_var[1]) for p in sp}
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


def merge_resimulation(result: dict, resim: dict | None, reason: str = "") -> dict:
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


#: What the attribution offers, its parts' names included (:mod:`.response`, :mod:`.fit`,
#: :mod:`.intervals`).
__all__ = ["ATTRIBUTION_VERSION", "BOOTSTRAP_DRAWS", "EXPLAINED", "FOOTPRINT_SIGMAS", "INTERVAL_LEVEL", "NO_GAP",
           "TIE_FRACTION", "TIE_SIGMAS", "UNEXPLAINED", "WORSE_FRACTION", "added_error_var", "alternatives",
           "bootstrap_interval", "CandidateResponse", "chi2_quantile", "diagnose", "error_scale", "Fit",
           "fit_candidate", "footprint_left", "grid_edge", "interpolation_shift", "merge_resimulation",
           "noise_interval", "ParamAxis", "resimulated_gap", "response_dof", "response_error_var", "search_step",
           "seed_interval", "stated_interval", "worse_regions"]
