"""The persisted Phase I model: everything ``twin detect`` fits, in one versioned file, so that a
capture can be scored later (``twin detect --model``, ``twin monitor``) exactly as it would be
by fitting anew.

What the model holds (:class:`Phase1Model`): the baseline standardisation (mean and standard
deviation of the 46 raw features over the baseline samples), the Fisher selection (indices of the
kept features), the transient-torque templates of the first baseline sample (the correlation
features compare with them), every fitted detector with its control limit ``threshold_``, the
alarm rule (``consecutive`` scores above the limit), the baseline's hours and raw scores (which
start the moving averages of GMM-MD and OC-SVM when scoring resumes after the baseline), and the
recording it expects (Phase I sampling rate, channels and their columns).

File layout (a ZIP archive, ``FORMAT`` / ``FORMAT_VERSION``):

- ``model.json``: ``format``, ``format_version``, the arrays above as JSON lists (floats written
  with ``repr``, so they read back bit for bit), the alarm rule, the recording, the provenance;
- ``detectors.skops``: the fitted detectors, ``{name: estimator}``, serialised with skops
  (``skops.io``), which stores objects as data and loads only the types it is told to trust:
  loading never executes code from the file, unlike pickle. The trusted types are those of
  scikit-learn, NumPy, SciPy and MiniSom and the classes of the registered detectors; a file
  naming any other type is refused, naming it.

``model.json`` is read first, and a file of another ``format_version`` is refused naming both
versions before anything else is loaded.
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from analysis.base import registry
from analysis.base.files import atomic_write
from analysis.phase1 import limits

__all__ = ["FORMAT", "FORMAT_VERSION", "ModelFileError", "Phase1Model", "recording_signature"]

FORMAT = "ballscrew-twin/phase1-model"
FORMAT_VERSION = 1
_TRUSTED_PREFIXES = ("sklearn.", "numpy.", "scipy.", "minisom.", "builtins.")


class ModelFileError(ValueError):
    """A model file that cannot be used (another version, unreadable, untrusted type, or a
    recording that does not match it); the message names the file and what differs."""


def recording_signature(capture) -> dict:
    """What a Phase I capture looks like to the model: ``{"fs_hz": Hz, "channels": {name:
    columns}}`` for the four channels (``speed``, ``torque`` (n,) -> 1; ``acc1``, ``acc2``
    (n, 3) -> 3). capture: an :class:`analysis.dataset.Phase1Capture`."""
    return {"fs_hz": float(capture.fs_hz),
            "channels": {k: (1 if np.ndim(getattr(capture, k)) == 1 else int(np.shape(getattr(capture, k))[1]))
                         for k in ("speed", "torque", "acc1", "acc2")}}


@dataclass
class Phase1Model:
    """A fitted Phase I pipeline.

    selected (k,) feature indices into ``feature_names`` (46,); scaler_mean, scaler_scale (46,)
    in each feature's unit; templates {+1, -1: (TRANSIENT_POINTS,) N*m}; detectors {name: fitted
    detector}; labels {name: label}; baseline_hours (N,) h; baseline_raw (name: (N,) score
    without moving average on the baseline rows); consecutive: scores above the limit in a row
    that make an alarm; recording: :func:`recording_signature` of the baseline's captures;
    provenance: where it was fitted (campaign, reference, selected feature names).
    """

    selected: tuple[int, ...]
    feature_names: tuple[str, ...]
    scaler_mean: np.ndarray
    scaler_scale: np.ndarray
    templates: dict[int, np.ndarray]
    detectors: dict
    labels: dict[str, str]
    baseline_hours: np.ndarray
    baseline_raw: dict[str, np.ndarray]
    consecutive: int = 1
    recording: dict = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)

    @property
    def n_baseline(self) -> int:
        return len(self.baseline_hours)

    def thresholds(self) -> dict[str, float]:
        return {n: float(d.threshold_) for n, d in self.detectors.items()}

    def standardise(self, X: np.ndarray) -> np.ndarray:
        """Raw features X (n, 46) -> (n, k) standardised, selected, NaN set to 0 (the baseline
        mean), as :func:`analysis.phase1.pipeline.baseline_standardised` does when fitting."""
        Z = (np.asarray(X, dtype=float) - self.scaler_mean) / self.scaler_scale
        return np.nan_to_num(Z, nan=0.0)[:, list(self.selected)]

    def inputs(self, name: str, X: np.ndarray, ae: np.ndarray) -> np.ndarray:
        """What detector ``name`` scores: the standardised features of X (n, 46) or, for a
        detector whose ``phase1_input`` is "torque_windows", the torque windows ae (n, m)."""
        det = self.detectors[name]
        if getattr(det, "phase1_input", "features") == "torque_windows":
            return np.asarray(ae, dtype=float)
        return self.standardise(X)

    def raw_scores(self, X: np.ndarray, ae: np.ndarray) -> dict[str, np.ndarray]:
        """{name: (n,) score before any moving average} of the rows X (n, 46), ae (n, m)."""
        return {n: np.asarray(d.score_samples(self.inputs(n, X, ae)), dtype=float)
                for n, d in self.detectors.items()}

    def score_table(self, X: np.ndarray, ae: np.ndarray) -> dict[str, dict]:
        """Score consecutive samples X (n, 46), ae (n, m) in time order with every detector's
        ``decision_function`` (moving averages run over these rows): {name: {"scores" (n,),
        "threshold", "detector", "label"}}, the shape of
        :func:`analysis.phase1.pipeline.run_detectors`."""
        return {n: {"scores": np.asarray(d.decision_function(self.inputs(n, X, ae)), dtype=float),
                    "threshold": float(d.threshold_), "detector": d, "label": self.labels[n]}
                for n, d in self.detectors.items()}

    def smooth(self, name: str, raw_history: np.ndarray) -> float:
        """The decision score of the last row given the raw scores (h,) of the rows up to and
        including it: the detector's trailing moving average (``moving_average``, default 1)."""
        w = int(getattr(self.detectors[name], "moving_average", 1) or 1)
        return float(limits.moving_average(np.asarray(raw_history[-w:], dtype=float), w)[-1])

    def check_recording(self, signature: dict, where: str) -> None:
        """Raise :class:`ModelFileError` when a capture's ``signature`` (:func:`recording_signature`)
        differs from the model's recording, naming each difference; ``where`` names the capture."""
        want = self.recording
        diffs = []
        if want.get("fs_hz") is not None and not np.isclose(signature["fs_hz"], want["fs_hz"], rtol=1e-9):
            diffs.append(f"sampling rate fs_hz = {signature['fs_hz']:g} Hz, the model expects "
                         f"{want['fs_hz']:g} Hz")
        for ch, cols in want.get("channels", {}).items():
            got = signature["channels"].get(ch)
            if got is None:
                diffs.append(f"channel {ch} is missing, the model expects it with {cols} column(s)")
            elif got != cols:
                diffs.append(f"channel {ch} has {got} column(s), the model expects {cols}")
        for ch in signature["channels"]:
            if ch not in want.get("channels", signature["channels"]):
                diffs.append(f"channel {ch} is not in the model")
        if diffs:
            fitted = self.provenance.get("campaign", "?")
            raise ModelFileError(f"{where} does not match the Phase I model fitted on {fitted}: "
                                 + "; ".join(diffs))

    # --- the file -------------------------------------------------------------------------------

    def to_json(self) -> dict:
        def arr(a):
            return [float(v) for v in np.asarray(a, dtype=float).ravel()]
        return {
            "format": FORMAT, "format_version": FORMAT_VERSION,
            "selected": [int(i) for i in self.selected], "feature_names": list(self.feature_names),
            "scaler_mean": arr(self.scaler_mean), "scaler_scale": arr(self.scaler_scale),
            "templates": {str(d): arr(t) for d, t in self.templates.items()},
            "labels": dict(self.labels), "baseline_hours": arr(self.baseline_hours),
            "baseline_raw": {n: arr(v) for n, v in self.baseline_raw.items()},
            "thresholds": self.thresholds(),
            "alarm_rule": {"consecutive": int(self.consecutive),
                           "rule": "alarm when `consecutive` scores in a row exceed the threshold"},
            "recording": self.recording, "provenance": self.provenance,
        }

    def save(self, path: str | Path) -> Path:
        """Write the model to ``path`` (ZIP: model.json + detectors.skops), atomically."""
        import skops.io as sio

        doc = json.dumps(self.to_json(), indent=1)
        blob = sio.dumps(dict(self.detectors))

        def write(tmp: Path) -> None:
            with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
                z.writestr("model.json", doc)
                z.writestr("detectors.skops", blob)

        return atomic_write(path, write)

    @classmethod
    def load(cls, path: str | Path) -> Phase1Model:
        """Read a model written by :meth:`save`. Raises :class:`ModelFileError` naming the file
        (and both versions, for a model of another ``format_version``)."""
        import skops.io as sio

        path = Path(path)
        if not path.is_file():
            raise ModelFileError(f"{path}: no such file; expected a Phase I model written by "
                                 "`twin detect --save-model`")
        try:
            with zipfile.ZipFile(path) as z:
                doc = json.loads(z.read("model.json"))
                fmt, ver = doc.get("format"), doc.get("format_version")
                if fmt != FORMAT:
                    raise ModelFileError(f"{path}: format {fmt!r}; expected {FORMAT!r}")
                if ver != FORMAT_VERSION:
                    raise ModelFileError(
                        f"{path}: Phase I model format_version {ver}; this version of ballscrew-twin "
                        f"reads format_version {FORMAT_VERSION} only: fit the model again with "
                        "`twin detect DIR --reference REF --save-model M`")
                blob = z.read("detectors.skops")
        except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ModelFileError(f"{path}: not a Phase I model file ({exc}); expected a ZIP with "
                                 "model.json and detectors.skops") from None
        untrusted = sio.get_untrusted_types(data=blob)
        allowed = {f"{e.factory.__module__}.{e.factory.__qualname__}"
                   for e in (registry.get("detectors", n) for n in registry.names("detectors"))}
        bad = [t for t in untrusted if t not in allowed and not t.startswith(_TRUSTED_PREFIXES)]
        if bad:
            raise ModelFileError(f"{path}: detectors.skops holds type(s) {', '.join(bad)} that are "
                                 "not trusted (trusted: scikit-learn, NumPy, SciPy, MiniSom and the "
                                 "registered detectors); refusing to load it")
        detectors = sio.loads(blob, trusted=list(untrusted))

        def arr(v):
            return np.asarray(v, dtype=float)
        return cls(selected=tuple(doc["selected"]), feature_names=tuple(doc["feature_names"]),
                   scaler_mean=arr(doc["scaler_mean"]), scaler_scale=arr(doc["scaler_scale"]),
                   templates={int(d): arr(t) for d, t in doc["templates"].items()},
                   detectors=dict(detectors), labels=dict(doc["labels"]),
                   baseline_hours=arr(doc["baseline_hours"]),
                   baseline_raw={n: arr(v) for n, v in doc["baseline_raw"].items()},
                   consecutive=int(doc["alarm_rule"]["consecutive"]), recording=doc["recording"],
                   provenance=doc["provenance"])


def from_fit(table, selected, results: dict[str, dict], n_baseline: int, consecutive: int,
             recording: dict, provenance: dict) -> Phase1Model:
    """The model of a fit: ``table`` the campaign's :class:`~analysis.phase1.pipeline.FeatureTable`
    whose first ``n_baseline`` rows were the baseline, ``selected`` (k,) indices, ``results``
    of :func:`~analysis.phase1.pipeline.run_detectors` (fitted detectors)."""
    from analysis.phase1.standardise import BaselineScaler

    base = table.X[:n_baseline]
    scaler = BaselineScaler().fit(np.where(np.isnan(base), np.nanmean(base, axis=0), base))
    model = Phase1Model(
        selected=tuple(int(i) for i in selected), feature_names=tuple(table.names),
        scaler_mean=scaler.mean_, scaler_scale=scaler.scale_, templates=dict(table.templates),
        detectors={n: r["detector"] for n, r in results.items()},
        labels={n: r["label"] for n, r in results.items()},
        baseline_hours=np.asarray(table.hours[:n_baseline], dtype=float), baseline_raw={},
        consecutive=int(consecutive), recording=recording, provenance=provenance)
    model.baseline_raw = {n: v[:n_baseline] for n, v in
                          model.raw_scores(table.X[:n_baseline], table.ae[:n_baseline]).items()}
    return model

