"""``twin check``: what a recording (``measurements.h5``) holds and what is wrong or suspicious.

:func:`check_recording` reads every capture and run through the validating reader and looks at the
signals: NaN or inf (the reader's refusal, naming the index), flat lines, clipping at the
converter's range (many samples at one extreme, or a pile-up there), dropouts (a sensor's value
held for many samples), operating hours that are negative or go back in time, sessions that share
their hours, sampling rates that differ between captures or runs, a run (capture) whose duration is
an outlier among its siblings (a file cut short), and an IMU accelerometer that does not see
gravity (about 9.81 m/s², on its z axis, at standstill). Next to an imported recording,
``import.json`` (:mod:`analysis.ingest.convert`) gives the names the laboratory gave its sessions
and samples; their order must agree with the order of the operating hours (hours typed in the wrong
order reorder the sessions silently). Findings are *errors* (the analysis would fail or be wrong:
``twin check`` exits 1) or *warnings* (suspicious; worth a look).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from analysis.dataset import DatasetError, open_measurements
from analysis.dataset.axis import AxisDescription

G = 9.80665
#: A sensor's value held this many samples in a row is a dropout.
DROPOUT_SAMPLES = 10
#: Samples at one extreme value (and at least 3) that make a clipping warning.
CLIP_FRACTION = 1e-3
#: A pile-up at a converter's rail: at least this many samples at one extreme value, and at least
#: CLIP_PILEUP_RATIO times as many as at the next value inside it (a signal that is not clipped
#: thins out towards its extremes; one clipped only at its peaks, a few samples a run, piles up).
CLIP_PILEUP_MIN = 8
CLIP_PILEUP_RATIO = 4
#: Accepted deviation of the IMU's mean |acceleration| from 1 g.
GRAVITY_TOLERANCE = 0.1
#: A run or capture whose duration differs from its siblings' median by more than this fraction
#: is an outlier (a file cut short, a run stopped early).
DURATION_TOLERANCE = 0.1
#: Axis keys the analyses need (docs/dataset-format.md#the-axis-contract): key -> who needs it.
NEEDED_AXIS_KEYS = {"lead_mm": "twin backlash", "travel_mm": "twin backlash"}
_SENSOR_RANGE = {"acc1": "sensors.nut_accelerometers.range_g", "acc2": "sensors.nut_accelerometers.range_g",
                 "imu_acc": "sensors.imu_accelerometer.range_g", "imu_gyro": "sensors.imu_gyroscope.range_deg_s"}


@dataclass
class Finding:
    """One problem: ``level`` "error" or "warning", ``where`` the HDF5 key, ``what`` the message."""

    level: str
    where: str
    what: str


def finding_channel(where: str) -> str:
    """The recording's channel a finding's HDF5 key names: ``/phase2/s000/r001/imu_acc[x]`` ->
    ``imu_acc`` (one axis of a three-axis channel names the channel)."""
    return str(where).rstrip("/").rsplit("/", 1)[-1].split("[", 1)[0]


def findings_by_channel(check: dict | None) -> dict[str, list[dict]]:
    """{channel: [finding, ...]} of ``check`` (the record of an analysis: :func:`check_record`, its
    ``errors`` then ``warnings``), each channel in the order first found (:func:`finding_channel`)."""
    out: dict[str, list[dict]] = {}
    for f in (check or {}).get("errors", []) + (check or {}).get("warnings", []):
        out.setdefault(finding_channel(f["where"]), []).append(f)
    return out


@dataclass
class CheckReport:
    """What :func:`check_recording` found: ``summary`` (counts, rates, durations, hours span)
    and ``findings``."""

    file: str
    summary: dict = field(default_factory=dict)
    findings: list[Finding] = field(default_factory=list)

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.level == "error"]

    def to_json(self) -> dict:
        return {"file": self.file, "summary": self.summary, "findings": [asdict(f) for f in self.findings],
                "errors": len(self.errors), "warnings": len(self.findings) - len(self.errors)}


def _longest_run(x: np.ndarray) -> tuple[int, int]:
    """(length, start index) of the longest run of equal consecutive samples of (n,) ``x``."""
    if x.size < 2:
        return x.size, 0
    same = np.concatenate(([False], x[1:] == x[:-1], [False]))
    edges = np.flatnonzero(np.diff(same.astype(np.int8)))
    if edges.size == 0:
        return 1, 0
    starts, ends = edges[::2], edges[1::2]
    k = int(np.argmax(ends - starts))
    return int(ends[k] - starts[k]) + 1, int(starts[k])


def _clipped(c: np.ndarray, name: str) -> str | None:
    """The clipping warning of (n,) samples ``c`` at their ``name`` ("maximum" or "minimum"), or
    None: many samples at that one value (:data:`CLIP_FRACTION` of them, and at least 3), or a
    pile-up there (:data:`CLIP_PILEUP_MIN` and :data:`CLIP_PILEUP_RATIO`)."""
    v = c.max() if name == "maximum" else c.min()
    k = int(np.count_nonzero(c == v))
    if k < 3:
        return None
    what = f"clipping: {k} samples at the {name} {v:g}"
    if k >= CLIP_FRACTION * c.size:
        return what
    if k < CLIP_PILEUP_MIN:
        return None
    inside = c[c < v] if name == "maximum" else c[c > v]
    if inside.size == 0:
        return None
    nxt = inside.max() if name == "maximum" else inside.min()
    k_next = int(np.count_nonzero(c == nxt))
    if k < CLIP_PILEUP_RATIO * k_next:
        return None
    return (f"{what} against {k_next} at the next value inside ({nxt:g}): a pile-up at a converter's "
            f"rail (the sensor saturates at its peaks)")


def _signal(rep: CheckReport, key: str, x: np.ndarray, *, sensor: bool, range_si: float | None) -> None:
    cols = x.reshape(len(x), -1)
    names = "xyz" if cols.shape[1] == 3 else [""]
    for j, ax in enumerate(names):
        c = cols[:, j]
        where = f"{key}[{ax}]" if ax else key
        if c.size > 1 and np.ptp(c) == 0:
            rep.findings.append(Finding("error", where, f"flat line: all {c.size} samples are {c[0]:g}"))
            continue
        if not sensor:
            continue
        run, start = _longest_run(c)
        if run >= DROPOUT_SAMPLES:
            rep.findings.append(Finding("warning", where, f"dropout: {run} samples in a row hold {c[start]:g} "
                                                          f"from index {start}"))
        for name in ("maximum", "minimum"):
            what = _clipped(c, name)
            if what:
                rep.findings.append(Finding("warning", where, what))
        if range_si is not None and np.abs(c).max() >= 0.99 * range_si:
            rep.findings.append(Finding("error", where, f"clipping: |value| reaches {np.abs(c).max():g}, the "
                                                        f"sensor's range is {range_si:g} (axis contract)"))


def _ranges(axis: AxisDescription | None) -> dict[str, float | None]:
    out = {}
    for ch, key in _SENSOR_RANGE.items():
        v = axis.get(key) if axis is not None else None
        out[ch] = None if v is None else (v * G if ch != "imu_gyro" else math.radians(v))
    return out


def _hours_order(rep: CheckReport, kind: str, items: list[tuple[str, float]]) -> None:
    """Items in name order must not go back in hours, nor be negative."""
    for name, h in items:
        if h < 0:
            rep.findings.append(Finding("error", name, f"operating hours {h:g} < 0; expected hours >= 0"))
    for (a, ha), (b, hb) in zip(items, items[1:], strict=False):
        if hb < ha:
            rep.findings.append(Finding("error", b, f"operating hours go back: {hb:g} h after {a} at {ha:g} h "
                                                    f"(the {kind} are in name order)"))


def _same_hours(rep: CheckReport, kind: str, items: list[tuple[str, float]]) -> None:
    """Two sessions (or samples) at the same operating hours: a copy-paste in an hours table?"""
    first: dict[float, str] = {}
    for name, h in items:
        if h in first:
            rep.findings.append(Finding("warning", name, f"the same operating hours ({h:g} h) as {first[h]}; "
                                                         f"expected distinct hours per {kind}"))
        else:
            first[h] = name


def _duration_outliers(rep: CheckReport, kind: str, groups: dict[str, list[tuple[str, float]]]) -> None:
    """Runs (captures) whose duration, s, is off the median of their siblings by more than
    :data:`DURATION_TOLERANCE`. ``groups``: {group: [(key, duration_s)]}; the siblings are the
    members of the group (itself included: the median of three or more is robust to one cut
    file) when it has at least three, else every member of all groups."""
    everyone = [d for members in groups.values() for _, d in members]
    for members in groups.values():
        pool = [d for _, d in members] if len(members) >= 3 else everyone
        if len(pool) < 3:
            continue
        med = float(np.median(pool))
        for key, d in members:
            if med > 0 and abs(d - med) > DURATION_TOLERANCE * med:
                rep.findings.append(Finding(
                    "warning", key, f"{kind} of {d:.6g} s where its siblings last {med:.6g} s (median); "
                                    f"expected within {DURATION_TOLERANCE:.0%} (a file cut short, a "
                                    f"{kind.split()[0]} stopped early?)"))


def _naming_order(rep: CheckReport, path: Path) -> None:
    """The laboratory's session names (``import.json`` next to the recording) in the order of
    the hours: a session named earlier but given more hours than a later one is a warning."""
    from analysis.base.files import read_json

    src = path.parent / "import.json"
    if not src.is_file():
        return
    try:
        doc = read_json(src, "the import's record of the files (twin import)")
    except (OSError, ValueError):
        rep.findings.append(Finding("warning", str(src), "unreadable; the laboratory's session names "
                                                         "cannot be compared with the hours"))
        return
    sessions = doc.get("sessions") if isinstance(doc, dict) else None
    if not isinstance(sessions, dict):
        return
    named = [(k, v.get("name"), v.get("hours")) for k, v in sorted(sessions.items())
             if isinstance(v, dict) and isinstance(v.get("name"), str) and isinstance(v.get("hours"), (int, float))]
    if len(named) < 2:
        return

    def natural(n: str):
        return (0, int(n), "") if n.isdigit() else (1, 0, n)

    by_name = sorted(named, key=lambda t: natural(t[1]))
    for (_, n1, h1), (k2, n2, h2) in zip(by_name, by_name[1:], strict=False):
        if h2 < h1:
            rep.findings.append(Finding(
                "warning", f"/phase2/{k2}", f"session {n2!r} ({h2:g} h) has fewer hours than session "
                                            f"{n1!r} ({h1:g} h) named before it, so the sessions' hours order "
                                            f"differs from their names' order (hours typed in the wrong "
                                            f"order?); sessions are stored in hours order ({src.name})"))


def check_recording(path: str | os.PathLike) -> CheckReport:
    """Check ``path`` (a campaign directory or a ``measurements.h5``); see the module's doc.

    Raises DatasetError / FileNotFoundError only when the file cannot be opened at all."""
    path = Path(path)
    if path.is_dir() or path.suffix != ".h5":
        path = path / "measurements.h5"
    rep = CheckReport(str(path))
    with open_measurements(path) as m:
        axis = None
        try:
            axis = AxisDescription.from_dict(m.axis(), m.label)
        except DatasetError as e:
            rep.findings.append(Finding("error", "/@axis", str(e)))
        if axis is not None:
            for key, who in NEEDED_AXIS_KEYS.items():
                if axis.get(key) is None:
                    rep.findings.append(Finding("warning", f"/@axis.{key}", f"missing; {who} needs it"))
        ranges = _ranges(axis)
        s = rep.summary
        caps = m.phase1_captures()
        hours_all: list[float] = []
        p1_rates, p1_dur, samples, p1_hours, p1_samples = set(), [], set(), [], []
        for c in sorted(caps):
            key = f"/phase1/{c}"
            try:
                cap = m.phase1(c)
            except DatasetError as e:
                rep.findings.append(Finding("error", key, str(e).removeprefix(f"{m.label}: ")))
                continue
            p1_rates.add(cap.fs_hz)
            p1_dur.append(len(cap.speed) / cap.fs_hz)
            p1_samples.append((key, cap.sample, cap.hours, p1_dur[-1]))
            samples.add(cap.sample)
            p1_hours.append((key, cap.hours))
            for ch in ("speed", "torque", "acc1", "acc2"):
                _signal(rep, f"{key}/{ch}", getattr(cap, ch), sensor=ch.startswith("acc"), range_si=ranges.get(ch))
        _hours_order(rep, "captures", p1_hours)
        for (_, sa, ha, _), (kb, sb, hb, _) in zip(p1_samples, p1_samples[1:], strict=False):
            if sb < sa and hb > ha:
                rep.findings.append(Finding("warning", kb, f"sample {sb} at {hb:g} h after sample {sa} at "
                                                           f"{ha:g} h: the samples' order differs from the "
                                                           "hours' order (hours typed in the wrong order?)"))
        _duration_outliers(rep, "capture duration", {"": [(k, d) for k, _, _, d in p1_samples]})
        hours_all += [h for _, h in p1_hours]
        s["phase1"] = {"captures": len(caps), "samples": len(samples), "fs_hz": sorted(p1_rates),
                       "capture_s": [min(p1_dur), max(p1_dur)] if p1_dur else None}
        if len(p1_rates) > 1:
            rep.findings.append(Finding("warning", "/phase1", f"captures at different rates {sorted(p1_rates)} Hz"))
        sessions = m.phase2_sessions()
        rates: dict[str, set] = {"imu_acc": set(), "imu_gyro": set(), "position_cmd": set()}
        run_dur, n_runs, s_hours = [], 0, []
        run_groups: dict[str, list[tuple[str, float]]] = {}
        for sname in sorted(sessions):
            skey = f"/phase2/{sname}"
            try:
                s_hours.append((skey, m.session_hours(sname)))
                runs = m.phase2_runs(sname)
            except DatasetError as e:
                rep.findings.append(Finding("error", skey, str(e).removeprefix(f"{m.label}: ")))
                continue
            for rname in runs:
                n_runs += 1
                key = f"{skey}/{rname}"
                try:
                    r = m.phase2(sname, rname)
                except DatasetError as e:
                    rep.findings.append(Finding("error", key, str(e).removeprefix(f"{m.label}: ")))
                    continue
                for ch in rates:
                    arr = getattr(r, ch, None)
                    if arr is None:
                        continue
                    rates[ch].add(getattr(r, f"{ch}_fs_hz"))
                    _signal(rep, f"{key}/{ch}", arr, sensor=ch != "position_cmd", range_si=ranges.get(ch))
                run_dur.append(len(r.imu_acc) / r.imu_acc_fs_hz)
                run_groups.setdefault(skey, []).append((key, run_dur[-1]))
                _gravity(rep, f"{key}/imu_acc", r.imu_acc)
        _hours_order(rep, "sessions", s_hours)
        _same_hours(rep, "session", s_hours)
        _duration_outliers(rep, "run duration", run_groups)
        _naming_order(rep, path)
        hours_all += [h for _, h in s_hours]
        for ch, rs in rates.items():
            if len(rs) > 1:
                rep.findings.append(Finding("warning", f"/phase2/*/*/{ch}", f"runs at different rates {sorted(rs)} Hz"))
        s["phase2"] = {"sessions": len(sessions), "runs": n_runs, "fs_hz": {k: sorted(v) for k, v in rates.items()},
                       "run_s": [min(run_dur), max(run_dur)] if run_dur else None}
        try:
            dial = m.dial_indicator()
        except DatasetError as e:
            rep.findings.append(Finding("error", "/dial_indicator", str(e).removeprefix(f"{m.label}: ")))
            dial = None
        s["dial_readings"] = 0 if dial is None else len(dial[0])
        s["hours"] = [min(hours_all), max(hours_all)] if hours_all else None
        s["axis"] = axis.to_dict() if axis is not None else None
    return rep


def _gravity(rep: CheckReport, key: str, acc: np.ndarray) -> None:
    """The IMU on the load sees gravity: mean |a| about 1 g, mostly on z."""
    mean = acc.mean(axis=0)
    g = float(np.linalg.norm(mean))
    if abs(g - G) > GRAVITY_TOLERANCE * G:
        hint = " (samples in g rather than m/s^2?)" if abs(g - 1.0) < 0.1 else (
            " (gravity removed, or an AC-coupled sensor?)" if g < 0.5 * G else "")
        rep.findings.append(Finding("error", key, f"mean acceleration {g:.3g} m/s^2; expected about {G:.2f} "
                                                  f"(gravity){hint}"))
    elif abs(mean[2]) < (1 - GRAVITY_TOLERANCE) * g:
        axis = "xyz"[int(np.argmax(np.abs(mean)))]
        rep.findings.append(Finding("warning", key, f"gravity is on the {axis} axis (mean {np.round(mean, 2).tolist()} "
                                                    "m/s^2); expected it on z (axes swapped or sensor tilted?)"))


#: Bumped when the checks change, so that a cached report is not reused.
CHECK_VERSION = 3
CACHE_NAME = ".twin-check.json"


def _signature(h5: Path) -> str:
    parts = [str(CHECK_VERSION)]
    for f in (h5, h5.parent / "import.json"):
        st = f.stat() if f.is_file() else None
        parts.append(f"{f.name}:{st.st_size}:{st.st_mtime_ns}" if st else f"{f.name}:-")
    return "|".join(parts)


def cached_check(directory: str | os.PathLike) -> CheckReport:
    """:func:`check_recording`, kept in ``<directory>/.twin-check.json`` for as long as
    ``measurements.h5`` and ``import.json`` (size, modification time) and :data:`CHECK_VERSION`
    are unchanged: the analyses check a recording before every run, and a campaign of tens of
    GB is read once. A cache that cannot be written (a read-only folder) is skipped."""
    from analysis.base.files import write_json

    path = Path(directory)
    h5 = path if path.suffix == ".h5" and not path.is_dir() else path / "measurements.h5"
    cache, sig = h5.parent / CACHE_NAME, None
    try:
        sig = _signature(h5)
        doc = json.loads(cache.read_text(encoding="utf-8")) if cache.is_file() else None
        if isinstance(doc, dict) and doc.get("signature") == sig:
            rep = CheckReport(doc["report"]["file"], doc["report"]["summary"],
                              [Finding(**f) for f in doc["report"]["findings"]])
            return rep
    except (OSError, ValueError, KeyError, TypeError):
        pass
    rep = check_recording(directory)
    if sig is not None:
        try:
            write_json(cache, {"signature": sig, "report": rep.to_json()})
        except (OSError, ValueError):
            pass
    return rep


class RecordingRefused(ValueError):
    """An analysis refuses a recording that ``twin check`` finds errors in (the message lists them)."""


#: Errors listed in a refusal (``twin check`` lists all).
REFUSAL_LISTED = 20


def require_clean_recording(directory: str | os.PathLike, force: bool = False,
                            verb: str = "the analysis") -> list[Finding]:
    """Run :func:`check_recording` on ``directory`` before an analysis (``twin detect``,
    ``backlash``, ``diagnose``, ``calibrate``).

    Returns the findings the analysis carries into its output: the warnings, and with ``force``
    the errors too. Raises :class:`RecordingRefused` listing the errors when there are any and
    ``force`` is false; DatasetError / FileNotFoundError when the file cannot be opened at all
    (as :func:`check_recording`)."""
    rep = cached_check(directory)
    errors = rep.errors
    if errors and not force:
        listed = "\n".join(f"  {f.where}: {f.what}" for f in errors[:REFUSAL_LISTED])
        more = (f"\n  ... and {len(errors) - REFUSAL_LISTED} more (twin check {directory} lists all)"
                if len(errors) > REFUSAL_LISTED else "")
        raise RecordingRefused(f"{rep.file}: twin check finds {len(errors)} error(s), so {verb} refuses the "
                               f"recording (--force analyses it anyway):\n{listed}{more}")
    return [f for f in rep.findings if f.level == "warning" or force]


def check_record(findings: list[Finding], forced: bool) -> dict:
    """What an analysis writes into its JSON under ``"check"``: the findings of ``twin check``
    it ran with (``errors`` only when ``forced``), and whether it was forced."""
    return {"forced": forced, "errors": [asdict(f) for f in findings if f.level == "error"],
            "warnings": [asdict(f) for f in findings if f.level == "warning"],
            "note": "findings of twin check on the recording, carried into this analysis"}
