"""``twin import``: convert the files an import spec names, resumably, into ``measurements.h5``.

Each source file becomes one *part* (``<output>/.import/<phase>/<key>.npz``: its channels in
SI units and its timing), written atomically. A part whose source file (size, modification time)
and spec section are unchanged is reused, so an interrupted import resumes where it stopped.
When every part is there, the parts are named in the format's order (captures by hours, sessions
by hours, runs by their run number) and streamed one at a time through the validating writer
:func:`analysis.dataset.assemble_measurements`. ``<output>/import.json`` maps every capture and
run to the file it came from, with the laboratory's session name and the hours and where they
came from (``mapping``, ``sessions``), and lists the import's warnings.

Operating hours come from one of: a ``hours`` group of the file name, a channel's first value,
a table (one line per file, or per session / sample joined on a group of the file name), a
property the file states (TDMS property, MAT variable, MDF header field, a CSV line above the
header), or the file's time stamp with an offset (``hours_clock``). With a time stamp, a channel
or a property, the runs of a session may differ by up to ``max_session_span_hours``; the session
takes the earliest.

Warnings (the import goes on; ``ImportSummary.warnings``, ``import.json``): a CSV file whose
last line has no line end; a file much shorter or longer than its siblings (a run cut at a line
end); files of a phase at different rates; sessions whose hours order differs from their
names' order.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.base.files import atomic_write, write_json
from analysis.dataset import DatasetError, assemble_measurements
from analysis.dataset.axis import AxisDescription
from analysis.dataset.schema import ROUTINE_ATTRS
from analysis.ingest.readers import Channel, read_channels
from analysis.ingest.spec import ImportSpec, ImportSpecError, PhaseSpec, load_spec
from analysis.ingest.units import factor, to_si

_SENSOR = {"acc1": "nut_accelerometers", "acc2": "nut_accelerometers", "imu_acc": "imu_accelerometer"}
_TIME_UNIT = {"s": 1.0, "ms": 1e-3, "us": 1e-6}
#: Bumped when the conversion changes, so that parts of an older import are redone.
_PART_VERSION = 2
#: A file whose duration differs from the median of its phase's files by more than this fraction
#: is named in a warning.
LENGTH_TOLERANCE = 0.1


@dataclass
class ImportSummary:
    """What an import wrote: the campaign directory, counts, parts converted now and reused."""

    output: Path
    captures: int
    sessions: int
    runs: int
    converted: int
    reused: int
    hours: tuple[float, float] | None
    mapping: list[dict] | None = None
    warnings: list[str] | None = None


def _files(spec_dir: Path, phase: str, p: PhaseSpec) -> list[Path]:
    files = sorted(f for f in spec_dir.glob(p.files) if f.is_file())
    if not files:
        raise ImportSpecError(f"{phase}.files = {p.files!r}: no file matches in {spec_dir}")
    return files


def _signature(path: Path, section: str) -> str:
    st = path.stat()
    text = f"{_PART_VERSION}|{path.resolve()}|{st.st_size}|{st.st_mtime_ns}|{section}"
    return hashlib.sha256(text.encode()).hexdigest()


def _part_path(out: Path, phase: str, src: Path) -> Path:
    return out / ".import" / phase / (hashlib.sha1(str(src.resolve()).encode()).hexdigest()[:20] + ".npz")


def _load_part(path: Path) -> tuple[dict, dict[str, np.ndarray]] | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            return meta, {k: z[k] for k in z.files if k != "meta"}
    except (OSError, ValueError, KeyError, EOFError):
        return None  # a damaged part counts as missing


def _save_part(path: Path, meta: dict, arrays: dict[str, np.ndarray]) -> None:
    def write(tmp: Path) -> None:
        buf = io.BytesIO()
        np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
        tmp.write_bytes(buf.getvalue())

    atomic_write(path, write)


def _norm_key(v) -> str:
    """A table key or file-name group as text; integers compare as integers (``03`` = ``3``)."""
    text = str(v).strip()
    return str(int(text)) if re.fullmatch(r"[+-]?\d+", text) else text


def _hours_table(spec_dir: Path, phase: str, p: PhaseSpec) -> dict[str, float]:
    """{key: hours} of ``p.hours_table`` (keys normalised by :func:`_norm_key`)."""
    import csv

    import pandas as pd

    t = p.hours_table
    path = spec_dir / t.file
    key_col, h_col = t.key_col(), t.hours_column
    try:
        sep = t.delimiter
        if sep is None:
            with open(path, encoding="utf-8-sig", errors="replace") as f:
                sample = "".join(f.readline() for _ in range(t.header_line + 5))
            try:
                sep = csv.Sniffer().sniff(sample, delimiters=",;\t|").delimiter
            except csv.Error:
                sep = ","
        df = pd.read_csv(path, sep=sep, skiprows=t.header_line - 1, dtype=str, keep_default_na=False,
                         skipinitialspace=True, encoding="utf-8-sig")
    except (OSError, ValueError, UnicodeDecodeError) as e:
        raise ImportSpecError(f"{path}: cannot read the hours table of {phase} ({e})") from None
    df.columns = [str(c).strip() for c in df.columns]
    for col, key in ((key_col, "key_column" if t.key_column else "key"), (h_col, "hours_column")):
        if col not in df.columns:
            raise ImportSpecError(f"{path}: column {col!r} ({phase}.hours_table.{key}) is missing; the table has "
                                  f"{', '.join(map(repr, df.columns))}")
    out: dict[str, float] = {}
    first_line = t.header_line + 1
    for i, (k, h) in enumerate(zip(df[key_col], df[h_col], strict=True)):
        text = str(h).strip()
        try:
            hours = float(text.replace(t.decimal, ".") if t.decimal != "." else text)
        except ValueError:
            raise ImportSpecError(f"{path}: line {first_line + i}: {h_col} {h!r} is not a number") from None
        k = _norm_key(k) if t.key != "file" else str(k).strip()
        if k in out and out[k] != hours:
            raise ImportSpecError(f"{path}: line {first_line + i}: {key_col} {k!r} again, at {hours:g} h after "
                                  f"{out[k]:g} h; expected one hours value per {t.key}")
        out[k] = hours
    return out


def _table_hours(src: Path, phase: str, p: PhaseSpec, groups: dict[str, str], table: dict[str, float],
                 spec_dir: Path) -> tuple[float, str]:
    t = p.hours_table
    where = f"the hours table {spec_dir / t.file}"
    if t.key == "file":
        key = src.name
    elif t.key not in groups:
        raise ImportSpecError(f"{src}: the file name has no {t.key!r} group ({phase}.name_pattern) to look up "
                              f"in {where}")
    else:
        key = _norm_key(groups[t.key])
    if key not in table:
        shown = ", ".join(map(repr, sorted(table)[:12])) + (" ..." if len(table) > 12 else "")
        raise ImportSpecError(f"{src}: no line for {t.key} {key!r} in {where} (column {t.key_col()!r}); the table "
                              f"has {shown or 'no lines'}")
    return table[key], f"{where}, {t.key} {key!r}"


def _clock_hours(src: Path, p: PhaseSpec) -> tuple[float, str]:
    """Hours from the file's time stamp (``hours_clock``)."""
    import datetime as dt

    from analysis.ingest.readers import start_time

    c = p.hours_clock
    if c.source == "mtime":
        stamp = dt.datetime.fromtimestamp(src.stat().st_mtime, dt.UTC)
    else:
        stamp = start_time(src, reader=p.reader, group=p.group)
    origin = c.origin if c.origin.tzinfo is not None else c.origin.replace(tzinfo=dt.UTC)
    hours = c.hours_at_origin + c.duty * (stamp - origin).total_seconds() / 3600.0
    return hours, f"the file's {c.source.replace('_', ' ')} {stamp.isoformat()}"


def _fs(src: Path, key: str, ch: Channel, m_fs: float | None, p: PhaseSpec, time_fs: float | None) -> float:
    for fs in (m_fs, p.fs_hz, time_fs, ch.fs_hz):
        if fs is not None:
            return float(fs)
    raise ImportSpecError(f"{src}: channel {ch.name!r} ({key}): no sampling rate; give fs_hz on the channel "
                          "or the phase, or time_channel")


def _time_rate(src: Path, t: Channel, unit: str) -> float:
    x = t.values * _TIME_UNIT[unit]
    if x.size < 2:
        raise ImportSpecError(f"{src}: time channel {t.name!r} has {x.size} sample(s); expected at least 2")
    dt = np.diff(x)
    bad = np.flatnonzero(~(dt > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise ImportSpecError(f"{src}: time channel {t.name!r}, {t.at(i)}: time {t.values[i]!r} does not "
                              f"increase (previous {t.values[i - 1]!r}); expected increasing times")
    step = float(np.median(dt))
    gap = np.flatnonzero(np.abs(dt - step) > 0.5 * step)
    if gap.size:
        i = int(gap[0]) + 1
        raise ImportSpecError(f"{src}: time channel {t.name!r}, {t.at(i)}: a step of {dt[i - 1]:.6g} s where "
                              f"the rate gives {step:.6g} s (a dropout or a changed rate); expected uniform "
                              "sampling")
    return float(f"{(x.size - 1) / (x[-1] - x[0]):.9g}")  # the printed times' rounding averaged out


def _convert(src: Path, phase: str, p: PhaseSpec, axis: AxisDescription, hours_of: dict[str, float],
             spec_dir: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """One file -> (meta, {channel: SI array}); ImportSpecError naming file, channel and line."""
    names = [n for m in p.channels.values() for n in m.names()]
    extra = [n for n in (p.time_channel, p.hours_channel) if n is not None]
    warnings: list[str] = []
    chans = read_channels(src, names + extra, reader=p.reader, group=p.group, delimiter=p.delimiter,
                          header_line=p.header_line, decimal=p.decimal, warnings=warnings)
    time_fs = _time_rate(src, chans[p.time_channel], p.time_unit) if p.time_channel else None
    arrays, fs = {}, {}
    for key, m in p.channels.items():
        cols = [chans[n] for n in m.names()]
        rates = {_fs(src, key, c, m.fs_hz, p, time_fs) for c in cols}
        lengths = {c.values.size for c in cols}
        if len(rates) > 1 or len(lengths) > 1:
            raise ImportSpecError(f"{src}: channels {m.names()} of {key} differ in rate {sorted(rates)} Hz or "
                                  f"length {sorted(lengths)}; expected the three axes of one sensor")
        sens = m.sensitivity_mV_per_g
        if sens is None and key in _SENSOR:
            sens = axis.get(f"sensors.{_SENSOR[key]}.sensitivity_mV_per_g")
        try:
            f = factor(key, m.unit, sensitivity_mV_per_g=sens, lead_mm=axis.lead_mm)
        except ValueError as e:
            raise ImportSpecError(f"{src}: channel {m.names()[0]!r} ({phase}.channels.{key}): {e}") from None
        for c in cols:
            bad = np.flatnonzero(~np.isfinite(c.values))
            if bad.size:
                raise ImportSpecError(f"{src}: channel {c.name!r}, {c.at(int(bad[0]))}: {float(c.values[bad[0]])!r} "
                                      f"({bad.size} non-finite value(s) in all); expected finite samples")
            if c.values.size == 0:
                raise ImportSpecError(f"{src}: channel {c.name!r} is empty; expected samples")
        data = np.stack([to_si(c.values, m.scale, m.offset, f) for c in cols], axis=1)
        arrays[key] = data[:, 0] if len(cols) == 1 else data
        fs[key] = rates.pop()
    meta: dict = {"source": str(src), "fs_hz": fs, "warnings": warnings,
                  "n": {k: int(a.shape[0]) for k, a in arrays.items()}}
    groups: dict[str, str] = {}
    if p.name_pattern:
        mt = re.search(p.name_pattern, src.name)
        if mt is None:
            raise ImportSpecError(f"{src}: the file name does not match {phase}.name_pattern = {p.name_pattern!r}")
        groups = {k: v for k, v in mt.groupdict().items() if v is not None}
    meta["groups"] = groups
    if "hours" in groups:
        hours_text = groups["hours"]
        where = f"the file name's hours {hours_text!r}"
    elif p.hours_channel:
        hc = chans[p.hours_channel]
        hours_text = hc.values[0] if hc.values.size else float("nan")
        where = f"channel {p.hours_channel!r}, {hc.at(0)}"
    elif p.hours_table:
        hours_text, where = _table_hours(src, phase, p, groups, hours_of, spec_dir)
    elif p.hours_property:
        from analysis.ingest.readers import read_property

        hours_text, where = read_property(src, p.hours_property, reader=p.reader, group=p.group,
                                          delimiter=p.delimiter, header_line=p.header_line, decimal=p.decimal)
    else:
        hours_text, where = _clock_hours(src, p)
    try:
        hours = float(hours_text)
    except (TypeError, ValueError):
        hours = float("nan")
    if not (np.isfinite(hours) and hours >= 0):
        raise ImportSpecError(f"{src}: operating hours {hours_text!r} from {where}; expected hours >= 0")
    meta["hours"] = hours
    meta["hours_from"] = where
    if phase == "phase1":
        lengths = {k: a.shape[0] for k, a in arrays.items()}
        if len(set(fs.values())) > 1 or len(set(lengths.values())) > 1:
            raise ImportSpecError(f"{src}: the Phase I channels differ in rate ({fs} Hz) or length ({lengths} "
                                  "samples); expected one rate and length for all of a capture")
    return meta, arrays


def _key(v: str):
    return (0, int(v), "") if v.isdigit() else (1, 0, v)


def run_import(spec_path: str | os.PathLike, *, output: str | os.PathLike | None = None,
               progress: Callable[[int, int, str, bool], None] | None = None) -> ImportSummary:
    """Import what the spec at ``spec_path`` names into ``<output>/measurements.h5``.

    ``output`` overrides the spec's ``output`` (relative to the current directory).
    ``progress(done, total, file, reused)`` is called after every source file.
    Raises :class:`ImportSpecError` (spec or source problem) or
    :class:`~analysis.dataset.DatasetError` (what the writer refuses), both naming what is wrong.
    """
    spec, spec_dir = load_spec(spec_path)
    out = Path(output) if output is not None else spec_dir / spec.output
    axis = AxisDescription.from_dict(spec.axis, f"{spec_path} [axis]")
    jobs = []
    for phase in ("phase1", "phase2"):
        p: PhaseSpec | None = getattr(spec, phase)
        if p is None:
            continue
        table = _hours_table(spec_dir, phase, p) if p.hours_table else {}
        jobs += [(phase, p, src, table, _section(spec, p, table)) for src in _files(spec_dir, phase, p)]
    parts: dict[str, list[tuple[dict, Path]]] = {"phase1": [], "phase2": []}
    converted = reused = 0
    for i, (phase, p, src, table, section) in enumerate(jobs):
        meta, part, was_reused = convert_file(out, phase, p, src, table, section, axis, spec_dir)
        reused += was_reused
        converted += not was_reused
        parts[phase].append((meta, part))
        if progress is not None:
            progress(i + 1, len(jobs), src.name, was_reused)
    return assemble_import(spec_path, spec, out, axis, parts, converted, reused)


def _section(spec: ImportSpec, p: PhaseSpec, table: dict[str, float]) -> str:
    """What of the spec a phase's parts depend on (a part converted under another is redone)."""
    return json.dumps([p.model_dump(), spec.axis, table], sort_keys=True, default=str)


def convert_file(out: Path, phase: str, p: PhaseSpec, src: Path, table: dict[str, float], section: str,
                 axis: AxisDescription, spec_dir: Path) -> tuple[dict, Path, bool]:
    """One source file as a part in ``out/.import/``: converted (:func:`_convert`), or reused when
    the part's signature (file size, modification time, spec section) is unchanged.
    Returns (meta, part path, reused); raises :class:`ImportSpecError` naming the file."""
    part = _part_path(out, phase, src)
    sig = _signature(src, section)
    got = _load_part(part) if part.exists() else None
    if got is not None and got[0].get("signature") == sig:
        return got[0], part, True
    meta, arrays = _convert(src, phase, p, axis, table, spec_dir)
    meta["signature"] = sig
    _save_part(part, meta, arrays)
    return meta, part, False


def load_part(part: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """A part's (meta, {channel: SI array}); ValueError if it is gone or damaged."""
    got = _load_part(part)
    if got is None:
        raise ValueError(f"{part}: the converted part is missing or damaged; import the file again")
    return got


def assemble_import(spec_path: str | os.PathLike, spec: ImportSpec, out: Path, axis: AxisDescription,
                    parts: dict[str, list[tuple[dict, Path]]], converted: int = 0,
                    reused: int = 0) -> ImportSummary:
    """Name the converted parts in the format's order and write ``out/measurements.h5`` and
    ``out/import.json`` (module docstring); ``parts`` is {phase: [(meta, part path)]}."""
    spec_dir = Path(spec_path).parent
    # Phase I: captures by (hours, file); samples from the name or one per distinct hours value
    p1 = sorted(parts["phase1"], key=lambda mp: (mp[0]["hours"], mp[0]["source"]))
    distinct = sorted({m["hours"] for m, _ in p1})
    p1_named = []
    for i, (m, part) in enumerate(p1):
        sample = m["groups"].get("sample")
        sample = int(sample) if sample is not None and sample.isdigit() else distinct.index(m["hours"])
        p1_named.append((f"c{i:06d}", sample, m, part))
    # Phase II: sessions by the name's session group (else hours), runs by their run group / file
    exact = "hours" in spec.phase2.groups() or spec.phase2.hours_table is not None if spec.phase2 else True
    span = spec.phase2.max_session_span_hours if spec.phase2 else 0.0
    by_session: dict[str, list[tuple[dict, Path]]] = {}
    for m, part in parts["phase2"]:
        by_session.setdefault(m["groups"].get("session", repr(m["hours"])), []).append((m, part))
    sessions = []
    for key, runs in by_session.items():
        hours = sorted({m["hours"] for m, _ in runs})
        if len(hours) > 1 and (exact or hours[-1] - hours[0] > span):
            a, b = sorted(runs, key=lambda mp: mp[0]["hours"])[:: len(runs) - 1]
            allowed = "one hours value per session" if exact else \
                f"the runs of a session within {span:g} h (phase2.max_session_span_hours)"
            raise ImportSpecError(f"{a[0]['source']} and {b[0]['source']}: runs of session {key!r} at "
                                  f"{a[0]['hours']:g} h and {b[0]['hours']:g} h; expected {allowed}")
        runs.sort(key=lambda mp: (_key(mp[0]["groups"].get("run", "")), mp[0]["source"]))
        sessions.append((hours[0], _key(key), runs, key if "session" in runs[0][0]["groups"] else None))
    sessions.sort(key=lambda s: (s[0], s[1]))
    warnings = [w for m, _ in parts["phase1"] + parts["phase2"] for w in m.get("warnings", [])]
    warnings += _length_warnings(parts) + _order_warnings(sessions)

    def phase1():
        for name, sample, m, part in p1_named:
            _, arrays = _load_part(part)
            yield name, {"hours": m["hours"], "sample": sample, "fs_hz": m["fs_hz"]["speed"]}, arrays

    # every run carries the routine of the axis description (what the IMU-axis analyses read)
    routine = axis.phase2_routine.model_dump(exclude_none=True) if axis.phase2_routine is not None else {}
    run_attrs = {k: v for k, v in routine.items() if k in ("speeds_mm_s", *ROUTINE_ATTRS)}

    def phase2():
        for j, (hours, _, runs, _) in enumerate(sessions):
            def run_iter(runs=runs):
                for k, (m, part) in enumerate(runs):
                    _, arrays = _load_part(part)
                    yield f"r{k:04d}", dict(run_attrs), arrays, {ch: {"fs_hz": fs} for ch, fs in m["fs_hz"].items()}
            yield f"s{j:04d}", {"hours": hours}, run_iter()

    dial = _dial(spec_dir, spec) if spec.dial else None
    try:
        assemble_measurements(out / "measurements.h5", axis.to_dict(), phase1(), phase2(), dial)
    except DatasetError:
        raise
    except ValueError as e:  # the truth-leak guard, a value the format cannot store
        msg = str(e)
        raise ImportSpecError(msg if str(out) in msg or str(spec_dir) in msg else f"{spec_path}: {msg}") from None
    mapping = [{"file": m["source"], "phase": "phase1", "capture": name, "sample": sample,
                "hours": m["hours"], "hours_from": m.get("hours_from")} for name, sample, m, _ in p1_named]
    mapping += [{"file": m["source"], "phase": "phase2", "session": f"s{j:04d}", "run": f"r{k:04d}",
                 "session_name": label, "file_hours": m["hours"], "hours": hours,
                 "hours_from": m.get("hours_from")}
                for j, (hours, _, runs, label) in enumerate(sessions) for k, (m, _) in enumerate(runs)]
    sources = {"spec": str(Path(spec_path).resolve()),
               "phase1": {name: m["source"] for name, _, m, _ in p1_named},
               "phase2": {f"s{j:04d}/r{k:04d}": m["source"] for j, (_, _, runs, _) in enumerate(sessions)
                          for k, (m, _) in enumerate(runs)},
               "sessions": {f"s{j:04d}": {"name": label, "hours": hours, "runs": len(runs)}
                            for j, (hours, _, runs, label) in enumerate(sessions)},
               "mapping": mapping, "warnings": warnings}
    write_json(out / "import.json", sources)
    all_hours = [m["hours"] for m, _ in parts["phase1"] + parts["phase2"]]
    return ImportSummary(out, len(p1_named), len(sessions), sum(len(r) for _, _, r, _ in sessions),
                         converted, reused, (min(all_hours), max(all_hours)) if all_hours else None,
                         mapping, warnings)


def _length_warnings(parts: dict[str, list[tuple[dict, Path]]]) -> list[str]:
    """Files much shorter or longer than their phase's median, and rates that differ within a
    phase: named so a run cut at a line end is not imported silently."""
    out = []
    for phase, items in parts.items():
        for ch in {c for m, _ in items for c in m.get("n", {})}:
            dur = [(m["source"], m["n"][ch] / m["fs_hz"][ch]) for m, _ in items if ch in m.get("n", {})]
            med = float(np.median([x for _, x in dur])) if len(dur) >= 3 else 0.0
            for src, d in dur:
                if med > 0 and abs(d - med) > LENGTH_TOLERANCE * med:
                    out.append(f"{src}: {ch} lasts {d:.6g} s where the other files of {phase} last {med:.6g} s "
                               f"(median); a file cut short or a run stopped early?")
            rates = [(m["source"], m["fs_hz"][ch]) for m, _ in items if ch in m["fs_hz"]]
            values = [f for _, f in rates]
            common = max(set(values), key=values.count) if values else None
            for src, f in rates:
                if f != common:
                    out.append(f"{src}: {ch} at {f:.9g} Hz where the other files of {phase} are at {common:.9g} Hz")
    return sorted(set(out))


def _order_warnings(sessions: list) -> list[str]:
    """Sessions whose names' order differs from their hours' order."""
    named = [(label, hours) for hours, _, _, label in sessions if label is not None]
    by_name = sorted(named, key=lambda t: _key(t[0]))
    return [f"session {b!r} ({hb:g} h) has fewer hours than session {a!r} ({ha:g} h) named before it: the "
            "sessions' hours order differs from their names' order (hours typed in the wrong order?); "
            "sessions are stored in hours order"
            for (a, ha), (b, hb) in zip(by_name, by_name[1:], strict=False) if hb < ha]


def _dial(spec_dir: Path, spec: ImportSpec) -> tuple[np.ndarray, np.ndarray]:
    import pandas as pd

    d = spec.dial
    path = spec_dir / d.file
    try:
        df = pd.read_csv(path, sep=d.delimiter, skipinitialspace=True)
    except (OSError, ValueError) as e:
        raise ImportSpecError(f"{path}: cannot read the dial-indicator readings ({e})") from None
    out = []
    for col in (d.hours_column, d.backlash_um_column):
        if col not in df.columns:
            raise ImportSpecError(f"{path}: column {col!r} is missing; the file has {list(df.columns)}")
        v = pd.to_numeric(df[col], errors="coerce").to_numpy(np.float64)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise ImportSpecError(f"{path}: column {col!r}, line {int(bad[0]) + 2}: {df[col].iloc[bad[0]]!r} "
                                  "is not a finite number")
        out.append(v)
    return out[0], out[1]
