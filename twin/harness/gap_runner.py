"""Sim-to-real gap diagnosis: simulate what the diagnosis needs and hand the signatures to
:mod:`analysis.diagnosis`.

For a recording and the scenario meant to describe it, :func:`run_diagnosis`

1. simulates the scenario once (the first seed of the spread) and refuses a recording whose
   layout differs (captures per sample, sessions, runs, channels, sampling rates:
   :mod:`analysis.diagnosis.layout`);
2. simulates the scenario with ``seeds`` seeds (the twin's spread);
3. simulates each candidate effect of the library, and each twin parameter
   (:mod:`twin.effects.parameters`, with ``kinds`` including "parameter"), on its parameter grid
   with the first of those seeds (common random numbers: its response is the difference to that seed's nominal run;
   an effect with random draws of its own, like the origin of each session, with every seed,
   its response averaged);
4. computes the signature (both parts) of every simulation and of the recording, and runs
   :func:`analysis.diagnosis.attribution.diagnose`;
5. when candidates were added, simulates the twin again with them at their fitted values for
   the seeds of the spread (signal artefacts post-processed on those campaigns) and measures
   the held-out gap on it: the re-simulated shrink the verdict follows (:func:`resimulate`,
   :func:`analysis.diagnosis.attribution.resimulated`);
6. writes ``OUT/diagnosis.json`` and the report (gap maps before and after) in ``OUT/report``.

Every simulation is a campaign of the scenario, cached by the hash of its scenario under
``cache`` (default ``OUT/cache``): a second diagnosis with the same scenario, e.g. every case of
the blind benchmark, reuses them. Campaigns are simulated in batches of up to ``BATCH`` with
batched rollouts (:func:`twin.campaign.simulate_campaigns_batched`: the grid values of a
candidate, or the seeds of the spread, share one ``mujoco.rollout`` call per capture and
session), the batches in parallel on ``workers`` processes, each with one BLAS thread; each
campaign's files are those it gives simulated alone, so results depend neither on the batching
nor on the number of workers.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.dataset import DatasetError
from analysis.diagnosis import artefacts as art
from analysis.diagnosis import attribution, layout, subset
from analysis.diagnosis.artefacts import (
    ARTEFACT_VERSION,
    ARTEFACTS,
    KIND_ARTEFACT,
    KIND_EFFECT,
    KIND_PARAMETER,
)
from analysis.diagnosis.attribution import CandidateResponse, ParamAxis
from analysis.diagnosis.gap_report import write_diagnosis_report
from analysis.diagnosis.signature import (
    PARTS,
    SIGNATURE_VERSION,
    Region,
    Signature,
    SignatureError,
    signature,
    update_signature,
)
from analysis.files import atomic_write, write_json, write_text
from analysis.phase1.features import FeatureError
from analysis.registry import RegistryError
from twin.campaign import simulate_campaigns_batched
from twin.effects import Effect, candidate, candidates
from twin.effects import parameters as twin_parameters
from twin.effects.parameters import PARAMETERS
from twin.executors import default_processes, make_executor, map_ordered, parallel_slots
from twin.scenario import Scenario, from_dict

DEFAULT_SEEDS = 8
#: Twin seeds each deterministic candidate's response is simulated (or post-processed) with: the
#: first one's response is fitted, all of them give the interval (the bootstrap over the seeds,
#: :func:`analysis.diagnosis.attribution.seed_interval`).
DEFAULT_RESPONSE_SEEDS = 3
#: Marks a cached simulation that could not be featurised (with the reason).
UNFEATURISABLE = "unfeaturisable.json"
BATCH = 6  # campaigns simulated together (batched rollouts) in one task
SEED_STRIDE = 7919  # twin seeds: scenario seed + SEED_STRIDE·(i + 1)


def run_tasks(fn: Callable, args: list[tuple], workers: int, scheduler: str | None = None,
              on_done: Callable[[int], None] | None = None) -> list:
    """``[fn(*a) for a in args]`` in order: on the Dask cluster at ``scheduler`` when given
    (its workers must see the cache at the same path), else on ``workers`` local processes
    (spawn), or in this process when there is one worker or one task (:mod:`twin.executors`,
    the executor choice of ``twin sweep`` and ``twin simulate``). ``on_done(i)`` is called as
    task i finishes. Each task is a pure function of its arguments and writes its own cache
    files, so the results do not depend on where it ran."""
    if not args:
        return []
    local = 1 if workers <= 1 or len(args) <= 1 else min(workers, len(args))
    with make_executor(local, scheduler=scheduler, prefix="diagnose") as ex:
        return map_ordered(ex, fn, args, [str(i) for i in range(len(args))],
                           None if on_done is None else (lambda i, _key: on_done(i)))


#: The kinds of candidate as ``--kinds`` names them: the registered physical effects, the twin
#: parameters (:data:`twin.effects.parameters.PARAMETERS`, simulated like the effects), the
#: signal artefacts.
KINDS = {"physical": KIND_EFFECT, "parameter": KIND_PARAMETER, "artefact": KIND_ARTEFACT}
#: The kinds a diagnosis tries unless told otherwise (docs/gap-diagnosis.md: the cost of each).
DEFAULT_KINDS = ("physical", "artefact")


def kind_of(name: str) -> str:
    """The kind of a candidate by its name."""
    return KIND_PARAMETER if name in PARAMETERS else KIND_ARTEFACT if name in ARTEFACTS else KIND_EFFECT


def simulated(name: str) -> Effect:
    """The scenario change of a simulated candidate: a twin parameter, or a registered effect
    (or ``module:NAME``: :func:`twin.effects.candidate`)."""
    return PARAMETERS[name] if name in PARAMETERS else candidate(name)


def twin_seeds(s: Scenario, k: int) -> list[int]:
    """The k seeds of the twin's spread (distinct from the scenario's own seed)."""
    return [(s.seed + SEED_STRIDE * (i + 1)) % 2**32 for i in range(k)]


def with_seed(s: Scenario, seed: int) -> Scenario:
    data = s.model_dump(mode="json")
    data["seed"] = int(seed)
    return from_dict(data)


def with_effects(s: Scenario, effects: dict[str, dict[str, float]]) -> Scenario:
    """The scenario with the effects {name or module:NAME: {param: value}} added (registered
    candidates: :func:`twin.effects.candidate`; twin parameters by their name)."""
    for name, values in effects.items():
        s = simulated(name).apply(s, values)
    return s


# ---------------------------------------------------------------------------------------------
# Cached evaluation of one scenario


def _key(s: Scenario) -> str:
    """Cache key: the scenario and the version of the statistics."""
    return hashlib.sha256(f"{SIGNATURE_VERSION}:{s.to_json()}".encode()).hexdigest()[:20]


def _save_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    with path.open("wb") as f:  # a file object: np.savez would append ".npz" to a path
        np.savez(f, **arrays)


def _regions_json(regions: list[Region]) -> str:
    return json.dumps([[r.domain, r.channel, r.family, r.bin, r.hours] for r in regions])


def _regions_from(text: str) -> list[Region]:
    return [Region(d, c, f, b, float(h) if h is not None else float("nan"))
            for d, c, f, b, h in json.loads(text)]


def evaluate(scenario_jsons: list[str], cache_dir: str, keep: bool | list[bool] = False) -> list[str]:
    """Simulate the scenarios not yet cached (one campaign each, batched rollouts:
    :func:`twin.campaign.simulate_campaigns_batched`) and store the signatures of both parts
    and the campaign's layout (``layout.json``, :func:`analysis.diagnosis.layout.describe`);
    returns the paths of their ``signature.npz`` (``cal``, ``heldout``: (n,) values;
    ``regions``: JSON). ``keep`` (one flag, or one per scenario): leave the simulated
    campaign's files in the cache (``<key>/campaign``) for a later post-processing."""
    from threadpoolctl import threadpool_limits

    ss = [from_dict(json.loads(j)) for j in scenario_jsons]
    keeps = [keep] * len(ss) if isinstance(keep, bool) else list(keep)
    dirs = [Path(cache_dir) / _key(s) for s in ss]
    todo = [i for i, d in enumerate(dirs) if not (d / "signature.npz").exists()]
    with threadpool_limits(1):
        if todo:
            simulate_campaigns_batched([ss[i] for i in todo], [dirs[i] / "campaign" for i in todo])
        for i in todo:
            d = dirs[i]
            try:
                write_json(d / "layout.json", layout.describe(d / "campaign" / "measurements.h5"), indent=None)
                sigs = {p: signature(d / "campaign" / "measurements.h5", p) for p in PARTS}
            except (FeatureError, DatasetError) as exc:  # cached as such: see load_signatures
                write_json(d / UNFEATURISABLE, {"error": f"{type(exc).__name__}: {exc}"})
                write_text(d / "scenario.json", scenario_jsons[i])
                if not keeps[i]:
                    shutil.rmtree(d / "campaign", ignore_errors=True)
                continue
            arrays = {"cal": sigs["cal"].values, "heldout": sigs["heldout"].values,
                      "regions": np.array(_regions_json(sigs["cal"].regions))}
            atomic_write(d / "signature.npz", lambda tmp, arrays=arrays: _save_npz(tmp, arrays))
            write_text(d / "scenario.json", scenario_jsons[i])
            if not keeps[i]:
                shutil.rmtree(d / "campaign", ignore_errors=True)
    return [str(d / "signature.npz") for d in dirs]


def unfeaturisable(path: str | Path) -> str | None:
    """Why the simulated campaign whose ``signature.npz`` would be ``path`` has no signature
    (its statistics could not be computed, e.g. a Phase I capture without a constant-speed
    segment), or None."""
    f = Path(path).parent / UNFEATURISABLE
    return json.loads(f.read_text())["error"] if f.exists() else None


def load_signatures(path: str) -> dict[str, Signature]:
    """The cached signatures at ``path``; :class:`SignatureError` with the reason when the
    simulation could not be featurised (:func:`unfeaturisable`)."""
    why = unfeaturisable(path)
    if why is not None:
        scen = Path(path).parent / "scenario.json"
        raise SignatureError(f"the twin's simulation cached in {Path(path).parent} has no statistics: {why} "
                             f"(its scenario: {scen})")
    with np.load(path) as z:
        regions = _regions_from(str(z["regions"]))
        return {p: Signature(z[p].copy(), regions) for p in PARTS}


def evaluate_all(scenarios: list[Scenario], cache_dir: Path, workers: int,
                 on_progress: Callable[[int, int], None] | None = None,
                 keep: bool | list[bool] = False, scheduler: str | None = None
                 ) -> list[dict[str, Signature] | None]:
    """Signatures of every scenario (cached), in order, on ``workers`` processes or the Dask
    cluster at ``scheduler`` (:func:`run_tasks`); None for a scenario whose simulation could
    not be featurised (:func:`unfeaturisable` says why); ``keep`` (one flag, or one per
    scenario): the simulated campaigns whose files stay in the cache (:func:`evaluate`)."""
    payloads = [s.to_json() for s in scenarios]
    keeps = [keep] * len(payloads) if isinstance(keep, bool) else list(keep)
    paths: list[str | None] = [None] * len(payloads)
    todo = []
    for i in range(len(payloads)):
        f = Path(cache_dir) / _key(scenarios[i]) / "signature.npz"
        if f.exists() or unfeaturisable(f) is not None:
            paths[i] = str(f)
        else:
            todo.append(i)
    done = len(payloads) - len(todo)
    if on_progress:
        on_progress(done, len(payloads))
    # Identical scenarios in one call are simulated once; the others in batches of campaigns of
    # the same plan (one mujoco.rollout call per capture or session of a batch), a batch per task.
    unique: dict[str, list[int]] = {}
    for i in todo:
        unique.setdefault(payloads[i], []).append(i)
    keys = list(unique)
    size = max(1, min(BATCH, -(-len(keys) // max(workers, 1))))
    batches = [keys[k:k + size] for k in range(0, len(keys), size)]

    counted = [done]

    def finished(i: int) -> None:
        counted[0] += sum(len(unique[payload]) for payload in batches[i])
        if on_progress:
            on_progress(counted[0], len(payloads))

    kept = {p: any(keeps[i] for i in unique[p]) for p in keys}
    results = run_tasks(evaluate, [(batch, str(cache_dir), [kept[p] for p in batch]) for batch in batches],
                        workers, scheduler, finished)
    for batch, result in zip(batches, results, strict=True):
        for payload, path in zip(batch, result, strict=True):
            for i in unique[payload]:
                paths[i] = path
    return [None if unfeaturisable(p) is not None else load_signatures(p)  # type: ignore[arg-type]
            for p in paths]


# ---------------------------------------------------------------------------------------------
# Candidate grids


@dataclass(frozen=True)
class GridPoint:
    effect: str
    index: tuple[int, ...]
    values: dict[str, float]


def grid_points(effect: Effect) -> list[GridPoint]:
    """Every point of the effect's parameter grid (the product of its parameters' grids)."""
    axes = [p.grid for p in effect.params]
    out = []
    for index in np.ndindex(*[len(a) for a in axes]):
        out.append(GridPoint(effect.name, tuple(int(i) for i in index),
                             {p.name: float(p.grid[i]) for p, i in zip(effect.params, index, strict=True)}))
    return out


def candidate_scenarios(seeded: list[Scenario], library: dict[str, Effect],
                        response_seeds: int = DEFAULT_RESPONSE_SEEDS
                        ) -> tuple[list[Scenario], list[tuple[GridPoint, list[int]]]]:
    """The scenarios to simulate for the candidates' responses: one per grid point where the
    effect is present and seed used: the first ``response_seeds`` twin seeds (every seed for a
    random effect). Returns (scenarios, [(grid point, indices into scenarios, one per seed used,
    in the order of ``seeded``; empty where the point is the nominal twin)])."""
    scen: list[Scenario] = []
    points: list[tuple[GridPoint, list[int]]] = []
    for eff in library.values():
        bases = seeded if eff.random else seeded[:response_seeds]
        for gp in grid_points(eff):
            idx: list[int] = []
            if not eff.is_off(gp.values):
                for base in bases:
                    idx.append(len(scen))
                    scen.append(eff.apply(base, gp.values))
            points.append((gp, idx))
    return scen, points


def responses(library: dict[str, Effect], points, grid_sigs: list[dict[str, Signature]],
              nominal: list[dict[str, Signature]]) -> list[CandidateResponse]:
    """The candidates' response arrays (grid shape + (n,)): the change of every statistic
    against the same seed's nominal twin (common random numbers) for each seed used
    (``per_seed``, (seeds, *grid, n)); the response fitted is the first seed's, or the mean over
    the seeds for a random effect (whose response is a draw of its own: the origin of each
    session)."""
    out = []
    n = nominal[0]["cal"].values.size
    for name, eff in library.items():
        shape = tuple(len(p.grid) for p in eff.params)
        k = max([len(idx) for gp, idx in points if gp.effect == name] + [1])
        per_seed = {p: np.zeros((k,) + shape + (n,)) for p in PARTS}
        for gp, idx in points:
            if gp.effect != name or not idx:
                continue
            for p in PARTS:
                for j, i in enumerate(idx):
                    per_seed[p][(j,) + gp.index] = grid_sigs[i][p].values - nominal[j][p].values
        delta = {p: per_seed[p].mean(axis=0) if eff.random else per_seed[p][0].copy() for p in PARTS}
        axes = [ParamAxis(p.name, tuple(p.grid), p.discrete, log=p.log) for p in eff.params]
        out.append(CandidateResponse(name, axes, delta, kind=kind_of(name),
                                     per_seed=per_seed if k > 1 else None))
    return out


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


# ---------------------------------------------------------------------------------------------
# The diagnosis


@dataclass
class TwinEnsemble:
    """What the diagnosis simulated for one nominal scenario: the seeds' signatures, the
    candidates' responses (reusable for every recording of that scenario) and the effects
    among them by name."""

    nominal: Scenario
    seeds: list[int]
    twin: dict[str, list[Signature]]
    candidates: list[CandidateResponse]
    effects: dict[str, Effect] = field(default_factory=dict)
    #: Candidates left out, with the reason: a simulation of theirs could not be featurised.
    left_out: dict[str, str] = field(default_factory=dict)


def check_kinds(kinds: tuple[str, ...] | list[str] | None) -> tuple[str, ...]:
    """The kinds of candidate to try (names of :data:`KINDS`; None: :data:`DEFAULT_KINDS`);
    ValueError naming the unknown ones, or an empty list."""
    kinds = DEFAULT_KINDS if kinds is None else tuple(kinds)
    unknown = [k for k in kinds if k not in KINDS]
    if unknown or not kinds:
        raise ValueError(f"unknown kind(s) of candidate {unknown}; expected one or more of {', '.join(KINDS)}")
    return kinds


def candidate_names(kinds: tuple[str, ...] | list[str] | None = None) -> list[str]:
    """The candidates of ``kinds`` (names of :data:`KINDS`; default :data:`DEFAULT_KINDS`): the
    registered physical effects (built-in, then installed: :func:`twin.effects.candidates`),
    then the twin parameters, then the signal artefacts."""
    kinds = check_kinds(kinds)
    return ((list(candidates()) if "physical" in kinds else [])
            + (list(PARAMETERS) if "parameter" in kinds else [])
            + (list(ARTEFACTS) if "artefact" in kinds else []))


def resolve_library(library: list[str] | None, kinds: tuple[str, ...] | list[str] | None = None
                    ) -> tuple[dict[str, Effect], list[str]]:
    """(the simulated candidates by name: effects and twin parameters, the signal artefacts) of
    a list of candidates: names of signal artefacts, twin parameters, registered effects or
    ``module:NAME`` of an Effect; None: every candidate of ``kinds`` (default
    :data:`DEFAULT_KINDS`). An unknown one raises ValueError naming it and the candidates."""
    if library is None:
        kinds = check_kinds(kinds)
        effects = {**(candidates() if "physical" in kinds else {}),
                   **(PARAMETERS if "parameter" in kinds else {})}
        return effects, (list(ARTEFACTS) if "artefact" in kinds else [])
    effects: dict[str, Effect] = {}
    artefacts: list[str] = []
    for spec in library:
        if spec in ARTEFACTS:
            artefacts.append(spec)
            continue
        if spec in PARAMETERS:
            effects[spec] = PARAMETERS[spec]
            continue
        try:
            eff = candidate(spec)
        except RegistryError as exc:
            if ":" in spec and spec.split(":")[0] not in {n.split(":")[0] for n in ARTEFACTS}:
                raise ValueError(str(exc)) from None  # module:NAME that cannot be used: why
            raise ValueError(f"unknown candidate {spec!r}; the candidates are "
                             f"{', '.join(candidate_names(tuple(KINDS)))}, or module:NAME of an Effect") from None
        effects[eff.name] = eff
    return effects, artefacts


def check_response_seeds(response_seeds: int, seeds: int) -> None:
    """Refuse a number of response seeds that the twin's spread does not have."""
    if not 1 <= int(response_seeds) <= int(seeds):
        raise ValueError(f"--response-seeds {response_seeds}: expected 1 to --seeds ({seeds}); the "
                         "candidates' responses are simulated with the twin's own seeds")


def build_ensemble(nominal: Scenario, cache: Path, seeds: int = DEFAULT_SEEDS,
                   workers: int | None = None, library: list[str] | None = None,
                   on_progress: Callable[[int, int], None] | None = None,
                   kinds: tuple[str, ...] | list[str] | None = None,
                   scheduler: str | None = None,
                   response_seeds: int = DEFAULT_RESPONSE_SEEDS) -> TwinEnsemble:
    """Simulate the twin's spread and the candidates' responses (cached): the physical effects
    and the twin parameters by simulation, the signal artefacts by post-processing the seeds'
    campaigns, each with the first ``response_seeds`` twin seeds. ``library`` (candidate names)
    wins over ``kinds``; ``scheduler``: run the simulations on that Dask cluster instead of
    ``workers`` local processes."""
    check_response_seeds(response_seeds, seeds)
    effects, artefacts = resolve_library(library, kinds)
    workers = workers or default_processes()
    seed_list = twin_seeds(nominal, seeds)
    seeded = [with_seed(nominal, sd) for sd in seed_list]
    cand_scen, points = candidate_scenarios(seeded, effects, response_seeds)
    # The seeds' campaigns the artefacts are post-processed on stay in the cache (not simulated
    # twice).
    n_bases = len(artefact_plans(artefacts, len(seeded), response_seeds)) if artefacts else 0
    keep = [i < n_bases for i in range(len(seeded) + len(cand_scen))]
    sigs = evaluate_all(seeded + cand_scen, cache, workers, on_progress, keep=keep, scheduler=scheduler)
    for sd, sg, sc in zip(seed_list, sigs, seeded, strict=False):
        if sg is None:
            raise SignatureError(
                f"scenario {nominal.name}: the twin's own simulation (seed {sd}) has no statistics: "
                f"{unfeaturisable(cache / _key(sc) / 'signature.npz')}; expected the routine of the "
                "recording (`twin calibrate` measures it from the recording)")
    left_out: dict[str, str] = {}
    for gp, idx in points:
        bad = [i for i in idx if sigs[len(seeded) + i] is None]
        if bad and gp.effect not in left_out:
            why = unfeaturisable(cache / _key(cand_scen[bad[0]]) / "signature.npz")
            left_out[gp.effect] = f"its simulation at {gp.values} has no statistics: {why}"
    if left_out:
        effects = {k: v for k, v in effects.items() if k not in left_out}
        points = [(gp, idx) for gp, idx in points if gp.effect not in left_out]
    twin = {p: [s[p] for s in sigs[:len(seeded)]] for p in PARTS}
    cands = responses(effects, points, sigs[len(seeded):], sigs[:len(seeded)])
    if artefacts:
        cands += artefact_responses(artefacts, seeded, cache, workers, scheduler=scheduler,
                                    response_seeds=response_seeds)
    return TwinEnsemble(nominal, seed_list, twin, cands, effects, left_out)


def check_layout(real_dir: Path, nominal: Scenario, cache: Path) -> None:
    """Refuse a scenario without the two parts, or a recording whose layout differs from the
    scenario's (raises :class:`analysis.diagnosis.layout.LayoutError` naming every difference).
    The scenario's layout is that of its first twin seed, simulated once (and cached for the
    spread)."""
    for key, n, on in (("phase1.captures_per_sample", nominal.captures_per_sample, nominal.campaign.phase1),
                       ("phase2.runs_per_session", nominal.runs_per_session, nominal.campaign.phase2)):
        if on and n < 2:
            raise ValueError(f"scenario {nominal.name}: {key} gives {n}; the diagnosis needs at "
                             "least 2 (even ones to fit, odd ones held out)")
    s0 = with_seed(nominal, twin_seeds(nominal, 1)[0])
    sig = evaluate([s0.to_json()], str(cache))[0]
    twin = json.loads((Path(sig).parent / "layout.json").read_text())
    layout.compare(Path(real_dir) / "measurements.h5", twin)


def diagnose_signatures(real: dict[str, Signature], ens: TwinEnsemble,
                        library: list[str] | None = None, alpha: float = 0.01
                        ) -> tuple[dict, dict[str, np.ndarray]]:
    """The diagnosis of a recording's signatures against an ensemble; ``library`` restricts
    the candidates (the blind benchmark's open-set cases; names or ``module:NAME``)."""
    if library is not None:
        effects, artefacts = resolve_library(library)
        library = [*effects, *artefacts]
    cands = [c for c in ens.candidates if library is None or c.name in library]
    return attribution.diagnose(real, ens.twin, cands, alpha=alpha)


# ---------------------------------------------------------------------------------------------
# The re-simulated shrink: the twin run again with the added candidates at their fitted values


def resim_plan(ens: TwinEnsemble, added: list[dict], n_seeds: int | None = None
               ) -> tuple[list[Scenario], dict[str, dict[str, float]]]:
    """What re-simulates the added candidates (entries of ``added``: effect, params): the
    scenarios of the first ``n_seeds`` twin seeds (default: all K) with every added physical
    effect and twin parameter applied at its fitted values (``Effect.apply``, the mechanism of
    the grid), and the signal artefacts {name: values} to post-process their campaigns with."""
    n = len(ens.seeds) if n_seeds is None else max(1, min(int(n_seeds), len(ens.seeds)))
    spec = {a["effect"]: dict(a["params"]) for a in added if a["effect"] in ARTEFACTS}
    scen = []
    for sd in ens.seeds[:n]:
        s = with_seed(ens.nominal, sd)
        for a in added:
            if a["effect"] not in ARTEFACTS:
                eff = ens.effects.get(a["effect"]) or simulated(a["effect"])
                s = eff.apply(s, dict(a["params"]))
        scen.append(s)
    return scen, spec


def _resim_path(s: Scenario, spec: dict[str, dict[str, float]], cache: Path) -> Path:
    d = Path(cache) / _key(s)
    return d / "artefacts" / f"{_spec_key(spec, s.seed)}.npz" if spec else d / "signature.npz"


def resimulate(ens: TwinEnsemble, addeds: list[list[dict]], cache: Path, workers: int | None = None,
               n_seeds: int | None = None, scheduler: str | None = None,
               on_progress: Callable[[int, int], None] | None = None
               ) -> list[dict[str, list[Signature]] | None]:
    """The signatures of the twin re-simulated with each list of added candidates (one list per
    diagnosis; None where it is empty) for the first ``n_seeds`` twin seeds (:func:`resim_plan`),
    all diagnoses' campaigns simulated together through the cache and the executor of the grid
    (:func:`evaluate_all`: batched rollouts, ``workers`` processes or the Dask cluster at
    ``scheduler``). Signal artefacts are applied to those campaigns by their post-processing
    (:func:`analysis.diagnosis.artefacts.apply`, the twin seed's random draws, as for their
    grid); the post-processed signatures are cached under the campaign's entry, the campaigns
    kept only for the nominal twin's seeds (every artefact-only diagnosis of the scenario
    post-processes those)."""
    workers = workers or default_processes()
    plans = [resim_plan(ens, a, n_seeds) if a else None for a in addeds]
    cache = Path(cache)
    plain = [s for p in plans if p and not p[1] for s in p[0]]
    if plain:
        evaluate_all(plain, cache, workers, on_progress, scheduler=scheduler)
    # Post-processed: the campaigns whose post-processed signature is missing.
    jobs: dict[str, tuple[Scenario, list[str]]] = {}
    for p in plans:
        if p and p[1]:
            for s in p[0]:
                if not _resim_path(s, p[1], cache).exists():
                    specs = jobs.setdefault(_key(s), (s, []))[1]
                    if json.dumps(p[1]) not in specs:
                        specs.append(json.dumps(p[1]))
    if jobs:
        scen = [s for s, _ in jobs.values()]
        had = {k for k in jobs if (cache / k / "campaign" / "measurements.h5").exists()}
        evaluate_all(scen, cache, workers, on_progress, keep=True, scheduler=scheduler)
        ensure_campaigns(scen, cache, workers, scheduler)
        args = []
        for k, (s, specs) in jobs.items():
            paths = [str(_resim_path(s, json.loads(sp), cache)) for sp in specs]
            Path(paths[0]).parent.mkdir(parents=True, exist_ok=True)
            args.append((str(cache / k / "campaign" / "measurements.h5"), specs, paths,
                         str(cache / k / "signature.npz"), s.seed))
        run_tasks(_artefact_batch, args, workers, scheduler)
        nominal = {_key(with_seed(ens.nominal, sd)) for sd in ens.seeds}
        for k in jobs:
            if k not in had and k not in nominal:
                shutil.rmtree(cache / k / "campaign", ignore_errors=True)
    out: list[dict[str, list[Signature]] | None] = []
    for p in plans:
        if not p:
            out.append(None)
            continue
        sigs = [load_signatures(str(_resim_path(s, p[1], cache))) for s in p[0]]
        out.append({part: [sg[part] for sg in sigs] for part in PARTS})
    return out


def add_resimulation(result: dict, real: dict[str, Signature], ens: TwinEnsemble,
                     resim: dict[str, list[Signature]] | None, alpha: float = 0.01) -> dict:
    """``result`` with its ``resimulation`` entry (:func:`analysis.diagnosis.attribution.resimulated`
    on the re-simulated signatures; the reason when there are none) and the verdict it gives."""
    if result["verdict"] == attribution.NO_GAP:
        return attribution.with_resimulation(result, None, "no significant gap: nothing to explain")
    if not result["added"]:
        return attribution.with_resimulation(result, None, "nothing was added")
    if resim is None:
        return attribution.with_resimulation(result, None, "not asked for (0 re-simulation seeds)")
    rs = attribution.resimulated(real, ens.twin, resim, alpha=alpha,
                                 explained_fraction=result.get("explained_fraction", 0.9))
    rs["twin_seeds"] = ens.seeds[:rs["seeds"]]
    return attribution.with_resimulation(result, rs)


def library_json(names: list[str], effects: dict[str, Effect] | None = None,
                 nominal: Scenario | None = None) -> dict:
    """The library's entry of ``diagnosis.json``: per candidate its kind ("physical effect" |
    "parameter" | "signal artefact"), title, source, (artefacts) the phrase in the owner's
    words, (twin parameters) the keys, quantity, unit and the value of each key in ``nominal``
    and, per parameter, the prior range (low, high) and how the report prints it (label, unit,
    digits, the fit grid's ends: :meth:`twin.effects.base.Param.display`). ``effects``: the
    effects by name (default: the registered ones)."""
    effects = candidates() if effects is None else effects

    def entry(n: str) -> dict:
        if n in PARAMETERS:
            return twin_parameters.library_entry(PARAMETERS[n], nominal)
        if n in effects:
            return {"kind": KIND_EFFECT, "title": effects[n].title, "source": effects[n].source,
                    "params": {p.name: {"low": p.low, "high": p.high, **p.display()}
                               for p in effects[n].params}}
        return art.library_entry(ARTEFACTS[n])
    return {n: entry(n) for n in names}


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
    return from_dict(data)


CALIBRATION_VERSION = 1
CALIBRATION_RUNS = 10  # runs per session of the second Phase II calibration campaign


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


def calibrate(nominal: Scenario, inv: subset.Inventory, cache: Path) -> tuple[subset.UnitCosts, float]:
    """The unit costs of this machine for the recording's layout, measured: the minimum subset
    (:func:`analysis.diagnosis.subset.minimum`) simulated with the first twin seed as a Phase
    I campaign, and as Phase II campaigns of 2 and (where the sessions have them)
    :data:`CALIBRATION_RUNS` runs per session (a session's motion is simulated once for all
    its runs: the two give its fixed and its per-run cost). Returns (costs, wall seconds spent now). Kept in
    ``cache/calibration/`` by the scenario, so a diagnosis with the same cache reuses them
    (and sizes the same subset)."""
    sub = subset.minimum(inv)
    s0 = with_seed(subset_scenario(nominal, sub), twin_seeds(nominal, 1)[0])
    f = Path(cache) / "calibration" / f"{CALIBRATION_VERSION}-{_key(s0)}.json"
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
        runs = [sub.runs] + ([min(CALIBRATION_RUNS, inv.runs)] if inv.runs > sub.runs else [])
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
    :func:`calibrate`), write it to ``OUT/subset/measurements.h5`` and return (that directory,
    the scenario with its layout: :func:`subset_scenario`, the ``subset`` entry of
    ``diagnosis.json`` without the actual minutes)."""
    budget_s = subset.check_budget(float(budget_minutes) * 60.0)
    src = Path(real_dir) / "measurements.h5"
    inv = subset.inventory(src)
    try:
        subset.ladder(inv)
    except DatasetError as exc:
        raise DatasetError(f"{src}: {exc}") from None
    costs, spent = calibrate(nominal, inv, cache)
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
    values = [{"key": k, **v} for k, v in cal.items() if isinstance(v, dict)]
    names = set(library or []) | (set(PARAMETERS) if library is None and "parameter" in check_kinds(kinds) else set())
    fitted = [v["key"] for v in values if v.get("source") == "fitted"]
    again = sorted(n for n in names if n in PARAMETERS and set(PARAMETERS[n].factor.keys) & set(fitted))
    words = (f"The calibrated parameters {', '.join(again)} stay candidates (factor 1 = the calibrated value)."
             if again else "The calibrated parameters are not candidates here (--kinds without 'parameter', or "
             "--candidate naming none of them): what remains is looked for among the unmodelled effects and "
             "the acquisition's artefacts.")
    return {"recording": cal.get("recording"), "version": cal.get("version"), "values": values,
            "defaults": list(cal.get("defaults", [])), "candidates_again": again, "candidates": words}


def run_diagnosis(real_dir: Path, nominal: Scenario, out: Path, *, seeds: int = DEFAULT_SEEDS,
                  workers: int | None = None, alpha: float = 0.01, cache: Path | None = None,
                  library: list[str] | None = None, plots: bool = True,
                  on_progress: Callable[[int, int], None] | None = None,
                  kinds: tuple[str, ...] | list[str] | None = None,
                  scheduler: str | None = None, resim_seeds: int | None = None,
                  on_resim_progress: Callable[[int, int], None] | None = None,
                  budget_minutes: float | None = None,
                  response_seeds: int = DEFAULT_RESPONSE_SEEDS) -> dict:
    """Diagnose the recording in ``real_dir`` against ``nominal``; writes OUT/diagnosis.json
    (and OUT/report/ with ``plots``) and returns its content. When candidates were added, the
    twin is re-simulated with them for the first ``resim_seeds`` twin seeds (default: all;
    0: none) and the verdict follows the re-simulated shrink (:func:`resimulate`). With
    ``budget_minutes`` the diagnosis is that of a subset of the recording sized to that time
    (:func:`prepare_subset`; ``subset`` in the result), else of the whole recording.
    ``response_seeds``: the twin seeds each candidate's response is computed with
    (:func:`build_ensemble`)."""
    check_response_seeds(response_seeds, seeds)
    t0 = time.perf_counter()
    calibration = calibration_entry(nominal, kinds, library)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cache = Path(cache) if cache else out / "cache"
    resolve_library(library, kinds)  # an unknown candidate or kind stops before anything is simulated
    recording, sub = str(real_dir), None
    if budget_minutes is not None:
        real_dir, nominal, sub = prepare_subset(
            real_dir, nominal, out, cache, budget_minutes, seeds=seeds, library=library, kinds=kinds,
            resim_seeds=resim_seeds, workers=parallel_slots(workers, scheduler), response_seeds=response_seeds)
    check_layout(real_dir, nominal, cache)
    real = {p: signature(Path(real_dir) / "measurements.h5", p) for p in PARTS}
    ens = build_ensemble(nominal, cache, seeds, workers, library, on_progress, kinds, scheduler,
                         response_seeds)
    result, t_heldout = diagnose_signatures(real, ens, library, alpha)
    resim = None
    if result["added"] and result["verdict"] != attribution.NO_GAP and resim_seeds != 0:
        resim = resimulate(ens, [result["added"]], cache, workers, resim_seeds, scheduler, on_resim_progress)[0]
    result = add_resimulation(result, real, ens, resim, alpha)
    result = {"recording": recording, "scenario": nominal.name, "twin_seeds": ens.seeds,
              "response_seeds": response_seeds, "calibration": calibration,
              "kinds": sorted({c.kind for c in ens.candidates}),
              "library": library_json([c.name for c in ens.candidates], ens.effects, nominal),
              **result}
    if ens.left_out:
        result["candidates_left_out"] = ens.left_out
    if sub is not None:
        result["subset"] = sub
    write_json(out / "diagnosis.json", result, nan_as_null=True)  # kept if the report fails
    if plots:
        write_diagnosis_report(out / "report", result, real["heldout"].regions, t_heldout)
    if sub is not None:
        sub["actual_minutes"] = (time.perf_counter() - t0) / 60.0  # the report included
        write_json(out / "diagnosis.json", result, nan_as_null=True)
    return result

