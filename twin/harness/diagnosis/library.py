"""The candidates a diagnosis tries, by kind: the registered physical effects
(:mod:`twin.harness.diagnosis.candidates`), the twin parameters
(:mod:`twin.harness.diagnosis.candidates.parameters`) and the signal artefacts
(:data:`analysis.diagnosis.artefacts.ARTEFACTS`); their names, the scenario change of the
simulated ones and their entry of ``diagnosis.json``.
"""

from __future__ import annotations

from analysis.base.registry import RegistryError
from analysis.diagnosis import artefacts as art
from analysis.diagnosis.artefacts import ARTEFACTS, KIND_ARTEFACT, KIND_EFFECT, KIND_PARAMETER
from twin.harness.diagnosis.candidates import Effect, candidate, candidates
from twin.harness.diagnosis.candidates import parameters as twin_parameters
from twin.harness.diagnosis.candidates.parameters import PARAMETERS
from twin.sim.scenario import Scenario

#: The kinds of candidate as ``--kinds`` names them: the registered physical effects, the twin
#: parameters (:data:`twin.harness.diagnosis.candidates.parameters.PARAMETERS`, simulated like the effects), the
#: signal artefacts.
KINDS = {"physical": KIND_EFFECT, "parameter": KIND_PARAMETER, "artefact": KIND_ARTEFACT}
#: The kinds a diagnosis tries unless told otherwise (docs/gap-diagnosis.md: the cost of each).
DEFAULT_KINDS = ("physical", "artefact")


def kind_of(name: str) -> str:
    """The kind of a candidate by its name."""
    return KIND_PARAMETER if name in PARAMETERS else KIND_ARTEFACT if name in ARTEFACTS else KIND_EFFECT


def simulated(name: str) -> Effect:
    """The scenario change of a simulated candidate: a twin parameter, or a registered effect
    (or ``module:NAME``: :func:`twin.harness.diagnosis.candidates.candidate`)."""
    return PARAMETERS[name] if name in PARAMETERS else candidate(name)


def with_effects(s: Scenario, effects: dict[str, dict[str, float]]) -> Scenario:
    """The scenario with the effects {name or module:NAME: {param: value}} added (registered
    candidates: :func:`twin.harness.diagnosis.candidates.candidate`; twin parameters by their name)."""
    for name, values in effects.items():
        s = simulated(name).apply(s, values)
    return s


def check_kinds(kinds: tuple[str, ...] | list[str] | None) -> tuple[str, ...]:
    """The kinds of candidate to try (names of :data:`KINDS`; None: :data:`DEFAULT_KINDS`);
    ValueError naming the unknown ones, or an empty list."""
    kinds = DEFAULT_KINDS if kinds is None else tuple(kinds)
    unknown = [k for k in kinds if k not in KINDS]
    if unknown or not kinds:
        raise ValueError(f"unknown kind(s) of candidate {unknown}; expected one or more of {', '.join(KINDS)}")
    return kinds


def candidate_names(kinds: tuple[str, ...] | list[str] | None = None) -> list[str]:
    """The candidates of ``kinds`` (names of :data:`KINDS`; default :data:`DEFAULT_KINDS`): the
    registered physical effects (built-in, then installed: :func:`twin.harness.diagnosis.candidates.candidates`),
    then the twin parameters, then the signal artefacts."""
    kinds = check_kinds(kinds)
    return ((list(candidates()) if "physical" in kinds else [])
            + (list(PARAMETERS) if "parameter" in kinds else [])
            + (list(ARTEFACTS) if "artefact" in kinds else []))


def resolve_library(library: list[str] | None, kinds: tuple[str, ...] | list[str] | None = None
                    ) -> tuple[dict[str, Effect], list[str]]:
    """(the simulated candidates by name: effects and twin parameters, the signal artefacts) of
    a list of candidates: names of signal artefacts, twin parameters, registered effects or
    ``module:NAME`` of an Effect; None: every candidate of ``kinds`` (default
    :data:`DEFAULT_KINDS`). An unknown one raises ValueError naming it and the candidates."""
    if library is None:
        kinds = check_kinds(kinds)
        effects = {**(candidates() if "physical" in kinds else {}),
                   **(PARAMETERS if "parameter" in kinds else {})}
        return effects, (list(ARTEFACTS) if "artefact" in kinds else [])
    effects: dict[str, Effect] = {}
    artefacts: list[str] = []
    for spec in library:
        if spec in ARTEFACTS:
            artefacts.append(spec)
            continue
        if spec in PARAMETERS:
            effects[spec] = PARAMETERS[spec]
            continue
        try:
            eff = candidate(spec)
        except RegistryError as exc:
            if ":" in spec and spec.split(":")[0] not in {n.split(":")[0] for n in ARTEFACTS}:
                raise ValueError(str(exc)) from None  # module:NAME that cannot be used: why
            raise ValueError(f"unknown candidate {spec!r}; the candidates are "
                             f"{', '.join(candidate_names(tuple(KINDS)))}, or module:NAME of an Effect") from None
        effects[eff.name] = eff
    return effects, artefacts


def library_json(names: list[str], effects: dict[str, Effect] | None = None,
                 nominal: Scenario | None = None) -> dict:
    """The library's entry of ``diagnosis.json``: per candidate its kind ("physical effect" |
    "parameter" | "signal artefact"), title, source, (artefacts) the phrase in the owner's
    words, (twin parameters) the keys, quantity, unit and the value of each key in ``nominal``
    and, per parameter, the prior range (low, high) and how the report prints it (label, unit,
    digits, the fit grid's ends: :meth:`twin.harness.diagnosis.candidates.base.Param.display`). ``effects``: the
    effects by name (default: the registered ones)."""
    effects = candidates() if effects is None else effects

    def entry(n: str) -> dict:
        if n in PARAMETERS:
            return twin_parameters.library_entry(PARAMETERS[n], nominal)
        if n in effects:
            return {"kind": KIND_EFFECT, "title": effects[n].title, "source": effects[n].source,
                    "params": {p.name: {"low": p.low, "high": p.high, **p.display()}
                               for p in effects[n].params}}
        return art.library_entry(ARTEFACTS[n])
    return {n: entry(n) for n in names}


