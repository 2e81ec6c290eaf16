"""Configuration files and their errors: dotted keys (``--set``, sweep axes, effects) and pydantic
validation errors as messages that name the file, the key, the value and what is allowed.

One translator serves the scenario (``twin simulate --set``, scenario TOML) and the sweep file;
each may pass a ``special`` hook for the messages only it knows (a sweep axis's label, its
spacing rules).
"""

from __future__ import annotations

import re
import types
import typing
from collections.abc import Callable
from typing import Any

from pydantic import BaseModel, ValidationError

from analysis.locations import key_path, value_at

__all__ = ["explain_errors", "get_dotted", "key_path", "model_at", "parse_key", "set_dotted", "value_at"]

_PART = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$")
# pydantic's labels of union members and validators, not keys of the file
_NOT_KEYS = ("str", "list[str]")


# ---------------------------------------------------------------------------------------------
# Dotted keys: `section.name`, with `[i]` for one element of a list


def parse_key(key: str, source: str, error: type[Exception]) -> list[tuple[str, int | None]]:
    """``"a.b[2]"`` -> ``[("a", None), ("b", 2)]``; a malformed key raises ``error``."""
    parts = []
    for p in key.split("."):
        m = _PART.match(p)
        if not m:
            raise error(f"{source}: key `{key}` is not a scenario key; allowed: dotted names "
                        "as in `twin simulate --set`, e.g. `sensors.imu_acc_noise_ug_per_rthz`, "
                        "with `[i]` for one element of a list, e.g. "
                        "`degradation.table_backlash_um[2]`.")
        parts.append((m.group(1), None if m.group(2) is None else int(m.group(2))))
    return parts


def _walk(data: dict, key: str, source: str, error: type[Exception], create: bool) -> tuple[Any, str | int]:
    """The container holding the last part of ``key`` and the name or index in it."""
    parts = parse_key(key, source, error)
    node: Any = data
    for i, (name, idx) in enumerate(parts):
        last = i == len(parts) - 1
        if node is None:  # reading (create=False) through a missing section
            raise error(f"{source}: key `{key}` is missing.")
        if not isinstance(node, dict):
            done = ".".join(k for k, _ in parts[:i])
            raise error(f"{source}: key `{key}`: `{done}` is a value, not a section.")
        if idx is None:
            if last:
                return node, name
            node = node.setdefault(name, {}) if create else node.get(name)
            continue
        lst = node.get(name)
        if not isinstance(lst, list):
            raise error(f"{source}: key `{key}`: `{name}` is "
                        f"{'missing' if lst is None else repr(lst)}, not a list; allowed: "
                        "`[i]` only on list-valued keys.")
        if idx >= len(lst):
            raise error(f"{source}: key `{key}`: index {idx} is beyond the list `{name}` = "
                        f"{lst!r} (length {len(lst)}); allowed: 0 <= i < {len(lst)}.")
        if last:
            return lst, idx
        node = lst[idx]
    raise error(f"{source}: key `{key}` is empty.")


def set_dotted(data: dict, key: str, value: Any, *, source: str = "--set",
               error: type[Exception] = ValueError) -> None:
    """Set ``key`` (dotted, ``name[i]`` for a list element) in the nested dict ``data``.

    Missing sections are created (validation then names an unknown key); a key that runs through
    a value, or an index beyond a list, raises ``error`` naming ``source`` and the key.
    """
    container, name = _walk(data, key, source, error, create=True)
    container[name] = value


def get_dotted(data: dict, key: str, *, source: str = "key", error: type[Exception] = KeyError) -> Any:
    """The value of ``key`` (dotted, ``name[i]`` for a list element) in ``data``."""
    container, name = _walk(data, key, source, error, create=False)
    if container is None or (isinstance(name, str) and name not in container):
        raise error(f"{source}: key `{key}` is missing.")
    return container[name]


# ---------------------------------------------------------------------------------------------
# Validation errors


def _submodel(annotation: Any) -> type[BaseModel] | None:
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if typing.get_origin(annotation) in (list, tuple, typing.Union, types.UnionType):
        for arg in typing.get_args(annotation):
            found = _submodel(arg)
            if found is not None:
                return found
    return None


def model_at(root: type[BaseModel], section: tuple) -> type[BaseModel] | None:
    """The model of the section at ``section`` (list indices skipped), or None."""
    model: type[BaseModel] | None = root
    for part in section:
        if isinstance(part, int):
            continue
        field = model.model_fields.get(str(part)) if model else None
        model = _submodel(field.annotation) if field else None
        if model is None:
            return None
    return model


def _section_label(section: tuple) -> str:
    """``()`` -> "at the top level"; ``("axis",)`` -> "in [axis]"; ``("grid", 0)`` -> "in [[grid]]"."""
    names = ".".join(str(p) for p in section if not isinstance(p, int))
    if not names:
        return "at the top level"
    return f"in [[{names}]]" if isinstance(section[-1], int) else f"in [{names}]"


#: ``special(kind, loc, key, value, msg, ctx)`` returns a message, or None for the generic one.
Special = Callable[[str, tuple, str, Any, str, dict], "str | None"]


def _explain(err: dict, data: Any, source: str, root: type[BaseModel], special: Special | None) -> str:
    loc = tuple(p for p in err.get("loc", ()) if p not in _NOT_KEYS and not str(p).startswith("function-"))
    key, kind, ctx = key_path(loc), err.get("type", ""), err.get("ctx") or {}
    value = value_at(data, loc) if loc else None
    if value is None:
        value = err.get("input")
    msg = str(ctx.get("error", err.get("msg", "")))
    if special is not None:
        text = special(kind, loc, key, value, msg, ctx)
        if text is not None:
            return f"{source}: {text}"
    if kind == "extra_forbidden":
        model = model_at(root, loc[:-1])
        allowed = ", ".join(model.model_fields) if model else "(none)"
        return f"{source}: unknown key `{key}` (value {value!r}); allowed keys {_section_label(loc[:-1])}: {allowed}."
    if kind == "missing":
        where = f" {_section_label(loc[:-1])}" if loc[:-1] else ""
        return f"{source}: key `{key}` is required but missing{where}."
    bounds = [f"{sym} {ctx[n]}" for n, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
              if n in ctx]
    if bounds:
        return f"{source}: key `{key}` = {value!r} is out of range; allowed: value {' and '.join(bounds)}."
    if kind == "value_error":
        # "field = value ..." from a section's validator (a field, or a key the section allows
        # beyond its fields), "section.field = value ..." from the root's own: name the full
        # dotted key.
        first, _, rest = msg.partition(" ")
        model = model_at(root, loc)
        if model is not None and (first in model.model_fields
                                  or (isinstance(value, dict) and first in value)):
            return f"{source}: key `{key + '.' if loc else ''}{first}` {rest}."
        if not loc and "." in first and rest.startswith("="):
            return f"{source}: key `{first}` {rest}."
        return f"{source}: key `{key}`: {msg}."
    return f"{source}: key `{key}` = {value!r} is not valid: {err.get('msg')}."


def explain_errors(exc: ValidationError, data: Any, source: str, root: type[BaseModel],
                   special: Special | None = None) -> str:
    """One sentence per distinct problem of ``exc``, joined by spaces.

    Args:
        exc: the error of ``root.model_validate(data)``.
        data: the dict that was validated (values are quoted from it).
        source: the file (or ``--set``) the dict came from, first word of every sentence.
        root: the model validated.
        special: a hook for messages only this kind of file knows.
    """
    seen: dict[str, None] = {}
    for e in exc.errors():
        seen.setdefault(_explain(e, data, source, root, special))
    return " ".join(seen)
