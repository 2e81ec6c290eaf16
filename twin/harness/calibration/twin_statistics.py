"""The twin's statistics for a parameter vector: the recording's auxiliary statistics computed on
the twin simulated with the recording's layout (cached by scenario), and on the recording.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from pathlib import Path

import numpy as np

from analysis.base.files import write_json
from analysis.calibration.drive import (
    imu_command_gain,
    imu_reversal,
    imu_ripple,
    imu_yaw_mode,
    recording_statistics,
    speed_overshoot,
    suspension_mode,
    vertical_mode,
)
from analysis.calibration.sensor_chain import measure_instruments
from analysis.dataset import open_measurements
from analysis.ingest.routine import MEASURED_RAMP, SPEED_SMOOTH_S, fit_moves
from twin.harness.calibration.values import CALIBRATE_VERSION, PRIOR_FACTOR, STAT_NAMES
from twin.sim.axis import Carriage
from twin.sim.scenario import Scenario, from_dict, to_axis

# ---------------------------------------------------------------------------------------------
# The twin's statistics for a parameter vector (cached by scenario)


def _key(s: Scenario, vertical_band: tuple[float, float] | None) -> str:
    return hashlib.sha256(f"{CALIBRATE_VERSION}:{vertical_band}:{s.to_json()}".encode()).hexdigest()[:20]


#: The pitch is looked for within this factor either side of its frequency at the fit's start:
#: the vertical trucks' prior span (:data:`PRIOR_FACTOR`) moves it by its square root.
PITCH_BAND_FACTOR = math.sqrt(PRIOR_FACTOR["axis.truck_stiffness_vertical_N_per_um"])
#: ... and below this fraction of the bounce at the start (the bounce stands 2.15 times above
#: the pitch: four trucks 120 mm apart under the carriage's I_yy/m), clear of its skirt.
BOUNCE_CLEARANCE = 0.62
#: The pitch is read where it stands this many times above its band's median PSD in every
#: Phase I capture of the recording (:func:`analysis.calibration.drive.mode_peak`), else the
#: centroid of the vertical spectrum (:func:`analysis.calibration.drive.suspension_mode`).
PITCH_MIN_STANDING = 3.0


def vertical_band_hz(s: Scenario) -> tuple[float, float]:
    """(low, high) Hz in which :func:`analysis.calibration.drive.vertical_mode` reads the pitch,
    on the twin and on the recording, for a whole calibration from the start scenario ``s``: the
    pitch (1/2π)·√(k_v·a²/I_yy) of its four vertical trucks (stiffness k_v N/m, spaced a m
    along the axis) under its carriage (mass m kg, I_yy kg·m² from
    :meth:`twin.sim.axis.Carriage.inertia_of`) over and times :data:`PITCH_BAND_FACTOR`, the top
    at most :data:`BOUNCE_CLEARANCE` of the bounce (1/2π)·√(4·k_v/m). A rigid bar on two
    springs: S. S. Rao, "Mechanical Vibrations", ch. 5. The carriage mass is the recording's
    ``/@axis`` one where it gives one (the inertia at the motor does not tell it on a fine lead,
    where the carriage is a few per cent of it), else the twin's default."""
    c = to_axis(s).carriage
    k = c.truck_stiffness_vertical
    pitch = math.sqrt(k * c.truck_spacing ** 2 / Carriage.inertia_of(c.mass)[1]) / (2 * math.pi)
    bounce = math.sqrt(4.0 * k / c.mass) / (2 * math.pi)
    return pitch / PITCH_BAND_FACTOR, min(pitch * PITCH_BAND_FACTOR, BOUNCE_CLEARANCE * bounce)


def vertical_statistic(m, captures: list[str], s: Scenario) -> tuple[float, float] | None:
    """How a whole calibration from the start scenario ``s`` reads the vertical trucks, on the twin
    and on the recording ``m`` (open): the pitch in :func:`vertical_band_hz` (returned) where it
    stands :data:`PITCH_MIN_STANDING` times above its band in every one of the Phase I
    ``captures``, else None: the centroid of the whole vertical spectrum. A weak or hidden pitch
    (a heavy carriage whose rails bounce it more than the screw rocks it) would be read as the
    strongest other bin in the band, which does not follow the trucks; the centroid mixes every
    vertical motion but moves with the trucks where nothing in it stands out."""
    band = vertical_band_hz(s)
    for name in captures:
        c = m.phase1(name)
        if vertical_mode([c.acc1, c.acc2], float(c.fs_hz), *band)[1] < PITCH_MIN_STANDING:
            return None
    return band


def fit_scenario(base: Scenario, sample_hours: float, n_captures: int, session_hours: float | None,
                 n_runs: int) -> dict:
    """The scenario data of the fit's twin: one Phase I sample of ``n_captures`` at the
    recording's hours and, with ``session_hours``, one Phase II session of ``n_runs`` runs (the
    ripple's statistic), no pause, the scenario's seed (common random numbers)."""
    data = base.model_dump(mode="json")
    last = max(float(sample_hours), float(session_hours or 0.0))
    data["campaign"].update(phase2=session_hours is not None, scale=1.0, pauses=[], warmup_hours=0.0,
                            total_hours=max(last + 1.0, 1.0))
    data["phase1"].update(sample_hours=[float(sample_hours)], captures_per_sample=int(n_captures))
    if session_hours is not None:
        data["phase2"].update(session_hours=[float(session_hours)], runs_per_session=int(n_runs))
        data["dial_indicator"]["every_n_sessions"] = 0  # no dial test in the fit
    return data


def _statistics(m, captures: list[str], runs: list[tuple[str, str]], s: Scenario,
                vertical_band: tuple[float, float] | None) -> tuple[np.ndarray, np.ndarray]:
    """(values (10,), standard errors (10,)) of :data:`STAT_NAMES` over the Phase I ``captures``
    and the Phase II ``runs`` of the open recording ``m`` described by ``s``: the drive
    statistics of the captures, with the ripple read on the IMU of the runs when there are any
    (:func:`analysis.calibration.drive.imu_ripple`: the ripple shakes the carriage far above the
    other content at its order; in the Phase I torque a component of random phase at the same
    order hides it), and the routine fit's acceleration (mm/s²: :func:`_ramps_mean_se`) and
    dwell (s) of Phase I, their errors from the scatter of the ramps' slopes and of the rests
    (both are fitted through the twin's servo), and the vertical mode on the trucks (Hz,
    :func:`analysis.calibration.drive.vertical_mode` in ``vertical_band`` (Hz), or with None the
    centroid :func:`analysis.calibration.drive.suspension_mode`: :func:`vertical_statistic`)
    with its scatter over the captures, and,
    on the IMU of the runs when there are any, the lateral (yaw)
    mode (:func:`analysis.calibration.drive.imu_yaw_mode`), the velocity loop's response (the
    gain from the commanded to the IMU's axial acceleration at 30-60 Hz:
    :func:`analysis.calibration.drive.imu_command_gain`) and the IMU's ringing at the starts and
    stops (:func:`analysis.calibration.drive.imu_reversal`, the extra statistic: it moves with
    the loop, not monotonically, and with the vertical trucks), else the lateral mode on the nut
    accelerometers, the speed's overshoot over the captures
    (:func:`analysis.calibration.drive.speed_overshoot`) and NaN for the ringing."""
    order = s.axis.torque_ripple_per_rev
    mean, se = recording_statistics(m, captures, order)
    loaded = [m.phase2(a, b) for a, b in runs]  # each run read once
    if runs:
        rip = [imu_ripple(run, s.axis.lead_mm * 1e-3, order, 0.5 * s.sensors.imu_acc_bandwidth_hz)
               for run in loaded]
        rip = [r for r in rip if np.isfinite(r)]
        mean[3] = float(np.mean(rip)) if rip else float("nan")
        se[3] = float(np.std(rip, ddof=1) / math.sqrt(len(rip))) if len(rip) > 1 else float("nan")
    ups, downs, dwells = [], [], []
    for name in captures:
        c = m.phase1(name)
        moves = fit_moves(np.asarray(c.speed) * s.axis.lead_mm / (2 * math.pi), float(c.fs_hz), MEASURED_RAMP,
                          SPEED_SMOOTH_S)
        ups += [mv["accel"] for mv in moves if mv["accel"] is not None]
        downs += [mv["decel"] for mv in moves if mv["decel"] is not None]
        dwells += [b["t_start"] - a["t_stop"] for a, b in zip(moves, moves[1:], strict=False)
                   if a["t_stop"] is not None and b["t_start"] is not None]
    acc, acc_se = _ramps_mean_se(ups, downs)
    dwell, dwell_se = _mean_se(dwells)
    # the vertical mode, the lateral mode, the loop's response, the IMU's ringing at the starts and stops
    rows: list[list[float]] = [[], [], [], []]
    for name in captures:
        c = m.phase1(name)
        fs = float(c.fs_hz)
        vertical = (suspension_mode([c.acc1, c.acc2], fs, 2) if vertical_band is None else
                    vertical_mode([c.acc1, c.acc2], fs, *vertical_band)[0])
        for row, x in zip(rows[:3], (vertical,
                                     np.nan if runs else suspension_mode([c.acc1, c.acc2], fs, 1),
                                     np.nan if runs else speed_overshoot(np.asarray(c.speed, float), fs)),
                          strict=True):
            if np.isfinite(x):
                row.append(x)
    for run in loaded:  # on the IMU, far sharper: the yaw mode, the velocity loop's tracking, the ringing
        for row, x in zip(rows[1:], (imu_yaw_mode(run), imu_command_gain(run), imu_reversal(run)), strict=True):
            if np.isfinite(x):
                row.append(x)
    extra = [_mean_se(row) for row in rows]
    return (np.append(mean, [acc, dwell, *(v for v, _ in extra)]),
            np.append(se, [acc_se, dwell_se, *(e for _, e in extra)]))


def _ramps_mean_se(ups: list[float], downs: list[float]) -> tuple[float, float]:
    """(value, standard error) of the Phase I acceleration statistic, mm/s²: the mean of the
    rising ramps' slopes and of the falling ramps' slopes, averaged (one kind alone when the
    other has none), the error combined from each kind's scatter. The servo's lag differs on the
    way up and on the way down (a short ramp's measured slope differs between the two by several
    per cent, and not by the same amount in every axis): pooled, that difference would be the
    statistic's error, and the share of each kind (a move cut by a capture's end) its value."""
    kinds = [_mean_se(x) for x in (ups, downs) if x]
    if not kinds:
        return float("nan"), float("nan")
    return (float(np.mean([v for v, _ in kinds])),
            float(math.sqrt(sum(e * e for _, e in kinds)) / len(kinds)))


def _mean_se(x: list[float]) -> tuple[float, float]:
    """(mean, standard error of the mean) of ``x``; NaN where it has too few values."""
    mean = float(np.mean(x)) if x else float("nan")
    return mean, float(np.std(x, ddof=1) / math.sqrt(len(x))) if len(x) > 1 else float("nan")


def evaluate(payloads: list[str], cache_dir: str, vertical_band: tuple[float, float] | None
             ) -> list[list[list[float]]]:
    """Simulate the scenarios (JSON) not yet cached, batched (one rollout per capture for all),
    and return [values, errors, instruments] of :data:`STAT_NAMES` for each (kept in
    ``cache_dir``), the vertical trucks read as ``vertical_band`` says (:func:`_statistics`); a
    scenario whose simulation runs away (diverges, or its carriage leaves the rails) has NaN
    values and errors, its cached file saying why (``error``)."""
    from threadpoolctl import threadpool_limits

    from twin.sim.campaign import simulate_campaigns_runaways

    ss = [from_dict(json.loads(p)) for p in payloads]
    files = [Path(cache_dir) / f"{_key(s, vertical_band)}.json" for s in ss]
    todo = [i for i, f in enumerate(files) if not f.exists()]
    if todo:
        dirs = [Path(cache_dir) / f"tmp-{_key(ss[i], vertical_band)}" for i in todo]
        for d in dirs:
            shutil.rmtree(d, ignore_errors=True)
        with threadpool_limits(1):  # a point that runs away (a step of the fit into an unstable axis)
            ran_away = {todo[k]: why for k, why in simulate_campaigns_runaways([ss[i] for i in todo], dirs).items()}
        for i, d in zip(todo, dirs, strict=True):
            s = ss[i]
            if i in ran_away:  # NaN statistics: the fit's residual there is its largest (1e6)
                write_json(files[i], {"values": [None] * len(STAT_NAMES), "errors": [None] * len(STAT_NAMES),
                                      "instruments": {}, "error": ran_away[i]})
                shutil.rmtree(d, ignore_errors=True)
                continue
            with open_measurements(d / "measurements.h5") as m:
                runs = [(a, b) for a in m.phase2_sessions() for b in m.phase2_runs(a)]
                v, e = _statistics(m, m.phase1_captures(), runs, s, vertical_band)
                inst = measure_instruments(m, m.phase1_captures(), runs, s.sensors.imu_acc_bandwidth_hz,
                                           s.sensors.imu_gyro_bandwidth_hz)
            write_json(files[i], {"values": v.tolist(), "errors": e.tolist(),
                                  "instruments": {k: x.value for k, x in inst.items()}}, nan_as_null=True)
            shutil.rmtree(d, ignore_errors=True)
    out = []
    for f in files:
        doc = json.loads(f.read_text())
        out.append([[np.nan if x is None else x for x in doc["values"]],
                    [np.nan if x is None else x for x in doc["errors"]], doc.get("instruments", {})])
    return out


