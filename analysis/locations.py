"""Locations in nested configuration data (a parsed TOML or JSON object): a pydantic error
location written as the key a user types, and the raw value found there.

Shared by every reader that validates with pydantic and must name the key and the value in its
message: the axis contract (``/@axis``), the import spec, and (through ``twin.sim.config``) the
scenario and sweep files.
"""

from __future__ import annotations

from typing import Any

__all__ = ["key_path", "value_at"]


def key_path(loc: tuple) -> str:
    """A pydantic location as the key a user writes: ``("grid", 0, "num")`` -> ``grid[0].num``."""
    out = ""
    for p in loc:
        if isinstance(p, int):
            out += f"[{p}]"
        else:
            out += ("." if out else "") + str(p)
    return out or "(top level)"


def value_at(data: Any, loc: tuple, missing: Any = None) -> Any:
    """The raw value at ``loc`` in ``data`` (nested dicts and lists), or ``missing`` where the
    location does not exist."""
    for p in loc:
        try:
            data = data[p]
        except (KeyError, IndexError, TypeError):
            return missing
    return data
