"""The candidates' responses: every point of a physical effect's or twin parameter's grid
simulated with the twin's seeds (common random numbers), the response the change of each
statistic against the same seed's nominal twin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.diagnosis.attribution import CandidateResponse, ParamAxis
from analysis.diagnosis.signature import PARTS, Signature
from twin.harness.diagnosis.cache import DEFAULT_RESPONSE_SEEDS
from twin.harness.diagnosis.candidates import Effect
from twin.harness.diagnosis.library import kind_of
from twin.sim.scenario import Scenario

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


