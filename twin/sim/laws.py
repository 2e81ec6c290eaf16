"""Degradation laws by name: what ``law`` in a scenario's ``[degradation]`` section selects.

A law is looked up in :mod:`analysis.base.registry` under the kind ``degradation_laws`` (defined
here): a registered name (the built-ins ``wear`` and ``table`` below, registered with the
decorator; an installed package's entry point in the group ``ballscrew_twin.degradation_laws``)
or ``module:Class`` importable from ``sys.path``.

The contract of a law (a plain class, no pydantic; :class:`DegradationLaw` documents it and may
be subclassed, but need not be):

- ``__init__(self, **params)``: keyword parameters with defaults. Each is read from the key of
  the same name in ``[degradation]`` when the section has it, else its default stays; a key of
  the section that is neither one of the section's own keys nor a parameter of the law is an
  error. Names are scenario keys, so they carry their unit where it is not SI
  (``midpoint_hours``, ``final_backlash_um``). A bad value raises ``ValueError`` whose message
  starts with the parameter's name (``"midpoint_hours = -3.0: allowed >= 0"``): the scenario's
  error then names the file and ``degradation.midpoint_hours``.
- ``preload_fraction(hours)``: operating hours (n,) [h] -> (n,) preload relative to the new
  nut's ``axis.preload_N`` [-], in [0, 1].
- ``backlash(hours)``: operating hours (n,) [h] -> (n,) axial backlash of the nut [m], >= 0.
- ``injected_onset_hours()``: the hour scored as the injected onset of degradation [h]
  (``truth.h5``'s ``/@onset_hours``), NaN if the law never degrades.
- ``label`` (class attribute, optional): how tables name it.

That is all the campaign asks of a law (:func:`twin.sim.campaign.condition_at`): the preload and the
backlash at each capture and session become the :class:`twin.sim.model.MechanicalState` (contact
stiffness, drag torque, the trucks' share through ``truck_wear_coupling``), the thermal
transient keeps its own keys of ``[degradation]``.
"""

from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import numpy as np

from analysis.base import registry
from twin.sim import degradation as deg

KIND = "degradation_laws"
registry.define_kind(KIND, f"ballscrew_twin.{KIND}", ("twin.sim.laws",), "degradation law")

__all__ = ["KIND", "DegradationLaw", "Table", "Wear", "default_name", "law_from_section", "names",
           "parameters"]


class DegradationLaw:
    """Base of a degradation law (optional: any class with these methods is one). Hours are
    operating hours, arrays of shape (n,)."""

    label = ""

    def preload_fraction(self, hours: np.ndarray) -> np.ndarray:
        """(n,) preload / the new nut's preload [-], in [0, 1]."""
        raise NotImplementedError

    def backlash(self, hours: np.ndarray) -> np.ndarray:
        """(n,) axial backlash [m], >= 0."""
        raise NotImplementedError

    def injected_onset_hours(self) -> float:
        """The onset of degradation [h] scored against detections; NaN if it never degrades."""
        raise NotImplementedError


@registry.register(KIND, "wear", label="wear (Archard, Hertz)", default=True)
@dataclass(frozen=True)
class Wear(deg.WearLaw, DegradationLaw):
    """The wear chain of :mod:`twin.sim.degradation`: Archard wear after ``onset_hours`` lowers the
    preload of a ball population with scattered interference (Hertz), then opens backlash
    (:func:`twin.sim.degradation.preload_fraction`, :func:`twin.sim.degradation.backlash_um`). Its
    parameters are the fields of :class:`twin.sim.degradation.WearLaw`."""

    label = "wear (Archard, Hertz)"

    def __post_init__(self) -> None:
        try:
            super().__post_init__()
        except ValueError as exc:  # start with the key's name, as a scenario's message needs
            raise ValueError(str(exc).removeprefix("WearLaw.")) from None

    def preload_fraction(self, hours) -> np.ndarray:
        return deg.preload_fraction(hours, self)

    def backlash(self, hours) -> np.ndarray:
        return deg.backlash_um(hours, self) * 1e-6

    def injected_onset_hours(self) -> float:
        return float(self.onset_hours) if self.wear_rate_um_per_kh > 0 else math.nan


@registry.register(KIND, "table", label="table (linear interpolation)")
@dataclass(frozen=True)
class Table(DegradationLaw):
    """Preload fraction and backlash given at hours, linearly interpolated between them (held
    constant beyond the ends): ``table_hours`` [h], strictly increasing, >= 0;
    ``table_preload_fraction`` [-] in (0, 1]; ``table_backlash_um`` [µm] >= 0; equal, non-zero
    lengths."""

    table_hours: tuple[float, ...] | list[float] = ()
    table_preload_fraction: tuple[float, ...] | list[float] = ()
    table_backlash_um: tuple[float, ...] | list[float] = ()

    label = "table (linear interpolation)"

    def __post_init__(self) -> None:
        n = len(self.table_hours)
        if n == 0 or len(self.table_preload_fraction) != n or len(self.table_backlash_um) != n:
            raise ValueError(
                "law = 'table' needs table_hours, table_preload_fraction and table_backlash_um "
                f"of equal, non-zero length (got {n}, {len(self.table_preload_fraction)}, "
                f"{len(self.table_backlash_um)})")
        if any(b < 0 for b in self.table_backlash_um):
            raise ValueError(f"table_backlash_um = {self.table_backlash_um} has a negative "
                             "backlash: allowed values are >= 0 µm")
        if any(b <= a for a, b in pairwise(self.table_hours)):
            raise ValueError(f"table_hours = {self.table_hours}: allowed strictly increasing hours")
        if self.table_hours[0] < 0:
            raise ValueError(f"table_hours = {self.table_hours}: allowed hours >= 0")
        if any(not 0 < p <= 1 for p in self.table_preload_fraction):
            raise ValueError(f"table_preload_fraction = {self.table_preload_fraction}: "
                             "allowed 0 < value <= 1")

    def _interp(self, hours, values) -> np.ndarray:
        h = np.atleast_1d(np.asarray(hours, dtype=float))
        th = np.asarray(self.table_hours, dtype=float)
        order = np.argsort(th)
        return np.interp(h, th[order], np.asarray(values, dtype=float)[order])

    def preload_fraction(self, hours) -> np.ndarray:
        return self._interp(hours, self.table_preload_fraction)

    def backlash(self, hours) -> np.ndarray:
        return self._interp(hours, self.table_backlash_um) * 1e-6

    def injected_onset_hours(self) -> float:
        """The last healthy point (preload fraction 1, no backlash) before the first degraded
        one; NaN if no point is degraded."""
        th = np.asarray(self.table_hours, dtype=float)
        bad = (np.asarray(self.table_preload_fraction) < 1.0) | (np.asarray(self.table_backlash_um) > 0.0)
        if not bad.any():
            return math.nan
        first_bad = int(np.argmax(bad))
        return float(th[first_bad - 1]) if first_bad > 0 else float(th[0])


# ---------------------------------------------------------------------------------------------
# From a scenario's section to a law


def names() -> tuple[str, ...]:
    """The registered laws (built-ins first, then installed ones)."""
    return registry.names(KIND)


def default_name() -> str:
    """The law of a scenario that names none."""
    return registry.default(KIND).name


def parameters(factory) -> dict[str, Any]:
    """The keyword parameters of a law's ``__init__`` and their defaults
    (``inspect.Parameter.empty`` where there is none)."""
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):
        return {}
    return {p.name: p.default for p in sig.parameters.values()
            if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}


def law_from_section(section: dict[str, Any]) -> Any:
    """The law of a ``[degradation]`` section (a dict with ``law``; validated by
    :class:`twin.sim.scenario.DegradationConfig`), made with the section's values of its parameters.

    Raises :class:`analysis.base.registry.RegistryError` for an unknown law and ``ValueError`` for
    values the law refuses (the law's message, which starts with the parameter's name)."""
    entry = registry.get(KIND, section["law"])
    kw = {k: section[k] for k in parameters(entry.factory) if k in section}
    try:
        law = entry.factory(**kw)
    except TypeError as exc:
        raise ValueError(f"law = {section['law']!r}: cannot be made from [degradation] "
                         f"({exc}); its parameters: {', '.join(parameters(entry.factory)) or 'none'}"
                         ) from None
    missing = [m for m in _METHODS if not callable(getattr(law, m, None))]
    if missing:
        raise ValueError(f"law = {section['law']!r} is a {type(law).__name__} without "
                         f"{', '.join(missing)}; expected a degradation law with "
                         f"{', '.join(_METHODS)} (twin.sim.laws)")
    return law


_METHODS = ("preload_fraction", "backlash", "injected_onset_hours")
