"""What an effect of the library is: named physical parameters with prior ranges, each mapped to
scenario keys, and the grid on which the diagnosis simulates its response.

An effect is absent when all its parameters are at their ``off`` value; :meth:`Effect.apply`
returns the scenario with the effect added (``add``: the value is added to the scenario's own,
``scale``: multiplies it, ``set``: replaces it; ``index`` picks an element of a list key).

The effects are the twin's candidates of the gap diagnosis, found by name in
:mod:`analysis.base.registry` under the kind ``gap_candidates`` (defined here, entry-point group
``ballscrew_twin.gap_candidates``): the built-ins of :mod:`twin.harness.diagnosis.candidates` register with
:func:`register_effect`, an installed package names an :class:`Effect` object in an entry point,
and ``module:NAME`` (an :class:`Effect`, or a class or function that returns one when called
without arguments) works wherever a candidate is named. An effect's name is its ``name``.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from analysis.base import registry
from analysis.diagnosis.candidate import CandidateParam
from twin.sim.config import get_dotted, set_dotted
from twin.sim.scenario import Scenario, from_dict

KIND = "gap_candidates"
registry.define_kind(KIND, f"ballscrew_twin.{KIND}", ("twin.harness.diagnosis.candidates",), "gap-diagnosis candidate")


@dataclass(frozen=True)
class Param(CandidateParam):
    """One physical parameter of an effect: the fitted parameter of the diagnosis
    (:class:`analysis.diagnosis.candidate.CandidateParam`: name, prior range, grid, off value,
    display) and how a value enters the scenario.

    keys: the scenario keys it sets (dotted, optional ``[i]``); mode: add | scale | set;
    factor: scenario units per parameter unit (e.g. 1e-6 for a scale error in ppm on a
    dimensionless key). ``keys`` and ``mode`` may follow the name by position, the
    fields of the fitted parameter are keyword-only: ``Param("rise_K",
    ("degradation.thermal_rise_K",), "add", low=4.0, high=20.0, grid=(0.0, 5.0, 10.0, 20.0))``."""

    keys: tuple[str, ...]
    mode: Literal["add", "scale", "set"]
    factor: float = 1.0


@dataclass(frozen=True)
class Effect:
    """An unmodelled effect: name, one-line title, parameters, and scenario keys set whenever
    the effect is present (``fixed``, e.g. a material constant). ``random``: the effect draws
    random values from the scenario's seed (e.g. an origin per session), so its response is
    averaged over the twin's seeds rather than taken from one. ``source``: the physical source
    (the module docstring has the details); amplitude: the parameter whose off value removes
    the effect whatever the others are (e.g. a cogging torque of zero, whatever its order)."""

    name: str
    title: str
    params: tuple[Param, ...]
    source: str
    fixed: dict[str, Any] = field(default_factory=dict)
    amplitude: str | None = None
    random: bool = False

    def is_off(self, values: dict[str, float]) -> bool:
        """Absent: its ``amplitude`` parameter at its off value, or (no amplitude parameter)
        every parameter at its off value."""
        if self.amplitude is not None:
            p = next(p for p in self.params if p.name == self.amplitude)
            return values[p.name] == p.off
        return all(p.off is not None and values[p.name] == p.off for p in self.params)

    def apply(self, s: Scenario, values: dict[str, float]) -> Scenario:
        """The scenario ``s`` with this effect at ``values`` {param name: value}."""
        unknown = set(values) - {p.name for p in self.params}
        if unknown:
            raise ValueError(f"effect {self.name}: unknown parameter(s) {sorted(unknown)}; "
                             f"allowed {[p.name for p in self.params]}")
        data = copy.deepcopy(s.model_dump(mode="json"))
        if self.is_off({p.name: values.get(p.name, p.off) for p in self.params}):
            return s
        for key, v in self.fixed.items():
            set_dotted(data, key, v, source=f"effect {self.name}")
        for p in self.params:
            v = values.get(p.name, p.off)
            for key in p.keys:
                cur = get_dotted(data, key, source=f"effect {self.name}")
                u = v * p.factor
                new = cur + u if p.mode == "add" else cur * u if p.mode == "scale" else u
                keep_int = isinstance(cur, int) and not isinstance(cur, bool) and float(new).is_integer()
                set_dotted(data, key, int(new) if keep_int else new, source=f"effect {self.name}")
        return from_dict(data, source=f"scenario with effect {self.name}")

    def draw(self, rng: np.random.Generator, magnitude: str) -> dict[str, float]:
        """Random values inside the prior range: ``magnitude`` "low" draws in the lower half of
        each continuous range, "high" in the upper half (log halves for log parameters)."""
        out = {}
        for p in self.params:
            if p.discrete:
                choices = [v for v in p.grid if v != p.off]
                out[p.name] = float(rng.choice(choices))
                continue
            lo, hi = (math.log(p.low), math.log(p.high)) if p.log else (p.low, p.high)
            mid = 0.5 * (lo + hi)
            a, b = (lo, mid) if magnitude == "low" else (mid, hi)
            v = rng.uniform(a, b)
            v = math.exp(v) if p.log else v
            if p.signed:
                v *= float(rng.choice([-1.0, 1.0]))
            out[p.name] = float(v)
        return out


def register_effect(effect: Effect) -> Effect:
    """Register a built-in ``effect`` of the library by its name, labelled by its title
    (returns it unchanged); the order of registration is the order of the library."""
    if not isinstance(effect, Effect):
        raise registry.RegistryError(f"register_effect: {effect!r} is not an Effect")
    return registry.register(KIND, effect.name, label=effect.title)(effect)
