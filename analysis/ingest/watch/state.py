"""What a watch has done, kept in its output folder so that a restarted watcher resumes: the
manifests of the units published into ``OUT/live/`` (each names its source files with their size
and modification time) and the append-only log ``OUT/import-watch.jsonl`` (``watch started``,
``file refused``, ``unit published``, ``watch stopped``), rebuilt into memory at a start
(:class:`_WatchState`); one watcher per output folder (a lock).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from analysis.base.files import read_json, write_json
from analysis.dataset.live import SOURCE_FORMAT, UNIT_FORMAT, UNIT_VERSION
from analysis.ingest.spec import ImportSpecError
from analysis.ingest.watch.folder import _stat

LIVE_DIR = "live"
WATCH_LOG = "import-watch.jsonl"


class _WatchState:
    """The state of the watch of output folder ``out``: what was published (from the manifests),
    what was refused (from the log), the sequence and name counters of the units, the rates of
    the channels published, and the counts of this process (``n_published_now``,
    ``n_refused_now``)."""

    def __init__(self, out: Path):
        self.out = out
        self.live = out / LIVE_DIR
        self.log = out / WATCH_LOG
        self.published: dict[str, dict] = {}  # rel -> {"bytes", "mtime_ns", "unit"}
        self.published_groups: dict[tuple[str, str], list[str]] = {}  # (phase, key) -> unit names
        self.refused: dict[str, tuple[int, int]] = {}
        self.n_seq = self.n_capture = self.n_session = 0
        self.p1_hours: list[float] = []
        self.last_order: tuple | None = None
        self.last_unit: str | None = None
        self.rates: dict[str, dict[str, float]] = {"phase1": {}, "phase2": {}}
        self.n_published_now = self.n_refused_now = 0

    def lock(self) -> None:
        """One watcher per output folder (an exclusive lock on ``OUT/.watch.lock``)."""
        from analysis.base.files import exclusive_lock

        self._lock_fh = exclusive_lock(self.out / ".watch.lock", f"{self.out}: another twin import --watch is "
                                       "writing this campaign folder; stop it first, or give another -o",
                                       ImportSpecError)

    def append(self, event: dict) -> None:
        """One line of the watch log, appended with a single write."""
        line = json.dumps({"event": event.pop("event"), **event, "wall_time": time.strftime("%Y-%m-%dT%H:%M:%S%z")},
                          allow_nan=False) + "\n"
        fd = os.open(self.log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, line.encode())
        finally:
            os.close(fd)

    def manifests(self) -> list[dict]:
        """The manifests of the units in ``OUT/live/`` whose data file is in place, in ``seq`` order."""
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

    def absorb(self, m: dict) -> None:
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

    def open(self, spec_path: Path) -> list[dict]:
        """Prepare ``OUT/live/`` for this run of the source of ``spec_path`` (temporary files and
        ``end.json`` removed, ``source.json`` written once) and rebuild the state from the
        manifests and the log. Returns the manifests, in ``seq`` order."""
        self.live.mkdir(parents=True, exist_ok=True)
        for tmp in self.live.glob(".*.tmp"):
            tmp.unlink(missing_ok=True)
        (self.live / "end.json").unlink(missing_ok=True)  # the source goes on
        if not (self.live / "source.json").is_file():
            write_json(self.live / "source.json", {"format": SOURCE_FORMAT, "version": UNIT_VERSION,
                                                   "producer": "twin import --watch",
                                                   "spec": str(spec_path.resolve())})
        manifests = self.manifests()
        for m in manifests:
            self.absorb(m)
        if self.log.is_file():
            for line in self.log.read_text(encoding="utf-8").splitlines():
                try:
                    ev = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a torn last line
                if ev.get("event") == "file refused":
                    self.refused[ev["file"]] = (ev["bytes"], ev["mtime_ns"])
        return manifests

    def refuse(self, rel: str, size: int, mtime_ns: int, reason: str) -> None:
        """Record a refused file (``rel``, at that size and modification time) and log why."""
        self.refused[rel] = (size, mtime_ns)
        self.n_refused_now += 1
        self.append({"event": "file refused", "file": rel, "bytes": size, "mtime_ns": mtime_ns,
                     "reason": reason})
