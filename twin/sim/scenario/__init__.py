"""Scenarios: TOML files describing the axis, its sensors, its degradation, the routines and the
campaign, validated with errors that name the key, the value and what is allowed.

Units at this edge carry their name (``_mm``, ``_um``, ``_hours``, ``_hz``...); :func:`to_axis`
and friends convert to the SI dataclasses used inside.

Overrides (``--set KEY=VALUE`` on the CLI) use dotted keys, e.g. ``phase2.runs_per_session=10``;
the value is parsed as TOML (``1e-3``, ``[20, 100]``, ``"table"``) and falls back to a string.

Modules: :mod:`~twin.sim.scenario.sections` (one model per section of the file),
:mod:`~twin.sim.scenario.document` (the whole scenario and its conversion to SI),
:mod:`~twin.sim.scenario.loading` (files, shipped names, overrides, errors). Every public name is
importable from this package.
"""

from twin.sim.scenario.document import Scenario, nominal_axis_description, to_axis
from twin.sim.scenario.loading import (
    SHIPPED,
    ScenarioError,
    find_scenario,
    from_dict,
    load,
    parse_override,
    read_toml,
    shipped_names,
)
from twin.sim.scenario.sections import (
    AxisConfig,
    CampaignConfig,
    DegradationConfig,
    DialConfig,
    EffectsConfig,
    GeometryConfig,
    PauseConfig,
    Phase1Config,
    Phase2Config,
    SensorsConfig,
)

__all__ = [
    "ScenarioError",
    "AxisConfig",
    "GeometryConfig",
    "SensorsConfig",
    "DegradationConfig",
    "Phase1Config",
    "Phase2Config",
    "DialConfig",
    "PauseConfig",
    "CampaignConfig",
    "EffectsConfig",
    "Scenario",
    "parse_override",
    "from_dict",
    "read_toml",
    "SHIPPED",
    "shipped_names",
    "find_scenario",
    "load",
    "to_axis",
    "nominal_axis_description",
]
