"""From a campaign's ``measurements.h5`` to the Phase I feature table, and from feature tables to
detector scores (paper section IV, Fig. 3).

:func:`extract` reads every Phase I capture, segments it and computes the per-sample features of
:mod:`analysis.phase1.features` and the autoencoder's torque windows. It reads only
``measurements.h5``. :func:`reference_labels` is the one function here that reads a ``truth.h5``:
the reference data set's condition labels (a real reference set comes with known conditions).
:func:`run_detectors` standardises with the baseline, keeps the selected features, fits each
detector on the baseline and scores every sample.
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
from threadpoolctl import threadpool_limits

from analysis.base import registry
from analysis.dataset import DatasetError, open_measurements, open_truth
from analysis.phase1.features import (
    FEATURE_NAMES,
    CaptureSummary,
    FeatureError,
    sample_features,
    summarise_capture,
    transient_templates,
)
from analysis.phase1.selection import fisher_scores, select_cumulative
from analysis.phase1.standardise import BaselineScaler

__all__ = [
    "N_BASELINE",
    "baseline_standardised",
    "ExtractionError",
    "FeatureTable",
    "extract",
    "make_detector",
    "reference_labels",
    "run_detectors",
    "select_features",
]

N_BASELINE = 15  # paper: "The first fifteen samples ... are used as baseline data"


class ExtractionError(ValueError):
    """A capture could not be read or segmented. ``partial`` holds the feature table of the
    complete samples before the failing one (or None)."""

    def __init__(self, message: str, partial: FeatureTable | None = None):
        super().__init__(message)
        self.partial = partial


@dataclass
class FeatureTable:
    """Per-sample features of one campaign, rows in time order.

    hours (n,) h: hours of each sample's first capture; samples (n,) sample index; X (n, 46) raw
    features in ``FEATURE_NAMES`` order (units per feature, see :mod:`features`); ae (n, m)
    averaged torque windows (N*m); n_captures (n,); names: the 46 feature names; source: the file;
    templates: the transient-torque templates the correlation features were computed against
    ({+1, -1: (TRANSIENT_POINTS,) N*m}).
    """

    hours: np.ndarray
    samples: np.ndarray
    X: np.ndarray
    ae: np.ndarray
    n_captures: np.ndarray
    names: tuple[str, ...]
    source: str
    templates: dict[int, np.ndarray] = field(default_factory=dict)

    def write_csv(self, path: Path) -> None:
        """Write the raw features, one row per sample (columns hours, sample, n_captures, names)."""
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["hours", "sample", "n_captures", *self.names])
            for i in range(len(self.hours)):
                w.writerow([f"{self.hours[i]:.6g}", int(self.samples[i]), int(self.n_captures[i]),
                            *(f"{v:.9g}" for v in self.X[i])])


def _table(groups: list[list[CaptureSummary]], source: str,
           templates: dict[int, np.ndarray] | None = None) -> FeatureTable:
    templates = transient_templates(groups[0]) if templates is None else templates
    X = np.array([sample_features(g, templates) for g in groups])
    ae_rows = []
    for g in groups:
        w = [x for c in g for x in c.ae_windows]
        ae_rows.append(np.mean(w, axis=0) if w else None)
    m = next((len(r) for r in ae_rows if r is not None), 0)
    ae = np.array([r if r is not None else np.full(m, np.nan) for r in ae_rows]).reshape(len(groups), m)
    return FeatureTable(
        hours=np.array([min(c.hours for c in g) for g in groups]),
        samples=np.array([g[0].sample for g in groups]),
        X=X, ae=ae, n_captures=np.array([len(g) for g in groups]),
        names=FEATURE_NAMES, source=source, templates=templates)


def extract(path: str | Path, progress: Callable[[int, int], None] | None = None,
            templates: dict[int, np.ndarray] | None = None) -> FeatureTable:
    """Feature table of the Phase I captures in ``path`` (a ``measurements.h5``).

    ``templates``: the transient-torque templates of a persisted model
    (:mod:`analysis.phase1.model_file`); default: those of the first sample of ``path``.

    Captures are grouped by their ``sample`` attribute; samples are ordered by hours. Raises
    :class:`ExtractionError` (message naming file, group and channel) on the first capture that
    cannot be read or segmented, with the table of the complete samples before it attached.
    """
    path = Path(path)
    summaries: list[CaptureSummary] = []
    name = None
    try:
        with open_measurements(path) as m:
            names = m.phase1_captures()
            if not names:
                raise ExtractionError(f"{path}: /phase1 has no captures; expected Phase I captures")
            for i, name in enumerate(names):
                summaries.append(summarise_capture(m.phase1(name), str(path)))
                if progress:
                    progress(i + 1, len(names))
    except (DatasetError, FeatureError, FileNotFoundError) as exc:
        partial = None
        if summaries:
            groups = _group(summaries)
            if _sample_of(path, name) in (None, groups[-1][0].sample):
                groups = groups[:-1]  # the failing capture's sample is incomplete
            if groups:
                partial = _table(groups, str(path), templates)
        raise ExtractionError(str(exc), partial) from None
    return _table(_group(summaries), str(path), templates)


def _sample_of(path: Path, name: str | None) -> int | None:
    """The ``sample`` attribute of capture ``name``, or None if it cannot be read."""
    try:
        with h5py.File(path, "r") as f:
            return int(np.asarray(f[f"/phase1/{name}"].attrs["sample"]).reshape(()))
    except Exception:  # noqa: BLE001 - any failure means "unknown"
        return None


def _group(summaries: list[CaptureSummary]) -> list[list[CaptureSummary]]:
    by: dict[int, list[CaptureSummary]] = {}
    for c in summaries:
        by.setdefault(c.sample, []).append(c)
    return sorted(by.values(), key=lambda g: min(c.hours for c in g))


def reference_labels(truth_path: str | Path, hours: np.ndarray) -> np.ndarray:
    """Labels of the reference samples from the reference campaign's ``truth.h5``.

    0 healthy (preload >= 99 % of its initial value and no backlash), 1 faulty (backlash > 0),
    -1 neither (e.g. preload loss without backlash: not used, as in the paper). hours: (n,) h.
    """
    with open_truth(truth_path) as t:
        tl = t.timeline()
    pre = np.interp(hours, tl["hours"], tl["preload_N"]) / tl["preload_N"][0]
    bl = np.interp(hours, tl["hours"], tl["backlash_um"])
    return np.where(bl > 0, 1, np.where(pre >= 0.99, 0, -1))


def select_features(X: np.ndarray, labels: np.ndarray, fraction: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
    """Fisher scores (46,) of the reference table and the selected indices (k,), best first.

    X: (n, 46) raw reference features; labels (n,) from :func:`reference_labels`. NaN features
    are replaced by their column mean first.
    """
    keep = labels >= 0
    Xk = X[keep]
    col_mean = np.nanmean(Xk, axis=0)
    Xk = np.where(np.isnan(Xk), col_mean, Xk)
    scores = fisher_scores(Xk, labels[keep])
    return scores, select_cumulative(scores, fraction)


def make_detector(name: str, random_state: int = 0, **params):
    """A fresh detector: ``name`` a registered detector (:mod:`analysis.base.registry`, the paper's
    settings for the six built-ins) or ``module:Class``; ``random_state`` is passed if the
    detector takes one; ``params`` are further constructor parameters."""
    if registry.accepts(registry.get("detectors", name).factory, "random_state"):
        params.setdefault("random_state", random_state)
    return registry.create("detectors", name, **params)


def baseline_standardised(X: np.ndarray, selected: Sequence[int], n_baseline: int = N_BASELINE) -> np.ndarray:
    """What every detector is fitted on and scores: the raw features ``X`` (n, 46) standardised
    with the mean and standard deviation of the first ``n_baseline`` rows (NaN in the baseline
    replaced by its column mean first), NaN set to the baseline mean (0), the ``selected``
    columns kept: (n, k), dimensionless."""
    base = X[:n_baseline]
    Z = BaselineScaler().fit(np.where(np.isnan(base), np.nanmean(base, axis=0), base)).transform(X)
    return np.nan_to_num(Z, nan=0.0)[:, list(selected)]


def run_detectors(table: FeatureTable, selected: Sequence[int], methods: Sequence[str] | None = None,
                  n_baseline: int = N_BASELINE, random_state: int = 0) -> dict[str, dict]:
    """Fit every method on the first ``n_baseline`` samples and score all samples.

    Features are standardised with the baseline mean and standard deviation; NaN features (a
    sample without a transient of one direction) are set to the baseline mean (0). The
    detectors whose ``phase1_input`` is "torque_windows" (the autoencoder) get ``table.ae``
    instead of the features. ``methods``: registered names or ``module:Class`` (default: every
    registered detector). Returns {name: {"scores" (n,), "threshold", "detector", "label"}}, keyed
    by the registered name (the class name for ``module:Class``).
    """
    methods = registry.names("detectors") if methods is None else methods
    n = len(table.hours)
    if n <= n_baseline:
        raise ValueError(f"{table.source}: {n} Phase I samples; expected more than the "
                         f"{n_baseline} baseline samples")
    Z = baseline_standardised(table.X, selected, n_baseline)
    out = {}
    with threadpool_limits(1):  # tiny matrices: BLAS threads only contend
        for spec in methods:
            entry = registry.get("detectors", spec)
            out[entry.name] = {**_fit_score(spec, table, Z, n_baseline, random_state),
                               "label": entry.label}
    return out


def _fit_score(name: str, table: FeatureTable, Z: np.ndarray, n_baseline: int, random_state: int) -> dict:
    """Fit one detector on the baseline rows and score every row."""
    det = make_detector(name, random_state)
    data = Z
    if getattr(det, "phase1_input", "features") == "torque_windows":
        data = table.ae
        if data.shape[1] == 0 or np.isnan(data).any():
            bad = int(np.flatnonzero(np.isnan(data).any(axis=1))[0]) if data.shape[1] else 0
            raise ValueError(f"{table.source}: Phase I sample {int(table.samples[bad])} has no "
                             f"complete acceleration window of torque; {name} needs one")
    det.fit(data[:n_baseline])
    return {"scores": det.decision_function(data), "threshold": float(det.threshold_),
            "detector": det}
