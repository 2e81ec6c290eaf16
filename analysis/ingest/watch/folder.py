"""The laboratory's export folder as a watch sees it: the files of each phase's pattern and when
each has settled (its size and modification time unchanged over ``settle_s`` seconds of this
process's own clock), and the phases' hours tables, read again when they change
(:class:`_ExportFolder`).
"""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

from analysis.ingest.convert import _hours_table, _norm_key
from analysis.ingest.spec import ImportSpecError, PhaseSpec
from analysis.ingest.watch.groups import _RANK, _Group


class _ExportFolder:
    """The files under ``spec_dir`` that the ``phases``' patterns match (those under ``live``, the
    watch's own output, excepted). ``say``: prints a sentence for the user; ``clock``: monotonic
    seconds."""

    def __init__(self, spec_dir: Path, phases: dict[str, PhaseSpec], live: Path, settle_s: float,
                 say: Callable[[str], None], clock: Callable[[], float]):
        self.spec_dir, self.phases, self.live = spec_dir, phases, live
        self.settle_s, self.say, self.clock = settle_s, say, clock
        self.tables: dict[str, tuple[int | None, dict[str, float]]] = {}
        self.seen: dict[str, tuple[int, int, float]] = {}  # rel -> (bytes, mtime_ns, first seen)
        self.waiting_said: set[str] = set()
        self.changed_said: set[str] = set()

    def table(self, phase: str, p: PhaseSpec) -> dict[str, float] | None:
        """The phase's hours table, read again when it changed (a table that grows with the
        folder); None while it cannot be read and none was read before (its files wait)."""
        if p.hours_table is None:
            return {}
        path = self.spec_dir / p.hours_table.file
        try:
            mtime = path.stat().st_mtime_ns
        except OSError:
            mtime = None
        old = self.tables.get(phase)
        if old is None or old[0] != mtime:
            try:
                self.tables[phase] = (mtime, _hours_table(self.spec_dir, phase, p))
            except ImportSpecError as exc:
                if str(exc) not in self.waiting_said:
                    self.waiting_said.add(str(exc))
                    self.say(f"waiting: {exc}" if old is None else f"kept the hours table read before: {exc}")
                if old is None:
                    return None
        return self.tables[phase][1]

    def in_table(self, src: Path, p: PhaseSpec, table: dict[str, float]) -> bool:
        t = p.hours_table
        if t is None:
            return True
        if t.key == "file":
            return src.name in table
        mt = re.search(p.name_pattern, src.name) if p.name_pattern else None
        if mt is None or mt.group(t.key) is None:
            return True  # the conversion names the problem
        return _norm_key(mt.group(t.key)) in table

    def name_hours(self, phase: str, src: Path) -> float | None:
        """The operating hours a file's name states (a ``hours`` group of ``name_pattern``), or None."""
        p = self.phases[phase]
        mt = re.search(p.name_pattern, src.name) if p.name_pattern and "hours" in p.groups() else None
        try:
            return float(mt.group("hours")) if mt and mt.group("hours") else None
        except ValueError:
            return None

    def candidates(self, published: dict[str, dict], refused: dict[str, tuple[int, int]],
                   groups: dict[tuple[str, str], _Group]
                   ) -> tuple[list[tuple[str, Path, str, int, int]], int, tuple | None]:
        """Files whose size and modification time have been unchanged for ``settle_s``:
        [(phase, path, rel, bytes, mtime_ns)] in name order; how many other files are still
        settling or changing; and the earliest (hours, phase rank) that the names of those
        files state (None if none states its hours). Files ``published`` (a warning, once, if one
        changed since), ``refused`` unchanged since, or waiting in the open ``groups`` are passed."""
        now = self.clock()
        ready, unsettled, holds = [], 0, []
        live = self.live.resolve()
        for phase, p in self.phases.items():
            for src in sorted(self.spec_dir.glob(p.files)):
                if not src.is_file() or src.name.startswith(".") or live in src.resolve().parents:
                    continue
                rel = src.relative_to(self.spec_dir).as_posix()
                try:
                    st = src.stat()
                except OSError:
                    continue
                sig = (st.st_size, st.st_mtime_ns)
                if rel in published:
                    old = published[rel]
                    if (old["bytes"], old["mtime_ns"]) != sig and rel not in self.changed_said:
                        self.changed_said.add(rel)
                        self.say(f"warning: {src} changed after it was imported as {old['unit']}; "
                                 "it is not imported again")
                    continue
                if refused.get(rel) == sig or any(rel in (f.rel for f in g.files)
                                                  for g in groups.values()):
                    continue
                seen = self.seen.get(rel)
                if seen is None or seen[:2] != sig:
                    self.seen[rel] = (*sig, now)
                elif st.st_size > 0 and now - seen[2] >= self.settle_s:
                    ready.append((phase, src, rel, *sig))
                    continue
                unsettled += 1
                if (h := self.name_hours(phase, src)) is not None:
                    holds.append((h, _RANK[phase]))
        return ready, unsettled, min(holds, default=None)


def _stat(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns
