"""``twin import SPEC --watch``: a laboratory's export folder, growing while the machine runs,
imported as a live source of ``twin monitor`` (docs/import.md, "twin import SPEC --watch").

**When a lab file is complete.** A lab's files carry no completeness mark, so a file is taken
when (1) it is not empty and its size and modification time have not changed over ``settle_s``
seconds of this process's own observation (two looks at least ``settle_s`` apart; the file
system's clock is not used, so a network share's clock skew does not matter), and (2) the
reader of the spec converts it without error (a TDMS file with a cut last segment, a CSV line
with fewer columns than the header, NaN samples, ... are errors). A file that changes while it
is read is looked at again. A file that fails (2) is *refused*: the reason, naming the file, is
logged, and the file is not read again unless its size or modification time changes (a copy
that stalled longer than ``settle_s`` and then resumed is read again and imported once whole).
Further refusals: a rate that differs from the axis description's sensor rate (or, for a channel
the axis does not rate, from the first imported file's) by more than :data:`RATE_TOLERANCE`; a
file whose operating hours come before the last imported unit's (files must arrive in hours
order, because the units' sequence and names are given once and for all); a file of a sample or
session already imported; a run whose hours differ from its session's (as ``twin import``).

**Units.** Accepted files are grouped as ``twin import`` groups them: captures into samples (the
``sample`` group of ``name_pattern``, else one sample per hours value), runs into sessions (the
``session`` group, else one per hours value). A group is *closed* when it has
``[watch] captures_per_sample`` (``runs_per_session``) files, when a file of later operating hours
has been accepted, or when a finite watch ends (``--once``, ``--until-idle``). Closed groups are
published in hours order (a capture before a session at equal hours) into ``OUT/live/`` in the
live-unit convention of :mod:`analysis.dataset.live` that ``twin monitor`` reads: each Phase I
capture a unit ``<seq>-phase1-c<NNNNNN>.h5`` (``captures_in_sample`` = the sample's captures),
each Phase II session a unit ``<seq>-phase2-s<NNNN>.h5``, written under a temporary name and
renamed into place, then its manifest (size, SHA-256). The names are those ``twin import`` gives
the same files in batch. A finite watch ends by writing ``OUT/measurements.h5`` and
``OUT/import.json`` from the imported files exactly as ``twin import`` does, then
``OUT/live/end.json``.

**State.** What was imported is the manifests in ``OUT/live/`` (each names its source files,
with their size and modification time); what was refused is ``OUT/import-watch.jsonl``, an
append-only log (``watch started``, ``file refused``, ``unit published``, ``watch stopped``).
A restarted watcher rebuilds both, so it neither imports a file again nor misses one that
arrived while it was stopped; a sample whose captures were being published when the process
was killed is completed first. Converted files are kept as parts in ``OUT/.import/`` (as by
``twin import``), so a restart does not convert an accepted file again.
"""

from __future__ import annotations

import glob
import json
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from analysis.base.files import read_json, write_json
from analysis.dataset import DatasetError, assemble_measurements
from analysis.dataset.axis import AxisDescription
from analysis.dataset.live import SOURCE_FORMAT, UNIT_FORMAT, UNIT_VERSION, sha256_of
from analysis.dataset.schema import ROUTINE_ATTRS
from analysis.ingest.convert import (
    _hours_table,
    _key,
    _norm_key,
    _part_path,
    _section,
    assemble_import,
    convert_file,
    load_part,
)
from analysis.ingest.spec import ImportSpecError, PhaseSpec, load_spec

__all__ = ["LIVE_DIR", "RATE_TOLERANCE", "WATCH_LOG", "ImportWatcher", "WatchResult"]

LIVE_DIR = "live"
WATCH_LOG = "import-watch.jsonl"
#: Relative difference of a file's sampling rate from the expected one above which it is refused.
RATE_TOLERANCE = 1e-4
_RANK = {"phase1": 0, "phase2": 1}
_COUNT = {"phase1": "captures_per_sample", "phase2": "runs_per_session"}
#: The axis description's sensor whose ``fs_hz`` a format channel must have.
_RATED = {"acc1": "nut_accelerometers", "acc2": "nut_accelerometers", "imu_acc": "imu_accelerometer",
          "imu_gyro": "imu_gyroscope"}


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


@dataclass
class WatchResult:
    """What a watch did: units and files imported, files refused, why it ended
    (``"idle"``, ``"once"`` or ``"stopped"``), the summary of the final assembly (or None)."""

    units: int
    files: int
    refused: int
    ended: str
    summary: object = None


def _group_key(phase: str, meta: dict) -> str:
    g = meta["groups"]
    if phase == "phase1":
        s = g.get("sample")
        return str(int(s)) if s is not None and s.isdigit() else "h" + repr(float(meta["hours"]))
    return g.get("session", repr(float(meta["hours"])))


class ImportWatcher:
    """Watch the folder of an import spec and publish its complete files as live units (module
    docstring). ``settle_s``: seconds a file's size and modification time must stay unchanged;
    ``say``: prints a sentence for the user; ``clock``: monotonic seconds."""

    def __init__(self, spec_path: str | os.PathLike, output: str | os.PathLike | None = None, *,
                 settle_s: float = 2.0, say: Callable[[str], None] = print,
                 clock: Callable[[], float] = time.monotonic):
        self.spec_path = Path(spec_path)
        self.spec, self.spec_dir = load_spec(self.spec_path)
        self.out = Path(output) if output is not None else self.spec_dir / self.spec.output
        self.axis = AxisDescription.from_dict(self.spec.axis, f"{self.spec_path} [axis]")
        self.live = self.out / LIVE_DIR
        self.log = self.out / WATCH_LOG
        self.settle_s, self.say, self.clock = float(settle_s), say, clock
        self.phases: dict[str, PhaseSpec] = {ph: p for ph in ("phase1", "phase2")
                                             if (p := getattr(self.spec, ph)) is not None}
        for ph, p in self.phases.items():
            if not glob.has_magic(p.files):
                raise ImportSpecError(
                    f"{self.spec_path}: {ph}.files = {p.files!r} names one file; a watched export folder "
                    f"needs a pattern that the files to come will match, e.g. '{ph}/*.tdms' (docs/import.md)")
        watch = self.spec.watch
        self.expected = {ph: getattr(watch, _COUNT[ph]) if watch else None for ph in _COUNT}
        self.tables: dict[str, tuple[int | None, dict[str, float]]] = {}
        self.seen: dict[str, tuple[int, int, float]] = {}  # rel -> (bytes, mtime_ns, first seen)
        self.waiting_said: set[str] = set()
        self.groups: dict[tuple[str, str], _Group] = {}
        self.stop = False
        # the state, rebuilt from the manifests and the log by _resume
        self.published: dict[str, dict] = {}  # rel -> {"bytes", "mtime_ns", "unit"}
        self.published_groups: dict[tuple[str, str], list[str]] = {}  # (phase, key) -> unit names
        self.refused: dict[str, tuple[int, int]] = {}
        self.changed_said: set[str] = set()
        self.n_seq = self.n_capture = self.n_session = 0
        self.p1_hours: list[float] = []
        self.last_order: tuple | None = None
        self.last_unit: str | None = None
        self.rates: dict[str, dict[str, float]] = {"phase1": {}, "phase2": {}}
        self.n_published_now = self.n_refused_now = 0

    # --- state -------------------------------------------------------------------------------------
    def _lock(self) -> None:
        """One watcher per output folder (an exclusive lock on ``OUT/.watch.lock``)."""
        from analysis.base.files import exclusive_lock

        self._lock_fh = exclusive_lock(self.out / ".watch.lock", f"{self.out}: another twin import --watch is "
                                       "writing this campaign folder; stop it first, or give another -o",
                                       ImportSpecError)

    def _append(self, event: dict) -> None:
        """One line of the watch log, appended with a single write."""
        line = json.dumps({"event": event.pop("event"), **event, "wall_time": time.strftime("%Y-%m-%dT%H:%M:%S%z")},
                          allow_nan=False) + "\n"
        fd = os.open(self.log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, line.encode())
        finally:
            os.close(fd)

    def _manifests(self) -> list[dict]:
        out = []
        for p in self.live.glob("[0-9]*.json"):
            try:
                m = read_json(p, "a live unit's manifest")
            except (ValueError, OSError):
                continue
            # A manifest is written after its data file is in place, so the size is check enough
            # here (the monitor checks the SHA-256; hashing every unit at each restart would not scale).
            if m.get("format") == UNIT_FORMAT and "sources" in m and _stat(self.live / m["file"]) is not None \
                    and _stat(self.live / m["file"])[0] == m["bytes"]:
                out.append(m)
        return sorted(out, key=lambda m: m["seq"])

    def _absorb(self, m: dict) -> None:
        """Take one published unit's manifest into the state."""
        for s in m["sources"]:
            self.published[s["file"]] = {"bytes": s["bytes"], "mtime_ns": s["mtime_ns"], "unit": m["name"]}
        self.published_groups.setdefault((m["kind"], m["group"]), []).append(m["name"])
        self.n_seq = max(self.n_seq, m["seq"] + 1)
        if m["kind"] == "phase1":
            self.n_capture += 1
            if m["hours"] not in self.p1_hours:
                self.p1_hours.append(m["hours"])
        else:
            self.n_session += 1
        for ch, fs in m.get("fs_hz", {}).items():
            self.rates[m["kind"]].setdefault(ch, fs)
        order = tuple(m["order"])
        if self.last_order is None or order >= self.last_order:
            self.last_order, self.last_unit = order, f"{m['name']} at {m['group_hours']:g} h"

    def _resume(self) -> None:
        self.live.mkdir(parents=True, exist_ok=True)
        for tmp in self.live.glob(".*.tmp"):
            tmp.unlink(missing_ok=True)
        (self.live / "end.json").unlink(missing_ok=True)  # the source goes on
        if not (self.live / "source.json").is_file():
            write_json(self.live / "source.json", {"format": SOURCE_FORMAT, "version": UNIT_VERSION,
                                                   "producer": "twin import --watch",
                                                   "spec": str(self.spec_path.resolve())})
        manifests = self._manifests()
        for m in manifests:
            self._absorb(m)
        if self.log.is_file():
            for line in self.log.read_text(encoding="utf-8").splitlines():
                try:
                    ev = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a torn last line
                if ev.get("event") == "file refused":
                    self.refused[ev["file"]] = (ev["bytes"], ev["mtime_ns"])
        # A sample killed while its captures were being published: publish the rest first.
        if manifests and manifests[-1]["kind"] == "phase1":
            last = manifests[-1]
            done = self.published_groups[("phase1", last["group"])]
            if len(done) < len(last["group_sources"]):
                try:
                    self._complete_sample(last, len(done))
                except (ImportSpecError, DatasetError, OSError, ValueError) as exc:
                    self.say(f"warning: the rest of sample {last['sample']} (cut short by a kill) could not be "
                             f"imported: {exc}")

    def _complete_sample(self, last: dict, done: int) -> None:
        phase, p = "phase1", self.phases["phase1"]
        files = []
        for rel in last["group_sources"]:
            src = self.spec_dir / rel
            part = _part_path(self.out, phase, src)
            try:
                meta, _ = load_part(part)
            except ValueError:
                table = self._table(phase, p) or {}
                meta, part, _ = convert_file(self.out, phase, p, src, table, _section(self.spec, p, table),
                                             self.axis, self.spec_dir)
            st = src.stat()
            files.append(_File(rel, src, meta, part, st.st_size, st.st_mtime_ns))
        g = _Group(phase, last["group"], files)
        first = last["seq"] - (done - 1)
        self.n_seq, self.n_capture = first, self.n_capture - done
        self.p1_hours = [h for h in self.p1_hours if h not in {f.hours for f in files}]
        self._publish(g, skip=done)

    # --- looking at the folder ------------------------------------------------------------------
    def _table(self, phase: str, p: PhaseSpec) -> dict[str, float] | None:
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

    def _in_table(self, src: Path, p: PhaseSpec, table: dict[str, float]) -> bool:
        t = p.hours_table
        if t is None:
            return True
        if t.key == "file":
            return src.name in table
        mt = re.search(p.name_pattern, src.name) if p.name_pattern else None
        if mt is None or mt.group(t.key) is None:
            return True  # the conversion names the problem
        return _norm_key(mt.group(t.key)) in table

    def _name_hours(self, phase: str, src: Path) -> float | None:
        """The operating hours a file's name states (a ``hours`` group of ``name_pattern``), or None."""
        p = self.phases[phase]
        mt = re.search(p.name_pattern, src.name) if p.name_pattern and "hours" in p.groups() else None
        try:
            return float(mt.group("hours")) if mt and mt.group("hours") else None
        except ValueError:
            return None

    def _candidates(self) -> tuple[list[tuple[str, Path, str, int, int]], int, tuple | None]:
        """Files whose size and modification time have been unchanged for ``settle_s``:
        [(phase, path, rel, bytes, mtime_ns)] in name order; how many other files are still
        settling or changing; and the earliest (hours, phase rank) that the names of those
        files state (None if none states its hours)."""
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
                if rel in self.published:
                    old = self.published[rel]
                    if (old["bytes"], old["mtime_ns"]) != sig and rel not in self.changed_said:
                        self.changed_said.add(rel)
                        self.say(f"warning: {src} changed after it was imported as {old['unit']}; "
                                 "it is not imported again")
                    continue
                if self.refused.get(rel) == sig or any(rel in (f.rel for f in g.files)
                                                       for g in self.groups.values()):
                    continue
                seen = self.seen.get(rel)
                if seen is None or seen[:2] != sig:
                    self.seen[rel] = (*sig, now)
                elif st.st_size > 0 and now - seen[2] >= self.settle_s:
                    ready.append((phase, src, rel, *sig))
                    continue
                unsettled += 1
                if (h := self._name_hours(phase, src)) is not None:
                    holds.append((h, _RANK[phase]))
        return ready, unsettled, min(holds, default=None)

    def _refuse(self, src: Path, rel: str, size: int, mtime_ns: int, reason: str) -> None:
        self.refused[rel] = (size, mtime_ns)
        self.seen.pop(rel, None)
        self.n_refused_now += 1
        self._append({"event": "file refused", "file": rel, "bytes": size, "mtime_ns": mtime_ns,
                      "reason": reason})
        self.say(f"refused: {reason}")

    def _rate_problem(self, phase: str, src: Path, meta: dict) -> str | None:
        for ch, fs in meta["fs_hz"].items():
            sensor = _RATED.get(ch)
            declared = self.axis.get(f"sensors.{sensor}.fs_hz") if sensor else None
            want = declared if declared is not None else self.rates[phase].get(ch)
            if want is None:  # nothing published yet: the files accepted before
                want = next((f.meta["fs_hz"][ch] for g in self.groups.values() if g.phase == phase
                             for f in g.files if ch in f.meta["fs_hz"]), None)
            if want is not None and abs(fs - want) > RATE_TOLERANCE * want:
                where = (f"the axis description's sensors.{sensor}.fs_hz" if declared is not None
                         else "the rate of the files imported before")
                return (f"{src}: channel {ch} sampled at {fs:.9g} Hz; expected {want:.9g} Hz ({where}, within "
                        f"{RATE_TOLERANCE:g} relative)")
        return None

    def _accept(self, phase: str, src: Path, rel: str, size: int, mtime_ns: int) -> bool:
        """Convert one settled file and put it into its group, or refuse it; False if it changed
        while it was read (it settles again)."""
        p = self.phases[phase]
        table = self._table(phase, p)
        if table is None:
            return True  # waiting for the hours table
        if not self._in_table(src, p, table):
            if rel not in self.waiting_said:
                self.waiting_said.add(rel)
                self.say(f"waiting: {src} has no line in the hours table {self.spec_dir / p.hours_table.file} yet")
            return True
        try:
            meta, part, _ = convert_file(self.out, phase, p, src, table, _section(self.spec, p, table),
                                         self.axis, self.spec_dir)
        except Exception as exc:  # noqa: BLE001 - a watcher that runs for months outlives any one bad file
            if _stat(src) != (size, mtime_ns):
                return False
            text = str(exc) if isinstance(exc, (ImportSpecError, DatasetError, OSError, ValueError)) \
                else f"{type(exc).__name__}: {exc}"
            self._refuse(src, rel, size, mtime_ns, text if str(src) in text else f"{src}: {text}")
            return True
        if _stat(src) != (size, mtime_ns):
            return False
        key = _group_key(phase, meta)
        f = _File(rel, src, meta, part, size, mtime_ns)
        what = "Phase I sample" if phase == "phase1" else "Phase II session"
        label = key if not key.startswith("h") or phase == "phase2" else f"at {meta['hours']:g} h"
        why = self._rate_problem(phase, src, meta)
        if why is None and (phase, key) in self.published_groups:
            why = (f"{src}: {what} {label} was imported before this file was complete (as "
                   f"{', '.join(self.published_groups[(phase, key)])}); a late file of an imported "
                   f"{what.split()[-1]} is refused ([watch] {_COUNT[phase]} makes it wait for all of them)")
        g = self.groups.get((phase, key))
        if why is None and g is not None and phase == "phase2":
            exact = "hours" in p.groups() or p.hours_table is not None
            lo, hi = min(g.hours, f.hours), max(g.max_hours, f.hours)
            if hi > lo and (exact or hi - lo > p.max_session_span_hours):
                allowed = "one hours value per session" if exact else \
                    f"the runs of a session within {p.max_session_span_hours:g} h (phase2.max_session_span_hours)"
                why = (f"{src}: run of session {key!r} at {f.hours:g} h where its other runs are at "
                       f"{g.hours:g}–{g.max_hours:g} h; expected {allowed}")
        order = (min(f.hours, g.hours) if g else f.hours, _RANK[phase])
        if why is None and self.last_order is not None and order < self.last_order[:2]:
            why = (f"{src}: operating hours {f.hours:g} h, before the last imported unit ({self.last_unit}); "
                   "expected the files to arrive in the order of their operating hours (a file that comes "
                   "late cannot be put before units already imported)")
        if why is not None:
            self._refuse(src, rel, size, mtime_ns, why)
            return True
        self.seen.pop(rel, None)
        if g is None:
            g = self.groups[(phase, key)] = _Group(phase, key)
        g.files.append(f)
        return True

    # --- publishing ---------------------------------------------------------------------------------
    def _closed(self, g: _Group, settling: bool) -> bool:
        """A group is closed when it has its ``[watch]`` count of files, or when a file of later
        hours has been accepted and no file is still settling (which might belong to it)."""
        n = self.expected[g.phase]
        if n is not None and len(g.files) >= n:
            return True
        return not settling and any(f.hours > g.max_hours for o in self.groups.values() if o is not g
                                    for f in o.files)

    def _publish_ready(self, flush: bool = False, settling: bool = False, hold: tuple | None = None) -> int:
        """Publish the closed groups in hours order (all of them with ``flush``); a group after
        ``hold`` (the hours and phase rank a file still being written states in its name) waits
        for that file. Returns how many were published."""
        n = 0
        while self.groups and not self.stop:
            g = min(self.groups.values(), key=_Group.order)
            if not flush and (not self._closed(g, settling) or (hold is not None and g.order()[:2] > hold)):
                break
            del self.groups[(g.phase, g.key)]
            self._publish(g)
            n += 1
        return n

    def _unit_file(self, stem: str, write: Callable[[Path], None], files: list[_File]) -> Path | None:
        """Write a unit's data file (the validating writer writes a temporary file and renames it
        into place); None, with its files refused, if the writer refuses the data."""
        path = self.live / f"{stem}.h5"
        try:
            write(path)
        except (DatasetError, ValueError) as exc:
            for f in files:
                self._refuse(f.src, f.rel, f.bytes, f.mtime_ns,
                             f"{f.src}: the dataset's writer refuses it ({exc})")
            return None
        return path

    def _manifest(self, stem: str, data: Path, **keys) -> dict:
        man = {"format": UNIT_FORMAT, "version": UNIT_VERSION, **keys, "file": data.name,
               "bytes": data.stat().st_size, "sha256": sha256_of(data)}
        write_json(self.live / f"{stem}.json", man)
        return man

    def _publish(self, g: _Group, skip: int = 0) -> None:
        """Write the group's unit(s) and manifest(s); ``skip`` captures of it were published already."""
        files = sorted(g.files, key=lambda f: (f.hours, str(f.src)) if g.phase == "phase1" else
                       (_key(f.meta["groups"].get("run", "")), str(f.src)))
        sources = [{"file": f.rel, "bytes": f.bytes, "mtime_ns": f.mtime_ns} for f in files]
        common = {"group": g.key, "group_hours": g.hours, "order": [g.hours, _RANK[g.phase]]}
        axis = self.axis.to_dict()
        if g.phase == "phase1":
            s = g.files[0].meta["groups"].get("sample")
            for f in files:
                if f.hours not in self.p1_hours:
                    self.p1_hours.append(f.hours)
            for i, f in enumerate(files):
                name, seq = f"c{self.n_capture:06d}", self.n_seq
                sample = int(s) if s is not None and s.isdigit() else sorted(self.p1_hours).index(f.hours)
                stem = f"{seq:06d}-phase1-{name}"
                if i >= skip:
                    _, arrays = load_part(f.part)
                    attrs = {"hours": f.hours, "sample": sample, "fs_hz": f.meta["fs_hz"]["speed"]}
                    data = self._unit_file(stem, lambda path, name=name, attrs=attrs, arrays=arrays:
                                           assemble_measurements(path, axis, [(name, attrs, arrays)]), [f])
                    if data is None:
                        continue
                    man = self._manifest(stem, data, seq=seq, kind="phase1", name=name, hours=f.hours,
                                         sample=sample, captures_in_sample=len(files),
                                         sources=[sources[i]], group_sources=[x["file"] for x in sources],
                                         fs_hz=f.meta["fs_hz"], **common)
                    self._absorb(man)
                    self._announce(man, [f])
                else:
                    self.n_seq, self.n_capture = seq + 1, self.n_capture + 1
            return
        name, seq = f"s{self.n_session:04d}", self.n_seq
        stem = f"{seq:06d}-phase2-{name}"
        routine = self.axis.phase2_routine.model_dump(exclude_none=True) if self.axis.phase2_routine else {}
        run_attrs = {k: v for k, v in routine.items() if k in ("speeds_mm_s", *ROUTINE_ATTRS)}

        def runs():
            for k, f in enumerate(files):
                _, arrays = load_part(f.part)
                yield f"r{k:04d}", dict(run_attrs), arrays, {ch: {"fs_hz": fs} for ch, fs in f.meta["fs_hz"].items()}

        data = self._unit_file(stem, lambda path: assemble_measurements(path, axis, (), [(name, {"hours": g.hours},
                                                                                         runs())]), files)
        if data is None:
            return
        label = g.key if "session" in files[0].meta["groups"] else None
        man = self._manifest(stem, data, seq=seq, kind="phase2", name=name, hours=g.hours, runs=len(files),
                             session_name=label, sources=sources, fs_hz=files[0].meta["fs_hz"], **common)
        self._absorb(man)
        self._announce(man, files)

    def _announce(self, man: dict, files: list[_File]) -> None:
        self.n_published_now += 1
        self._append({"event": "unit published", "seq": man["seq"], "kind": man["kind"], "name": man["name"],
                      "hours": man["hours"], "files": [f.rel for f in files]})
        what = (f"sample {man['sample']}" if man["kind"] == "phase1" else f"{man['runs']} run(s)")
        self.say(f"imported {man['name']} ({what}, {man['hours']:g} h) from "
                 f"{', '.join(f.rel for f in files)} -> {self.live / man['file']}")

    # --- the loop -------------------------------------------------------------------------------------
    def step(self) -> tuple[int, int]:
        """One look at the folder: accept the settled files (in name order), publish the closed
        groups. Returns (files accepted or refused now, files still settling)."""
        ready, unsettled, hold = self._candidates()
        handled = 0
        for phase, src, rel, size, mtime_ns in ready:
            if self.stop:
                break
            before = self.n_refused_now, sum(len(g.files) for g in self.groups.values())
            if not self._accept(phase, src, rel, size, mtime_ns):  # it changed while it was read
                self.seen.pop(rel, None)
                unsettled += 1
            elif before != (self.n_refused_now, sum(len(g.files) for g in self.groups.values())):
                handled += 1
            # else: waiting for its line in an hours table (neither settling nor handled)
        handled += self._publish_ready(settling=unsettled > 0, hold=hold)
        return handled, unsettled

    def run(self, poll_s: float = 1.0, once: bool = False, until_idle_s: float | None = None,
            sleep: Callable[[float], None] = time.sleep) -> WatchResult:
        """Watch until :attr:`stop` is set (a signal handler sets it), or with ``once`` until every
        file present has settled and been imported or refused, or with ``until_idle_s`` until
        nothing has arrived or changed for that many seconds. A finite watch publishes the open
        groups, writes ``measurements.h5`` and ``import.json`` and ``live/end.json``."""
        self._lock()
        self._resume()
        self._append({"event": "watch started", "spec": str(self.spec_path.resolve()), "output": str(self.out),
                      "files_imported_before": len(self.published), "files_refused_before": len(self.refused),
                      "settle_s": self.settle_s})
        idle_since = self.clock()
        ended = "stopped"
        while not self.stop:
            handled, unsettled = self.step()
            if handled or unsettled:
                idle_since = self.clock()
            if once and not unsettled and not handled:
                ended = "once"
                break
            if until_idle_s is not None and self.clock() - idle_since >= until_idle_s:
                ended = "idle"
                break
            t_end = self.clock() + poll_s
            while not self.stop and self.clock() < t_end:
                sleep(min(0.05, poll_s))
        summary = None
        if ended != "stopped":
            self._publish_ready(flush=True)
            if self.published and not self.stop:
                try:
                    if self.n_published_now or not (self.out / "measurements.h5").is_file():
                        summary = self.assemble()
                finally:  # the live units are complete even if the campaign file cannot be written
                    write_json(self.live / "end.json", {"format": SOURCE_FORMAT, "version": UNIT_VERSION,
                                                        "units": self.n_seq, "finished": True})
        self._append({"event": "watch stopped", "ended": ended, "units": self.n_seq,
                      "published_now": self.n_published_now, "refused_now": self.n_refused_now})
        return WatchResult(self.n_seq, len(self.published), len(self.refused), ended, summary)

    def assemble(self):
        """``OUT/measurements.h5`` and ``OUT/import.json`` of the imported files, as ``twin import``
        writes them (:func:`analysis.ingest.convert.assemble_import`); says if a name differs from
        the live unit's."""
        parts: dict[str, list] = {"phase1": [], "phase2": []}
        units: dict[str, str] = {}
        for m in self._manifests():
            for s in m["sources"]:
                part = _part_path(self.out, m["kind"], self.spec_dir / s["file"])
                meta = load_part(part)[0]
                parts[m["kind"]].append((meta, part))
                units[meta["source"]] = m["name"]
        summary = assemble_import(self.spec_path, self.spec, self.out, self.axis, parts)
        for r in summary.mapping or []:
            name = r.get("capture") or r["session"]
            if units.get(r["file"]) != name:
                self.say(f"warning: {r['file']} is {name} in {self.out / 'measurements.h5'} but "
                         f"{units.get(r['file'])} in {self.live} (files out of hours order?)")
        return summary


def _stat(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_size, st.st_mtime_ns


