"""The ``twin detect`` workflow: reference features -> Fisher selection -> campaign features ->
the registered detectors -> scores against the injected onset -> files in OUT.

Files written to OUT, each as soon as it is computed (so a failure later loses nothing before it):

- ``reference_features.csv``, ``selection.json``: the reference table, Fisher scores, selection;
- ``features.csv``: the campaign's raw features (or ``features.partial.csv`` with the complete
  samples before a capture that cannot be read; the error is then raised);
- ``detection.json`` (schema in docs/usage.md), ``detection_details.json`` (scores against the onset,
  parameters), ``detection.png`` (one panel per detector like the paper's Fig. 6).

The detectors see ``measurements.h5`` only; ``truth.h5`` of the campaign is read for scoring
(``onset_hours``) and ``truth.h5`` of the reference for its condition labels.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from analysis.base import registry
from analysis.base.files import write_json
from analysis.dataset import open_measurements, open_truth
from analysis.phase1 import pipeline
from analysis.phase1.figures import plot_fig6
from analysis.phase1.scoring import score_method

__all__ = ["DetectError", "run"]


class DetectError(ValueError):
    """Bad input to the workflow (missing file, unknown method, too few samples)."""


def _require(path: Path, what: str) -> None:
    if not path.is_file():
        raise DetectError(f"{path}: no such file; expected {what}")


def _extract_to_csv(measurements: Path, stem: Path):
    """Features of every sample of ``measurements`` (:func:`pipeline.extract`), written to
    ``<stem>.csv``; if a capture is bad, the samples before it go to ``<stem>.partial.csv`` and
    the error is raised again, so nothing computed is lost."""
    try:
        table = pipeline.extract(measurements)
    except pipeline.ExtractionError as exc:
        if exc.partial is not None:
            exc.partial.write_csv(stem.with_name(stem.name + ".partial.csv"))
        raise
    table.write_csv(stem.with_name(stem.name + ".csv"))
    return table


def run(campaign: Path, reference: Path | None, out: Path, methods: Sequence[str] | None = None,
        consecutive: int = 1, n_baseline: int = pipeline.N_BASELINE, fraction: float = 0.9,
        random_state: int = 0, *, model: Path | None = None, save_model: Path | None = None) -> dict:
    """Run the workflow; returns the details dict (also written as ``detection_details.json``).

    ``save_model``: also write the fitted pipeline there (:mod:`analysis.phase1.model_file`).
    ``model``: score with that persisted model instead of fitting (``reference``, ``methods``,
    ``n_baseline``, ``fraction`` and ``consecutive`` are then the model's); the campaign's
    baseline rows are those whose hours are the model's baseline hours (none if it was fitted
    on another campaign).

    ``methods``: registered detector names or ``module:Class`` (:mod:`analysis.base.registry`);
    default every registered detector, in registration order.

    Raises :class:`DetectError`, :class:`analysis.dataset.DatasetError` or
    :class:`analysis.phase1.pipeline.ExtractionError` (all ``ValueError``) on bad input.
    """
    if model is not None:
        return _run_with_model(Path(campaign), Path(model), Path(out))
    if reference is None:
        raise DetectError("no reference data set and no model: give --reference REF (to fit) or "
                          "--model M (a model written by --save-model)")
    campaign, reference, out = Path(campaign), Path(reference), Path(out)
    try:
        specs = list(registry.names("detectors")) if not methods else list(methods)
        entries = [registry.get("detectors", m) for m in specs]
    except registry.RegistryError as exc:
        raise DetectError(f"--method: {exc}") from None
    seen: dict[str, str] = {}
    for spec, e in zip(specs, entries, strict=True):
        seen.setdefault(e.name, spec)
    methods = list(seen.values())
    _require(campaign / "measurements.h5", "the campaign's measurements.h5")
    _require(reference / "measurements.h5", "the reference data set's measurements.h5")
    _require(reference / "truth.h5", "the reference data set's truth.h5 (its condition labels)")
    with open_measurements(campaign / "measurements.h5"):
        pass  # an unreadable or truncated campaign file fails here, before any work
    out.mkdir(parents=True, exist_ok=True)

    # 1. Reference set: features, labels, Fisher selection.
    ref = _extract_to_csv(reference / "measurements.h5", out / "reference_features")
    labels = pipeline.reference_labels(reference / "truth.h5", ref.hours)
    n_h, n_f = int(np.sum(labels == 0)), int(np.sum(labels == 1))
    if n_h < 2 or n_f < 2:
        raise DetectError(f"{reference / 'truth.h5'}: /timeline gives {n_h} healthy and {n_f} "
                          "backlash samples of the reference set; expected at least 2 of each")
    fisher, selected = pipeline.select_features(ref.X, labels, fraction)
    total = float(np.sum(np.nan_to_num(fisher, posinf=0.0)))
    selection = {
        "selected": [ref.names[i] for i in selected],
        "fisher_scores": {n: (float(s) if np.isfinite(s) else None) for n, s in zip(ref.names, fisher, strict=True)},
        "cumulative_fraction": (float(np.sum(fisher[selected]) / total) if total > 0 else None),
        "threshold_fraction": fraction,
        "reference_samples": {"healthy": n_h, "backlash": n_f, "unused": int(np.sum(labels < 0))},
    }
    write_json(out / "selection.json", selection)

    # 2. Campaign features.
    table = _extract_to_csv(campaign / "measurements.h5", out / "features")
    if len(table.hours) <= n_baseline:
        raise DetectError(f"{campaign / 'measurements.h5'}: /phase1 has {len(table.hours)} samples; "
                          f"expected more than the {n_baseline} baseline samples")

    # 3. Detectors and scoring.
    results = pipeline.run_detectors(table, selected, methods, n_baseline, random_state)
    if save_model is not None:
        from analysis.phase1.model_file import from_fit, recording_signature

        with open_measurements(campaign / "measurements.h5") as m:
            rec = recording_signature(m.phase1(m.phase1_captures()[0]))
        from_fit(table, selected, results, n_baseline, consecutive, rec,
                 {"campaign": str(campaign), "reference": str(reference),
                  "selected_features": selection["selected"]}).save(save_model)
    return _finish(campaign, out, table, results, n_baseline, consecutive,
                   {"reference": str(reference), "selected_features": selection["selected"]})


def _run_with_model(campaign: Path, model_path: Path, out: Path) -> dict:
    """``run`` with a persisted model: features with its templates, scores with its detectors."""
    from analysis.phase1.model_file import Phase1Model, recording_signature

    model = Phase1Model.load(model_path)
    _require(campaign / "measurements.h5", "the campaign's measurements.h5")
    with open_measurements(campaign / "measurements.h5") as m:
        names = m.phase1_captures()
        if not names:
            raise DetectError(f"{campaign / 'measurements.h5'}: /phase1 has no captures")
        model.check_recording(recording_signature(m.phase1(names[0])),
                              f"{campaign / 'measurements.h5'}: /phase1/{names[0]}")
    out.mkdir(parents=True, exist_ok=True)
    table = pipeline.extract(campaign / "measurements.h5", templates=model.templates)
    table.write_csv(out / "features.csv")
    results = model.score_table(table.X, table.ae)
    nb = model.n_baseline
    n_baseline = nb if len(table.hours) >= nb and np.array_equal(table.hours[:nb], model.baseline_hours) else 0
    return _finish(campaign, out, table, results, n_baseline, model.consecutive,
                   {"model": str(model_path), "reference": model.provenance.get("reference"),
                    "selected_features": [model.feature_names[i] for i in model.selected]})


def _finish(campaign: Path, out: Path, table, results: dict, n_baseline: int, consecutive: int,
            extra: dict) -> dict:
    """Score the detectors against the injected onset; write detection.json, the details, the PNG."""
    onset = None
    truth = campaign / "truth.h5"
    if truth.is_file():
        with open_truth(truth) as t:
            onset = t.onset_hours
    scores = {m: score_method(table.hours, r["scores"], r["threshold"], n_baseline, onset, consecutive)
              for m, r in results.items()}
    detections = {m: s.detection_hours for m, s in scores.items()}
    write_json(out / "detection.json", detection_json(table.hours, results, detections))
    details = {
        "campaign": str(campaign), "reference": extra.get("reference"), "onset_hours": onset,
        "n_samples": len(table.hours), "n_baseline": n_baseline, "consecutive": consecutive,
        "selected_features": extra["selected_features"],
        **({"model": extra["model"]} if "model" in extra else {}),
        "methods": {m: {"label": results[m]["label"], **asdict(scores[m]),
                        "threshold": results[m]["threshold"],
                        "n_components": getattr(results[m]["detector"], "n_components_", None)}
                    for m in results},
    }
    write_json(out / "detection_details.json", details)
    plot_fig6(out / "detection.png", table.hours, results, n_baseline, onset, detections)
    return details


def _num(x: float | None) -> float | None:
    return None if x is None or not np.isfinite(x) else float(x)


def detection_json(hours: np.ndarray, results: dict[str, dict], detections: dict[str, float | None]) -> dict:
    """The ``detection.json`` object: ``{"methods": {NAME: {"label": str, "detection_hours": float
    or null, "threshold": float, "scores": [...], "hours": [...]}}}``, scores oriented so that above the
    threshold is an alarm (selected features, delays and false alarms go to
    ``detection_details.json``). results: {name: {"scores" (n,), "threshold"}}."""
    return {"methods": {
        name: {"label": r.get("label", name), "detection_hours": _num(detections[name]),
               "threshold": float(r["threshold"]),
               "scores": [float(v) for v in r["scores"]], "hours": [float(h) for h in hours]}
        for name, r in results.items()}}
