"""The re-simulated shrink: the twin run again with the added candidates at their fitted values
(signal artefacts post-processed on those campaigns), and the held-out gap measured on it.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

from analysis.base.executors import default_processes, run_tasks
from analysis.diagnosis import attribution
from analysis.diagnosis.artefacts import ARTEFACTS
from analysis.diagnosis.signature import PARTS, Signature
from twin.harness.diagnosis.artefact_grid import _artefact_batch, _spec_key, ensure_campaigns
from twin.harness.diagnosis.cache import _key, evaluate_all, load_signatures, with_seed
from twin.harness.diagnosis.ensemble import TwinEnsemble
from twin.harness.diagnosis.library import simulated
from twin.sim.scenario import Scenario

# ---------------------------------------------------------------------------------------------
# The re-simulated shrink: the twin run again with the added candidates at their fitted values


def resimulation_plan(ens: TwinEnsemble, added: list[dict], n_seeds: int | None = None
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


def simulate_with_added(ens: TwinEnsemble, addeds: list[list[dict]], cache: Path, workers: int | None = None,
               n_seeds: int | None = None, scheduler: str | None = None,
               on_progress: Callable[[int, int], None] | None = None
               ) -> list[dict[str, list[Signature]] | None]:
    """The signatures of the twin re-simulated with each list of added candidates (one list per
    diagnosis; None where it is empty) for the first ``n_seeds`` twin seeds (:func:`resimulation_plan`),
    all diagnoses' campaigns simulated together through the cache and the executor of the grid
    (:func:`evaluate_all`: batched rollouts, ``workers`` processes or the Dask cluster at
    ``scheduler``). Signal artefacts are applied to those campaigns by their post-processing
    (:func:`analysis.diagnosis.artefacts.apply`, the twin seed's random draws, as for their
    grid); the post-processed signatures are cached under the campaign's entry, the campaigns
    kept only for the nominal twin's seeds (every artefact-only diagnosis of the scenario
    post-processes those)."""
    workers = workers or default_processes()
    plans = [resimulation_plan(ens, a, n_seeds) if a else None for a in addeds]
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
    """``result`` with its ``resimulation`` entry (:func:`analysis.diagnosis.attribution.resimulated_gap`
    on the re-simulated signatures; the reason when there are none) and the verdict it gives."""
    if result["verdict"] == attribution.NO_GAP:
        return attribution.merge_resimulation(result, None, "no significant gap: nothing to explain")
    if not result["added"]:
        return attribution.merge_resimulation(result, None, "nothing was added")
    if resim is None:
        return attribution.merge_resimulation(result, None, "not asked for (0 re-simulation seeds)")
    rs = attribution.resimulated_gap(real, ens.twin, resim, alpha=alpha,
                                     explained_fraction=result.get("explained_fraction", 0.9),
                                     error_var=attribution.added_error_var(ens.candidates, result["added"], ens.twin))
    rs["twin_seeds"] = ens.seeds[:rs["seeds"]]
    return attribution.merge_resimulation(result, rs)


