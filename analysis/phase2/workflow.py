"""The ``twin backlash`` workflow: session error motions -> change of backlash per session ->
Kalman trend and prognosis -> ``OUT/backlash.json`` and the figures of paper section V.

Reads ``measurements.h5`` only for the estimates; ``truth.h5`` (if present) only to draw the
injected values in Fig. 13. The CLI and the harness (``twin demo``, ``twin sweep``) both call
:func:`run`, so what they write is the same file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.base import registry
from analysis.base.files import write_json
from analysis.dataset import DOFS, open_measurements, open_truth
from analysis.injected import injected_change_um
from analysis.phase2.backlash import (
    BacklashEstimator,
    CampaignBacklash,
    campaign_backlash,
    estimator_for,
    primary_m,
)
from analysis.phase2.error_motion_cache import ErrorMotionCache
from analysis.phase2.error_motion_file import write_error_motions
from analysis.phase2.error_motions import BAND_PRECISION, resolve_position_reference
from analysis.phase2.figures import write_figures
from analysis.phase2.prognosis import BacklashTrend, Prognosis, prognosis, savgol_trend
from analysis.phase2.traces import band_mm

__all__ = ["BacklashRun", "estimator_dir", "run"]

#: What the traces' position axis is, per ``position_reference``, as written in backlash.json.
POSITION_REFERENCES = {
    "command": ("commanded position (position_cmd, screw-locked); rail-fixed features shift "
                "by +Δbacklash forward minus reverse"),
    "imu": ("IMU-based position (strokes timed from the accelerometer, the routine's nominal trapezoid "
            "between them); rail-fixed features stay put, E_XX's screw-locked content moves with the "
            "backlash: Eq. 5 refers each DOF's ΔPositionShift to E_XX's (ΔPositionShift_j − ΔPositionShift_XX)"),
}


@dataclass
class BacklashRun:
    """What :func:`run` computed.

    Attributes:
        doc: the content of ``backlash.json`` (µm, h, mm at this edge).
        result: the per-session estimates (SI).
        trend: the Kalman trend, or None with fewer than two usable sessions.
        prognosis: remaining time to the limit, or None without a trend.
        figures: PNG paths written.
    """

    doc: dict
    result: CampaignBacklash
    trend: BacklashTrend | None
    prognosis: Prognosis | None
    figures: list[Path]


def estimator_dir(out: str | Path, name: str) -> Path:
    """Where estimator ``name`` writes under ``out`` (a campaign's ``backlash/``): ``out`` itself
    for the default estimator (where scoring, the report and the viewer read it),
    ``out/<name>`` for every other one."""
    return Path(out) if name == registry.default("backlash_estimators").name else Path(out) / name


def run(directory: str | Path, out: str | Path | None = None, *, strict: bool = False,
        plots: bool = True, process_noise: float | str = "auto",
        baseline_sessions: int = 1, estimator: BacklashEstimator | str | None = None,
        position_reference: str = "auto", params: dict | None = None,
        map_sessions=None, cache: str | Path | None = None) -> BacklashRun:
    """Estimate the change of backlash of every Phase II session of ``directory``.

    Args:
        directory: campaign directory holding ``measurements.h5``.
        out: output directory (default ``directory/backlash``); ``backlash.json`` and, with
            ``plots``, the PNGs of Figs. 7–13 are written there.
        strict: raise on a bad run (missing, cut short, non-finite) instead of skipping it.
        process_noise: Kalman process noise q in m²/h³, ``"ml"`` (maximum likelihood) or ``"auto"``
            (the default: 1e-23 unless a likelihood-ratio test rejects it,
            :mod:`analysis.phase2.prognosis`).
        baseline_sessions: leading sessions known to share the initial backlash; the estimates
            are re-zeroed on their mean.
        estimator: an unfitted backlash estimator, or a registered name or ``module:Class``
            (:mod:`analysis.base.registry`; made with ``params`` and the axis's stroke and lead)
            (default: the registered default, the paper's method; on the IMU axis with
            ``stationary="E_XX"``, Eq. 5); its registered name and label are recorded in
            ``estimator`` and its class in ``parameters.estimator``.
        params: constructor parameters of a named ``estimator``.
        position_reference: "auto" (default: "command" when the runs record ``position_cmd``, else
            "imu"), "command" (the controller's ``position_cmd``) or "imu" (the
            IMU-based position: strokes from the accelerometer and the run's routine metadata;
            ``position_cmd`` is not read). Recorded in ``parameters.position_reference``.
        map_sessions: runs the sessions' error motions elsewhere (the caller's executor; see
            :func:`analysis.phase2.backlash.campaign_backlash`); None: here, one by one.
        cache: a folder that keeps the sessions' error motions
            (:class:`analysis.phase2.error_motion_cache.ErrorMotionCache`): a rerun on the same
            recording with the same error-motion options computes none again; None: no cache.

    Raises:
        DatasetError, FileNotFoundError, OSError: unreadable input (names file, key, channel).
        ValueError: traces that cannot be correlated.
    """
    directory = Path(directory)
    out = Path(out) if out is not None else directory / "backlash"
    with open_measurements(directory / "measurements.h5") as m:
        position_reference = resolve_position_reference(m, position_reference)
        if estimator is None and position_reference == "imu":
            estimator = estimator_for(m, stationary="E_XX", **(params or {}))  # Eq. 5
        elif estimator is None or isinstance(estimator, str):
            estimator = estimator_for(m, estimator, **(params or {}))
        result = campaign_backlash(m, on_bad_run="raise" if strict else "skip",
                                   baseline_sessions=baseline_sessions, estimator=estimator,
                                   position_reference=position_reference,
                                   map_sessions=map_sessions,
                                   cache=None if cache is None else ErrorMotionCache(cache))
        dial = m.dial_indicator()
    ses = result.sessions
    hours = [s.hours for s in ses]
    shift = [primary_m(s, result.estimator) for s in ses]  # the estimator's primary estimate
    trend = None
    if len(ses) >= 2 and np.isfinite(shift).any():
        trend = BacklashTrend(process_noise=process_noise).fit(hours, shift)
    prog = prognosis(trend) if trend is not None else None
    savgol = savgol_trend(shift)
    savgol_pitch = savgol_trend([s.delta_backlash_pitch_m for s in ses])  # Fig. 13b's filtered curve
    dial_delta = None
    if dial is not None and len(dial[0]):
        dial_delta = (dial[0], dial[1] - dial[1][0])
    bands = {em.session: em.combined.band_m for em in result.error_motions}
    records = []
    for i, s in enumerate(ses):
        rec = s.to_json()
        rec["error_motion_band_mm"] = band_mm(bands.get(s.session))
        rec["delta_backlash_um"] = None if not math.isfinite(shift[i]) else shift[i] * 1e6
        if trend is not None:
            rec["smoothed_um"] = float(trend.smoothed[i] * 1e6)
            rec["smoothed_std_um"] = float(trend.smoothed_std[i] * 1e6)
        if savgol is not None and np.isfinite(savgol.values[i]):
            rec["savgol_um"] = float(savgol.values[i] * 1e6)
        if savgol_pitch is not None and np.isfinite(savgol_pitch.values[i]):
            rec["savgol_pitch_um"] = float(savgol_pitch.values[i] * 1e6)
        if dial_delta is not None:
            k = int(np.argmin(np.abs(dial_delta[0] - s.hours)))
            if abs(dial_delta[0][k] - s.hours) < 1e-6:
                rec["dial_indicator_um"] = float(dial[1][k])
                rec["dial_delta_um"] = float(dial_delta[1][k])
        records.append(rec)
    est = result.estimator
    entry = registry.entry_of("backlash_estimators", est)
    doc = {
        "estimator": {"name": entry.name, "label": entry.label,
                      "primary_estimate": getattr(est, "primary_estimate", "shift")},
        "sessions": records,
        "prognosis": prog.to_json() if prog is not None else None,
        "reference_session": ses[0].session if ses else None,
        "position_reference": POSITION_REFERENCES[position_reference],
        "sign": "positive = more backlash than in the reference session",
        "skipped_runs": [{"session": a, "run": b, "reason": c} for a, b, c in result.skipped_runs],
        "skipped_sessions": [{"session": a, "reason": b} for a, b in result.skipped_sessions],
        "parameters": {"estimator": f"{type(est).__module__}.{type(est).__qualname__}",
                       "position_reference": position_reference,
                       "estimator_params": _params_json(est),
                       "error_motion_band_precision": {
                           d: BAND_PRECISION[i] * 1e6 for i, d in enumerate(DOFS)},
                       "cutoff_wavelength_mm": est.cutoff_wavelength_m * 1e3,
                       "baseline_sessions": result.baseline_sessions,
                       "baseline_offset_um": {"shift": result.baseline_offset_m[0] * 1e6,
                                              "pitch": result.baseline_offset_m[1] * 1e6},
                       "kalman_process_noise_m2_per_h3": None if trend is None else trend.process_noise,
                       "kalman_process_noise_choice": None if trend is None else trend.process_noise_choice,
                       "kalman_measurement_std_um": None if trend is None else trend.measurement_std * 1e6,
                       "savgol": None if savgol is None else {"window_sessions": savgol.window,
                                                               "polyorder": savgol.polyorder},
                       "window_definition": est.window_definition, "threshold": est.threshold,
                       "sigma": est.sigma, "dofs": list(est.dofs), "stationary": est.stationary,
                       "travel_mm": est.travel_m * 1e3, "lead_mm": est.lead_m * 1e3,
                       "reference_pitch_mm": None if not math.isfinite(est.reference_pitch_m_)
                       else est.reference_pitch_m_ * 1e3},
    }
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "backlash.json", doc)
    write_error_motions(out / "error_motions.h5", result.error_motions)
    figures: list[Path] = []
    if plots and ses:
        injected = None
        if (directory / "truth.h5").exists():
            with open_truth(directory / "truth.h5") as t:
                injected = (hours, list(injected_change_um(t, [s.session for s in ses],
                                                           result.baseline_sessions)))
        figures = write_figures(result, doc, out, injected=injected)
    return BacklashRun(doc=doc, result=result, trend=trend, prognosis=prog, figures=figures)


def _params_json(est) -> dict:
    """The estimator's ``get_params()`` as JSON values (tuples as lists, others as strings)."""
    out = {}
    for k, v in (est.get_params() if hasattr(est, "get_params") else {}).items():
        if isinstance(v, tuple):
            v = list(v)
        out[k] = v if isinstance(v, (int, float, str, bool, list, type(None))) else repr(v)
    return out
