"""A campaign-sized recording diagnosed within a time budget: the twin's unit costs measured once
per cache, the workload of a diagnosis, and the subset of the recording's parts that fits
(:mod:`analysis.diagnosis.subset`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
import time
from pathlib import Path

from analysis.base.files import write_json
from analysis.dataset import DatasetError
from analysis.diagnosis import subset
from analysis.diagnosis.artefacts import ARTEFACTS
from analysis.diagnosis.signature import PARTS, signature
from twin.harness.diagnosis.artefact_grid import artefact_plans
from twin.harness.diagnosis.cache import DEFAULT_RESPONSE_SEEDS, _key, twin_seeds, with_seed
from twin.harness.diagnosis.grid import candidate_scenarios
from twin.harness.diagnosis.library import resolve_library
from twin.sim.campaign import simulate_campaigns_batched
from twin.sim.scenario import Scenario, from_dict

# ---------------------------------------------------------------------------------------------
# A campaign-sized recording: a subset sized to a time budget


def subset_scenario(nominal: Scenario, sub: subset.Subset) -> Scenario:
    """The nominal scenario with the layout of the subset ``sub`` at its hours: Phase I samples
    at ``phase1.sample_hours`` (each sample's first capture) of ``sub.captures`` captures,
    Phase II sessions at ``phase2.session_hours`` of ``sub.runs`` runs (``campaign.scale`` 1,
    so these counts are exact)."""
    data = nominal.model_dump(mode="json")
    data["campaign"]["scale"] = 1.0
    if sub.samples:
        data["phase1"].update(sample_hours=[h for _, h in sub.samples], captures_per_sample=sub.captures)
    if sub.sessions:
        data["phase2"].update(session_hours=[h for _, h in sub.sessions], runs_per_session=sub.runs)
    data["calibration"] = dict(nominal.calibration)  # what the twin seeds draw from (not in the JSON)
    return from_dict(data)


COSTS_VERSION = 1
COSTS_RUNS = 10  # runs per session of the second Phase II calibration campaign


def _timed_campaign(s: Scenario, d: Path) -> tuple[float, float]:
    """(wall seconds simulating the campaign of ``s`` into ``d``, computing its signature's two
    parts), in this process with one BLAS thread, as a worker does."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        t0 = time.perf_counter()
        simulate_campaigns_batched([s], [d])
        t1 = time.perf_counter()
        for p in PARTS:
            signature(d / "measurements.h5", p)
        return t1 - t0, time.perf_counter() - t1


def measure_unit_costs(nominal: Scenario, inv: subset.Inventory, cache: Path) -> tuple[subset.UnitCosts, float]:
    """The unit costs of this machine for the recording's layout, measured: the minimum subset
    (:func:`analysis.diagnosis.subset.minimum`) simulated with the first twin seed as a Phase
    I campaign, and as Phase II campaigns of 2 and (where the sessions have them)
    :data:`COSTS_RUNS` runs per session (a session's motion is simulated once for all
    its runs: the two give its fixed and its per-run cost). Returns (costs, wall seconds spent now). Kept in
    ``cache/calibration/`` by the scenario, so a diagnosis with the same cache reuses them
    (and sizes the same subset)."""
    sub = subset.minimum(inv)
    s0 = with_seed(subset_scenario(nominal, sub), twin_seeds(nominal, 1)[0])
    f = Path(cache) / "calibration" / f"{COSTS_VERSION}-{_key(s0)}.json"
    if f.exists():
        return subset.UnitCosts(**json.loads(f.read_text())), 0.0
    t0 = time.perf_counter()
    tmp = Path(cache) / "calibration" / f"tmp-{_key(s0)}"
    shutil.rmtree(tmp, ignore_errors=True)
    n_caps = len(sub.samples) * sub.captures
    cap = cap_sig = 0.0
    if n_caps and nominal.campaign.phase1:
        data = json.loads(s0.to_json())
        data["campaign"]["phase2"] = False
        sim, sig = _timed_campaign(from_dict(data), tmp / "phase1")
        cap, cap_sig = (sim + sig) / n_caps, sig / n_caps
    sess = run = sess_sig = run_sig = 0.0
    m = len(sub.sessions)
    if m and nominal.campaign.phase2:
        # A session's motion costs seconds, a run tens of ms: 10 runs set the per-run cost
        # apart from the timing's scatter on a shared machine.
        runs = [sub.runs] + ([min(COSTS_RUNS, inv.runs)] if inv.runs > sub.runs else [])
        timed = []
        for r in runs:
            data = json.loads(s0.to_json())
            data["campaign"]["phase1"] = False
            data["phase2"]["runs_per_session"] = r
            timed.append(_timed_campaign(from_dict(data), tmp / f"phase2-{r}"))

        def session_and_run(series: list[float]) -> tuple[float, float]:
            """(fixed cost per session, cost per run) from the campaigns' seconds."""
            per_run = max((series[1] - series[0]) / (m * (runs[1] - runs[0])), 0.0) if len(runs) > 1 else 0.0
            return max(series[0] / m - runs[0] * per_run, 0.0), per_run

        sess, run = session_and_run([a + b for a, b in timed])
        sess_sig, run_sig = session_and_run([b for _, b in timed])
    shutil.rmtree(tmp, ignore_errors=True)
    # The signature is part of the whole cost (a scatter of the timings can say otherwise).
    costs = subset.UnitCosts(cap, max(sess, sess_sig), max(run, run_sig), cap_sig, sess_sig, run_sig)
    write_json(f, dataclasses.asdict(costs))
    return costs, time.perf_counter() - t0


def workload(nominal: Scenario, seeds: int, library: list[str] | None, kinds, resim_seeds: int | None,
             workers: int, response_seeds: int = DEFAULT_RESPONSE_SEEDS) -> subset.Workload:
    """What a diagnosis of ``nominal`` computes (:class:`analysis.diagnosis.subset.Workload`):
    the twin's seeds, the simulated candidates' grid points (:func:`candidate_scenarios`, with
    ``response_seeds`` seeds) and a re-simulation with ``resim_seeds`` seeds (default all: the
    cost when something is added); the artefacts' grid points post-processed on the seeds'
    campaigns (:func:`artefact_plans`; the campaigns are the spread's, kept), each recomputing
    the statistics of the domains it touches, and each base campaign's signature; the stages
    that wait for each other (the twin and the grids, then the re-simulation)."""
    effects, artefacts = resolve_library(library, kinds)
    seeded = [with_seed(nominal, sd) for sd in twin_seeds(nominal, seeds)]
    cand, _ = candidate_scenarios(seeded, effects, response_seeds)
    plans = artefact_plans(artefacts, seeds, response_seeds) if artefacts else []
    p1 = p2 = len(plans)
    for specs, _ in plans:
        for spec in specs:
            domains = {d for name in spec for d in ARTEFACTS[name].target.domains}
            p1 += "phase1" in domains
            p2 += "phase2" in domains
    resim = seeds if resim_seeds is None else min(int(resim_seeds), seeds)
    stages = 1 + (resim > 0)  # the twin and grids; the re-simulation
    return subset.Workload(seeds + len(cand) + resim, p1, p2, workers, stages)


def prepare_subset(real_dir: Path, nominal: Scenario, out: Path, cache: Path, budget_minutes: float, *,
                   seeds: int, library: list[str] | None, kinds, resim_seeds: int | None,
                   workers: int, response_seeds: int = DEFAULT_RESPONSE_SEEDS) -> tuple[Path, Scenario, dict]:
    """Choose the subset of the recording in ``real_dir`` that fits ``budget_minutes`` on
    ``workers`` workers (:func:`analysis.diagnosis.subset.choose`, the unit costs measured by
    :func:`measure_unit_costs`), write it to ``OUT/subset/measurements.h5`` and return (that directory,
    the scenario with its layout: :func:`subset_scenario`, the ``subset`` entry of
    ``diagnosis.json`` without the actual minutes)."""
    budget_s = subset.check_budget(float(budget_minutes) * 60.0)
    src = Path(real_dir) / "measurements.h5"
    inv = subset.inventory(src)
    try:
        subset.ladder(inv)
    except DatasetError as exc:
        raise DatasetError(f"{src}: {exc}") from None
    costs, spent = measure_unit_costs(nominal, inv, cache)
    work = workload(nominal, seeds, library, kinds, resim_seeds, workers, response_seeds)
    sub = subset.choose(inv, costs, work, max(budget_s - spent, 1e-9))
    if not sub.fits:
        need = (spent + sub.estimated_s) / 60.0
        raise ValueError(
            f"{src}: the smallest subset of the recording ({len(sub.samples)} Phase I sample(s) of {sub.captures} "
            f"captures, {len(sub.sessions)} Phase II session(s) of {sub.runs} runs) needs about {need:.2g} min on "
            f"{work.workers} worker(s) ({work.campaigns} twin campaigns; the unit costs measured on this machine "
            f"are kept in {Path(cache) / 'calibration'}); --budget-minutes {budget_minutes:g} is too small: give "
            f"at least {math.ceil(sub.estimated_s / 60.0 * 1.2 * 100) / 100:g}")
    t0 = time.perf_counter()
    subset.write_subset(src, Path(out) / "subset" / "measurements.h5", inv, sub)
    entry = {**sub.to_json(inv), "file": "subset/measurements.h5", "budget_minutes": float(budget_minutes),
             "estimated_minutes": (spent + sub.estimated_s) / 60.0, "calibration_s": spent,
             "subset_write_s": time.perf_counter() - t0, "workers": work.workers,
             "unit_costs_s": dataclasses.asdict(costs), "workload": dataclasses.asdict(work)}
    return Path(out) / "subset", subset_scenario(nominal, sub), entry


