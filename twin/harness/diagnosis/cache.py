"""The diagnosis's simulations, cached: every campaign of a scenario simulated once (batched
rollouts, ``workers`` processes or a Dask cluster) and kept as its signature under the hash of
its scenario; a simulation whose statistics cannot be computed is cached as such, with the
reason.

Each campaign's files are those it gives simulated alone, so results depend neither on the
batching nor on the number of workers.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

from analysis.base.executors import run_tasks
from analysis.base.files import atomic_write, write_json, write_text
from analysis.dataset import DatasetError
from analysis.diagnosis import layout
from analysis.diagnosis.signature import PARTS, SIGNATURE_VERSION, Region, Signature, SignatureError, signature
from analysis.phase1.features import FeatureError
from twin.sim.campaign import simulate_campaigns_runaways
from twin.sim.scenario import Scenario, from_dict

#: Twin seeds of the spread unless told otherwise.
DEFAULT_SEEDS = 8
#: Twin seeds each deterministic candidate's response is simulated (or post-processed) with: the
#: first one's response is fitted, all of them give the interval (the bootstrap over the seeds,
#: :func:`analysis.diagnosis.attribution.seed_interval`).
DEFAULT_RESPONSE_SEEDS = 3
#: Marks a cached simulation that could not be featurised (with the reason).
UNFEATURISABLE = "unfeaturisable.json"
BATCH = 6  # campaigns simulated together (batched rollouts) in one task
SEED_STRIDE = 7919  # twin seeds: scenario seed + SEED_STRIDE·(i + 1)



def twin_seeds(s: Scenario, k: int) -> list[int]:
    """The k seeds of the twin's spread (distinct from the scenario's own seed)."""
    return [(s.seed + SEED_STRIDE * (i + 1)) % 2**32 for i in range(k)]


def with_seed(s: Scenario, seed: int) -> Scenario:
    """``s`` with ``seed``; for a calibrated scenario, its calibrated values drawn from the
    calibration's joint distribution with that seed (:func:`twin.harness.calibration.uncertainty.draw_calibrated`:
    the twin's spread then holds the calibration's uncertainty)."""
    from twin.harness.calibration.uncertainty import draw_calibrated

    data = s.model_dump(mode="json")
    data["seed"] = int(seed)
    return from_dict(draw_calibrated(data, s.calibration, seed))


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
    :func:`twin.sim.campaign.simulate_campaigns_batched`) and store the signatures of both parts
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
            # a scenario that runs away (a candidate's or a drawn value that makes the axis
            # unstable) is cached as such
            ran_away = simulate_campaigns_runaways([ss[i] for i in todo], [dirs[i] / "campaign" for i in todo])
            for k, why in ran_away.items():
                _mark_unfeaturisable(dirs[todo[k]], "its simulation ran away (diverged, or the carriage left the "
                                     f"rails' modelled length): {why}", scenario_jsons[todo[k]], keep=False)
            todo = [i for k, i in enumerate(todo) if k not in ran_away]
        for i in todo:
            d = dirs[i]
            try:
                write_json(d / "layout.json", layout.describe(d / "campaign" / "measurements.h5"), indent=None)
                sigs = {p: signature(d / "campaign" / "measurements.h5", p) for p in PARTS}
            except (FeatureError, DatasetError) as exc:  # cached as such: see load_signatures
                _mark_unfeaturisable(d, f"{type(exc).__name__}: {exc}", scenario_jsons[i], keeps[i])
                continue
            arrays = {"cal": sigs["cal"].values, "heldout": sigs["heldout"].values,
                      "regions": np.array(_regions_json(sigs["cal"].regions))}
            atomic_write(d / "signature.npz", lambda tmp, arrays=arrays: _save_npz(tmp, arrays))
            write_text(d / "scenario.json", scenario_jsons[i])
            if not keeps[i]:
                shutil.rmtree(d / "campaign", ignore_errors=True)
    return [str(d / "signature.npz") for d in dirs]


def _mark_unfeaturisable(d: Path, why: str, scenario_json: str, keep: bool) -> None:
    """Cache ``d`` as a simulation without statistics (:data:`UNFEATURISABLE`, with ``why``);
    its campaign's files are deleted unless ``keep``."""
    write_json(d / UNFEATURISABLE, {"error": why})
    write_text(d / "scenario.json", scenario_json)
    if not keep:
        shutil.rmtree(d / "campaign", ignore_errors=True)


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


