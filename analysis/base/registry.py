"""Methods by name: the one place that knows which Phase I detectors and backlash estimators exist.

Two ways in, both giving an :class:`Entry` (name, label for tables and figures, the class or
factory, a fixed colour and marker):

- in-tree code decorates its class: ``@register("detectors", "pca_t2", label="PCA-T²",
  color="tab:blue", marker="o")``; the modules that hold built-ins are imported on first use;
- an installed package declares an entry point in the group ``ballscrew_twin.<kind>``
  (``ballscrew_twin.detectors``, ``ballscrew_twin.backlash_estimators``), its name the method's
  name, its object the class (e.g. ``knn = "mypkg.detectors:KNN"`` in ``pyproject.toml``).

Besides a registered name, every lookup accepts ``module:Class`` (importable from ``sys.path``),
named by its class name. The label is the entry's ``label``, else the class attribute ``label``,
else the name. Methods without a colour get one from a palette the built-ins do not use, chosen
by a hash of the name, so a method keeps its colour and marker in every figure of every run.

Kinds and what their objects must be (contracts: docs/developer-guide.md):

- ``detectors``: an unfitted scikit-learn-style novelty detector (``fit``, ``decision_function``
  higher = more abnormal, ``threshold_``), e.g. a subclass of
  :class:`analysis.phase1.detectors.PhaseIDetector`;
- ``backlash_estimators``: an unfitted estimator with ``fit(reference)`` and
  ``estimate(session)`` returning a :class:`analysis.phase2.backlash.SessionBacklash`, e.g. a
  subclass of :class:`analysis.phase2.backlash.BacklashEstimator`.

Other layers add kinds of their own with :func:`define_kind` (this module imports none of them):
the twin defines ``degradation_laws`` (``twin.sim.laws``: the laws of a scenario's ``[degradation]``
section) and ``gap_candidates`` (``twin.harness.diagnosis.candidates.base``: the effects the gap diagnosis can add),
each with its entry-point group ``ballscrew_twin.<kind>`` and the modules holding its built-ins.
"""

from __future__ import annotations

import importlib
import inspect
import re
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Any

__all__ = ["KINDS", "Entry", "RegistryError", "create", "default", "define_kind", "entries", "entry_of",
           "get", "label", "names", "register", "style"]

#: kind -> (entry-point group, modules holding the in-tree registrations, what it is called).
KINDS: dict[str, tuple[str, tuple[str, ...], str]] = {
    "detectors": ("ballscrew_twin.detectors",
                  ("analysis.phase1.detectors", "analysis.phase1.autoencoder"), "Phase I detector"),
    "backlash_estimators": ("ballscrew_twin.backlash_estimators", ("analysis.phase2.backlash",),
                            "backlash estimator"),
}

#: Colours and markers left for methods that do not choose one (the built-ins use tab10's first six).
_PALETTE = ("tab:pink", "tab:olive", "tab:cyan", "magenta", "indigo", "gold", "navy", "teal",
            "crimson", "darkorange")
_MARKERS = ("X", "*", "h", "p", "<", ">", "8", "d")
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_\-]*$")
#: Names a backlash estimator cannot take (they are score groups of score.json's phase2).
RESERVED = {"prognosis", "error_motion", "error_motions", "sessions", "estimators"}


class RegistryError(ValueError):
    """An unknown or unloadable method (names the kind, the name and what is available)."""


@dataclass(frozen=True)
class Entry:
    """One registered method. ``factory(**params)`` makes an unfitted instance; ``source`` says
    where it came from ("built-in", "entry point <dist>", "module:Class")."""

    kind: str
    name: str
    label: str
    factory: Callable[..., Any]
    color: str
    marker: str
    source: str
    default: bool = False


_REGISTERED: dict[str, dict[str, Entry]] = {k: {} for k in KINDS}
_LOADED: set[str] = set()


def define_kind(kind: str, group: str, modules: tuple[str, ...] | list[str], what: str) -> None:
    """Add a kind of method: its entry-point ``group`` (``ballscrew_twin.<kind>``), the
    ``modules`` holding its in-tree registrations (imported on first use) and ``what`` one of
    them is called in messages ("degradation law"). Called by the layer that owns the kind,
    before its first :func:`register`; defining it again the same way does nothing, another way
    raises :class:`RegistryError`."""
    if not isinstance(kind, str) or not _NAME.match(kind):
        raise RegistryError(f"define_kind: kind {kind!r}; expected letters, digits, '_' or '-', "
                            "starting with a letter")
    if group != f"ballscrew_twin.{kind}":
        raise RegistryError(f"define_kind: group {group!r} of kind {kind!r}; expected "
                            f"'ballscrew_twin.{kind}'")
    spec = (group, tuple(modules), what)
    if kind in KINDS:
        if KINDS[kind] != spec:
            raise RegistryError(f"define_kind: kind {kind!r} is already defined as {KINDS[kind]}, "
                                f"not {spec}")
        return
    KINDS[kind] = spec
    _REGISTERED[kind] = {}


def _auto_style(name: str) -> tuple[str, str]:
    h = zlib.crc32(name.encode())
    return _PALETTE[h % len(_PALETTE)], _MARKERS[(h // len(_PALETTE)) % len(_MARKERS)]


def _check_kind(kind: str) -> None:
    if kind not in KINDS:
        raise RegistryError(f"unknown kind {kind!r}; expected one of {', '.join(KINDS)} (a kind "
                            "of another layer exists once the module that defines it is imported)")


def _check_name(kind: str, name: str, where: str) -> None:
    if not isinstance(name, str) or not _NAME.match(name):
        raise RegistryError(f"{where}: {KINDS[kind][2]} name {name!r}; expected letters, digits, "
                            "'_' or '-', starting with a letter")
    if kind == "backlash_estimators" and name in RESERVED:
        raise RegistryError(f"{where}: backlash estimator name {name!r} is reserved "
                            f"({', '.join(sorted(RESERVED))})")


def register(kind: str, name: str, *, label: str | None = None, color: str | None = None,
             marker: str | None = None, default: bool = False):
    """Class decorator: register ``cls`` as method ``name`` of ``kind`` (returns it unchanged)."""
    _check_kind(kind)
    _check_name(kind, name, "register")

    def deco(obj):
        auto = _auto_style(name)
        _REGISTERED[kind][name] = Entry(kind, name, label or getattr(obj, "label", None) or name,
                                        obj, color or auto[0], marker or auto[1], "built-in",
                                        default)
        return obj
    return deco


def _load(kind: str) -> None:
    if kind in _LOADED:
        return
    _LOADED.add(kind)
    group, modules, what = KINDS[kind]
    for mod in modules:
        importlib.import_module(mod)
    for ep in entry_points(group=group):
        if ep.name in _REGISTERED[kind]:
            continue  # an in-tree name wins over an installed one of the same name
        try:
            obj = ep.load()
        except Exception as exc:  # noqa: BLE001 - any import failure is reported the same way
            raise RegistryError(f"entry point {ep.name} = {ep.value!r} of group {group} "
                                f"(package {getattr(ep.dist, 'name', '?')}) cannot be loaded: "
                                f"{type(exc).__name__}: {exc}") from None
        _check_name(kind, ep.name, f"entry point {ep.value!r} of group {group}")
        found = _REGISTERED[kind].get(ep.name)
        if found is not None:  # the module registered itself with the decorator on import
            continue
        auto = _auto_style(ep.name)
        _REGISTERED[kind][ep.name] = Entry(kind, ep.name, getattr(obj, "label", None) or ep.name,
                                           obj, getattr(obj, "color", None) or auto[0],
                                           getattr(obj, "marker", None) or auto[1],
                                           f"entry point {getattr(ep.dist, 'name', '?')}")


def entries(kind: str) -> dict[str, Entry]:
    """Every registered method of ``kind``: built-ins in registration order, then installed ones."""
    _check_kind(kind)
    _load(kind)
    return dict(_REGISTERED[kind])


def names(kind: str) -> tuple[str, ...]:
    """The registered names of ``kind`` in :func:`entries` order."""
    return tuple(entries(kind))


def default(kind: str) -> Entry:
    """The entry registered with ``default=True`` (the method a verb runs when none is given)."""
    for e in entries(kind).values():
        if e.default:
            return e
    raise RegistryError(f"no default {KINDS[kind][2]} is registered")


def _from_path(kind: str, spec: str) -> Entry:
    mod, _, attr = spec.partition(":")
    try:
        obj = importlib.import_module(mod)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise RegistryError(f"{KINDS[kind][2]} {spec!r}: cannot import it ({exc}); expected "
                            "module:Class importable from sys.path") from None
    for e in _REGISTERED[kind].values():  # a registered class named by path keeps its entry
        if e.factory is obj:
            return e
    name = getattr(obj, "name", None) or attr.split(".")[-1]
    _check_name(kind, name, spec)
    color, marker = _auto_style(name)
    return Entry(kind, name, getattr(obj, "label", None) or name, obj,
                 getattr(obj, "color", None) or color, getattr(obj, "marker", None) or marker, spec)


def get(kind: str, spec: str) -> Entry:
    """The entry of ``spec``: a registered name or ``module:Class``. Raises :class:`RegistryError`
    naming the kind, the value and the names available."""
    known = entries(kind)
    if spec in known:
        return known[spec]
    if ":" in spec:
        return _from_path(kind, spec)
    raise RegistryError(f"{KINDS[kind][2]} {spec!r} is unknown; expected one of "
                        f"{', '.join(known)} or module:Class")


def accepts(factory: Callable, param: str) -> bool:
    """Whether ``factory(**{param: ...})`` is accepted (a named parameter or ``**kwargs``)."""
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):
        return False
    return any(p.name == param or p.kind is p.VAR_KEYWORD for p in sig.parameters.values())


def create(kind: str, spec: str, **params) -> Any:
    """A fresh, unfitted instance of ``spec`` made with ``params``; a parameter the factory does
    not take raises :class:`RegistryError` naming it."""
    e = get(kind, spec)
    bad = [k for k in params if not accepts(e.factory, k)]
    if bad:
        raise RegistryError(f"{KINDS[kind][2]} {e.name!r}: unknown parameter(s) {', '.join(bad)}; "
                            f"expected parameters of {getattr(e.factory, '__qualname__', e.factory)}"
                            f"{inspect.signature(e.factory)}")
    return e.factory(**params)


def entry_of(kind: str, obj: Any) -> Entry:
    """The entry of an instance (by its class): the registered one, else one named by the class
    (or its ``name`` attribute)."""
    cls = type(obj)
    for e in entries(kind).values():
        if e.factory is cls:
            return e
    return _from_path(kind, f"{cls.__module__}:{cls.__qualname__}")


def label(kind: str, name: str) -> str:
    """Label of method ``name`` for tables and figures (the name itself if it is not registered)."""
    e = entries(kind).get(name)
    return e.label if e is not None else name


def style(kind: str, name: str) -> tuple[str, str]:
    """(matplotlib colour, marker) of method ``name``, the same in every figure."""
    e = entries(kind).get(name)
    return (e.color, e.marker) if e is not None else _auto_style(name)
