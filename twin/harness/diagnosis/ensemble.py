"""The twin's ensemble for one nominal scenario: its seeds' spread and the candidates' responses
(:class:`TwinEnsemble`), the layout check of a recording against it, and the attribution of a
recording's signatures.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.base.executors import default_processes
from analysis.diagnosis import attribution, layout
from analysis.diagnosis.attribution import CandidateResponse
from analysis.diagnosis.signature import PARTS, Signature, SignatureError
from twin.harness.diagnosis.artefact_grid import artefact_plans, artefact_responses
from twin.harness.diagnosis.cache import (
    DEFAULT_RESPONSE_SEEDS,
    DEFAULT_SEEDS,
    _key,
    evaluate,
    evaluate_all,
    twin_seeds,
    unfeaturisable,
    with_seed,
)
from twin.harness.diagnosis.candidates import Effect
from twin.harness.diagnosis.grid import candidate_scenarios, responses
from twin.harness.diagnosis.library import resolve_library
from twin.sim.scenario import Scenario

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


def check_layout(real_dir: Path, nominal: Scenario, cache: Path, keep: bool = False) -> None:
    """Refuse a scenario without the two parts, or a recording whose layout differs from the
    scenario's (raises :class:`analysis.diagnosis.layout.LayoutError` naming every difference).
    The scenario's layout is that of its first twin seed, simulated once (and cached for the
    spread; ``keep``: its campaign's files too, for the artefacts post-processed on it)."""
    for key, n, on in (("phase1.captures_per_sample", nominal.captures_per_sample, nominal.campaign.phase1),
                       ("phase2.runs_per_session", nominal.runs_per_session, nominal.campaign.phase2)):
        if on and n < 2:
            raise ValueError(f"scenario {nominal.name}: {key} gives {n}; the diagnosis needs at "
                             "least 2 (even ones to fit, odd ones held out)")
    s0 = with_seed(nominal, twin_seeds(nominal, 1)[0])
    sig = evaluate([s0.to_json()], str(cache), keep=keep)[0]
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


