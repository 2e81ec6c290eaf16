"""The blind benchmark of the gap diagnosis: "real" recordings made by the twin with an effect
(or none) the diagnosis is not told about, diagnosed against the nominal scenario, and scored.

Cases (:func:`plan_cases`, every draw from ``rng_seed``):

- ``single``: each effect of the library at two magnitudes: parameter values drawn uniformly in
  the lower ("low") or upper ("high") half of the effect's prior range (log-uniformly for
  log-scaled parameters; discrete ones uniformly among their grid values), ``per_cell`` cases
  per effect and magnitude;
- ``null``: the nominal twin with another seed;
- ``open_set``: an effect (upper half of its range) removed from the diagnosis's library for
  that case;
- ``pair``: two effects at once;
- ``artefact``: a signal artefact (:mod:`analysis.diagnosis.artefacts`) on the recording of the
  nominal twin with the case's seed: each artefact (gain, noise, mains line, order line, bias
  drift, time offset, clipping) at two magnitudes, its target drawn among the artefact's
  targets, ``artefacts_per_cell`` cases per artefact and magnitude; the recording is the twin's
  campaign post-processed (``measurements.h5`` rewritten), the diagnosis sees only its
  signature;
- ``parameter``: a twin parameter set wrong (:mod:`twin.harness.diagnosis.candidates.parameters`): the twin with one
  key's factor drawn away from 1 by at least 15 % (side and log distance within the prior
  range, "low" nearer 1, "high" farther, and beyond the least deviation the diagnosis sees on
  that side, ``TwinParameter.least_seen``), ``parameters_per_cell`` cases per candidate and
  magnitude (one with ``twin diagnose-benchmark``, whose ``--parameters 0`` leaves them out);
  the diagnosis then tries the twin parameters too;
- ``edit``: an edit of the recording no candidate models (:data:`analysis.diagnosis.artefacts.EDITS`:
  impulses, lost samples held, a low-pass filter) on the nominal twin's campaign with the
  case's seed, post-processed as the artefact cases, its target drawn; ``edits_per_cell`` cases
  per edit, drawn in the upper half of each parameter's range (as the open set: the gap is
  there, the question is whether the diagnosis invents an explanation).

Every case has its own seed (10 000 + case number), different from the twin's seeds. The
diagnosis sees only the signatures computed from each recording's ``measurements.h5``; the
benchmark alone knows what was injected (the case plan, also stored in the recording's
``truth.h5`` scenario) and scores:

- ``top1_accuracy``: single cases whose first added effect (the first-ranked candidate, with a
  significant held-out gain) is the injected one;
- ``median_heldout_shrink``: median over single cases of 1 − G_after/G_before on held-out data;
- ``null_correct_fraction``: null cases with verdict "no significant gap";
- ``open_set_correct_fraction``: open-set cases whose verdict is "unexplained gap remains" (a
  wrong effect may be added, but not presented as the explanation: that would take 90 % of the
  gap); ``open_set_no_wrong_effect_fraction``, stricter: and no false attribution (below);
- ``pair_both_top3_fraction``: pair cases with both effects among the first three of the ranking;
- ``out_of_everything_unexplained_fraction``: open-set and edit cases (nothing in the library
  explains them) whose verdict is "unexplained gap remains"; per kind in
  ``per_out_of_everything_unexplained``;
- ``false_attribution_rate``: cases where a candidate that was not injected (nor its
  same-recording twin, :func:`same_answer`) is added and its
  held-out gain is ``HIGH_SCORE`` (50 %) or more of the recording's held-out gap, over all cases; per case kind in
  ``per_case_kind_false_attribution``;
- ``median_heldout_shrink_resimulated``, ``per_kind_median_heldout_shrink_resimulated``: the
  same on the twin re-simulated with each case's added candidates (the first ``resim_seeds``
  twin seeds; the verdicts follow it), ``per_kind_median_shrink_difference`` the median
  |re-simulated − interpolated|;
- ``per_kind_top1``: top-1 accuracy per kind of candidate ("physical effect": the single cases,
  "signal artefact": the artefact cases, whose first added candidate must be the injected
  artefact on its target, "parameter": the parameter cases, the injected key first; with
  :func:`same_answer`, a twin parameter above 1 and the signal artefact that make the same
  recording answer for each other, and those cases are listed in ``same_recording``), with
  ``per_kind_median_heldout_shrink``; ``per_kind_top1_or_not_told_apart`` (the injected one
  first or among the ``alternatives`` of the first: candidates the data do not tell apart from
  it); ``per_artefact_top1``, ``per_parameter_top1``; ``per_kind_detected``: the cases whose
  verdict is not "no significant gap" (the injected change is beyond the twin's seed-to-seed
  spread), and ``per_kind_top1_when_detected`` (top1, or_not_told_apart, n) over those: what the
  diagnosis names when it sees something, apart from what it can see;
- each case's row lists its ``refused`` candidates (they passed the selection test but leave
  more than 10 % of the gap where they act: :mod:`analysis.diagnosis.attribution`) and each
  added candidate's ``footprint_gap_left``;
- ``confusion`` (also ``benchmark_confusion.csv``): the cases whose first added candidate is not
  the injected one, as (kind, injected, named first or none, count, case ids): the pairs the
  diagnosis does not tell apart, measured (:func:`confusion`).
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from analysis.base.executors import default_processes
from analysis.base.files import write_json
from analysis.diagnosis.artefacts import ARTEFACTS, EDITS, KIND_ARTEFACT, KIND_EFFECT, KIND_PARAMETER
from analysis.diagnosis.attribution import NO_GAP, UNEXPLAINED
from analysis.diagnosis.signature import PARTS
from analysis.diagnosis.wording import same_recording
from twin.harness.diagnosis.artefact_grid import artefact_cached, artefact_signatures
from twin.harness.diagnosis.cache import DEFAULT_RESPONSE_SEEDS, DEFAULT_SEEDS, evaluate_all, with_seed
from twin.harness.diagnosis.candidates import candidates
from twin.harness.diagnosis.candidates.parameters import PARAMETERS
from twin.harness.diagnosis.ensemble import build_ensemble, diagnose_signatures
from twin.harness.diagnosis.library import DEFAULT_KINDS, with_effects
from twin.harness.diagnosis.resimulation import add_resimulation, simulate_with_added
from twin.sim.scenario import Scenario

#: Twin seeds the benchmark re-simulates each case with (fewer than the spread's K: the
#: re-simulation costs that many campaigns per case with candidates added; docs/gap-diagnosis.md).
DEFAULT_RESIM_SEEDS = 2
HIGH_SCORE = 0.5  # a false attribution: a wrong candidate added that removes this much of the gap
#: The cases nothing in the library explains: physics withheld from the library (open set) and
#: edits of the recording no candidate models (:data:`analysis.diagnosis.artefacts.EDITS`).
OUT_OF_EVERYTHING = {"open_set": "physics withheld", "edit": "recording edit"}
CASE_SEED0 = 10_000


@dataclass
class Case:
    """One benchmark case: id, kind (single | null | open_set | pair | artefact | parameter),
    injected effects or twin parameters {name: {param: value}}, magnitude (single and artefact cases), seed, the library
    the diagnosis may use (None: every candidate, effects and artefacts), and the signal
    artefacts applied to the recording {candidate: {param: value}}."""

    id: str
    kind: str
    effects: dict[str, dict[str, float]]
    magnitude: str
    seed: int
    library: list[str] | None
    artefacts: dict[str, dict[str, float]] = field(default_factory=dict)


def plan_cases(rng_seed: int = 2026, per_cell: int = 1, nulls: int = 10, open_set: int = 5,
               pairs: int = 5, library: list[str] | None = None,
               artefacts_per_cell: int = 1, parameters_per_cell: int = 1,
               edits_per_cell: int = 2) -> list[Case]:
    """The benchmark's cases (deterministic in ``rng_seed``; the artefact cases, then the
    parameter cases come after the others and draw after them, so adding them changes no case
    before; the recording edits come last, drawn from a stream of their own)."""
    effects = candidates()
    lib = list(effects) if library is None else list(library)
    rng = np.random.default_rng(rng_seed)
    cases: list[Case] = []

    def add(kind, effects, magnitude="", library=None, artefacts=None):
        n = len(cases)
        cases.append(Case(f"{kind}-{n:03d}", kind, effects, magnitude, CASE_SEED0 + n,
                          None if library is None else list(library), dict(artefacts or {})))

    for name in lib:
        for mag in ("low", "high"):
            for _ in range(per_cell):
                add("single", {name: effects[name].draw(rng, mag)}, mag)
    for _ in range(nulls):
        add("null", {})
    for name in rng.permutation(lib)[:open_set]:
        # The upper half of the range: the gap is clearly there (check 1 covers both
        # magnitudes), the question is only whether the diagnosis invents an explanation.
        add("open_set", {str(name): effects[str(name)].draw(rng, "high")}, "high",
            [n for n in lib if n != name] + list(ARTEFACTS) + list(PARAMETERS))
    for _ in range(pairs):
        a, b = (str(n) for n in rng.choice(lib, 2, replace=False))
        add("pair", {a: effects[a].draw(rng, "high"), b: effects[b].draw(rng, "high")}, "high")
    kinds: dict[str, list[str]] = {}
    for name, art in ARTEFACTS.items():
        kinds.setdefault(art.artefact, []).append(name)
    for names in kinds.values():
        for mag in ("low", "high"):
            for _ in range(artefacts_per_cell):
                name = str(rng.choice(names))
                add("artefact", {}, mag, artefacts={name: ARTEFACTS[name].draw(rng, mag)})
    for name, par in PARAMETERS.items():
        for mag in ("low", "high"):
            for _ in range(parameters_per_cell):
                add("parameter", {name: par.draw(rng, mag)}, mag)
    edit_kinds: dict[str, list[str]] = {}
    for name, ed in EDITS.items():
        edit_kinds.setdefault(ed.artefact, []).append(name)
    # The edits draw from a stream of their own: adding parameter cases before them changes
    # their ids and seeds, not what they are.
    edit_rng = np.random.default_rng([rng_seed, 1])
    for names in edit_kinds.values():
        # As for the open set, the upper half of each range: the gap is clearly there, the
        # question is only whether the diagnosis invents an explanation.
        for _ in range(edits_per_cell):
            name = str(edit_rng.choice(names))
            add("edit", {}, "high", artefacts={name: EDITS[name].draw(edit_rng, "high")})
    return cases


def same_answer(injected: str, injected_values: dict[str, float], named: str,
                named_values: dict[str, float]) -> bool:
    """Whether naming ``named`` (with its fitted values) answers a case that injected ``injected``
    (with its values): the same candidate, or two that make the same recording
    (:func:`analysis.diagnosis.wording.same_recording`, the rule the verdict's words use, on the
    twin parameters' ``same_above_one``: a torque signal twice as noisy and white noise added on
    it are one recording, which no diagnosis can tell apart)."""
    if named == injected:
        return True
    library = {n: {"same_recording_above_one": PARAMETERS[n].same_above_one}
               for n in (injected, named) if n in PARAMETERS}
    return same_recording({"library": library}, {"effect": injected, "params": injected_values},
                          {"effect": named, "params": named_values})


def _score_case(case: Case, res: dict) -> dict:
    ranking = [r["effect"] for r in res["ranking"]]
    added = res["added"]
    top = next((r for r in res["regions"] if r["significant"]), None)
    row = {"id": case.id, "kind": case.kind, "injected": sorted(case.effects) + list(case.artefacts),
           "values": {**case.effects, **case.artefacts}, "magnitude": case.magnitude, "seed": case.seed,
           "added_kinds": [a.get("kind", KIND_EFFECT) for a in added],
           "verdict": res["verdict"], "ranking": ranking[:3],
           "added": [a["effect"] for a in added],
           "footprint_gap_left": {a["effect"]: a.get("footprint_gap_left") for a in added},
           "refused": [a["effect"] for a in res.get("refused", [])],
           "fitted": {a["effect"]: a["params"] for a in added},
           "intervals": {a["effect"]: a["interval"] for a in added},
           "heldout_gap_before": res["heldout_gap_before"],
           "heldout_gap_after": res["heldout_gap_after"],
           "heldout_shrink": res["heldout_shrink"],
           "heldout_shrink_resimulated": res.get("heldout_shrink_resimulated"),
           "heldout_gap_after_resimulated": (res.get("resimulation") or {}).get("heldout_gap_after"),
           "verdict_interpolated": res.get("verdict_interpolated", res["verdict"]),
           "n_significant": res["n_significant_calibration"], "n_statistics": res["n_statistics"],
           "top_region": ([top["domain"], top["channel"], top["family"], top["bin"]] if top else None)}
    values = {**case.effects, **case.artefacts}

    def true_answer(a: dict) -> bool:
        return any(same_answer(name, v, a["effect"], a["params"]) for name, v in values.items())

    if case.kind in ("single", "parameter", "artefact"):
        injected = next(iter(case.artefacts or case.effects))
        row["correct"] = bool(added and same_answer(injected, values[injected], added[0]["effect"],
                                                    added[0]["params"]))
        # the injected candidate first, or among those the data do not tell apart from the first
        row["alternatives"] = [a["effect"] for a in (added[0].get("alternatives", []) if added else [])]
        row["correct_or_not_told_apart"] = bool(row["correct"] or injected in row["alternatives"])
    gap = res["heldout_gap_before"]
    row["false_attribution"] = bool(gap > 0 and any(
        not true_answer(a) and a["gain"] >= HIGH_SCORE * gap for a in added))
    if case.kind == "null":
        row["correct"] = res["verdict"] == NO_GAP
    elif case.kind in OUT_OF_EVERYTHING:
        row["correct"] = res["verdict"] == UNEXPLAINED
        row["no_wrong_effect"] = row["correct"] and not row["false_attribution"]
    elif case.kind == "pair":
        row["correct"] = bool(res["verdict"] != NO_GAP and set(case.effects) <= set(ranking[:3]))
    return row


def _fit_errors(singles: list[dict]) -> dict[str, float]:
    """Median |fitted − injected| / |injected| of each continuous parameter over the single
    cases where the injected effect was added first (not its same-recording twin, whose
    parameters differ)."""
    errs: dict[str, list[float]] = {}
    effects = candidates()
    for r in singles:
        name = r["injected"][0]
        if not r["correct"] or name not in r["fitted"]:
            continue
        for p in (effects.get(name) or PARAMETERS.get(name) or ARTEFACTS[name]).params:
            if p.discrete:
                continue
            true, fit = r["values"][name][p.name], r["fitted"][name][p.name]
            errs.setdefault(f"{name}.{p.name}", []).append(abs(fit - true) / abs(true))
    return {k: float(np.median(v)) for k, v in sorted(errs.items())}


def interval_coverage(rows: list[dict]) -> dict:
    """How often the stated interval of a fitted parameter holds the injected value: over the
    continuous parameters of the injected candidate in the single, artefact and parameter cases
    where it was added first. Returns {"per_kind": {kind: fraction or None}, "per_parameter":
    {candidate.param: fraction}, "n": {kind: count}, "median_relative_half_width": {kind: the
    median of (hi − lo) / 2 / |injected| or None}, "missed": [[case, candidate.param, injected,
    [lo, hi]], ...]}."""
    effects = candidates()
    kind_of_case = {"single": KIND_EFFECT, "artefact": KIND_ARTEFACT, "parameter": KIND_PARAMETER}
    hits: dict[str, list[bool]] = {k: [] for k in kind_of_case.values()}
    widths: dict[str, list[float]] = {k: [] for k in kind_of_case.values()}
    per_param: dict[str, list[bool]] = {}
    missed = []
    for r in rows:
        if r["kind"] not in kind_of_case or not r.get("correct") or r["injected"][0] not in r["intervals"]:
            continue
        name = r["injected"][0]
        for p in (effects.get(name) or PARAMETERS.get(name) or ARTEFACTS[name]).params:
            if p.discrete:
                continue
            true = r["values"][name][p.name]
            lo, hi = r["intervals"][name][p.name]
            inside = bool(lo - 1e-9 * abs(true) <= true <= hi + 1e-9 * abs(true))
            hits[kind_of_case[r["kind"]]].append(inside)
            widths[kind_of_case[r["kind"]]].append((hi - lo) / 2.0 / abs(true))
            per_param.setdefault(f"{name}.{p.name}", []).append(inside)
            if not inside:
                missed.append([r["id"], f"{name}.{p.name}", true, [lo, hi]])
    return {"per_kind": {k: (float(np.mean(v)) if v else None) for k, v in hits.items()},
            "n": {k: len(v) for k, v in hits.items()},
            "median_relative_half_width": {k: (float(np.median(v)) if v else None) for k, v in widths.items()},
            "per_parameter": {k: float(np.mean(v)) for k, v in sorted(per_param.items())},
            "missed": missed}


def confusion(rows: list[dict]) -> list[dict]:
    """What the diagnosis cannot tell apart, measured: every single, parameter and artefact case
    whose first added candidate is not the injected one, grouped by (kind, injected, named) with
    the count and the case ids, most frequent first. ``named`` is the first added candidate, or
    ``None`` when nothing was added (``verdict`` then says whether a gap was seen at all)."""
    groups: dict[tuple, dict] = {}
    for r in rows:
        if r["kind"] not in ("single", "parameter", "artefact") or r["correct"]:
            continue
        named = r["added"][0] if r["added"] else None
        key = (r["kind"], r["injected"][0], named, None if named else r["verdict"])
        g = groups.setdefault(key, {"kind": r["kind"], "injected": r["injected"][0], "named": named,
                                    "verdict": key[3], "count": 0, "cases": []})
        g["count"] += 1
        g["cases"].append(r["id"])
    return sorted(groups.values(), key=lambda g: (-g["count"], g["kind"], g["injected"], str(g["named"])))


def _fraction(rows, kind) -> float | None:
    sel = [r["correct"] for r in rows if r["kind"] == kind]
    return float(np.mean(sel)) if sel else None


def run_benchmark(out: Path, nominal: Scenario, cases: list[Case], *, seeds: int = DEFAULT_SEEDS,
                  workers: int | None = None, alpha: float = 0.01, cache: Path | None = None,
                  on_progress: Callable[[str, int, int], None] | None = None,
                  kinds: tuple[str, ...] | list[str] | None = None,
                  resim_seeds: int = DEFAULT_RESIM_SEEDS,
                  response_seeds: int = DEFAULT_RESPONSE_SEEDS) -> dict:
    """Simulate, diagnose and score every case; writes OUT/benchmark.json and
    OUT/benchmark_cases.csv and returns the summary. ``kinds``: the kinds of candidate the
    diagnosis tries (default :data:`DEFAULT_KINDS`, and "parameter" when there are parameter
    cases). Every case with candidates added is re-simulated with them for the first
    ``resim_seeds`` twin seeds (0: none; all the cases' campaigns together,
    :func:`twin.harness.diagnosis.resimulation.simulate_with_added`) and scored with the verdict that gives."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(cache) if cache else out / "cache"
    workers = workers or default_processes()
    t0 = time.perf_counter()
    prog = (lambda what: (lambda d, n: on_progress(what, d, n))) if on_progress else (lambda what: None)
    if kinds is None:
        kinds = tuple(DEFAULT_KINDS) + (("parameter",) if any(c.kind == "parameter" for c in cases)
                                         and "parameter" not in DEFAULT_KINDS else ())
    ens = build_ensemble(nominal, cache, seeds, workers, None, prog("twin and candidates"), kinds,
                         response_seeds=response_seeds)
    t_ens = time.perf_counter() - t0
    reals = [with_seed(with_effects(nominal, c.effects), c.seed) for c in cases]
    plain = [i for i, c in enumerate(cases) if not c.artefacts]
    post = [i for i, c in enumerate(cases) if c.artefacts]
    sigs: list = [None] * len(cases)
    for i, sg in zip(plain, evaluate_all([reals[i] for i in plain], cache, workers, prog("recordings")),
                     strict=True):
        sigs[i] = sg
    # Recordings with artefacts: the twin's campaign (kept once simulated), post-processed.
    todo = [i for i in post if not artefact_cached(reals[i], [cases[i].artefacts], cache)]
    evaluate_all([reals[i] for i in todo], cache, workers, prog("recordings to post-process"), keep=True)
    for i in post:
        sigs[i] = artefact_signatures(reals[i], [cases[i].artefacts], cache, 1, keep_campaign=False)[1][0]
    t_real = time.perf_counter() - t0 - t_ens
    results = [diagnose_signatures({p: sig[p] for p in PARTS}, ens, case.library, alpha)[0]
               for case, sig in zip(cases, sigs, strict=True)]
    t_diag = time.perf_counter() - t0 - t_ens - t_real
    # The re-simulated shrink: the twin run with each case's added candidates (all cases at once).
    todo = [i for i, r in enumerate(results) if r["added"] and r["verdict"] != NO_GAP] if resim_seeds else []
    resims: list = [None] * len(cases)
    for i, rs in zip(todo, simulate_with_added(ens, [results[i]["added"] for i in todo], cache, workers,
                                      resim_seeds, on_progress=prog("re-simulations")), strict=True):
        resims[i] = rs
    rows = []
    for case, sig, res, rs in zip(cases, sigs, results, resims, strict=True):
        res = add_resimulation(res, {p: sig[p] for p in PARTS}, ens, rs, alpha)
        rows.append(_score_case(case, res))
    t_all = time.perf_counter() - t0
    singles = [r for r in rows if r["kind"] == "single"]
    arts = [r for r in rows if r["kind"] == "artefact"]
    pars = [r for r in rows if r["kind"] == "parameter"]
    by_kind = ((KIND_EFFECT, singles), (KIND_ARTEFACT, arts), (KIND_PARAMETER, pars))
    med = lambda rs: float(np.median([r["heldout_shrink"] for r in rs])) if rs else None  # noqa: E731

    def med_resim(rs: list[dict]) -> float | None:
        vals = [r["heldout_shrink_resimulated"] for r in rs if r["heldout_shrink_resimulated"] is not None]
        return float(np.median(vals)) if vals else None

    def resim_diff(rs: list[dict]) -> float | None:
        vals = [abs(r["heldout_shrink_resimulated"] - r["heldout_shrink"]) for r in rs
                if r["heldout_shrink_resimulated"] is not None]
        return float(np.median(vals)) if vals else None

    summary = {
        "scenario": nominal.name, "twin_seeds": ens.seeds, "alpha": alpha,
        "n_cases": len(rows),
        "top1_accuracy": _fraction(rows, "single"),
        "median_heldout_shrink": float(np.median([r["heldout_shrink"] for r in singles])) if singles else None,
        "median_heldout_shrink_resimulated": med_resim(singles),
        "resim_seeds": min(resim_seeds, len(ens.seeds)),
        "response_seeds": response_seeds,
        "n_resimulated": len(todo),
        "verdict_changed_by_resimulation": [r["id"] for r in rows if r["verdict"] != r["verdict_interpolated"]],
        "null_correct_fraction": _fraction(rows, "null"),
        "open_set_correct_fraction": _fraction(rows, "open_set"),
        "open_set_no_wrong_effect_fraction": (float(np.mean([r["no_wrong_effect"] for r in rows
                                                             if r["kind"] == "open_set"]))
                                              if any(r["kind"] == "open_set" for r in rows) else None),
        "pair_both_top3_fraction": _fraction(rows, "pair"),
        "out_of_everything_unexplained_fraction": (
            float(np.mean([r["correct"] for r in rows if r["kind"] in OUT_OF_EVERYTHING]))
            if any(r["kind"] in OUT_OF_EVERYTHING for r in rows) else None),
        "per_out_of_everything_unexplained": {words: _fraction(rows, kind)
                                              for kind, words in OUT_OF_EVERYTHING.items()},
        "false_attribution_rate": float(np.mean([r["false_attribution"] for r in rows])) if rows else None,
        "per_case_kind_false_attribution": {
            kind: float(np.mean([r["false_attribution"] for r in rows if r["kind"] == kind]))
            for kind in dict.fromkeys(r["kind"] for r in rows)},
        "kinds": sorted({c.kind for c in ens.candidates}),
        "per_kind_top1": {KIND_EFFECT: _fraction(rows, "single"), KIND_ARTEFACT: _fraction(rows, "artefact"),
                          KIND_PARAMETER: _fraction(rows, "parameter")},
        "per_kind_median_heldout_shrink": {KIND_EFFECT: med(singles), KIND_ARTEFACT: med(arts),
                                           KIND_PARAMETER: med(pars)},
        "per_kind_median_heldout_shrink_resimulated": {KIND_EFFECT: med_resim(singles), KIND_ARTEFACT: med_resim(arts),
                                                       KIND_PARAMETER: med_resim(pars)},
        "per_kind_median_shrink_difference": {KIND_EFFECT: resim_diff(singles), KIND_ARTEFACT: resim_diff(arts),
                                              KIND_PARAMETER: resim_diff(pars)},
        "per_kind_top1_or_not_told_apart": {
            kind: (float(np.mean([r["correct_or_not_told_apart"] for r in rs])) if rs else None)
            for kind, rs in by_kind},
        "per_kind_detected": {
            kind: (float(np.mean([r["verdict"] != NO_GAP for r in rs])) if rs else None)
            for kind, rs in by_kind},
        "per_kind_top1_when_detected": {
            kind: ({"top1": float(np.mean([r["correct"] for r in d])),
                    "or_not_told_apart": float(np.mean([r["correct_or_not_told_apart"] for r in d])), "n": len(d)}
                   if d else None)
            for kind, d in ((k, [r for r in rs if r["verdict"] != NO_GAP]) for k, rs in by_kind)},
        "per_parameter_top1": {name: float(np.mean([r["correct"] for r in pars if r["injected"] == [name]]))
                               for name in sorted({r["injected"][0] for r in pars})},
        "per_artefact_top1": {k: float(np.mean([r["correct"] for r in arts
                                                if ARTEFACTS[r["injected"][0]].artefact == k]))
                              for k in sorted({ARTEFACTS[r["injected"][0]].artefact for r in arts})},
        "fitted_relative_error": _fit_errors(singles + arts + pars),
        "interval_coverage": interval_coverage(rows),
        "per_effect_top1": {name: float(np.mean([r["correct"] for r in singles if r["injected"] == [name]]))
                            for name in sorted({r["injected"][0] for r in singles})},
        "confusion": confusion(rows),
        "same_recording": [{"id": r["id"], "injected": r["injected"][0], "named": r["added"][0]} for r in rows
                           if r.get("correct") and r["kind"] in ("single", "parameter", "artefact")
                           and r["added"][0] != r["injected"][0]],
        "wall_time_s": {"twin_and_candidates": t_ens, "recordings": t_real,
                        "diagnoses": t_diag, "resimulations": t_all - t_ens - t_real - t_diag, "total": t_all},
        "cases": rows,
        "plan": [asdict(c) for c in cases],
    }
    write_json(out / "benchmark.json", summary, nan_as_null=True)
    with open(out / "benchmark_cases.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "kind", "injected", "magnitude", "verdict", "ranking", "added",
                    "heldout_shrink", "heldout_shrink_resimulated", "verdict_interpolated", "correct"])
        for r in rows:
            w.writerow([r["id"], r["kind"], "+".join(r["injected"]) or "-", r["magnitude"],
                        r["verdict"], " > ".join(r["ranking"]), "+".join(r["added"]) or "-",
                        f"{r['heldout_shrink']:.3f}",
                        "" if r["heldout_shrink_resimulated"] is None else f"{r['heldout_shrink_resimulated']:.3f}",
                        r["verdict_interpolated"], r["correct"]])
    with open(out / "benchmark_confusion.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["kind", "injected", "named first", "verdict when none", "count", "cases"])
        for g in summary["confusion"]:
            w.writerow([g["kind"], g["injected"], g["named"] or "-", g["verdict"] or "", g["count"],
                        " ".join(g["cases"])])
    return summary
