"""The library of unmodelled effects for the sim-to-real gap diagnosis (one module per effect,
each with its physical parameters, prior ranges and physical source; see
:mod:`twin.harness.diagnosis.candidates.base`).

Every effect is a candidate of the kind ``gap_candidates`` of :mod:`analysis.base.registry`: the
modules below register theirs on import, in the library's order (the order of the diagnosis's
candidates and of the blind benchmark's draws); installed packages add theirs through the
entry-point group ``ballscrew_twin.gap_candidates``. :func:`candidates` gives them all,
:func:`candidate` one by name or ``module:NAME``; ``LIBRARY`` the built-ins.
"""

# The order of these imports is the order of registration, hence of the library.
# isort: off
from twin.harness.diagnosis.candidates.base import KIND, Effect, Param, register_effect
from twin.harness.diagnosis.candidates import thermal_growth  # noqa: F401
from twin.harness.diagnosis.candidates import ball_recirculation  # noqa: F401
from twin.harness.diagnosis.candidates import origin_variability  # noqa: F401
from twin.harness.diagnosis.candidates import servo_dynamics  # noqa: F401
from twin.harness.diagnosis.candidates import cogging  # noqa: F401
from twin.harness.diagnosis.candidates import stribeck_friction  # noqa: F401
from twin.harness.diagnosis.candidates import imu_misalignment  # noqa: F401
from twin.harness.diagnosis.candidates import base_resonance  # noqa: F401
# isort: on

from analysis.base import registry

__all__ = ["KIND", "LIBRARY", "Effect", "Param", "candidate", "candidates", "register_effect"]


def _effect(obj, spec: str) -> Effect:
    """The Effect of a registered object: itself, or what calling it without arguments gives."""
    if not isinstance(obj, Effect) and callable(obj):
        obj = obj()
    if not isinstance(obj, Effect):
        raise registry.RegistryError(
            f"gap-diagnosis candidate {spec!r} is a {type(obj).__name__}; expected a "
            "twin.harness.diagnosis.candidates.base.Effect (or a class or function returning one)")
    return obj


def candidates() -> dict[str, Effect]:
    """Every registered effect by name: the built-ins in the library's order, then the installed
    ones (entry points)."""
    out = {}
    for name, e in registry.entries(KIND).items():
        effect = _effect(e.factory, name)
        if effect.name != name:
            raise registry.RegistryError(
                f"gap-diagnosis candidate {name!r} ({e.source}) is an Effect named "
                f"{effect.name!r}; expected the name it is registered under")
        out[name] = effect
    return out


def candidate(spec: str) -> Effect:
    """The effect named ``spec``: a registered name or ``module:NAME``. Raises
    :class:`analysis.base.registry.RegistryError` naming the value and the candidates available; an
    effect of another object under a registered name is refused."""
    e = registry.get(KIND, spec)
    effect = _effect(e.factory, spec)
    known = registry.entries(KIND).get(effect.name)
    if known is not None and _effect(known.factory, known.name) is not effect:
        raise registry.RegistryError(
            f"gap-diagnosis candidate {spec!r} is named {effect.name!r}, the name of the "
            f"registered candidate of {known.source}; expected another name")
    return effect


def __getattr__(name: str):
    if name == "LIBRARY":  # the built-in effects, {name: Effect}, in the library's order
        return {n: e.factory for n, e in registry.entries(KIND).items() if e.source == "built-in"}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
