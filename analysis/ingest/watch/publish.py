"""Publishing a closed group as live units in ``OUT/live/``, in the live-unit convention of
:mod:`analysis.dataset.live` that ``twin monitor`` reads: each Phase I capture a unit
``<seq>-phase1-c<NNNNNN>.h5``, each Phase II session a unit ``<seq>-phase2-s<NNNN>.h5``, written
under a temporary name and renamed into place, then its manifest (size, SHA-256), taken into the
watch's state and logged (:class:`_UnitPublisher`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from analysis.base.files import write_json
from analysis.dataset import DatasetError, assemble_measurements
from analysis.dataset.axis import AxisDescription
from analysis.dataset.live import UNIT_FORMAT, UNIT_VERSION, sha256_of
from analysis.dataset.schema import ROUTINE_ATTRS
from analysis.ingest.convert import _key, load_part
from analysis.ingest.watch.groups import _RANK, _File, _Group
from analysis.ingest.watch.state import _WatchState


class _UnitPublisher:
    """Writes the units of the watch whose ``state`` it advances, with the ``axis`` description in
    each. ``say``: prints a sentence for the user; ``refuse(src, rel, bytes, mtime_ns, reason)``:
    refuses a file whose unit the dataset's writer refuses."""

    def __init__(self, state: _WatchState, axis: AxisDescription, say: Callable[[str], None],
                 refuse: Callable[[Path, str, int, int, str], None]):
        self.state, self.axis, self.say, self.refuse = state, axis, say, refuse
        self.live = state.live

    def unit_file(self, stem: str, write: Callable[[Path], None], files: list[_File]) -> Path | None:
        """Write a unit's data file (the validating writer writes a temporary file and renames it
        into place); None, with its files refused, if the writer refuses the data."""
        path = self.live / f"{stem}.h5"
        try:
            write(path)
        except (DatasetError, ValueError) as exc:
            for f in files:
                self.refuse(f.src, f.rel, f.bytes, f.mtime_ns,
                            f"{f.src}: the dataset's writer refuses it ({exc})")
            return None
        return path

    def manifest(self, stem: str, data: Path, **keys) -> dict:
        man = {"format": UNIT_FORMAT, "version": UNIT_VERSION, **keys, "file": data.name,
               "bytes": data.stat().st_size, "sha256": sha256_of(data)}
        write_json(self.live / f"{stem}.json", man)
        return man

    def publish(self, g: _Group, skip: int = 0) -> None:
        """Write the group's unit(s) and manifest(s); ``skip`` captures of it were published already."""
        st = self.state
        files = sorted(g.files, key=lambda f: (f.hours, str(f.src)) if g.phase == "phase1" else
                       (_key(f.meta["groups"].get("run", "")), str(f.src)))
        sources = [{"file": f.rel, "bytes": f.bytes, "mtime_ns": f.mtime_ns} for f in files]
        common = {"group": g.key, "group_hours": g.hours, "order": [g.hours, _RANK[g.phase]]}
        axis = self.axis.to_dict()
        if g.phase == "phase1":
            s = g.files[0].meta["groups"].get("sample")
            for f in files:
                if f.hours not in st.p1_hours:
                    st.p1_hours.append(f.hours)
            for i, f in enumerate(files):
                name, seq = f"c{st.n_capture:06d}", st.n_seq
                sample = int(s) if s is not None and s.isdigit() else sorted(st.p1_hours).index(f.hours)
                stem = f"{seq:06d}-phase1-{name}"
                if i >= skip:
                    _, arrays = load_part(f.part)
                    attrs = {"hours": f.hours, "sample": sample, "fs_hz": f.meta["fs_hz"]["speed"]}
                    data = self.unit_file(stem, lambda path, name=name, attrs=attrs, arrays=arrays:
                                          assemble_measurements(path, axis, [(name, attrs, arrays)]), [f])
                    if data is None:
                        continue
                    man = self.manifest(stem, data, seq=seq, kind="phase1", name=name, hours=f.hours,
                                        sample=sample, captures_in_sample=len(files),
                                        sources=[sources[i]], group_sources=[x["file"] for x in sources],
                                        fs_hz=f.meta["fs_hz"], **common)
                    st.absorb(man)
                    self.announce(man, [f])
                else:
                    st.n_seq, st.n_capture = seq + 1, st.n_capture + 1
            return
        name, seq = f"s{st.n_session:04d}", st.n_seq
        stem = f"{seq:06d}-phase2-{name}"
        routine = self.axis.phase2_routine.model_dump(exclude_none=True) if self.axis.phase2_routine else {}
        run_attrs = {k: v for k, v in routine.items() if k in ("speeds_mm_s", *ROUTINE_ATTRS)}

        def runs():
            for k, f in enumerate(files):
                _, arrays = load_part(f.part)
                yield f"r{k:04d}", dict(run_attrs), arrays, {ch: {"fs_hz": fs} for ch, fs in f.meta["fs_hz"].items()}

        data = self.unit_file(stem, lambda path: assemble_measurements(path, axis, (), [(name, {"hours": g.hours},
                                                                                        runs())]), files)
        if data is None:
            return
        label = g.key if "session" in files[0].meta["groups"] else None
        man = self.manifest(stem, data, seq=seq, kind="phase2", name=name, hours=g.hours, runs=len(files),
                            session_name=label, sources=sources, fs_hz=files[0].meta["fs_hz"], **common)
        st.absorb(man)
        self.announce(man, files)

    def announce(self, man: dict, files: list[_File]) -> None:
        self.state.n_published_now += 1
        self.state.append({"event": "unit published", "seq": man["seq"], "kind": man["kind"], "name": man["name"],
                           "hours": man["hours"], "files": [f.rel for f in files]})
        what = (f"sample {man['sample']}" if man["kind"] == "phase1" else f"{man['runs']} run(s)")
        self.say(f"imported {man['name']} ({what}, {man['hours']:g} h) from "
                 f"{', '.join(f.rel for f in files)} -> {self.live / man['file']}")
