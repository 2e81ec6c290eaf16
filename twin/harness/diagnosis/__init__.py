"""The sim-to-real gap diagnosis's simulator side: what it simulates and how, beside its statistics
(:mod:`analysis.diagnosis`).

- :mod:`.library`: the candidates by kind (physical effects, twin parameters, signal artefacts);
- :mod:`.cache`: every simulation cached as its signature (batched rollouts, processes or Dask);
- :mod:`.grid`: the simulated candidates' responses on their grids;
- :mod:`.artefact_grid`: the signal artefacts' responses, post-processed on the twin's campaigns;
- :mod:`.ensemble`: the twin's spread and responses for one scenario, the layout check;
- :mod:`.resimulation`: the twin run again with what was added (the re-simulated shrink);
- :mod:`.budget`: a campaign-sized recording diagnosed on a subset that fits a time budget;
- :mod:`.runner`: :func:`run_diagnosis`, the whole of ``twin diagnose``.
"""

from twin.harness.diagnosis.artefact_grid import (
    artefact_cached,
    artefact_grid,
    artefact_plans,
    artefact_responses,
    artefact_signatures,
    ensure_campaigns,
)
from twin.harness.diagnosis.budget import (
    COSTS_RUNS,
    COSTS_VERSION,
    measure_unit_costs,
    prepare_subset,
    subset_scenario,
    workload,
)
from twin.harness.diagnosis.cache import (
    BATCH,
    DEFAULT_RESPONSE_SEEDS,
    DEFAULT_SEEDS,
    SEED_STRIDE,
    UNFEATURISABLE,
    evaluate,
    evaluate_all,
    load_signatures,
    twin_seeds,
    unfeaturisable,
    with_seed,
)
from twin.harness.diagnosis.ensemble import (
    TwinEnsemble,
    build_ensemble,
    check_layout,
    check_response_seeds,
    diagnose_signatures,
)
from twin.harness.diagnosis.grid import GridPoint, candidate_scenarios, grid_points, responses
from twin.harness.diagnosis.library import (
    DEFAULT_KINDS,
    KINDS,
    candidate_names,
    check_kinds,
    kind_of,
    library_json,
    resolve_library,
    simulated,
    with_effects,
)
from twin.harness.diagnosis.resimulation import add_resimulation, resimulation_plan, simulate_with_added
from twin.harness.diagnosis.runner import calibration_entry, run_diagnosis

__all__ = [
    "BATCH", "COSTS_RUNS", "COSTS_VERSION", "DEFAULT_KINDS", "DEFAULT_RESPONSE_SEEDS", "DEFAULT_SEEDS",
    "GridPoint", "KINDS", "SEED_STRIDE", "TwinEnsemble", "UNFEATURISABLE", "add_resimulation", "artefact_cached",
    "artefact_grid", "artefact_plans", "artefact_responses", "artefact_signatures", "build_ensemble",
    "calibration_entry", "candidate_names", "candidate_scenarios", "check_kinds", "measure_unit_costs", "check_layout",
    "check_response_seeds", "diagnose_signatures", "ensure_campaigns", "evaluate", "evaluate_all", "grid_points",
    "kind_of", "library_json", "load_signatures", "prepare_subset", "resimulation_plan", "resolve_library",
    "responses", "run_diagnosis", "simulate_with_added", "simulated", "subset_scenario", "twin_seeds", "unfeaturisable",
    "with_effects", "with_seed", "workload",
]
