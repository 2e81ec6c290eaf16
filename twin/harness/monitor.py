"""``twin monitor SOURCE --model M -o STATE``: the paper's online workflow on a growing campaign
folder. Phase I scores every new sample against the persisted baseline model; an alarm asks for
Phase II, whose sessions then give the change of backlash, its trend and the prognosis.

**Source.** ``SOURCE/live/`` (or ``SOURCE`` itself) holds units published as
:mod:`twin.sim.live` describes: a data file in the dataset format and, written after it, a manifest
``<seq>-<kind>-<name>.json`` with the file's size and SHA-256. A unit is read only once its
manifest exists and the data file matches it, so a file being written is never read half-way.
Units are processed in ``seq`` order; a Phase I sample is scored when its
``captures_in_sample`` captures have arrived (or, if one never arrives, when a capture of a later
sample does).

**Event log.** ``STATE/events.jsonl``, one JSON object per line, appended (docs/monitoring.md has
the format): ``monitor started``, ``input refused``, ``sample scored``, ``alarm``,
``alarm cleared``, ``Phase II requested``, ``Phase II baseline``, ``Phase II estimated``. Every
event has ``n`` (its index in the log), ``event``, ``hours`` and ``units`` (the seqs of the
source units it accounts for); the events of one unit are written with a single ``write`` and
the last of them carries ``"commit": true``.

**Resume.** The monitor's state is a fold over the events (:meth:`MonitorState.absorb`): on
(re)start the log is read, a torn last line or a batch without its ``commit`` is cut off, the
state is rebuilt from the rest, and the units not yet accounted for are processed. Processing is
deterministic, so a monitor killed at any moment (SIGKILL included) and restarted writes the
same events as one that ran through, apart from the ``monitor started`` line of the restart.
Only the Phase II reference session is read again (to refit the backlash estimator).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.base.files import read_json
from analysis.dataset import DatasetError, open_measurements
from analysis.dataset.live import MANIFEST_KEYS, UNIT_FORMAT, manifest_ok
from analysis.phase1.features import FeatureError, sample_features, summarise_capture
from analysis.phase1.model_file import ModelFileError, Phase1Model, recording_signature

__all__ = ["EVENT_LOG", "Monitor", "MonitorError", "MonitorState", "read_events"]

EVENT_LOG = "events.jsonl"
EVENT_FORMAT_VERSION = 1


class MonitorError(ValueError):
    """Bad input at start (a model that does not match the recording, an unreadable source)."""


def live_dir_of(source: Path) -> Path:
    """Where the units are: ``source`` itself when it holds the live source's ``source.json`` or
    unit manifests, else ``source/live`` (which may not exist yet)."""
    if (source / "source.json").is_file() or any(source.glob("[0-9]*.json")):
        return source
    return source / "live"


def read_events(path: Path) -> tuple[list[dict], int]:
    """The committed events of a log and the byte length they occupy (a torn last line, or
    events after the last ``commit``, are not included)."""
    if not path.is_file():
        return [], 0
    raw = path.read_bytes()
    events, good, pos = [], 0, 0
    pending: list[dict] = []
    for line in raw.split(b"\n")[:-1]:  # the part after the last newline is torn
        pos += len(line) + 1
        try:
            ev = json.loads(line)
        except json.JSONDecodeError:
            break
        pending.append(ev)
        if ev.get("commit"):
            events += pending
            pending = []
            good = pos
    return events, good


@dataclass
class MonitorState:
    """What the monitor knows, rebuilt from its events.

    covered: source unit seqs accounted for; raw: {detector: recent raw scores} (the moving
    averages' history); above/below: {detector: run length of scores above / at or below the
    limit}; in_alarm: {detector: bool}; requested: Phase II has been requested; reference:
    the Phase II reference session's event; backlash: [(hours, Δbacklash m)] of the sessions.
    """

    covered: set = field(default_factory=set)
    raw: dict = field(default_factory=dict)
    above: dict = field(default_factory=dict)
    below: dict = field(default_factory=dict)
    in_alarm: dict = field(default_factory=dict)
    requested: bool = False
    reference: dict | None = None
    backlash: list = field(default_factory=list)
    n_events: int = 0
    scored_samples: set = field(default_factory=set)

    def absorb(self, ev: dict, model: Phase1Model) -> None:
        self.n_events += 1
        self.covered.update(ev.get("units", ()))
        kind = ev["event"]
        if kind == "sample scored":
            self.scored_samples.add(ev["sample"])
            for name, r in ev["raw"].items():
                w = int(getattr(model.detectors[name], "moving_average", 1) or 1)
                self.raw[name] = (self.raw.get(name, []) + [r])[-w:]
            for name, s in ev["scores"].items():  # a baseline sample starts no run (twin detect)
                over = s is not None and not ev["baseline"] and s > model.detectors[name].threshold_
                self.above[name] = self.above.get(name, 0) + 1 if over else 0
                self.below[name] = 0 if over else self.below.get(name, 0) + 1
        elif kind == "alarm":
            self.in_alarm[ev["detector"]] = True
        elif kind == "alarm cleared":
            self.in_alarm[ev["detector"]] = False
        elif kind == "Phase II requested":
            self.requested = True
        elif kind in ("Phase II baseline", "Phase II estimated"):
            if self.reference is None:
                self.reference = ev
            d = ev["delta_backlash_m"]  # SI, as twin backlash's trend takes it (no µm round trip)
            self.backlash.append((ev["hours"], math.nan if d is None else d))


def _num(v: float) -> float | None:
    return float(v) if v is not None and math.isfinite(v) else None


class Monitor:
    """The long-running monitor (module docstring). ``say`` prints a sentence for the user."""

    def __init__(self, source: Path, model_path: Path, state_dir: Path,
                 say: Callable[[str], None] = print, on_event: Callable[[dict], None] | None = None):
        self.source, self.live = Path(source), live_dir_of(Path(source))
        self.model_path = Path(model_path)
        self.model = Phase1Model.load(model_path)
        self.state_dir = Path(state_dir)
        self.say, self.on_event = say, on_event
        self.log = self.state_dir / EVENT_LOG
        self.state = MonitorState()
        self.pending: dict[int, list] = {}  # sample -> [(seq, manifest, summary or None)]
        self.estimator = None
        self.position_reference = None
        self._checked = False

    # --- the log ------------------------------------------------------------------------------
    def _lock(self) -> None:
        """One monitor per state directory: an exclusive lock on ``STATE/.lock``, held while the
        process lives (the kernel releases it when the process dies, even by SIGKILL)."""
        from analysis.base.files import exclusive_lock

        self._lock_fh = exclusive_lock(self.state_dir / ".lock", f"{self.state_dir}: another twin monitor is "
                                       "writing this state directory; stop it first, or give another -o",
                                       MonitorError)

    def _resume(self) -> int:
        self.state_dir.mkdir(parents=True, exist_ok=True)
        events, good = read_events(self.log)
        if self.log.is_file() and self.log.stat().st_size != good:
            with open(self.log, "r+b") as fh:
                fh.truncate(good)
        for ev in events:
            self.state.absorb(ev, self.model)
        if self.state.reference is not None:
            self._fit_reference(self.state.reference["file"], self.state.reference["session"])
        if self.on_event:  # a viewer shows the history too
            for ev in events:
                self.on_event(ev)
        return len(events)

    def _write(self, events: list[dict]) -> None:
        """Append one unit's events with a single write; absorb them."""
        if not events:
            return
        lines = []
        for i, ev in enumerate(events):
            ev = {"n": self.state.n_events + i, **ev}
            if i == len(events) - 1:
                ev["commit"] = True
            events[i] = ev
            lines.append(json.dumps(ev, allow_nan=False))
        data = ("\n".join(lines) + "\n").encode()
        fd = os.open(self.log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, data)
        finally:
            os.close(fd)
        for ev in events:
            self.state.absorb(ev, self.model)
            if ev["event"] == "Phase II requested":
                self.say(f"Phase II requested at {ev['hours']:g} h: {ev['reason']}")
            elif ev["event"] in ("alarm", "alarm cleared", "input refused"):
                self.say(f"{ev['event']} at {ev['hours']:g} h: {ev['reason']}")
            if self.on_event:
                self.on_event(ev)

    # --- the source ---------------------------------------------------------------------------
    def complete_units(self) -> list[dict]:
        """Manifests of the complete units not yet accounted for, in seq order. The folder is
        listed once; a name whose seq is accounted for is skipped without being read."""
        done = self.state.covered | {item[0] for v in self.pending.values() for item in v}
        out = []
        try:
            entries = [e.name for e in os.scandir(self.live)]
        except FileNotFoundError:
            return []
        for name in entries:
            if not name.endswith(".json") or not name[:1].isdigit():
                continue
            head = name.split("-", 1)[0]
            if head.isdigit() and int(head) in done:
                continue  # accounted for: not even read
            try:
                man = read_json(self.live / name, "a live unit's manifest")
            except (ValueError, OSError):
                continue
            if man.get("format") != UNIT_FORMAT or not MANIFEST_KEYS <= set(man) or man["seq"] in done:
                continue
            if manifest_ok(self.live, man):
                out.append(man)
        return sorted(out, key=lambda m: m["seq"])

    def finished(self) -> bool:
        """The source says it is finished and every unit it published is accounted for."""
        end = self.live / "end.json"
        if not end.is_file():
            return False
        return not self.complete_units() and not self.pending

    def check_start(self) -> None:
        """Refuse a model that does not match the recording: the first Phase I capture of the
        source, checked once (at start, or when it arrives) before anything is scored."""
        if self._checked:
            return
        for man in self.complete_units():
            if man["kind"] == "phase1":
                path = self.live / man["file"]
                with open_measurements(path) as m:
                    sig = recording_signature(m.phase1(m.phase1_captures()[0]))
                try:
                    self.model.check_recording(sig, f"{path}: /phase1/{man['name']}")
                except ModelFileError as exc:
                    raise MonitorError(str(exc)) from None
                self._checked = True
                return

    # --- processing ---------------------------------------------------------------------------
    def _refusal(self, man: dict) -> str | None:
        """Why a unit's file fails the dataset's checks (None if it passes)."""
        from analysis.ingest.check import check_recording

        path = self.live / man["file"]
        try:
            rep = check_recording(path)
        except (DatasetError, OSError) as exc:
            return str(exc)
        errors = [f"{path}: {f.what}" if f.what.startswith(f.where) else f"{path}: {f.where}: {f.what}"
                  for f in rep.findings if f.level == "error"]
        if errors:
            return "; ".join(errors)
        if man["kind"] == "phase1":
            try:
                with open_measurements(path) as m:
                    sig = recording_signature(m.phase1(man["name"]))
                self.model.check_recording(sig, f"{path}: /phase1/{man['name']}")
            except (DatasetError, ModelFileError, OSError) as exc:
                return str(exc)
        return None

    def step(self) -> int:
        """Process the complete units not yet accounted for, in seq order and without a gap (a
        unit whose predecessor is still being written waits for it, so the order, and with it
        the log, never depends on when files arrive); returns how many."""
        done = self.state.covered | {item[0] for v in self.pending.values() for item in v}
        expected = 0
        n = 0
        for man in self.complete_units():
            while expected in done:
                expected += 1
            if man["seq"] != expected:
                break
            self._unit(man)
            done.add(expected)
            n += 1
        return n

    def _unit(self, man: dict) -> None:
        seq, hours = man["seq"], float(man["hours"])
        if man["kind"] == "phase1":
            # A capture's events (its refusal included) are written with its sample's, when the
            # sample closes: until then nothing is logged and a restart reads the capture again.
            sample = int(man["sample"])
            events = []
            for s in sorted(k for k in self.pending if k < sample):  # an earlier sample cut short
                events += self._score_sample(s)
            why = self._refusal(man)
            summary = None
            if why is None:
                try:
                    with open_measurements(self.live / man["file"]) as m:
                        summary = summarise_capture(m.phase1(man["name"]), str(self.live / man["file"]))
                except (DatasetError, FeatureError, OSError) as exc:
                    why = str(exc)
            self.pending.setdefault(sample, []).append((seq, man, summary, why))
            if len(self.pending[sample]) >= int(man.get("captures_in_sample", 1)):
                events += self._score_sample(sample)
            self._write(events)
        elif man["kind"] == "phase2":
            why = self._refusal(man)
            if why is not None:
                self._write([{"event": "input refused", "hours": hours, "units": [seq],
                              "unit": man["name"], "kind": "phase2", "reason": why}])
            else:
                self._write(self._phase2(man))
        else:  # a unit of a kind the monitor does not use
            self._write([{"event": "input refused", "hours": hours, "units": [seq], "unit": man["name"],
                          "kind": man["kind"], "reason": f"unit kind {man['kind']!r} is not monitored"}])

    def _score_sample(self, sample: int) -> list[dict]:
        items = self.pending.pop(sample)
        events = [{"event": "input refused", "hours": float(m["hours"]), "units": [seq],
                   "unit": m["name"], "kind": "phase1", "reason": why}
                  for seq, m, _, why in items if why is not None]
        seqs = [seq for seq, _, c, _ in items if c is not None]
        caps = [c for _, _, c, _ in items if c is not None]
        if not caps:
            events.append({"event": "input refused", "hours": float(min(m["hours"] for _, m, _, _ in items)),
                           "units": [], "sample": sample, "kind": "phase1 sample",
                           "reason": f"Phase I sample {sample} has no usable capture"})
            return events
        hours = float(min(c.hours for c in caps))
        model = self.model
        X = sample_features(caps, model.templates)[None, :]
        w = [x for c in caps for x in c.ae_windows]
        ae = (np.mean(w, axis=0) if w else np.full(0, np.nan))[None, :]
        raw, scores, reasons = {}, {}, {}
        for name, det in model.detectors.items():
            if getattr(det, "phase1_input", "features") == "torque_windows" and (
                    ae.shape[1] != det.n_features_in_ or np.isnan(ae).any()):
                raw[name], scores[name] = None, None
                reasons[name] = "no complete acceleration window of torque"
                continue
            r = float(det.score_samples(model.inputs(name, X, ae))[0])
            hist = [v for v in self.state.raw.get(name, []) if v is not None] + [r]
            raw[name], scores[name] = r, model.smooth(name, np.asarray(hist))
        ev = {"event": "sample scored", "hours": hours, "units": seqs, "sample": sample,
              "captures": [c.name for c in caps],
              "scores": scores, "raw": raw,
              "above": [n for n, s in scores.items() if s is not None and s > model.detectors[n].threshold_],
              "baseline": bool(np.any(np.isclose(model.baseline_hours, hours)))}
        if reasons:
            ev["not_scored"] = reasons
        events.append(ev)
        # The alarm rule on the state after this sample (the same fold the log is rebuilt with).
        after = MonitorState(above=dict(self.state.above), below=dict(self.state.below),
                             raw=dict(self.state.raw))
        after.absorb(ev, model)
        k = model.consecutive
        for name in model.detectors:
            s = scores[name]
            thr = float(model.detectors[name].threshold_)
            if s is None or ev["baseline"]:
                continue
            label = model.labels[name]
            if not self.state.in_alarm.get(name) and after.above.get(name, 0) >= k:
                first = self._run_start_hours(hours, k)
                events.append({"event": "alarm", "hours": first, "raised_at_hours": hours,
                               "detector": name, "score": s, "threshold": thr, "units": [],
                               "reason": f"{label} score {s:.4g} > limit {thr:.4g} for {k} sample(s) in a row"})
            elif self.state.in_alarm.get(name) and after.below.get(name, 0) >= k:
                events.append({"event": "alarm cleared", "hours": hours, "detector": name, "score": s,
                               "threshold": thr, "units": [],
                               "reason": f"{label} score {s:.4g} <= limit {thr:.4g} for {k} sample(s) in a row"})
        alarms = [e for e in events if e["event"] == "alarm"]
        if alarms and not self.state.requested:
            names = ", ".join(model.labels[e["detector"]] for e in alarms)
            events.append({"event": "Phase II requested", "hours": hours, "units": [],
                           "reason": f"Phase I alarm of {names} at {hours:g} h: run the Phase II IMU "
                                     "sessions to measure the change of backlash"})
        return events

    def _run_start_hours(self, hours: float, k: int) -> float:
        """Hours of the first sample of the run of k that raised the alarm (as ``twin detect``
        dates a detection)."""
        if k <= 1:
            return hours
        evs, _ = read_events(self.log)
        scored = [e["hours"] for e in evs if e["event"] == "sample scored"]
        return ([*scored, hours][-k:])[0]

    # --- Phase II -------------------------------------------------------------------------------
    def _fit_reference(self, file: str, session: str):
        from analysis.phase2.backlash import estimator_for
        from analysis.phase2.error_motions import resolve_position_reference, session_error_motions

        with open_measurements(self.live / file) as m:
            self.position_reference = resolve_position_reference(m, "auto")
            kw = {"stationary": "E_XX"} if self.position_reference == "imu" else {}
            self.estimator = estimator_for(m, **kw)
            em = session_error_motions(m, session, on_bad_run="skip",
                                       position_reference=self.position_reference)
        self.estimator.fit(em)
        return em

    def _phase2(self, man: dict) -> list[dict]:
        from analysis.phase2.backlash import primary_m
        from analysis.phase2.error_motions import session_error_motions
        from analysis.phase2.prognosis import BacklashTrend, prognosis

        seq, hours, name = man["seq"], float(man["hours"]), man["name"]
        try:
            if self.state.reference is None:
                em = self._fit_reference(man["file"], name)
            else:
                with open_measurements(self.live / man["file"]) as m:
                    em = session_error_motions(m, name, on_bad_run="skip",
                                               position_reference=self.position_reference)
            est = self.estimator.estimate(em)
        except (DatasetError, ValueError) as exc:
            return [{"event": "input refused", "hours": hours, "units": [seq], "unit": name,
                     "kind": "phase2", "reason": str(exc)}]
        delta = primary_m(est, self.estimator)
        ev = {"hours": hours, "units": [seq], "session": name, "file": man["file"],
              "delta_backlash_um": _num(delta * 1e6), "delta_backlash_m": _num(delta),
              "delta_backlash_um_pitch": _num(est.delta_backlash_pitch_m * 1e6),
              "reference_session": name if self.state.reference is None else self.state.reference["session"],
              "skipped_runs": [{"run": r, "reason": w} for r, w in em.skipped]}
        if not self.state.requested:
            ev = {"event": "Phase II baseline", **ev,
                  "reason": "a Phase II session before any Phase I alarm: kept as the baseline of the "
                            "change of backlash"}
            return [ev]
        hist = [*self.state.backlash, (hours, delta)]
        t = np.array([h for h, _ in hist])
        z = np.array([v for _, v in hist])
        ev = {"event": "Phase II estimated", **ev}
        if len(hist) >= 2 and np.isfinite(z).any():
            trend = BacklashTrend().fit(t, z)
            prog = prognosis(trend)
            ev["trend"] = {"smoothed_um": float(trend.smoothed[-1] * 1e6),
                           "smoothed_std_um": float(trend.smoothed_std[-1] * 1e6),
                           "rate_um_per_kh": float(trend.rate[-1] * 1e9)}
            ev["prognosis"] = prog.to_json()
        rem = ev.get("prognosis", {}).get("remaining_hours")
        when = ("" if rem is None else f", {rem:.0f} h to the 10 µm limit" if rem >= 0
                else f", the trend crossed the 10 µm limit {-rem:.0f} h ago")
        self.say(f"Phase II session {name} at {hours:g} h: change of backlash "
                 f"{ev['delta_backlash_um'] if ev['delta_backlash_um'] is not None else float('nan'):.2f} µm"
                 + when)
        return [ev]

    # --- the loop ---------------------------------------------------------------------------------
    def run(self, poll_s: float = 0.2, exit_at_end: bool = False, max_idle_s: float | None = None) -> int:
        """Resume from the log, then process units as they become complete until stopped (or,
        with ``exit_at_end``, until the source is finished). Returns the events written."""
        self._lock()
        resumed = self._resume()
        self.check_start()
        self._write([{"event": "monitor started", "hours": None, "units": [],
                      "source": str(self.source), "model": str(self.model_path),
                      "resumed_events": resumed, "format_version": EVENT_FORMAT_VERSION,
                      "wall_time": time.strftime("%Y-%m-%dT%H:%M:%S%z")}])
        idle = 0.0
        while True:
            if not self._checked and not self.state.scored_samples:
                self.check_start()
            if self.step():
                idle = 0.0
                continue
            if exit_at_end and self.finished():
                return self.state.n_events
            if exit_at_end and (self.live / "end.json").is_file() and self.pending \
                    and not self.complete_units():
                for sample in sorted(self.pending):  # the source ended inside a sample
                    self._write(self._score_sample(sample))
                continue
            if max_idle_s is not None and idle >= max_idle_s:
                return self.state.n_events
            time.sleep(poll_s)
            idle += poll_s

