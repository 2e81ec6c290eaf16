"""The files a watch has accepted, gathered into the units they will be published as: a Phase I
sample of captures or a Phase II session of runs (:class:`_Group`, keyed as ``twin import``
groups them), and when such a group is closed (:func:`_closed`). Hours in h.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from analysis.ingest.convert import _key

_RANK = {"phase1": 0, "phase2": 1}
_COUNT = {"phase1": "captures_per_sample", "phase2": "runs_per_session"}


@dataclass
class _File:
    """An accepted file waiting in an open group: path relative to the spec, meta of its part."""

    rel: str
    src: Path
    meta: dict
    part: Path
    bytes: int
    mtime_ns: int

    @property
    def hours(self) -> float:
        return float(self.meta["hours"])


@dataclass
class _Group:
    """A Phase I sample or a Phase II session being gathered."""

    phase: str
    key: str
    files: list[_File] = field(default_factory=list)

    @property
    def hours(self) -> float:
        return min(f.hours for f in self.files)

    @property
    def max_hours(self) -> float:
        return max(f.hours for f in self.files)

    def order(self) -> tuple:
        return (self.hours, _RANK[self.phase], _key(self.key))


def _group_key(phase: str, meta: dict) -> str:
    g = meta["groups"]
    if phase == "phase1":
        s = g.get("sample")
        return str(int(s)) if s is not None and s.isdigit() else "h" + repr(float(meta["hours"]))
    return g.get("session", repr(float(meta["hours"])))


def _closed(g: _Group, groups: dict[tuple[str, str], _Group], expected: dict[str, int | None],
            settling: bool) -> bool:
    """A group is closed when it has its ``[watch]`` count of files (``expected[phase]``, None if
    not given), or when a file of later hours has been accepted into another of the open ``groups``
    and no file is still settling (which might belong to it)."""
    n = expected[g.phase]
    if n is not None and len(g.files) >= n:
        return True
    return not settling and any(f.hours > g.max_hours for o in groups.values() if o is not g
                                for f in o.files)
