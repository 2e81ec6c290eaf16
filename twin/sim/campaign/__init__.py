"""A run-to-failure campaign: the plan of captures and sessions over operating hours, the state of
the axis at each of them, and the resumable, parallel runner that writes the dataset.

Determinism: every random draw comes from ``numpy.random.SeedSequence([seed, kind, index...])``,
so a unit of work gives the same arrays whichever process, executor or order runs it.

Resuming: each finished unit is stored as its own part file (atomic rename, see
:class:`twin.sim.parts.PartStore`); a rerun skips the parts that exist and assembles
``measurements.h5`` and ``truth.h5`` from all parts at the end.

Modules: :mod:`~twin.sim.campaign.seeds` (the generator of each unit),
:mod:`~twin.sim.campaign.state` (the world, the axis over hours), :mod:`~twin.sim.campaign.planning`
(the units), :mod:`~twin.sim.campaign.units` (a unit simulated in a worker),
:mod:`~twin.sim.campaign.assembly` (the two files from the parts), :mod:`~twin.sim.campaign.runner`
(the executor, resuming, Ctrl-C). Every public name is importable from this package.
"""

from twin.sim.campaign.assembly import ASSEMBLY_ORDER, assemble, phase2_item
from twin.sim.campaign.planning import Unit, plan, sample_hours, session_hours
from twin.sim.campaign.runner import (
    CampaignDirectoryError,
    CampaignInterrupted,
    simulate_campaign,
    simulate_campaigns_batched,
    simulate_campaigns_runaways,
)
from twin.sim.campaign.seeds import KIND_DIAL, KIND_ORIGIN, KIND_PHASE1, KIND_PHASE2, KIND_WORLD, rng_for
from twin.sim.campaign.state import (
    RAIL_MARGIN,
    condition_at,
    degradation_at,
    degradation_law,
    make_world,
    onset_hours,
    origin_offset,
    resume_hours,
    temperature_at,
)
from twin.sim.campaign.units import run_unit, run_unit_batch

__all__ = [
    "KIND_WORLD",
    "KIND_PHASE1",
    "KIND_PHASE2",
    "KIND_DIAL",
    "KIND_ORIGIN",
    "rng_for",
    "RAIL_MARGIN",
    "make_world",
    "degradation_law",
    "degradation_at",
    "onset_hours",
    "resume_hours",
    "temperature_at",
    "condition_at",
    "origin_offset",
    "Unit",
    "session_hours",
    "sample_hours",
    "plan",
    "run_unit",
    "run_unit_batch",
    "phase2_item",
    "ASSEMBLY_ORDER",
    "assemble",
    "CampaignDirectoryError",
    "CampaignInterrupted",
    "simulate_campaign",
    "simulate_campaigns_batched",
    "simulate_campaigns_runaways",
]
