"""The calibration fitted again with a candidate effect in the twin.

A calibration is fitted to a recording of the machine as it is, unmodelled effects included: an
effect the twin does not have moves the statistics layer (c) reads (a base resonance rings in
the carriage's pitch and in the speed loop's response), and the fit bends the parameters read
on them (the trucks' stiffness, the velocity loop) to take part of it. The diagnosis against
that twin then looks for what the calibration *left*: the effect's footprint is no longer the
effect's (the calibration took a share of it), a candidate fitted on it approximates the gap
without explaining it, and it is refused or not named.

So when a calibrated twin leaves an unexplained gap, :func:`refit_candidates` takes the
leading physical effects of the diagnosis (by their held-out gain, refused ones included: a
refusal may be the calibration's doing) and :func:`refit_with` calibrates the twin again on the
recording (``twin calibrate``, its three layers) with each in the twin. The effect's size is not
the diagnosis's: fitted against a twin that took part of it, it is too small (and interpolated
between the grid's simulations); the calibration is fitted with the effect at each size its grid
simulates (:func:`refit_sizes`), and the recording diagnosed against each refitted twin with the
effect as the only candidate (its size fitted again). Layer (c) has about as many parameters as
statistics, so its χ² can come out near zero at more than one size and does not choose; the
diagnosis's held-out part does: the size kept is the one whose diagnosis explains the gap with
the least held-out gap left, in units of its critical value (a profile over the effect's size on
its grid: Press et al., Numerical Recipes, 3rd ed., §15.6). Each refitted twin is judged in its
own spread, so a refit that keeps a parameter at its default over its prior span (a wider
spread) is favoured. The effect explains when that diagnosis adds it and calls the gap
explained, or finds no significant gap; the calibrated values the refit moved, against their
first interval, are in the entry.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from analysis.diagnosis import attribution
from analysis.diagnosis.artefacts import ARTEFACTS
from analysis.diagnosis.wording import gap_number, number
from twin.harness.calibration.values import CalibrationError
from twin.sim.config import get_dotted
from twin.sim.scenario import Scenario

#: Raised when what a refit does changes (a benchmark's recorded diagnoses are keyed on it).
REFIT_VERSION = 2  # 2: the benchmark row says refitted_with

#: The leading physical effects the calibration is fitted again with (each costs a calibration per
#: size of its grid, :func:`refit_sizes`, and a one-candidate diagnosis).
REFIT_EFFECTS = 1

#: The kinds of candidate a refit takes: a physical effect changes what layer (c) simulates; a
#: signal artefact (post-processing of the recording) and a twin parameter (layer c's own) do not.
REFIT_KINDS = ("physical effect",)


def refit_candidates(result: dict, nominal: Scenario, n: int = REFIT_EFFECTS) -> list[dict]:
    """The entries of ``result`` (a diagnosis's, ``ranking`` and ``refused``) to fit the
    calibration again with: none unless ``nominal`` was calibrated with a layer (c) fit (a fitted
    value in its ``[calibration]`` table) and the verdict is "unexplained gap remains"; else the
    ``n`` physical effects with the largest positive held-out gain, not already added, that set
    no key layer (c) fits (``servo_dynamics`` scales the velocity loop: a calibration takes it
    whole, there is nothing to fit again)."""
    from twin.harness.calibration.values import FITTED
    from twin.harness.diagnosis.library import simulated

    fits = {k for k, *_ in FITTED}
    cal = nominal.calibration or {}
    fitted = any(isinstance(v, dict) and v.get("source") == "fitted" for v in cal.values())
    if not fitted or result.get("verdict") != attribution.UNEXPLAINED:
        return []
    added = {a["effect"] for a in result.get("added", [])}
    seen: dict[str, dict] = {}
    for e in [*result.get("refused", []), *result.get("ranking", [])]:
        if (e.get("kind") in REFIT_KINDS and e["effect"] not in added and (e.get("gain") or 0.0) > 0.0
                and not fits & {k for p in simulated(e["effect"]).params for k in p.keys}):
            if e["effect"] not in seen or e["gain"] > seen[e["effect"]]["gain"]:
                seen[e["effect"]] = e
    return sorted(seen.values(), key=lambda e: -e["gain"])[:n]


def refit_sizes(choice: dict) -> list[dict]:
    """The effect's values the calibration is fitted again with, for the diagnosis entry
    ``choice`` (effect, params): its amplitude parameter at every value of its grid but the one
    that removes the effect (the sizes the grid simulates), the others at their fitted values;
    an effect without an amplitude parameter, at its fitted values only."""
    from twin.harness.diagnosis.library import simulated

    eff = simulated(choice["effect"])
    params = dict(choice["params"])
    amp = next((p for p in eff.params if p.name == eff.amplitude), None)
    if amp is None or amp.discrete:
        return [params]
    return [{**params, amp.name: float(v)} for v in amp.grid if v != amp.off]


def moved_values(nominal: Scenario, values: list[dict], refitted: Scenario) -> list[dict]:
    """The values the first calibration of ``nominal`` fitted and the refit (``values``: its
    record's, key, value, source, low, high; ``refitted``: its scenario) fitted or kept at the
    twin's default: {key, calibrated, low, high (its 90 % interval), refitted, refit_low,
    refit_high (None where kept), kept (the refit kept it at the default: not told apart or not
    informed with the effect in), outside (the refitted value outside the first interval)}."""
    cal = nominal.calibration or {}
    data = refitted.model_dump(mode="json")
    fitted = {v["key"]: v for v in values if v.get("source") == "fitted"}
    first = [k for k, c in cal.items() if isinstance(c, dict) and c.get("source") == "fitted"]
    rows = []
    for key in first + [k for k in fitted if k not in first]:
        c, v = cal.get(key) or {}, fitted.get(key)
        lo, hi = c.get("low"), c.get("high")
        value = v["value"] if v else float(get_dotted(data, key))
        rows.append({"key": key, "calibrated": c.get("value"), "low": lo, "high": hi, "refitted": value,
                     "refit_low": v.get("low") if v else None, "refit_high": v.get("high") if v else None,
                     "kept": v is None, "outside": bool(lo is not None and hi is not None and not lo <= value <= hi)})
    return rows


def refit_with(choice: dict, real_dir: Path, nominal: Scenario, out: Path, cache: Path, *,
               diagnose: Callable[..., dict], workers: int, scheduler: str | None,
               check: dict | None, progress: Callable[[str], None]) -> tuple[dict, dict | None]:
    """The twin calibrated again on the recording ``real_dir`` (``twin calibrate``, written to
    ``out/<effect>/axis-<i>.toml``) with the physical effect of ``choice`` (a diagnosis entry:
    effect, params) in it at each of :func:`refit_sizes`, and ``diagnose`` (the runner's
    :func:`run_diagnosis`, keyword arguments library, out, cache) of the recording against each
    refitted twin with the effect as the only candidate (``out/<effect>/diagnosis-<i>``); the
    size kept is the one whose diagnosis explains with the least held-out gap left.

    Returns (the ``refit`` entry of the effect, that diagnosis's result or None): the entry holds
    effect, done, tried ([{params, chi2, misfit, explains, left}] per size: layer c's χ² and
    misfit, the held-out gap left over its critical value), params (the size kept), values
    (:func:`moved_values`), misfit (the kept refit's), diagnosis {verdict, added,
    heldout_gap_before, heldout_gap_critical, heldout_gap_after, heldout_shrink,
    heldout_shrink_resimulated}, explains, seconds and sentence (:func:`refit_sentence`); or
    effect, done False, reason and sentence when the twin cannot be calibrated with it."""
    from twin.harness.calibration.run import calibrate
    from twin.harness.diagnosis.library import simulated
    from twin.sim.scenario import load

    t0 = time.perf_counter()
    name = choice["effect"]
    if name in ARTEFACTS:
        raise ValueError(f"refit with {name!r}: a signal artefact; expected a physical effect")
    eff = simulated(name)
    tried: list[dict] = []
    for i, params in enumerate(refit_sizes(choice)):
        progress(f"refit: the calibration again with {name} ({_params(params)}) in the twin")
        toml = Path(out) / name / f"axis-{i}.toml"
        try:
            rec = calibrate(real_dir, toml, workers=workers, scheduler=scheduler, cache=Path(cache) / "refit",
                            name=nominal.name, progress=lambda t: progress(f"refit: {t}"), check=check,
                            twin_with=lambda s, p=params: eff.apply(s, p))
        except CalibrationError as exc:
            return with_sentence({"effect": name, "done": False, "reason": str(exc)}), None
        if not any(v["source"] == "fitted" for v in rec["values"]):
            continue
        progress(f"refit: diagnosing against the twin calibrated with {name} ({_params(params)})")
        refitted = load(toml)
        sub = diagnose(refitted, library=[name], out=Path(out) / name / f"diagnosis-{i}", cache=Path(cache))
        added = [a["effect"] for a in sub.get("added", [])]
        explains = sub["verdict"] == attribution.NO_GAP or (sub["verdict"] == attribution.EXPLAINED and name in added)
        left = sub.get("heldout_gap_after") if sub["verdict"] != attribution.NO_GAP else sub["heldout_gap_before"]
        tried.append({"params": params, "chi2": rec.get("chi2"), "misfit": rec.get("misfit"),
                      "explains": bool(explains), "left": left / max(sub["heldout_gap_critical"], 1e-300),
                      "values": moved_values(nominal, rec["values"], refitted), "result": sub,
                      "added": added})
    if not tried:
        return with_sentence({"effect": name, "done": False,
                              "reason": "layer c fitted nothing with it in the twin"}), None
    # the size whose refitted twin the effect explains, the least held-out gap left (in units of
    # its critical value) among them, or among all when none does
    best = min(tried, key=lambda t: (not t["explains"], t["left"]))
    sub = best["result"]
    entry = {"effect": name, "done": True, "params": best["params"],
             "tried": [{k: t[k] for k in ("params", "chi2", "misfit", "explains", "left")} for t in tried],
             "values": best["values"], "misfit": best["misfit"],
             "diagnosis": {k: sub.get(k) for k in ("verdict", "heldout_gap_before", "heldout_gap_critical",
                                                   "heldout_gap_after", "heldout_shrink",
                                                   "heldout_shrink_resimulated")} | {"added": best["added"]},
             "explains": best["explains"], "seconds": time.perf_counter() - t0}
    return with_sentence(entry), sub


def explaining(refits: list[tuple[dict, dict | None]]) -> tuple[dict, dict] | None:
    """The first (entry, diagnosis) of ``refits`` (:func:`refit_with`'s) whose refit explains,
    or None."""
    return next(((e, sub) for e, sub in refits if e.get("explains") and sub is not None), None)


def merge_refit(result: dict, refits: list[tuple[dict, dict | None]]) -> dict:
    """The diagnosis's result after the refits ``refits`` ((entry, its diagnosis) of
    :func:`refit_with`): when one explains, that diagnosis (against the refitted twin, its
    ``calibration`` entry holding the refitted values) with ``before_refit`` (the first
    diagnosis's verdict, held-out gaps, added and refused candidates) and ``refit`` (every entry);
    else ``result`` with its ``refit`` entries."""
    entries = [e for e, _ in refits]
    done = explaining(refits)
    if done is None:
        return {**result, "refit": entries}
    before = {"verdict": result["verdict"], "heldout_gap_before": result["heldout_gap_before"],
              "heldout_gap_critical": result["heldout_gap_critical"],
              "heldout_gap_after": result.get("heldout_gap_after"),
              "heldout_shrink_resimulated": result.get("heldout_shrink_resimulated"),
              "added": [a["effect"] for a in result.get("added", [])],
              "refused": [a["effect"] for a in result.get("refused", [])]}
    return {**done[1], "before_refit": before, "refit": entries}


def refit_sentence(refit: dict) -> str:
    """One sentence on a ``refit`` entry, for the page and the log."""
    name = refit["effect"]
    if not refit.get("done"):
        return f"The calibration was not fitted again with {name}: {refit.get('reason')}."
    moved = [v for v in refit["values"] if v["outside"]]
    moves = "; ".join(f"{v['key']} {number(v['calibrated'], 4)} → {number(v['refitted'], 4)}"
                      + (" (kept at the twin's default)" if v.get("kept") else "") for v in moved)
    d = refit["diagnosis"]
    tail = ("explains the gap" if refit["explains"] else
            f"does not explain the gap ({d['verdict']}, held-out gap {gap_number(d['heldout_gap_after'])} "
            f"for a critical {gap_number(d['heldout_gap_critical'])})")
    how = (f"values moved beyond their first interval: {moves}" if moved
           else "no value moved beyond its first interval")
    return (f"With {name} in the twin ({_params(refit['params'])}) and the calibration fitted again ({how}), "
            f"{name} {tail}.")


def with_sentence(entry: dict) -> dict:
    return {**entry, "sentence": refit_sentence(entry)}


def _params(p: dict) -> str:
    return ", ".join(f"{k} {number(v, 4)}" for k, v in p.items())


__all__ = ["REFIT_EFFECTS", "REFIT_KINDS", "REFIT_VERSION", "explaining", "merge_refit", "moved_values",
           "refit_candidates", "refit_sentence", "refit_sizes", "refit_with", "with_sentence"]
