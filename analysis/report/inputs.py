"""Reading what the analyses wrote into a campaign directory (never rerunning an estimator);
score.json is computed and written when it is missing or stale."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.base.files import read_json
from analysis.dataset import open_measurements, open_truth
from analysis.report.paper import COMMANDS
from analysis.scoring import score, write_score


class ReportError(ValueError):
    """A directory that cannot be reported on (names the path and what is missing)."""


# --------------------------------------------------------------------------------------------
# Reading the inputs
# --------------------------------------------------------------------------------------------


@dataclass
class Inputs:
    """Everything the report shows, as read from ``directory`` (None where absent)."""

    directory: Path
    scenario: dict | None = None
    axis: dict | None = None
    onset_hours: float | None = None
    score: dict | None = None
    detection: dict | None = None
    details: dict | None = None
    backlash: dict | None = None
    preload: tuple[np.ndarray, np.ndarray] | None = None  # truth: hours (t,), fraction of new (t,)
    notes: list[str] = field(default_factory=list)


def _read_optional_json(path: Path, what: str) -> dict | None:
    return read_json(path, what, error=ReportError, missing_ok=True)


def _needs_score(d: Path) -> bool:
    """score.json missing, unreadable, or older than an analysis output it is computed from."""
    path = d / "score.json"
    if not path.is_file():
        return True
    try:
        read_json(path, "the scores of `twin score`", error=ReportError)
    except ReportError:
        return True
    t = path.stat().st_mtime
    return any(p.is_file() and p.stat().st_mtime > t
               for p in (d / "phase1" / "detection.json", d / "backlash" / "backlash.json",
                         *(d / "backlash").glob("*/backlash.json")))


def read_inputs(directory: str | Path) -> Inputs:
    """Read what the analyses wrote into ``directory``; compute and write score.json if needed.

    Raises:
        ReportError: ``directory`` is not a directory, or holds none of measurements.h5,
            truth.h5, score.json, phase1/detection.json, backlash/backlash.json.
        DatasetError: an unreadable truth.h5 or measurements.h5 (names the key).
        ScoreError: outputs that cannot be scored (names the file).
    """
    d = Path(directory)
    if not d.is_dir():
        raise ReportError(f"{d}: no such directory; expected a campaign directory "
                          f"(written by {COMMANDS['measurements'].format(dir=d)})")
    wanted = {"measurements.h5": COMMANDS["measurements"], "truth.h5": COMMANDS["measurements"],
              "phase1/detection.json": f"twin detect {d} --reference REF",
              "backlash/backlash.json": COMMANDS["phase2"], "score.json": COMMANDS["score"]}
    wanted = {k: v.format(dir=d) for k, v in wanted.items()}
    if not any((d / p).is_file() for p in wanted):
        raise ReportError(f"{d}: nothing to report on; found none of "
                          + ", ".join(f"{p} ({c})" for p, c in wanted.items()))
    inp = Inputs(directory=d)
    if (d / "truth.h5").is_file():
        with open_truth(d / "truth.h5") as t:
            inp.scenario = t.scenario()
            inp.onset_hours = t.onset_hours
            tl = t.timeline()
            inp.preload = (tl["hours"], tl["preload_N"] / tl["preload_N"][0])
    if (d / "measurements.h5").is_file():
        with open_measurements(d / "measurements.h5") as m:
            inp.axis = m.axis()
    inp.detection = _read_optional_json(d / "phase1" / "detection.json",
                                        "the Phase I detection results of `twin detect`")
    inp.details = _read_optional_json(d / "phase1" / "detection_details.json",
                                      "the Phase I details of `twin detect`")
    inp.backlash = _read_optional_json(d / "backlash" / "backlash.json",
                                       "the Phase II backlash results of `twin backlash`")
    has_outputs = inp.detection is not None or inp.backlash is not None
    if inp.scenario is not None and has_outputs and _needs_score(d):
        inp.score = score(d)
        try:
            write_score(d, inp.score)
            inp.notes.append(f"score.json computed from the analysis outputs and written to "
                             f"{d / 'score.json'}.")
        except OSError as exc:
            inp.notes.append(f"score.json computed for this report but not written ({exc}).")
    else:
        inp.score = _read_optional_json(d / "score.json", "the scores of `twin score`")
    if inp.onset_hours is None and inp.score and inp.score.get("phase1"):
        inp.onset_hours = inp.score["phase1"].get("onset_hours")
    if inp.onset_hours is None and inp.details:
        inp.onset_hours = inp.details.get("onset_hours")
    return inp
