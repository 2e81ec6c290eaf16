"""What every candidate of the gap diagnosis has in common: its fitted parameters.

A candidate (a physical effect of the twin, a twin parameter set wrong, a signal artefact) is
fitted on a grid of values of each of its parameters and drawn from a prior range by the blind
benchmark; :class:`CandidateParam` holds those fields and how a person reads the value. The
signal artefacts (:mod:`analysis.diagnosis.artefacts`) use it as it is; the twin's effects extend
it with the scenario keys a value sets (``twin.harness.diagnosis.candidates.base.Param``), so the diagnosis and the
report read both kinds the same way without importing the twin.
"""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass
from typing import Any


@dataclass(frozen=True)
class CandidateParam:
    """One fitted parameter of a candidate.

    name: with its unit (``rise_K``); low, high: prior range of a present candidate (the blind
    benchmark draws from it; of |value| when ``signed``: the sign is drawn too); grid: values
    simulated or applied for the fit (ascending; includes ``off`` where the candidate can be
    absent); off: the value that leaves the twin or the recording unchanged (None: none, e.g.
    a cogging order); discrete: no interpolation between grid values; closed: the grid lists
    every value the parameter can take (the mains frequency and its harmonics), so a fit on
    its first or last value is not "beyond" the grid; log: drawn log-uniformly. label, unit,
    digits: how a person reads it (the diagnosis report: "cogging torque 0.033 N·m"): a short
    label in words, the unit as printed ("" for a ratio) and the significant digits shown; an
    integer-valued discrete parameter (an order) is printed whole. Every field after ``name`` is
    keyword-only, so that a subclass can add positional fields after the name."""

    name: str
    _: KW_ONLY
    low: float
    high: float
    grid: tuple[float, ...]
    off: float | None = 0.0
    discrete: bool = False
    closed: bool = False
    log: bool = False
    signed: bool = False
    label: str = ""
    unit: str = ""
    digits: int = 2

    def display(self) -> dict[str, Any]:
        """The display entry of the parameter (what the report reads): label, unit, digits,
        and the fit grid's ends."""
        return {"label": self.label or self.name, "unit": self.unit, "digits": self.digits,
                "grid": [float(self.grid[0]), float(self.grid[-1])]}
