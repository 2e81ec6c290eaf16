"""Signal artefacts: their responses from post-processed copies of the twin's own simulated
campaigns (no simulation): :func:`analysis.diagnosis.artefacts.apply` on each seed's
recording, the signature of each copy cached beside the campaign's.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

from analysis.base.executors import run_tasks
from analysis.base.files import atomic_write
from analysis.diagnosis import artefacts as art
from analysis.diagnosis.artefacts import ARTEFACT_VERSION, ARTEFACTS, KIND_ARTEFACT
from analysis.diagnosis.attribution import CandidateResponse, ParamAxis
from analysis.diagnosis.signature import PARTS, SIGNATURE_VERSION, Signature, signature, update_signature
from twin.harness.diagnosis.cache import (
    BATCH,
    DEFAULT_RESPONSE_SEEDS,
    _key,
    _regions_json,
    _save_npz,
    load_signatures,
)
from twin.sim.campaign import simulate_campaigns_batched
from twin.sim.scenario import Scenario, from_dict

# ---------------------------------------------------------------------------------------------
# Signal artefacts: post-processed copies of a simulated recording (no simulation)


def _spec_key(artefacts: dict[str, dict[str, float]], seed: int) -> str:
    text = json.dumps([ARTEFACT_VERSION, SIGNATURE_VERSION, int(seed), artefacts], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def _artefact_batch(h5: str, specs: list[str], paths: list[str], base_path: str, seed: int) -> None:
    """Worker: the signatures of the recording ``h5`` with each spec (JSON {name: values})
    applied, the statistics of untouched domains taken from the base signature."""
    from threadpoolctl import threadpool_limits

    base = load_signatures(base_path)
    with threadpool_limits(1):
        for spec_json, path in zip(specs, paths, strict=True):
            spec = json.loads(spec_json)
            domains = tuple(sorted({d for n in spec for d in art.lookup(n).target.domains}))
            tmp = Path(path).with_suffix(".tmp.h5")
            art.apply(Path(h5), tmp, spec, seed)
            try:
                arrays = {p: update_signature(base[p], tmp, p, domains).values for p in PARTS}
            finally:
                tmp.unlink(missing_ok=True)
            arrays["regions"] = np.array(_regions_json(base["cal"].regions))
            atomic_write(Path(path), lambda t, a=arrays: _save_npz(t, a))


def artefact_cached(base: Scenario, specs: list[dict[str, dict[str, float]]], cache: Path) -> bool:
    """Whether :func:`artefact_signatures` of these specs would read them all from the cache."""
    adir = Path(cache) / _key(base) / "artefacts"
    return (adir / f"base-{_spec_key({}, base.seed)}.npz").exists() and all(
        (adir / f"{_spec_key(sp, base.seed)}.npz").exists() for sp in specs)


def artefact_signatures(base: Scenario, specs: list[dict[str, dict[str, float]]], cache: Path,
                        workers: int = 1, keep_campaign: bool = True,
                        on_progress: Callable[[int, int], None] | None = None,
                        scheduler: str | None = None
                        ) -> tuple[dict[str, Signature], list[dict[str, Signature]]]:
    """The signatures of the campaign of ``base`` as simulated (the base) and post-processed
    with each of ``specs`` ({artefact candidate: {param: value}}, applied in order; random
    draws from ``base.seed``), cached in ``cache/<key of base>/artefacts/``. The campaign is
    simulated only when a spec is not cached and its files are not kept in the cache; with
    ``keep_campaign`` they stay there for later specs."""
    d = Path(cache) / _key(base)
    h5 = d / "campaign" / "measurements.h5"
    adir = d / "artefacts"
    adir.mkdir(parents=True, exist_ok=True)
    base_path = adir / f"base-{_spec_key({}, base.seed)}.npz"
    paths = [adir / f"{_spec_key(sp, base.seed)}.npz" for sp in specs]
    todo = [i for i, p in enumerate(paths) if not p.exists()]
    if todo or not base_path.exists():
        if not h5.exists():
            simulate_campaigns_batched([base], [d / "campaign"])
        if (d / "signature.npz").exists():  # the twin seed's own (:func:`evaluate`), of these files
            shutil.copyfile(d / "signature.npz", base_path)
        else:
            sigs = {p: signature(h5, p) for p in PARTS}
            arrays = {"cal": sigs["cal"].values, "heldout": sigs["heldout"].values,
                      "regions": np.array(_regions_json(sigs["cal"].regions))}
            atomic_write(base_path, lambda t, a=arrays: _save_npz(t, a))
    uniq: dict[str, tuple[str, str]] = {}
    for i in todo:
        uniq.setdefault(str(paths[i]), (json.dumps(specs[i]), str(paths[i])))
    jobs = list(uniq.values())
    n_tasks = max(1, min(workers, len(jobs)))
    chunks = [jobs[k::n_tasks] for k in range(n_tasks)] if jobs else []
    done = len(specs) - len(jobs)
    if on_progress:
        on_progress(done, len(specs))
    run_tasks(_artefact_batch, [(str(h5), [c[0] for c in ch], [c[1] for c in ch], str(base_path), base.seed)
                                for ch in chunks], len(chunks), scheduler)
    if on_progress:
        on_progress(len(specs), len(specs))
    if not keep_campaign:
        shutil.rmtree(d / "campaign", ignore_errors=True)
    return load_signatures(str(base_path)), [load_signatures(str(p)) for p in paths]


def artefact_grid(name: str) -> list[tuple[tuple[int, ...], dict[str, float]]]:
    """Every point of an artefact candidate's parameter grid: (index, values)."""
    a = ARTEFACTS[name]
    out = []
    for index in np.ndindex(*[len(p.grid) for p in a.params]):
        out.append((tuple(int(i) for i in index),
                    {p.name: float(p.grid[i]) for p, i in zip(a.params, index, strict=True)}))
    return out


def _simulate_kept(payloads: list[str], dirs: list[str]) -> None:
    """Worker: simulate campaigns (batched rollouts) into ``dirs`` (their files kept)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        simulate_campaigns_batched([from_dict(json.loads(p)) for p in payloads], [Path(d) for d in dirs])


def ensure_campaigns(scenarios: list[Scenario], cache: Path, workers: int,
                     scheduler: str | None = None) -> None:
    """Simulate the campaigns of ``scenarios`` whose files are not kept in the cache
    (``cache/<key>/campaign``), in batches of up to ``BATCH`` on ``workers`` processes or the
    Dask cluster at ``scheduler`` (:func:`run_tasks`)."""
    todo = [s for s in scenarios if not (Path(cache) / _key(s) / "campaign" / "measurements.h5").exists()]
    if not todo:
        return
    size = max(1, min(BATCH, -(-len(todo) // max(workers, 1))))
    batches = [todo[k:k + size] for k in range(0, len(todo), size)]
    args = [([s.to_json() for s in b], [str(Path(cache) / _key(s) / "campaign") for s in b]) for b in batches]
    run_tasks(_simulate_kept, args, workers, scheduler)


def artefact_plans(names: list[str], n_seeds: int, response_seeds: int = DEFAULT_RESPONSE_SEEDS
                   ) -> list[tuple[list[dict], list[tuple[str, tuple]]]]:
    """Per base campaign (the twin seeds' in order: the first ``response_seeds``, and all
    ``n_seeds`` when a ``seed_dependent`` artefact is among ``names``) the artefact specs
    ({name: values}) post-processed on it and where each goes (name, grid index): every grid
    point where the artefact is present."""
    def used(name: str) -> int:
        return n_seeds if ARTEFACTS[name].seed_dependent else min(response_seeds, n_seeds)

    n_bases = max([used(n) for n in names] + [1])
    plans: list[tuple[list[dict], list[tuple[str, tuple]]]] = []
    for k in range(n_bases):
        specs, where = [], []
        for name in names:
            if k >= used(name):
                continue
            for index, values in artefact_grid(name):
                if not ARTEFACTS[name].is_off(values):
                    where.append((name, index))
                    specs.append({name: values})
        plans.append((specs, where))
    return plans


def artefact_responses(names: list[str], seeded: list[Scenario], cache: Path, workers: int = 1,
                       on_progress: Callable[[int, int], None] | None = None,
                       scheduler: str | None = None,
                       response_seeds: int = DEFAULT_RESPONSE_SEEDS) -> list[CandidateResponse]:
    """The artefact candidates' responses: the change of every statistic when each grid point
    is applied to the campaign of each of the first ``response_seeds`` twin seeds (every seed of
    ``seeded`` for a ``seed_dependent`` artefact), against that campaign (``per_seed``); the
    response fitted is the first seed's, or for a ``seed_dependent`` artefact the mean over the
    seeds, with its seed-to-seed standard deviation (``spread``)."""
    plans = artefact_plans(names, len(seeded), response_seeds)
    n_bases = len(plans)
    # The seeds' campaigns simulated together where their post-processed signatures are missing.
    ensure_campaigns([seeded[k] for k in range(1, n_bases) if not artefact_cached(seeded[k], plans[k][0], cache)],
                     cache, workers, scheduler)
    changes: dict[str, dict[str, list[np.ndarray]]] = {}
    for k, (specs, where) in enumerate(plans):
        # The first seed's campaign stays in the cache (the artefact grid of a later version is
        # post-processed from it); the others only serve the responses on other seeds.
        base_sig, sigs = artefact_signatures(seeded[k], specs, cache, workers, keep_campaign=k == 0,
                                             on_progress=on_progress, scheduler=scheduler)
        n = base_sig["cal"].values.size
        for name in {nm for nm, _ in where}:
            shape = tuple(len(q.grid) for q in ARTEFACTS[name].params) + (n,)
            for p in PARTS:
                changes.setdefault(name, {q: [] for q in PARTS})[p].append(np.zeros(shape))
        for (name, index), sig in zip(where, sigs, strict=True):
            for p in PARTS:
                changes[name][p][-1][index] = sig[p].values - base_sig[p].values
    out = []
    for name in names:
        per_seed = {p: np.stack(changes[name][p]) for p in PARTS}
        k = len(per_seed["cal"])
        dep = ARTEFACTS[name].seed_dependent
        delta = {p: per_seed[p].mean(axis=0) if dep else per_seed[p][0].copy() for p in PARTS}
        # the seed-to-seed standard deviation of the change (ddof 1) of a response averaged over seeds
        spread = {p: per_seed[p].std(axis=0, ddof=1) for p in PARTS} if dep and k > 1 else None
        out.append(CandidateResponse(name, [ParamAxis(q.name, tuple(q.grid), q.discrete, q.closed, q.log)
                                            for q in ARTEFACTS[name].params],
                                     delta, kind=KIND_ARTEFACT, spread=spread,
                                     per_seed=per_seed if k > 1 else None))
    return out


