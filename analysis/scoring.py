"""Scores of both phases against the injected truth (``twin score`` in docs/usage.md).

:func:`score` reads what the analyses wrote into a campaign directory and the directory's
``truth.h5``; it never reruns an estimator, so the same numbers come out of ``twin score``,
``twin demo`` and every point of ``twin sweep``:

- ``DIR/phase1/detection.json`` and ``detection_details.json`` (``twin detect``): per method the
  detection hour (the first alarm after the injected onset, :mod:`analysis.phase1.scoring`), the
  delay from the onset, false alarms on the healthy post-baseline samples
  (:func:`analysis.phase1.scoring.score_method`), and the same over threshold factors (the limit
  times 0.25 … 4) for detection-rate against false-alarm curves;
- ``DIR/backlash/backlash.json`` (the default estimator, ``twin backlash``) and
  ``DIR/backlash/<estimator>/backlash.json`` (``twin backlash --estimator NAME``), each with its
  ``error_motions.h5``: per estimator and session the
  estimated change of backlash against the injected one (both relative to the mean of the
  baseline sessions), their RMS, largest and mean error; the same against the injected change of
  *lost motion* (clearance plus the elastic deflection 2·F/K of the nut under the rail friction F
  at the axial stiffness K of truth.h5, which is what a reversal of the table measures: the
  estimate follows it as the preload, and with it K, falls); the predicted hour at which the change
  reaches the 10 µm limit against the hour the injected backlash does; the RMS error of the
  recovered straightness and angular error motions against the true ones after removal of the
  unobservable terms (:func:`analysis.phase2.fusion.remove_unobservable`; E_XX is left out
  because the kinematic truth lacks the axial dynamics the IMU sees).

Units: the JSON carries µm, µrad and h in its key names; :func:`flat` gives one row of scalars
(dotted names) for sweep tables.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from analysis.base.files import read_json, write_json
from analysis.dataset import DOFS, DatasetError, open_truth
from analysis.injected import injected_backlash_um
from analysis.phase1.scoring import score_method
from analysis.phase2.error_motion_file import read_error_motion_bands, read_error_motions
from analysis.phase2.fusion import band_limit, remove_unobservable

__all__ = ["ESTIMATOR_SCORES", "ScoreError", "THRESHOLD_FACTORS", "backlash_results", "flat", "score",
           "write_score"]

THRESHOLD_FACTORS = tuple(float(f) for f in np.round(np.logspace(-2, 2, 17, base=2), 6))
LIMIT_UM = 10.0
EM_DOFS = ("E_YX", "E_ZX", "E_AX", "E_BX", "E_CX")


class ScoreError(ValueError):
    """A campaign directory that cannot be scored (names the file and what is missing)."""



def _none(x) -> float | None:
    return None if x is None or not math.isfinite(float(x)) else float(x)


def score_phase1(directory: Path, onset_hours: float | None) -> dict | None:
    """Phase I scores from ``DIR/phase1``; None if ``detection.json`` is absent."""
    det = read_json(directory / "phase1" / "detection.json", "the Phase I detection results of `twin detect`",
                    error=ScoreError, missing_ok=True)
    if det is None:
        return None
    details = read_json(directory / "phase1" / "detection_details.json", "the Phase I details of `twin detect`",
                        error=ScoreError, missing_ok=True) or {}
    n_base = int(details.get("n_baseline", 15))
    consecutive = int(details.get("consecutive", 1))
    methods = {}
    n_samples = 0
    for name, r in det["methods"].items():
        hours, scores = np.asarray(r["hours"], float), np.asarray(r["scores"], float)
        n_samples = len(hours)
        s = score_method(hours, scores, r["threshold"], n_base, onset_hours, consecutive)
        rec = {"label": r.get("label") or name, **asdict(s)}
        rec["threshold"] = float(r["threshold"])
        rec["false_alarm_rate"] = (s.false_alarms / s.healthy_test_samples
                                   if s.healthy_test_samples else None)
        roc = {"threshold_factor": list(THRESHOLD_FACTORS), "false_alarm_rate": [], "detected": [],
               "delay_hours": []}
        for f in THRESHOLD_FACTORS:
            # Scores are compared as "score > f * limit"; for the one-class SVM (limit 0) the
            # factor cannot scale, so the threshold is shifted by (f - 1) instead.
            thr = r["threshold"] * f if r["threshold"] != 0 else (f - 1.0)
            sf = score_method(hours, scores, thr, n_base, onset_hours, consecutive)
            roc["false_alarm_rate"].append(sf.false_alarms / sf.healthy_test_samples
                                           if sf.healthy_test_samples else None)
            roc["detected"].append(sf.detection_hours is not None)  # after the onset by definition
            roc["delay_hours"].append(sf.delay_hours)
        rec["roc"] = roc
        methods[name] = rec
    return {"onset_hours": onset_hours, "n_samples": n_samples, "n_baseline": n_base,
            "consecutive": consecutive, "methods": methods}


def _crossing(hours: np.ndarray, values: np.ndarray, limit: float) -> float | None:
    """First hour at which ``values`` reaches ``limit`` (linear interpolation), or None."""
    above = np.flatnonzero(values >= limit)
    if not len(above):
        return None
    i = int(above[0])
    if i == 0:
        return float(hours[0])
    h0, h1, v0, v1 = hours[i - 1], hours[i], values[i - 1], values[i]
    return float(h0 + (limit - v0) / (v1 - v0) * (h1 - h0))


def _error_motion_errors(path: Path, truth) -> dict | None:
    """Median over sessions of the RMS error of the recovered error motions (µm, µrad): over the
    whole stroke (``rms_um``, ``rms_urad``) and, where ``error_motions.h5`` records the band the
    recording resolves, within that band (``in_band``: the error, the true error motion's RMS
    in the band for scale, and the band in mm; both traces band-limited by
    :func:`analysis.phase2.fusion.band_limit`)."""
    if not path.is_file():
        return None
    bands = read_error_motion_bands(path)
    per = {d: [] for d in EM_DOFS}
    per_band = {d: [] for d in EM_DOFS}
    true_band = {d: [] for d in EM_DOFS}
    band_lims = {d: [] for d in EM_DOFS}
    for name, (x, fwd, rev) in read_error_motions(path).items():
        try:
            xt, et, attrs = truth.session(name)
        except DatasetError:
            continue
        ref = np.array([np.interp(x + attrs["origin_offset_m"], xt, et[i]) for i in range(6)])
        est = remove_unobservable(0.5 * (fwd + rev), x)
        ref = remove_unobservable(ref, x)
        rms = np.sqrt(((est - ref) ** 2).mean(axis=1))
        band = bands.get(name)
        for d in EM_DOFS:
            i = DOFS.index(d)
            per[d].append(float(rms[i]) * 1e6)
            if band is not None and np.isfinite(band[i]).all():
                dx = float(x[1] - x[0])
                eb, tb = (band_limit(a[i], dx, tuple(band[i])) for a in (est, ref))
                per_band[d].append(float(np.sqrt(np.mean((eb - tb) ** 2))) * 1e6)
                true_band[d].append(float(np.sqrt(np.mean(tb ** 2))) * 1e6)
                band_lims[d].append(band[i] * 1e3)
    if not per[EM_DOFS[0]]:
        return None
    out = {"rms_um": {d: float(np.median(per[d])) for d in EM_DOFS[:2]},
           "rms_urad": {d: float(np.median(per[d])) for d in EM_DOFS[2:]},
           "sessions": len(per[EM_DOFS[0]])}
    if any(per_band.values()):
        med = {d: float(np.median(v)) if v else None for d, v in per_band.items()}
        tru = {d: float(np.median(v)) if v else None for d, v in true_band.items()}
        out["in_band"] = {
            "rms_um": {d: med[d] for d in EM_DOFS[:2]}, "rms_urad": {d: med[d] for d in EM_DOFS[2:]},
            "true_rms_um": {d: tru[d] for d in EM_DOFS[:2]}, "true_rms_urad": {d: tru[d] for d in EM_DOFS[2:]},
            "band_mm": {d: np.median(band_lims[d], axis=0).tolist() if band_lims[d] else None for d in EM_DOFS}}
    return out


def _elastic_um(scenario: dict, tl: dict, hours: list[float]) -> np.ndarray | None:
    """Elastic lost motion 2·F/K in µm at ``hours``: F the rail friction of the scenario (N), K the
    axial stiffness of the drive from truth.h5's timeline ``tl`` (N/m). None if either is not there."""
    friction = (scenario.get("axis") or {}).get("rail_friction_N")
    if friction is None or "axial_stiffness_N_per_m" not in tl:
        return None
    k = np.interp(hours, tl["hours"], tl["axial_stiffness_N_per_m"])
    return 2.0 * float(friction) / k * 1e6


def backlash_results(directory: Path) -> dict[str, Path]:
    """{estimator name: its directory} of every ``backlash.json`` under ``DIR/backlash``: the
    default estimator's in ``DIR/backlash`` itself, the others' in ``DIR/backlash/<name>``
    (the name is the one recorded in the file, else the directory's)."""
    found: dict[str, Path] = {}
    base = Path(directory) / "backlash"
    for d in [base, *sorted(p for p in base.glob("*") if p.is_dir())]:
        path = d / "backlash.json"
        if not path.is_file():
            continue
        doc = read_json(path, "the Phase II backlash results of `twin backlash`", error=ScoreError)
        name = (doc.get("estimator") or {}).get("name") or (d.name if d != base else "shift")
        found.setdefault(name, d)
    return found


def score_phase2(directory: Path, truth, backlash_dir: Path | None = None) -> dict | None:
    """Phase II scores from ``backlash_dir`` (default ``DIR/backlash``); None if its
    ``backlash.json`` is absent. The estimate scored is each session's ``delta_backlash_um``
    (the estimator's primary estimate), else ``delta_backlash_um_shift`` (older files)."""
    bdir = Path(backlash_dir) if backlash_dir is not None else directory / "backlash"
    doc = read_json(bdir / "backlash.json", "the Phase II backlash results of `twin backlash`",
                    error=ScoreError, missing_ok=True)
    if doc is None or not doc.get("sessions"):
        return None
    k = int(doc.get("parameters", {}).get("baseline_sessions", 1))
    names = [r["session"] for r in doc["sessions"]]
    try:
        injected = injected_backlash_um(truth, names)
    except DatasetError as exc:
        raise ScoreError(f"{bdir / 'backlash.json'} names sessions truth.h5 "
                         f"cannot give the backlash of: {exc}") from None
    ref = float(np.mean(injected[:k]))
    tl = truth.timeline()
    elastic = _elastic_um(truth.scenario(), tl, [r["hours"] for r in doc["sessions"]])
    lost = None if elastic is None else np.asarray(injected) + elastic
    rows, err, perr, lerr = [], [], [], []
    for i, (rec, b) in enumerate(zip(doc["sessions"], injected, strict=True)):
        est = _none(rec.get("delta_backlash_um", rec.get("delta_backlash_um_shift")))
        pit = _none(rec.get("delta_backlash_um_pitch"))
        row = {"session": rec["session"], "hours": rec["hours"], "injected_delta_um": b - ref,
               "estimated_delta_um": est, "error_um": None if est is None else est - (b - ref),
               "pitch_estimated_delta_um": pit,
               "pitch_error_um": None if pit is None else pit - (b - ref),
               "smoothed_um": _none(rec.get("smoothed_um")),
               "dial_delta_um": _none(rec.get("dial_delta_um"))}
        if lost is not None:
            row["injected_lost_motion_delta_um"] = float(lost[i] - lost[:k].mean())
            row["error_vs_lost_motion_um"] = (None if est is None else
                                              est - row["injected_lost_motion_delta_um"])
            if est is not None:
                lerr.append(row["error_vs_lost_motion_um"])
        rows.append(row)
        if row["error_um"] is not None:
            err.append(row["error_um"])
        if row["pitch_error_um"] is not None:
            perr.append(row["pitch_error_um"])
    err_a = np.asarray(err)
    true_cross = _crossing(tl["hours"], tl["backlash_um"] - ref, LIMIT_UM)
    prog = doc.get("prognosis") or {}
    pred = _none(prog.get("crossing_hours"))
    est_doc = doc.get("estimator") or {}
    return {
        "estimator": est_doc.get("name") or "shift", "label": est_doc.get("label") or "shift",
        "baseline_sessions": k, "n_sessions": len(rows), "sessions": rows,
        "rms_error_um": float(np.sqrt(np.mean(err_a ** 2))) if len(err) else None,
        "max_abs_error_um": float(np.max(np.abs(err_a))) if len(err) else None,
        "bias_um": float(np.mean(err_a)) if len(err) else None,
        "pitch_rms_error_um": float(np.sqrt(np.mean(np.square(perr)))) if perr else None,
        "rms_error_vs_lost_motion_um": float(np.sqrt(np.mean(np.square(lerr)))) if lerr else None,
        "prognosis": {"limit_um": LIMIT_UM, "predicted_crossing_hours": pred,
                      "true_crossing_hours": true_cross,
                      "error_hours": None if pred is None or true_cross is None else pred - true_cross},
        "error_motions": _error_motion_errors(bdir / "error_motions.h5", truth),
        "skipped_runs": len(doc.get("skipped_runs", [])),
    }


def score(directory: str | Path) -> dict:
    """Score the analyses found in ``directory`` against its ``truth.h5`` (the score.json object).

    Raises:
        ScoreError: no truth.h5, or neither ``phase1/detection.json`` nor ``backlash/backlash.json``.
        DatasetError: an unreadable truth.h5 (names the key).
    """
    directory = Path(directory)
    truth_path = directory / "truth.h5"
    if not truth_path.is_file():
        raise ScoreError(f"{truth_path}: no such file; scoring needs the injected truth "
                         "(a real machine's recordings have none)")
    with open_truth(truth_path) as t:
        scen = t.scenario()
        p1 = score_phase1(directory, t.onset_hours)
        estimators = {}
        for name, bdir in backlash_results(directory).items():
            r = score_phase2(directory, t, bdir)
            if r is not None:
                estimators[name] = r
    p2 = next(iter(estimators.values()), None)  # the default estimator's, else the first found
    if p1 is None and p2 is None:
        raise ScoreError(f"{directory}: found neither phase1/detection.json (twin detect) nor "
                         "backlash/backlash.json (twin backlash); run the analyses first")
    return {"directory": str(directory), "scenario": {"name": scen.get("name"), "seed": scen.get("seed")},
            "phase1": p1, "phase2": p2,
            "phase2_estimators": {k: {key: v for key, v in r.items() if key != "error_motions"}
                                  for k, r in estimators.items()}}


def write_score(directory: str | Path, doc: dict) -> Path:
    """Write ``doc`` to ``directory/score.json`` (through a temporary file) and return the path."""
    return write_json(Path(directory) / "score.json", doc)


ESTIMATOR_SCORES = ("rms_error_um", "max_abs_error_um", "bias_um", "pitch_rms_error_um",
                    "rms_error_vs_lost_motion_um")


def flat(doc: dict) -> dict[str, float | int | None]:
    """One row of scalars from a score object: ``phase1.<method>.<score>``, ``phase2.<score>``
    (the default estimator) and ``phase2.<estimator>.<score>`` for every estimator scored
    (:data:`ESTIMATOR_SCORES` and ``prognosis_error_hours``); lists, per-session rows and curves
    left out."""
    row: dict[str, float | int | None] = {}
    p1 = doc.get("phase1")
    if p1:
        for name, r in p1["methods"].items():
            for key in ("detection_hours", "delay_hours", "delay_samples", "false_alarms",
                        "false_alarm_rate", "baseline_alarms"):
                row[f"phase1.{name}.{key}"] = r[key]
    p2 = doc.get("phase2")
    if p2:
        for key in ("rms_error_um", "max_abs_error_um", "bias_um", "pitch_rms_error_um",
                    "rms_error_vs_lost_motion_um", "skipped_runs"):
            row[f"phase2.{key}"] = p2[key]
        for key, v in p2["prognosis"].items():
            if key != "limit_um":
                row[f"phase2.prognosis.{key}"] = v
        for name, r in (doc.get("phase2_estimators") or {}).items():
            for key in ESTIMATOR_SCORES:
                row[f"phase2.{name}.{key}"] = r.get(key)
            row[f"phase2.{name}.prognosis_error_hours"] = (r.get("prognosis") or {}).get("error_hours")
        em = p2.get("error_motions") or {}
        for unit in ("rms_um", "rms_urad"):
            for d, v in em.get(unit, {}).items():
                row[f"phase2.error_motion.{d}.{unit}"] = v
            for d, v in (em.get("in_band") or {}).get(unit, {}).items():
                row[f"phase2.error_motion.{d}.in_band_{unit}"] = v
    return row
