"""Scoring of Phase I detection against the injected fault onset (``twin score`` in docs/usage.md).

One definition of "detected", used by ``twin detect``, ``score.json``, the sweep tables, the ROC
curves and the report: the detection is the **first alarm after the injected onset** (with
``consecutive`` = k > 1, the first alarm of the first run of k consecutive alarms that starts
after the onset), never on a baseline sample (the baseline is what the detector was fitted on).
Alarms on post-baseline samples at or before the onset are **false alarms**; baseline alarms are
reported separately. Without an onset (a real machine) the detection is the first alarm after
the baseline. Delay = detection hour - onset hours (> 0 by construction).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MethodScore", "detection_index", "score_method"]


def detection_index(alarm: np.ndarray, start: int, consecutive: int = 1) -> int | None:
    """Index of the first alarm at or after ``start`` that begins ``consecutive`` alarms in a row.

    alarm: (n,) bool. Returns None if there is no such run.
    """
    k = max(1, int(consecutive))
    run = 0
    for i in range(start, len(alarm)):
        run = run + 1 if alarm[i] else 0
        if run >= k:
            return i - k + 1
    return None


@dataclass
class MethodScore:
    """Scores of one method. Hours in h; delay_hours None without onset or detection;
    delay_samples: number of samples after the onset up to and including the detection."""

    detection_hours: float | None
    delay_hours: float | None
    delay_samples: int | None
    false_alarms: int
    healthy_test_samples: int
    baseline_alarms: int


def score_method(hours: np.ndarray, scores: np.ndarray, threshold: float, n_baseline: int,
                 onset_hours: float | None, consecutive: int = 1) -> MethodScore:
    """Score one method. hours (n,) h, scores (n,), alarm where score > threshold."""
    hours = np.asarray(hours, dtype=float)
    alarm = np.asarray(scores) > threshold
    start = n_baseline
    if onset_hours is not None:
        after = np.flatnonzero(hours > onset_hours)
        start = max(start, int(after[0]) if after.size else len(hours))
    i = detection_index(alarm, start, consecutive)
    det = float(hours[i]) if i is not None else None
    test = np.arange(len(hours)) >= n_baseline
    if onset_hours is None:
        healthy = test
    else:
        healthy = test & (hours <= onset_hours)
    delay = delay_s = None
    if det is not None and onset_hours is not None:
        delay = det - onset_hours
        delay_s = int(np.count_nonzero((hours > onset_hours) & (hours <= det)))
    return MethodScore(det, delay, delay_s, int(np.count_nonzero(alarm & healthy)),
                       int(np.count_nonzero(healthy)), int(np.count_nonzero(alarm[:n_baseline])))
