"""Sim-to-real gap diagnosis: simulate what the diagnosis needs and hand the signatures to
:mod:`analysis.diagnosis`.

For a recording and the scenario meant to describe it, :func:`run_diagnosis`

1. simulates the scenario once (the first seed of the spread) and refuses a recording whose
   layout differs (captures per sample, sessions, runs, channels, sampling rates:
   :mod:`analysis.diagnosis.layout`);
2. simulates the scenario with ``seeds`` seeds (the twin's spread);
3. simulates each candidate effect of the library, and each twin parameter
   (:mod:`twin.harness.diagnosis.candidates.parameters`, with ``kinds`` including "parameter"), on its parameter grid
   with the first of those seeds (common random numbers: its response is the difference to that seed's nominal run;
   an effect with random draws of its own, like the origin of each session, with every seed,
   its response averaged);
4. computes the signature (both parts) of every simulation and of the recording, and runs
   :func:`analysis.diagnosis.attribution.diagnose`;
5. when candidates were added, simulates the twin again with them at their fitted values for
   the seeds of the spread (signal artefacts post-processed on those campaigns) and measures
   the held-out gap on it: the re-simulated shrink the verdict follows (:func:`simulate_with_added`,
   :func:`analysis.diagnosis.attribution.resimulated_gap`);
6. takes ``twin check``'s findings into it (:mod:`analysis.diagnosis.flagged`): a channel the check
   finds clipped or flat is left out of the comparison, and its clipping named from the finding
   (``found_by_check``);
7. when a calibrated twin leaves an unexplained gap, fits the calibration again with the leading
   physical effect in the twin and diagnoses against that (:mod:`twin.harness.diagnosis.refit`:
   the calibration may have taken part of the effect);
8. writes ``OUT/diagnosis.json`` and the report (gap maps before and after) in ``OUT/report``.

Every simulation is a campaign of the scenario, cached by the hash of its scenario under
``cache`` (default ``OUT/cache``): a second diagnosis with the same scenario, e.g. every case of
the blind benchmark, reuses them. Campaigns are simulated in batches of up to ``BATCH`` with
batched rollouts (:func:`twin.sim.campaign.simulate_campaigns_batched`: the grid values of a
candidate, or the seeds of the spread, share one ``mujoco.rollout`` call per capture and
session), the batches in parallel on ``workers`` processes, each with one BLAS thread; each
campaign's files are those it gives simulated alone, so results depend neither on the batching
nor on the number of workers.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

from analysis.base.executors import default_processes, parallel_slots
from analysis.base.files import write_json
from analysis.diagnosis import attribution
from analysis.diagnosis.artefacts import ARTEFACTS
from analysis.diagnosis.flagged import found_by_check, leave_out
from analysis.diagnosis.gap_report import write_diagnosis_report
from analysis.diagnosis.signature import PARTS, signature
from twin.harness.calibration.misfit import misfit_sentence
from twin.harness.calibration.uncertainty import check_drawable
from twin.harness.diagnosis.budget import prepare_subset
from twin.harness.diagnosis.cache import DEFAULT_RESPONSE_SEEDS, DEFAULT_SEEDS
from twin.harness.diagnosis.candidates.parameters import PARAMETERS
from twin.harness.diagnosis.ensemble import build_ensemble, check_layout, check_response_seeds, diagnose_signatures
from twin.harness.diagnosis.library import check_kinds, library_json, resolve_library
from twin.harness.diagnosis.refit import (
    REFIT_EFFECTS,
    explaining,
    merge_refit,
    refit_candidates,
    refit_with,
    with_sentence,
)
from twin.harness.diagnosis.resimulation import add_resimulation, simulate_with_added
from twin.sim.scenario import Scenario


def calibration_entry(nominal: Scenario, kinds, library: list[str] | None) -> dict | None:
    """``diagnosis.json``'s ``calibration``: what ``twin calibrate`` measured and fitted for the
    scenario (its ``[calibration]`` table) and whether the fitted parameters are candidates
    here; None for a scenario that was not calibrated. The twin parameters are candidates only
    with ``--kinds parameter`` (or named with ``--candidate``): then a calibrated one's factor
    1 is its calibrated value and its grid the same factors around it, so the diagnosis can still
    say it was fitted wrong (its interval is in the entry); by default what is left after the
    calibration is looked for among the unmodelled effects and the acquisition's artefacts."""
    cal = nominal.calibration
    if not cal:
        return None
    check_drawable(cal, f"scenario {nominal.name!r}")
    values = [{"key": k, **v} for k, v in cal.items() if isinstance(v, dict) and k not in ("covariance", "misfit")]
    names = set(library or []) | (set(PARAMETERS) if library is None and "parameter" in check_kinds(kinds) else set())
    fitted = [v["key"] for v in values if v.get("source") == "fitted"]
    again = sorted(n for n in names if n in PARAMETERS and set(PARAMETERS[n].factor.keys) & set(fitted))
    words = (f"The calibrated parameters {', '.join(again)} stay candidates (factor 1 = the calibrated value)."
             if again else "The calibrated parameters are not candidates here (--kinds without 'parameter', or "
             "--candidate naming none of them): what remains is looked for among the unmodelled effects and "
             "the acquisition's artefacts.")
    cov = cal.get("covariance") or {}
    misfit = cal.get("misfit") or None
    if cov:
        words += (f" The twin's spread holds the calibration's uncertainty: each twin seed draws the "
                  f"{len(cov['keys'])} calibrated values with an uncertainty (those kept at the default with "
                  "their prior span) from their joint distribution, so a statistic a calibrated value moves "
                  "within its interval is not a gap.")
    if misfit:
        words += (f" The calibration's fit: {misfit_sentence(misfit)}; a gap behind the misfit may be taken in "
                  "part by the calibrated values, or hidden in their spread.")
    return {"recording": cal.get("recording"), "version": cal.get("version"), "values": values,
            "defaults": list(cal.get("defaults", [])), "candidates_again": again, "candidates": words,
            "drawn": list(cov.get("keys", [])), "misfit": misfit}


def run_diagnosis(real_dir: Path, nominal: Scenario, out: Path, *, seeds: int = DEFAULT_SEEDS,
                  workers: int | None = None, alpha: float = 0.01, cache: Path | None = None,
                  library: list[str] | None = None, plots: bool = True,
                  on_progress: Callable[[int, int], None] | None = None,
                  kinds: tuple[str, ...] | list[str] | None = None,
                  scheduler: str | None = None, resim_seeds: int | None = None,
                  on_resim_progress: Callable[[int, int], None] | None = None,
                  budget_minutes: float | None = None,
                  response_seeds: int = DEFAULT_RESPONSE_SEEDS, check: dict | None = None,
                  refit_effects: int = REFIT_EFFECTS, progress: Callable[[str], None] | None = None,
                  heldout_t: dict | None = None) -> dict:
    """Diagnose the recording in ``real_dir`` against ``nominal``; writes OUT/diagnosis.json
    (and OUT/report/ with ``plots``) and returns its content. When candidates were added, the
    twin is re-simulated with them for the first ``resim_seeds`` twin seeds (default: all;
    0: none) and the verdict follows the re-simulated shrink (:func:`simulate_with_added`). With
    ``budget_minutes`` the diagnosis is that of a subset of the recording sized to that time
    (:func:`prepare_subset`; ``subset`` in the result), else of the whole recording.
    ``response_seeds``: the twin seeds each candidate's response is computed with
    (:func:`build_ensemble`). ``check``: ``twin check``'s record of the recording
    (:func:`analysis.ingest.check.check_record`; None: checked here, every finding).
    ``refit_effects``: the leading physical effects the calibration of a calibrated ``nominal``
    is fitted again with when the gap stays unexplained (:mod:`twin.harness.diagnosis.refit`; 0:
    none; not with ``budget_minutes``, whose estimate does not hold them); ``progress``: a line per
    step of it (default: standard error). ``heldout_t``: a dict that receives the held-out t of
    the gap maps ({"before", "after"}: (n,)), for a caller that draws them."""
    from analysis.ingest.check import cached_check, check_record

    check_response_seeds(response_seeds, seeds)
    t0 = time.perf_counter()
    calibration = calibration_entry(nominal, kinds, library)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(cache) if cache else out / "cache"
    # an unknown candidate or kind stops before anything is simulated
    artefacts = resolve_library(library, kinds)[1]
    recording, sub = str(real_dir), None
    if check is None:
        check = check_record(cached_check(real_dir).findings, True)
    if budget_minutes is not None:
        real_dir, nominal, sub = prepare_subset(
            real_dir, nominal, out, cache, budget_minutes, seeds=seeds, library=library, kinds=kinds,
            resim_seeds=resim_seeds, workers=parallel_slots(workers, scheduler), response_seeds=response_seeds)
    check_layout(real_dir, nominal, cache, keep=bool(artefacts))  # the artefacts' first base
    real = {p: signature(Path(real_dir) / "measurements.h5", p) for p in PARTS}
    found = found_by_check(check, real["cal"].regions + real["heldout"].regions, ARTEFACTS)
    real = {p: leave_out(s, [f["channel"] for f in found]) for p, s in real.items()}
    ens = build_ensemble(nominal, cache, seeds, workers, library, on_progress, kinds, scheduler,
                         response_seeds)
    result, t_heldout = diagnose_signatures(real, ens, library, alpha)
    resim = None
    if result["added"] and result["verdict"] != attribution.NO_GAP and resim_seeds != 0:
        resim = simulate_with_added(ens, [result["added"]], cache, workers, resim_seeds, scheduler,
                                    on_resim_progress)[0]
    result = add_resimulation(result, real, ens, resim, alpha)
    say = progress or (lambda t: print(f"diagnose: {t}", file=sys.stderr, flush=True))
    choices = refit_candidates(result, nominal, refit_effects)
    if choices and sub is not None:
        result = {**result, "refit": [with_sentence({"effect": c["effect"], "done": False, "reason": (
            "--budget-minutes: the refit is not in the budget's estimate (diagnose without a budget to "
            "fit the calibration again)")}) for c in choices]}
    elif choices:
        ts: dict[int, dict] = {}

        def again(s: Scenario, library: list[str], out: Path, cache: Path) -> dict:
            t: dict = {}
            res = run_diagnosis(real_dir, s, out, seeds=seeds, workers=workers, alpha=alpha, cache=cache,
                                library=library, plots=False, scheduler=scheduler, resim_seeds=resim_seeds,
                                response_seeds=response_seeds, check=check, refit_effects=0, heldout_t=t)
            ts[id(res)] = t
            return res

        refits = [refit_with(c, real_dir, nominal, out / "refit", cache, diagnose=again,
                             workers=workers or default_processes(), scheduler=scheduler, check=check,
                             progress=say) for c in choices]
        for r, _ in refits:
            say(r["sentence"])
        result = merge_refit(result, refits)
        if result.get("before_refit"):  # the page's gap maps: the diagnosis against the refitted twin
            t_heldout = ts[id(explaining(refits)[1])]
    result = {"recording": recording, "scenario": nominal.name, "twin_seeds": ens.seeds,
              "response_seeds": response_seeds, "calibration": calibration,
              "kinds": sorted({c.kind for c in ens.candidates}),
              "library": library_json([c.name for c in ens.candidates], ens.effects, nominal),
              "found_by_check": found, **result}
    if ens.left_out:
        result["candidates_left_out"] = ens.left_out
    if sub is not None:
        result["subset"] = sub
    write_json(out / "diagnosis.json", result, nan_as_null=True)  # kept if the report fails
    if heldout_t is not None:
        heldout_t.update(t_heldout)
    if plots:
        write_diagnosis_report(out / "report", result, real["heldout"].regions, t_heldout)
    if sub is not None:
        sub["actual_minutes"] = (time.perf_counter() - t0) / 60.0  # the report included
        write_json(out / "diagnosis.json", result, nan_as_null=True)
    return result

