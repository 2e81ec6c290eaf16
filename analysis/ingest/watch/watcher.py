"""The watcher (:class:`ImportWatcher`): it looks at the export folder, accepts the settled files
(converted by the spec's reader and checked: rate, hours order, groups) or refuses them, and
publishes the closed groups as live units; a finite watch ends with ``measurements.h5`` and
``import.json`` as ``twin import`` writes them. What each step does and why: :mod:`analysis.ingest.watch`.
"""

from __future__ import annotations

import glob
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from analysis.base.files import write_json
from analysis.dataset import DatasetError
from analysis.dataset.axis import AxisDescription
from analysis.dataset.live import SOURCE_FORMAT, UNIT_VERSION
from analysis.ingest.convert import _part_path, _section, assemble_import, convert_file, load_part
from analysis.ingest.spec import ImportSpecError, PhaseSpec, load_spec
from analysis.ingest.watch.folder import _ExportFolder, _stat
from analysis.ingest.watch.groups import _COUNT, _RANK, _closed, _File, _Group, _group_key
from analysis.ingest.watch.publish import _UnitPublisher
from analysis.ingest.watch.state import _WatchState

#: Relative difference of a file's sampling rate from the expected one above which it is refused.
RATE_TOLERANCE = 1e-4
#: The axis description's sensor whose ``fs_hz`` a format channel must have.
_RATED = {"acc1": "nut_accelerometers", "acc2": "nut_accelerometers", "imu_acc": "imu_accelerometer",
          "imu_gyro": "imu_gyroscope"}


def _refuser(state: _WatchState, folder: _ExportFolder, say: Callable[[str], None]
             ) -> Callable[[Path, str, int, int, str], None]:
    """``refuse(src, rel, bytes, mtime_ns, reason)``: the file is recorded as refused (at that size
    and modification time) and logged with its reason, forgotten by the folder's settling, and
    the reason said."""

    def refuse(src: Path, rel: str, size: int, mtime_ns: int, reason: str) -> None:
        state.refuse(rel, size, mtime_ns, reason)
        folder.seen.pop(rel, None)
        say(f"refused: {reason}")

    return refuse


@dataclass
class WatchResult:
    """What a watch did: units and files imported, files refused, why it ended
    (``"idle"``, ``"once"`` or ``"stopped"``), the summary of the final assembly (or None)."""

    units: int
    files: int
    refused: int
    ended: str
    summary: object = None


class ImportWatcher:
    """Watch the folder of an import spec and publish its complete files as live units (docstring
    of :mod:`analysis.ingest.watch`). ``settle_s``: seconds a file's size and modification time
    must stay unchanged; ``say``: prints a sentence for the user; ``clock``: monotonic seconds.

    Its jobs are held by helpers: the folder and its settling files (:class:`_ExportFolder`),
    the state kept in the output folder (:class:`_WatchState`), the writing of units
    (:class:`_UnitPublisher`); the open groups are :attr:`groups`."""

    def __init__(self, spec_path: str | os.PathLike, output: str | os.PathLike | None = None, *,
                 settle_s: float = 2.0, say: Callable[[str], None] = print,
                 clock: Callable[[], float] = time.monotonic):
        self.spec_path = Path(spec_path)
        self.spec, self.spec_dir = load_spec(self.spec_path)
        self.out = Path(output) if output is not None else self.spec_dir / self.spec.output
        self.axis = AxisDescription.from_dict(self.spec.axis, f"{self.spec_path} [axis]")
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
        self.state = _WatchState(self.out)  # rebuilt from the manifests and the log by _resume
        self.live, self.log = self.state.live, self.state.log
        self.folder = _ExportFolder(self.spec_dir, self.phases, self.live, self.settle_s, say, clock)
        # Helpers hold no reference to the watcher: a watcher dropped is freed at once, and with it
        # the lock on its output folder (tests/test_import_watch.py starts a second one).
        self._refuse = _refuser(self.state, self.folder, say)
        self.publisher = _UnitPublisher(self.state, self.axis, say, self._refuse)
        self.groups: dict[tuple[str, str], _Group] = {}
        self.stop = False

    @property
    def n_published_now(self) -> int:
        """Units published by this process."""
        return self.state.n_published_now

    # --- resuming --------------------------------------------------------------------------------
    def _resume(self) -> None:
        manifests = self.state.open(self.spec_path)
        # A sample killed while its captures were being published: publish the rest first.
        if manifests and manifests[-1]["kind"] == "phase1":
            last = manifests[-1]
            done = self.state.published_groups[("phase1", last["group"])]
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
                table = self.folder.table(phase, p) or {}
                meta, part, _ = convert_file(self.out, phase, p, src, table, _section(self.spec, p, table),
                                             self.axis, self.spec_dir)
            st = src.stat()
            files.append(_File(rel, src, meta, part, st.st_size, st.st_mtime_ns))
        g = _Group(phase, last["group"], files)
        first = last["seq"] - (done - 1)
        state = self.state
        state.n_seq, state.n_capture = first, state.n_capture - done
        state.p1_hours = [h for h in state.p1_hours if h not in {f.hours for f in files}]
        self.publisher.publish(g, skip=done)

    # --- accepting or refusing a file --------------------------------------------------------------
    def _rate_problem(self, phase: str, src: Path, meta: dict) -> str | None:
        for ch, fs in meta["fs_hz"].items():
            sensor = _RATED.get(ch)
            declared = self.axis.get(f"sensors.{sensor}.fs_hz") if sensor else None
            want = declared if declared is not None else self.state.rates[phase].get(ch)
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
        table = self.folder.table(phase, p)
        if table is None:
            return True  # waiting for the hours table
        if not self.folder.in_table(src, p, table):
            if rel not in self.folder.waiting_said:
                self.folder.waiting_said.add(rel)
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
        published_groups = self.state.published_groups
        if why is None and (phase, key) in published_groups:
            why = (f"{src}: {what} {label} was imported before this file was complete (as "
                   f"{', '.join(published_groups[(phase, key)])}); a late file of an imported "
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
        last_order = self.state.last_order
        if why is None and last_order is not None and order < last_order[:2]:
            why = (f"{src}: operating hours {f.hours:g} h, before the last imported unit ({self.state.last_unit}); "
                   "expected the files to arrive in the order of their operating hours (a file that comes "
                   "late cannot be put before units already imported)")
        if why is not None:
            self._refuse(src, rel, size, mtime_ns, why)
            return True
        self.folder.seen.pop(rel, None)
        if g is None:
            g = self.groups[(phase, key)] = _Group(phase, key)
        g.files.append(f)
        return True

    # --- publishing ---------------------------------------------------------------------------------
    def _publish_ready(self, flush: bool = False, settling: bool = False, hold: tuple | None = None) -> int:
        """Publish the closed groups in hours order (all of them with ``flush``); a group after
        ``hold`` (the hours and phase rank a file still being written states in its name) waits
        for that file. Returns how many were published."""
        n = 0
        while self.groups and not self.stop:
            g = min(self.groups.values(), key=_Group.order)
            if not flush and (not _closed(g, self.groups, self.expected, settling)
                              or (hold is not None and g.order()[:2] > hold)):
                break
            del self.groups[(g.phase, g.key)]
            self.publisher.publish(g)
            n += 1
        return n

    # --- the loop -------------------------------------------------------------------------------------
    def step(self) -> tuple[int, int]:
        """One look at the folder: accept the settled files (in name order), publish the closed
        groups. Returns (files accepted or refused now, files still settling)."""
        ready, unsettled, hold = self.folder.candidates(self.state.published, self.state.refused, self.groups)
        handled = 0
        for phase, src, rel, size, mtime_ns in ready:
            if self.stop:
                break
            before = self.state.n_refused_now, sum(len(g.files) for g in self.groups.values())
            if not self._accept(phase, src, rel, size, mtime_ns):  # it changed while it was read
                self.folder.seen.pop(rel, None)
                unsettled += 1
            elif before != (self.state.n_refused_now, sum(len(g.files) for g in self.groups.values())):
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
        state = self.state
        state.lock()
        self._resume()
        state.append({"event": "watch started", "spec": str(self.spec_path.resolve()), "output": str(self.out),
                      "files_imported_before": len(state.published), "files_refused_before": len(state.refused),
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
            if state.published and not self.stop:
                try:
                    if state.n_published_now or not (self.out / "measurements.h5").is_file():
                        summary = self.assemble()
                finally:  # the live units are complete even if the campaign file cannot be written
                    write_json(self.live / "end.json", {"format": SOURCE_FORMAT, "version": UNIT_VERSION,
                                                        "units": state.n_seq, "finished": True})
        state.append({"event": "watch stopped", "ended": ended, "units": state.n_seq,
                      "published_now": state.n_published_now, "refused_now": state.n_refused_now})
        return WatchResult(state.n_seq, len(state.published), len(state.refused), ended, summary)

    def assemble(self):
        """``OUT/measurements.h5`` and ``OUT/import.json`` of the imported files, as ``twin import``
        writes them (:func:`analysis.ingest.convert.assemble_import`); says if a name differs from
        the live unit's."""
        parts: dict[str, list] = {"phase1": [], "phase2": []}
        units: dict[str, str] = {}
        for m in self.state.manifests():
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
