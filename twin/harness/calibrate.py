"""``twin calibrate``: the twin fitted to a recording, in three layers.

a. **Routine and layout**, measured (:func:`analysis.ingest.routine.measure_recording`: the
   moves' ramps, plateaus and rests fitted over every capture and run), as ``twin scenario
   init`` writes them;
b. **the sensor chain**, measured from the rests (:mod:`analysis.calibration.sensor_chain`: noise
   floors, bandwidths, the torque signal's noise and resolution, the IMU's gravity);
c. **the drive's physical parameters and the Phase I acceleration, jointly**, fitted by indirect
   inference (C. Gouriéroux, A. Monfort and E. Renault, "Indirect inference", J. Appl. Econometrics
   8, 1993): the auxiliary statistics of :mod:`analysis.calibration.drive` (the torque's rigid-body
   fit J and c_v, the drag over the cruise, the ripple at its order, the carriage's vertical and
   lateral suspension modes on the nut accelerometers, the IMU's axial acceleration around the
   starts and stops of the Phase II runs) and the routine fit's acceleration are computed on the
   recording's first Phase I sample and on the twin simulated with the same layout and one seed
   (common random numbers: every evaluation draws the same noise), and
   ``scipy.optimize.least_squares`` (trust-region reflective, bounds a factor of 10 either side of
   the start) moves the parameters until the two agree within the statistics' standard errors. The
   Jacobian's columns are simulated together (one batched rollout per capture). The 90 % intervals
   come from the Jacobian at the solution and the statistics' errors (delta method: Cov = (JᵀJ)⁻¹
   for residuals in units of their standard error); an error is the recording's own (the scatter
   over its captures), the twin's, and the scatter of the statistic over :data:`SPREAD_SEEDS` twin
   seeds at the start (the machine's random geometry and ripple phase, which one recording cannot
   average out); the interval uses the statistics' full covariance over those seeds (Cov = J⁻¹ Σ
   J⁻ᵀ: one regression gives J and c_v, and a machine's draw moves them together).

Why least_squares and not a black-box optimiser: the statistics are smooth in the parameters (each
responds mostly to one: J to the mass, the cruise's drag to the rails' friction, c_v to the viscous drag, the
ripple amplitude to the ripple, the ramps' slope to the commanded acceleration, a suspension mode's
frequency to the trucks' stiffness in its direction and the mass, the IMU's ringing around the
starts and stops, or the speed's overshoot, to the velocity loop's bandwidth), the problem is
square and small (9 unknowns), and with common random numbers the residual is deterministic, so a
Gauss–Newton method converges in a few Jacobians where a Bayesian optimiser would need tens of
evaluations; its Jacobian is also what the intervals need.

What the recording cannot inform keeps the twin's default and says why (:data:`NOT_INFORMED`).
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import optimize

from analysis.calibration.drive import (
    imu_reversal,
    imu_ripple,
    imu_yaw_mode,
    recording_statistics,
    speed_overshoot,
    suspension_mode,
)
from analysis.calibration.sensor_chain import Measured, measure_instruments
from analysis.dataset import open_measurements
from analysis.files import write_json, write_text
from analysis.ingest.routine import MEASURED_RAMP, SPEED_SMOOTH_S, fit_moves
from twin.config import get_dotted, set_dotted
from twin.executors import default_processes
from twin.scenario import Scenario, ScenarioError, from_dict, load

CALIBRATE_VERSION = 8
#: Phase I captures of the first sample the fit uses (the twin simulates as many).
FIT_CAPTURES = 4
#: Phase II runs of the first session the fit uses for the ripple (the twin simulates as many).
FIT_RUNS = 2
#: Jacobian evaluations least_squares may make (each simulates 1 + the parameters' count).
MAX_JACOBIANS = 6
#: Twin seeds simulated at the start point: their scatter is the machine-to-machine part of the
#: statistics' error (the twin's random geometry, ripple phase, ... at the same parameters).
SPREAD_SEEDS = 8
#: Twin seeds each evaluation averages (common to every evaluation: the residual stays
#: deterministic); one seed alone lets a component of random phase at the ripple's order
#: (the machine's draw) bias the ripple's fit.
FIT_SEEDS = 2
#: Standard errors a parameter's statistic must move for a factor 2 of it to be fitted.
MIN_SEEN = 3.0
#: A fitted parameter's 90 % interval must lie within this factor either side of its value;
#: wider, it is not told apart from the others (kept at its start, the rest fitted again).
MAX_SPAN = 2.0
#: Step of the finite differences in log(parameter).
LOG_STEP = 0.03
#: Student's t 95th percentile with SPREAD_SEEDS − 1 degrees of freedom: a two-sided 90 %
#: interval whose error is estimated from the seeds' scatter (scipy.stats.t.ppf(0.95, 7)).
T90 = 1.894578605061305
Z90 = 1.6448536269514722  # the standard normal's 95th percentile: a two-sided 90 % interval

#: The fitted parameters of layer (c): (scenario key, auxiliary statistic, unit).
FITTED = (
    ("axis.carriage_mass_kg", "inertia", "kg"),
    ("axis.rail_friction_N", "cruise_drag", "N"),
    ("axis.drag_viscous_Nm_s_per_rad", "viscous_drag", "N·m·s/rad"),
    ("axis.torque_ripple_Nm", "ripple", "N·m"),
    ("phase1.accel_mm_s2", "accel", "mm/s²"),
    ("phase1.dwell_s", "dwell", "s"),
    ("axis.truck_stiffness_vertical_N_per_um", "vertical_mode", "N/µm"),
    ("axis.truck_stiffness_lateral_N_per_um", "lateral_mode", "N/µm"),
    ("axis.velocity_bandwidth_hz", "loop_response", "Hz"),
)
#: The span of machines assumed for each fitted parameter: 90 % of axes of this class lie within
#: this factor either side of the twin's default (a stated assumption, the calibrate benchmark's
#: draws lie within it). A parameter kept at its default (not informed, or not told apart) is
#: uncertain by this much, and what the others' fit owes to it widens their intervals.
PRIOR_FACTOR = {
    "axis.carriage_mass_kg": 4.0, "axis.rail_friction_N": 3.5, "axis.drag_viscous_Nm_s_per_rad": 2.5,
    "axis.torque_ripple_Nm": 3.0, "phase1.accel_mm_s2": 1.5, "phase1.dwell_s": 2.0,
    "axis.truck_stiffness_vertical_N_per_um": 1.7, "axis.truck_stiffness_lateral_N_per_um": 1.7,
    "axis.velocity_bandwidth_hz": 2.0,
}
STAT_NAMES = ("inertia", "cruise_drag", "viscous_drag", "ripple", "accel", "dwell", "vertical_mode",
              "lateral_mode", "loop_response")

#: Parameters the twin has and the recording does not inform in this version, and why.
NOT_INFORMED = {
    "axis.motor_inertia_kg_m2": "one inertia is seen at the motor (rotor, screw and the carriage through the "
                                "lead): the fit puts all of it in the carriage mass",
    "axis.no_load_torque_Nm": "one constant drag is seen at the motor (the nut's and the rails' reflected "
                              "through the lead): the fit puts all of it in the rail friction",
    "axis.nut_stiffness_N_per_um": "the axial mode is damped by the servo into a broad hump the velocity loop "
                                   "moves as much as the nut's spring: not fitted in this version",
    "axis.bearing_stiffness_N_per_um": "in series with the nut's spring behind the same damped axial mode",
    "axis.position_bandwidth_hz": "Phase I records no command: the position loop's lag is not told from the "
                                  "routine's timing, and it moves the speed's overshoot 20 times less than "
                                  "the velocity loop does",
}

#: Sensor-chain keys of layer (b) that are scenario keys.
SENSOR_KEYS = ("sensors.imu_acc_noise_ug_per_rthz", "sensors.imu_acc_bandwidth_hz",
               "sensors.imu_gyro_noise_urad_s_per_rthz", "sensors.imu_gyro_bandwidth_hz",
               "sensors.nut_acc_noise_ug_per_rthz", "sensors.torque_noise_Nm")


#: The channels each calibrated key is fitted or measured on: a key whose channel `twin check`
#: flags keeps the twin's default (nothing is fitted to a flagged channel).
CHANNELS = {
    "axis.carriage_mass_kg": ("speed", "torque"), "axis.rail_friction_N": ("speed", "torque"),
    "axis.drag_viscous_Nm_s_per_rad": ("speed", "torque"), "axis.torque_ripple_Nm": ("imu_acc", "position_cmd"),
    "phase1.accel_mm_s2": ("speed",), "phase1.dwell_s": ("speed",),
    "axis.velocity_bandwidth_hz": ("speed", "imu_acc", "position_cmd"),
    "axis.truck_stiffness_vertical_N_per_um": ("acc1", "acc2"),
    "axis.truck_stiffness_lateral_N_per_um": ("acc1", "acc2", "imu_gyro"),
    "sensors.imu_acc_noise_ug_per_rthz": ("imu_acc",), "sensors.imu_acc_bandwidth_hz": ("imu_acc",),
    "sensors.imu_gyro_noise_urad_s_per_rthz": ("imu_gyro",), "sensors.imu_gyro_bandwidth_hz": ("imu_gyro",),
    "sensors.nut_acc_noise_ug_per_rthz": ("acc1", "acc2"), "sensors.torque_noise_Nm": ("torque",),
}


def flagged_keys(check: dict | None) -> dict[str, str]:
    """{calibrated key: why it keeps its default} for the channels that ``check`` (the record of
    ``twin check``: :func:`analysis.ingest.check.check_record`) flags: a finding whose HDF5 key
    ends in a channel's name flags that channel."""
    out: dict[str, str] = {}
    for f in (check or {}).get("errors", []) + (check or {}).get("warnings", []):
        ch = str(f["where"]).rstrip("/").rsplit("/", 1)[-1]
        for key, chans in CHANNELS.items():
            if ch in chans and key not in out:
                out[key] = f"twin check flags the channel {ch} ({f['where']}: {f['what']}): nothing fitted to it"
    return out


class _OutOfTime(Exception):
    """The budget's deadline leaves no time for another step of the fit."""


class CalibrationError(ValueError):
    """A calibration that cannot run; the message names the recording, what is wrong and what
    would do."""


@dataclass(frozen=True)
class Value:
    """A calibrated value: ``key`` (scenario key), ``value`` (its unit), ``source`` ("measured",
    "fitted"), ``low``/``high`` (the 90 % interval, or None), ``note`` how it was found."""

    key: str
    value: float
    source: str
    low: float | None
    high: float | None
    note: str

    def comment(self) -> str:
        iv = f"; 90 % interval {_g(self.low)} to {_g(self.high)}" if self.low is not None else ""
        return f"{self.note}{iv}"

    def to_json(self) -> dict:
        return {"key": self.key, "value": self.value, "source": self.source, "low": self.low,
                "high": self.high, "note": self.note}


def _g(v: float | None) -> str:
    return "None" if v is None else f"{v:.6g}"


def _progress(text: str, stream=None) -> None:
    """One line per step (a log shows where a long calibration is)."""
    print(f"calibrate: {text}", file=stream or sys.stderr, flush=True)


# ---------------------------------------------------------------------------------------------
# The twin's statistics for a parameter vector (cached by scenario)


def _key(s: Scenario) -> str:
    return hashlib.sha256(f"{CALIBRATE_VERSION}:{s.to_json()}".encode()).hexdigest()[:20]


def _statistics(m, captures: list[str], runs: list[tuple[str, str]], s: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """(values (9,), standard errors (9,)) of :data:`STAT_NAMES` over the Phase I ``captures``
    and the Phase II ``runs`` of the open recording ``m`` described by ``s``: the drive
    statistics of the captures, with the ripple read on the IMU of the runs when there are any
    (:func:`analysis.calibration.drive.imu_ripple`: the ripple shakes the carriage far above the
    other content at its order; in the Phase I torque a component of random phase at the same
    order hides it), and the routine fit's acceleration (mm/s²) and dwell (s) of Phase I, their
    errors from the scatter of the ramps' slopes and of the rests (the servo's lag at the start
    and at the end of a move differ a little: both are fitted through the twin's servo), and the
    vertical suspension mode (Hz, :func:`analysis.calibration.drive.suspension_mode`) with its
    scatter over the captures, and, on the IMU of the runs when there are any, the lateral (yaw)
    mode (:func:`analysis.calibration.drive.imu_yaw_mode`) and the velocity loop's response (the
    axial acceleration around the starts and stops: :func:`analysis.calibration.drive.imu_reversal`),
    else the lateral mode on the nut accelerometers and the speed's overshoot over the captures
    (:func:`analysis.calibration.drive.speed_overshoot`)."""
    order = s.axis.torque_ripple_per_rev
    mean, se = recording_statistics(m, captures, order)
    loaded = [m.phase2(a, b) for a, b in runs]  # each run read once
    if runs:
        rip = [imu_ripple(run, s.axis.lead_mm * 1e-3, order, 0.5 * s.sensors.imu_acc_bandwidth_hz)
               for run in loaded]
        rip = [r for r in rip if np.isfinite(r)]
        mean[3] = float(np.mean(rip)) if rip else float("nan")
        se[3] = float(np.std(rip, ddof=1) / math.sqrt(len(rip))) if len(rip) > 1 else float("nan")
    slopes, dwells = [], []
    for name in captures:
        c = m.phase1(name)
        moves = fit_moves(np.asarray(c.speed) * s.axis.lead_mm / (2 * math.pi), float(c.fs_hz), MEASURED_RAMP,
                          SPEED_SMOOTH_S)
        for mv in moves:
            slopes += [mv[k] for k in ("accel", "decel") if mv[k] is not None]
        dwells += [b["t_start"] - a["t_stop"] for a, b in zip(moves, moves[1:], strict=False)
                   if a["t_stop"] is not None and b["t_start"] is not None]
    acc, acc_se = _mean_se(slopes)
    dwell, dwell_se = _mean_se(dwells)
    rows: list[list[float]] = [[], [], []]  # vertical mode, lateral mode, the loop's response
    for name in captures:
        c = m.phase1(name)
        fs = float(c.fs_hz)
        for row, x in zip(rows, (suspension_mode([c.acc1, c.acc2], fs, 2),
                                 np.nan if runs else suspension_mode([c.acc1, c.acc2], fs, 1),
                                 np.nan if runs else speed_overshoot(np.asarray(c.speed, float), fs)), strict=True):
            if np.isfinite(x):
                row.append(x)
    for run in loaded:  # on the IMU, far sharper: the yaw mode, the velocity loop around starts and stops
        for row, x in zip(rows[1:], (imu_yaw_mode(run), imu_reversal(run)), strict=True):
            if np.isfinite(x):
                row.append(x)
    extra = [_mean_se(row) for row in rows]
    return (np.append(mean, [acc, dwell, *(v for v, _ in extra)]),
            np.append(se, [acc_se, dwell_se, *(e for _, e in extra)]))


def _mean_se(x: list[float]) -> tuple[float, float]:
    """(mean, standard error of the mean) of ``x``; NaN where it has too few values."""
    mean = float(np.mean(x)) if x else float("nan")
    return mean, float(np.std(x, ddof=1) / math.sqrt(len(x))) if len(x) > 1 else float("nan")


def evaluate(payloads: list[str], cache_dir: str) -> list[list[list[float]]]:
    """Simulate the scenarios (JSON) not yet cached, batched (one rollout per capture for all),
    and return [values, errors] of :data:`STAT_NAMES` for each (kept in ``cache_dir``)."""
    from threadpoolctl import threadpool_limits

    from twin.campaign import simulate_campaigns_batched

    ss = [from_dict(json.loads(p)) for p in payloads]
    files = [Path(cache_dir) / f"{_key(s)}.json" for s in ss]
    todo = [i for i, f in enumerate(files) if not f.exists()]
    if todo:
        dirs = [Path(cache_dir) / f"tmp-{_key(ss[i])}" for i in todo]
        for d in dirs:
            shutil.rmtree(d, ignore_errors=True)
        with threadpool_limits(1):
            simulate_campaigns_batched([ss[i] for i in todo], dirs)
        for i, d in zip(todo, dirs, strict=True):
            s = ss[i]
            with open_measurements(d / "measurements.h5") as m:
                runs = [(a, b) for a in m.phase2_sessions() for b in m.phase2_runs(a)]
                v, e = _statistics(m, m.phase1_captures(), runs, s)
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


# ---------------------------------------------------------------------------------------------
# Layer (c): the joint fit


@dataclass
class FitResult:
    """Layer (c)'s outcome: the fitted ``values``, the ``skipped``
    ones and why, the twin ``simulations`` run, the ``seconds`` spent, the ``residual`` (in
    standard errors) and, for layer (b)'s correction, the instruments the twin's own rests give
    at each of the spread's seeds (``instruments``: {key: [value per seed]}) for the values it
    was set to; ``estimated_s``: the whole calibration's longest time as estimated after the
    first simulations (None when no fit ran); ``stopped``: why the fit stopped before it
    converged (``--budget-minutes``' deadline), or None."""

    values: list[Value]
    skipped: dict[str, str]
    simulations: int
    seconds: float
    residual: list[float]
    instruments: dict[str, list[float]]
    first_sensors: dict[str, float]
    estimated_s: float | None = None
    stopped: str | None = None


def _fit_scenario(base: Scenario, sample_hours: float, n_captures: int, session_hours: float | None,
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
        data["dial_indicator"]["every_n_sessions"] = 100  # no dial test in the fit
    return data


def fit_physical(base: Scenario, recording: Path, cache: Path, budget_s: float | None,
                 workers: int, scheduler: str | None = None,
                 progress: Callable[[str], None] = _progress, spent_s: float = 0.0,
                 sensors: dict[str, Measured] | None = None) -> FitResult:
    """Layer (c) of the module docstring on ``recording`` against ``base`` (layers a and b
    applied). Raises :class:`CalibrationError` when ``budget_s`` (the whole calibration's, of
    which ``spent_s`` is spent) cannot hold: after timing the twin's first simulations, with the
    estimate and the smallest budget that would do. ``sensors``: layer (b) as measured; the
    spread at the solution is simulated with their first correction set
    (:func:`corrected_sensor_values`), so its instruments give the second."""
    from twin.harness.diagnosis.cache import run_tasks

    t0 = time.perf_counter()
    with open_measurements(recording / "measurements.h5") as m:
        names = m.phase1_captures()
        if not names:
            return FitResult([], {k: "no Phase I capture: no torque to fit" for k, _, _ in FITTED}, 0,
                             0.0, [], {}, {})
        first = min(m.phase1_header(n)[1] for n in names)
        caps = [n for n in names if m.phase1_header(n)[1] == first][:FIT_CAPTURES]
        hours = float(m.phase1(caps[0]).hours)
        sessions = m.phase2_sessions()
        runs = [(sessions[0], r) for r in m.phase2_runs(sessions[0])[:FIT_RUNS]] if sessions else []
        if runs and getattr(m.phase2(*runs[0]), "position_cmd", None) is None:
            runs = []  # the motor angle needs the command: the ripple is read on the torque
        session_h = m.session_hours(sessions[0]) if runs else None
        real, real_se = _statistics(m, caps, runs, base)
    skipped: dict[str, str] = {}
    use = []
    for i, (key, stat, _) in enumerate(FITTED):
        if not np.isfinite(real[i]):
            skipped[key] = (
                "the ripple's order is above half the IMU accelerometer's bandwidth at every Phase II speed, or "
                "no cruise spans 4 of its periods" if stat == "ripple" and runs else
                f"the recording's {stat.replace('_', ' ')} cannot be measured (no ramp, or no cruise of 4 "
                "ripple periods, in its first Phase I sample)")
        else:
            use.append(i)
    data0 = _fit_scenario(base, hours, len(caps), session_h, len(runs))
    keys = [FITTED[i][0] for i in use]
    start = np.array([float(get_dotted(data0, k)) for k in keys])
    if np.any(start <= 0):
        bad = [k for k, v in zip(keys, start, strict=True) if v <= 0]
        for k in bad:
            skipped[k] = "its starting value is 0: a factor cannot move it"
        use = [i for i in use if FITTED[i][0] not in bad]
        keys = [FITTED[i][0] for i in use]
        start = np.array([float(get_dotted(data0, k)) for k in keys])
    stat_idx = np.array(use, dtype=int)
    cache.mkdir(parents=True, exist_ok=True)
    sims = [0]

    extra: dict[str, float] = {}  # set at every evaluation (the sensors' first correction, at the end)

    def scenario_at(logp: np.ndarray, seed: int | None = None) -> str:
        data = json.loads(json.dumps(data0))
        for k, v in extra.items():
            set_dotted(data, k, float(v), source="calibrate")
        for k, lp in zip(keys, logp, strict=True):
            set_dotted(data, k, float(np.exp(lp)), source="calibrate")
        if seed is not None:
            data["seed"] = int(seed)
        return from_dict(data).to_json()

    def run(points: list[np.ndarray], seeds: list[int]) -> list[list[list[float]]]:
        """Statistics of each point with each seed (point-major)."""
        payloads = [scenario_at(p, sd) for p in points for sd in seeds]
        n = len(payloads)
        size = max(1, -(-n // max(1, workers)))
        batches = [payloads[k:k + size] for k in range(0, n, size)]
        results = run_tasks(evaluate, [(b, str(cache)) for b in batches], workers, scheduler)
        sims[0] += n
        return [r for res in results for r in res]

    def averaged(points: list[np.ndarray]) -> list[np.ndarray]:
        """The statistics of each point averaged over the FIT_SEEDS seeds."""
        rows = run(points, seeds[:FIT_SEEDS])
        return [np.nanmean([rows[i * FIT_SEEDS + k][0] for k in range(FIT_SEEDS)], axis=0)[stat_idx]
                for i in range(len(points))]

    x0 = np.log(start)
    t_first = time.perf_counter()
    seeds = [int(data0["seed"])] + [(int(data0["seed"]) + 7919 * (i + 1)) % 2**32 for i in range(SPREAD_SEEDS - 1)]
    spread = run([x0], seeds)
    first_eval = spread[0]
    unit_s = (time.perf_counter() - t_first) / max(1.0, len(seeds) / max(1, workers))

    def cost_s(n_points: int, n_seeds: int = FIT_SEEDS) -> float:
        """Time of ``n_points`` evaluations of ``n_seeds`` seeds each on the workers."""
        return unit_s * math.ceil(n_points * n_seeds / max(1, workers))

    # at most: the first Jacobian, MAX_JACOBIANS more, the spread at the solution; at least
    # (what a fit with intervals needs): the first Jacobian, one step and its Jacobian, the spread
    reserve_s = cost_s(1, SPREAD_SEEDS) + 2.0  # the spread at the solution, the files
    full = cost_s((MAX_JACOBIANS + 1) * (len(keys) + 1)) + reserve_s
    least = cost_s(3 * (len(keys) + 1)) + reserve_s
    elapsed = spent_s + (time.perf_counter() - t0)
    total = elapsed + full
    deadline = None if budget_s is None else t0 + budget_s - spent_s
    progress(f"layer c: {len(keys)} parameters jointly; one twin evaluation {unit_s:.1f} s: the calibration "
             f"takes at most {total / 60:.1f} min" + ("" if budget_s is None or total <= budget_s else
                                                       f"; the fit stops at the budget ({budget_s / 60:g} min)"))
    if budget_s is not None and elapsed + least > budget_s:
        raise CalibrationError(
            f"{recording}: the calibration needs at least {(elapsed + least) / 60:.1f} min on {workers} worker(s) "
            f"(about {total / 60:.1f} min to converge: one evaluation of the twin takes {unit_s:.1f} s); "
            f"--budget-minutes {budget_s / 60:g} is too small: give at least "
            f"{math.ceil((elapsed + least) / 60 * 1.1 * 10) / 10:g} ({math.ceil(total / 60 * 10) / 10:g} to converge)")
    sim_se = np.array(first_eval[1])[stat_idx] / math.sqrt(FIT_SEEDS)
    seed_sd = np.nanstd(np.array([r[0] for r in spread])[:, stat_idx], axis=0, ddof=1)
    # the recording is one machine (one draw: its seed scatter counts whole), the twin's
    # average of FIT_SEEDS draws
    se = np.sqrt(real_se[stat_idx] ** 2 + np.nan_to_num(sim_se, nan=0.0) ** 2
                 + np.nan_to_num(seed_sd) ** 2 * (1 + 1 / FIT_SEEDS))
    # a statistic whose error cannot be estimated (one capture): 1 % of its value
    se = np.where(np.isfinite(se) & (se > 0), se, 0.01 * np.abs(real[stat_idx]))
    target = real[stat_idx]
    memo: dict[bytes, np.ndarray] = {
        x0.tobytes(): np.nanmean([r[0] for r in spread[:FIT_SEEDS]], axis=0)[stat_idx]}

    def values_at(points: list[np.ndarray]) -> list[np.ndarray]:
        todo = [p for p in points if p.tobytes() not in memo]
        if todo:
            for p, r in zip(todo, averaged(todo), strict=True):
                memo[p.tobytes()] = r
        return [memo[p.tobytes()] for p in points]

    rows = np.arange(len(keys))  # the statistics in the fit (one per parameter)

    def resid(x: np.ndarray) -> np.ndarray:
        return np.nan_to_num((values_at([x])[0] - target) / se, nan=1e6)[rows]

    def jac(x: np.ndarray, cols: np.ndarray, final: bool = False) -> np.ndarray:
        """d(residual)/d(log p) of the parameters ``cols`` at ``x`` (all parameters); unless
        ``final`` (the intervals'), :class:`_OutOfTime` when it and the fit's end would pass
        the budget's deadline."""
        if deadline is not None and not final and (
                time.perf_counter() + cost_s(len(cols) + 1) * 2 + reserve_s > deadline):
            raise _OutOfTime
        pts = [x.copy() for _ in cols]
        for p, j in zip(pts, cols, strict=True):
            p[j] += LOG_STEP
        f0 = resid(x)
        vals = values_at(pts)
        at = ", ".join(f"{k.split('.')[-1]}={np.exp(v):.4g}" for k, v in zip(keys, x, strict=True))
        progress(f"layer c: Jacobian at {at} ({sims[0]} evaluations so far)")
        return np.column_stack([(np.nan_to_num((c - target) / se, nan=1e6)[rows] - f0) / LOG_STEP for c in vals])

    # A parameter whose statistic moves by less than MIN_SEEN standard errors for a factor 2 of
    # it is not informed by this recording (e.g. the rails' friction behind a screw of 5 mm
    # lead): kept at its start, its statistic out of the fit.
    all_cols = np.arange(len(keys))
    j0 = jac(x0, all_cols, final=True)
    seen = np.abs(np.diag(j0)) * math.log(2.0) >= MIN_SEEN
    for j in np.flatnonzero(~seen):
        skipped[keys[j]] = (f"the recording's {FITTED[use[j]][1].replace('_', ' ')} moves by "
                            f"{abs(j0[j, j]) * math.log(2.0):.2g} standard errors for a factor 2 of it (under "
                            f"{MIN_SEEN:g}): not informed, kept at {start[j]:.6g}")
    free = np.flatnonzero(seen)
    rows = free

    def embed(z: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[free] = z
        return x

    lo, hi = x0 - math.log(10.0), x0 + math.log(10.0)
    xs, fun, sd = x0, np.zeros(0), np.zeros(0)

    stopped: list[str] = []

    def solve(start_at: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the solution, all parameters; its residuals) of the parameters ``free`` from
        ``start_at``; at the budget's deadline, the best point evaluated so far."""
        tried: list[tuple[float, np.ndarray, np.ndarray]] = []

        def f(z: np.ndarray) -> np.ndarray:
            r = resid(embed(z))
            tried.append((float(r @ r), z.copy(), r))
            return r

        try:
            sol = optimize.least_squares(f, start_at[free], jac=lambda z: jac(embed(z), free),
                                         bounds=(lo[free], hi[free]), method="trf", x_scale="jac",
                                         xtol=1e-3, ftol=1e-4, max_nfev=MAX_JACOBIANS * 2)
        except _OutOfTime:
            _, z, r = min(tried, key=lambda t: t[0]) if tried else (0.0, start_at[free], resid(start_at)[free])
            stopped.append(f"the fit stopped at the budget's deadline after {sims[0]} evaluations (not "
                           f"converged: the best point so far, residual {float(np.sqrt(r @ r)):.2f} standard "
                           "errors); a larger --budget-minutes lets it converge")
            progress(f"layer c: {stopped[-1]}")
            return embed(z), r
        return embed(sol.x), sol.fun

    if free.size:
        xs, fun = solve(x0)
        # the delta method with the statistics' full covariance: one regression gives J and
        # c_v, and a machine's draw moves them together, so their errors correlate
        J = jac(xs, free, final=True) * se[free][:, None]  # d(statistic)/d(log p), the statistics' units
    # the machine-to-machine scatter at the solution (it grows with the ripple, the drags, the
    # noise): the spread's seeds again, with layer (b)'s first correction set
    first: dict[str, float] = {}
    if sensors:
        inst0: dict[str, list[float]] = {}
        for r in spread:
            for k, v in r[2].items():
                inst0.setdefault(k, []).append(float(v))
        first = {v.key: v.value for v in corrected_sensor_values(
            sensors, {k: float(f"{m.value:.6g}") for k, m in sensors.items()}, inst0)}
        extra.update(first)
    final = run([xs], seeds)
    if free.size:
        spread_all = np.array([r[0] for r in final])[:, stat_idx]
        own_all = np.nan_to_num(real_se[stat_idx] ** 2 + np.nan_to_num(sim_se, nan=0.0) ** 2, nan=0.0)

        def deltas(J: np.ndarray) -> np.ndarray:
            """The delta method's standard deviations of log p for the parameters ``free``."""
            vals = spread_all[:, free]
            ok = np.all(np.isfinite(vals), axis=1)
            cov_seed = np.cov(vals[ok].T, ddof=1).reshape(free.size, free.size) if ok.sum() > 2 else 0.0
            cov_stat = np.diag(own_all[free]) + cov_seed * (1 + 1 / FIT_SEEDS)
            try:
                jinv = np.linalg.inv(J)
            except np.linalg.LinAlgError:
                return np.full(free.size, np.inf)
            return np.sqrt(np.clip(np.diag(jinv @ cov_stat @ jinv.T), 0, None))

        sd = deltas(J)
        # Jointly not told apart: a parameter whose 90 % interval spans more than MAX_SPAN either
        # side (its statistic moves with another parameter as much as with it) is kept at its
        # start, the widest first, and the others fitted again without it.
        while free.size > 1 and not T90 * float(np.max(sd)) <= math.log(MAX_SPAN):
            w = int(np.argmax(sd))
            j = int(free[w])
            others = [keys[k].split(".")[-1] for k in free if k != j]
            skipped[keys[j]] = (f"not told apart jointly: its 90 % interval would span a factor "
                                f"{math.exp(min(T90 * float(sd[w]), 50.0)):.3g} either side (its statistic, the "
                                f"recording's {FITTED[use[j]][1].replace('_', ' ')}, moves with "
                                f"{', '.join(others)} as well): kept at {start[j]:.6g}")
            progress(f"layer c: {keys[j]} not told apart jointly; fitted again without it")
            free = np.delete(free, w)
            rows = free
            xs, fun = solve(xs)
            J = jac(xs, free, final=True) * se[free][:, None]
            sd = deltas(J)
    # The parameters kept at their start are uncertain by their prior span (PRIOR_FACTOR): the
    # fitted ones move with them by −J_ff⁻¹·J_fk (the linearised fit; J_fk from the first
    # Jacobian), which the delta method adds in quadrature (the intervals are marginal, not
    # conditional on the kept values).
    kept = np.array([j for j in range(len(keys)) if j not in set(free.tolist())], dtype=int)
    widened = ""
    if free.size and kept.size:
        prior_var = np.array([(math.log(PRIOR_FACTOR[keys[j]]) / Z90) ** 2 for j in kept])
        j_fk = j0[np.ix_(free, kept)] * se[free][:, None]
        try:
            a = -np.linalg.solve(J, j_fk)
        except np.linalg.LinAlgError:
            a = np.full((free.size, kept.size), np.inf)
        sd = np.sqrt(sd ** 2 + (a ** 2) @ prior_var)
        widened = ("; the interval includes the span of " + ", ".join(keys[j].split(".")[-1] for j in kept)
                   + ", kept at the twin's default")
    values = []
    for jj, j in enumerate(free):
        k, x, i = keys[j], xs[j], use[j]
        stat = FITTED[i][1]
        if stat in ("accel", "dwell"):
            note = f"fitted through the twin's servo to the moves of {len(caps)} Phase I captures"
        elif stat == "loop_response" and runs:
            note = (f"fitted jointly to the IMU's axial acceleration around the starts and stops of {len(runs)} "
                    f"Phase II runs at {session_h:g} h")
        elif stat == "loop_response":
            note = f"fitted jointly to the motor speed's overshoot at the ramps' ends in {len(caps)} Phase I captures"
        elif stat == "lateral_mode" and runs:
            note = f"fitted jointly to the IMU's yaw mode in {len(runs)} Phase II runs at {session_h:g} h"
        elif stat.endswith("_mode"):
            note = (f"fitted jointly to the {stat.split('_')[0]} suspension mode of the nut accelerometers in "
                    f"{len(caps)} Phase I captures at {hours:g} h")
        elif stat == "ripple" and runs:
            note = (f"fitted jointly to the IMU's axial acceleration at the ripple's order in {len(runs)} Phase II "
                    f"runs at {session_h:g} h")
        else:
            note = (f"fitted jointly to the torque's {stat.replace('_', ' ')} of {len(caps)} Phase I captures "
                    f"at {hours:g} h")
        w = T90 * sd[jj]
        low, high = (float(np.exp(x - w)), float(np.exp(x + w))) if np.isfinite(w) else (None, None)
        values.append(Value(k, float(np.exp(x)), "fitted", low, high, note + widened))
    progress(f"layer c: done in {sims[0]} evaluations, {time.perf_counter() - t0:.1f} s; residual "
             f"{', '.join(f'{r:+.2f}' for r in fun)} standard errors")
    inst: dict[str, list[float]] = {}
    for r in final:
        for k, v in r[2].items():
            inst.setdefault(k, []).append(float(v))
    return FitResult(values, skipped, sims[0], time.perf_counter() - t0,
                     [float(r) for r in fun], inst, first, total, stopped[0] if stopped else None)


# ---------------------------------------------------------------------------------------------
# Layer (b): the sensor chain


def sensor_values(recording: Path, base: Scenario) -> tuple[dict[str, Measured], list[str]]:
    """Layer (b), as measured: the instruments from the rests (:func:`measure_instruments`) by
    scenario key, and notes on what is not a scenario key (the torque's resolution, the IMU's
    gravity)."""
    with open_measurements(recording / "measurements.h5") as m:
        caps = m.phase1_captures()[:2 * FIT_CAPTURES]
        sess = m.phase2_sessions()
        runs = [(s, r) for s in sess[:2] for r in m.phase2_runs(s)[:4]]
        meas = measure_instruments(m, caps, runs, base.sensors.imu_acc_bandwidth_hz,
                                   base.sensors.imu_gyro_bandwidth_hz)
    notes = []
    if "torque_resolution_Nm" in meas:
        notes.append(f"the torque signal's resolution is {meas['torque_resolution_Nm'].value:.4g} N·m (the "
                     "twin's is 0.001 N·m, not a scenario key)")
    if "imu_gravity_scale" in meas:
        g = meas["imu_gravity_scale"].value
        notes.append(f"the IMU reads gravity as {g:.5f} × 9.80665 m/s² at rest"
                     + (" (a sensitivity error or local gravity: check the IMU's unit and sensitivity)"
                        if abs(g - 1) > 0.003 else ""))
    return {k: v for k, v in meas.items() if k in SENSOR_KEYS}, notes


def corrected_sensor_values(measured: dict[str, Measured], set_to: dict[str, float],
                            twin: dict[str, list[float]]) -> list[Value]:
    """Layer (b)'s values, each measurement corrected by the twin's own: the twin set to
    ``set_to[key]`` and measured the same way at each seed of the spread (``twin[key]``)
    reads mean(twin) where the recording reads ``measured``; the value is
    set · measured / mean(twin) (a step of indirect inference: the statistic is nearly
    proportional to the value; what the rests hold beside the noise and the estimator's own bias
    cancel). :func:`calibrate` takes two steps, the second from the first's values. The 90 %
    interval combines the recording's own error and the twin's scatter over the seeds (Student's
    t with the seeds' degrees of freedom). Without the twin's measurement the raw value and its
    own error."""
    out = []
    for key, v in measured.items():
        tw = np.array(twin.get(key, []), dtype=float)
        tw = tw[np.isfinite(tw)]
        if tw.size >= 2 and set_to.get(key):
            ratio = tw / set_to[key]
            r = float(np.mean(ratio))
            rel = math.sqrt(v.rel_se ** 2 + (float(np.std(ratio, ddof=1)) / r) ** 2 * (1 + 1 / tw.size))
            value = set_to[key] * v.value / float(np.mean(tw))
            note = f"{v.note}; corrected by the twin's own measurement (× {value / v.value:.4f})"
            w = T90 * rel
        else:
            value, note, w = v.value, v.note, Z90 * v.rel_se
        ok = np.isfinite(w)
        out.append(Value(key, float(f"{value:.6g}"), "measured", float(value * math.exp(-w)) if ok else None,
                         float(value * math.exp(w)) if ok else None, note))
    return out


# ---------------------------------------------------------------------------------------------
# The verb


def calibrate(recording: str | Path, out_toml: str | Path, *, budget_minutes: float | None = None,
              workers: int | None = None, scheduler: str | None = None, cache: str | Path | None = None,
              name: str | None = None, progress: Callable[[str], None] = _progress,
              check: dict | None = None) -> dict:
    """Calibrate the twin to ``recording`` (a campaign directory) and write the scenario to
    ``out_toml`` with the provenance of every value, and ``<out_toml>.calibration.json`` (what
    was measured, fitted and left, the fit's residuals and time). ``check``: the record of ``twin
    check`` on the recording (the CLI refuses errors unless forced): a value whose channel it flags
    keeps the twin's default (:func:`flagged_keys`). Returns that JSON's content."""
    from twin.scenario_init import scenario_text

    t0 = time.perf_counter()
    recording = Path(recording)
    out_toml = Path(out_toml)
    budget_s = None if budget_minutes is None else float(budget_minutes) * 60.0
    if budget_s is not None and not budget_s > 0:
        raise CalibrationError(f"--budget-minutes {budget_minutes}: expected a positive number of minutes")
    workers = workers or default_processes()
    cache = Path(cache) if cache else out_toml.parent / ".calibrate-cache"
    progress("layer a: the routine and the layout from the recording's moves")
    text_a, notes = scenario_text(recording, name)
    base = _load_text(text_a)
    progress("layer b: the sensor chain from the rests")
    measured, sens_notes = sensor_values(recording, base)
    data = base.model_dump(mode="json")
    for key, v in measured.items():
        set_dotted(data, key, float(f"{v.value:.6g}"), source="calibrate")
    base_b = from_dict(data)
    fit = fit_physical(base_b, recording, cache / "fit", budget_s, workers, scheduler, progress,
                       spent_s=time.perf_counter() - t0, sensors=measured)
    if fit.first_sensors:
        # the second step: the calibrated twin, set to the first step's floors, measured again
        sens = corrected_sensor_values(measured, fit.first_sensors, fit.instruments)
    else:  # no fit ran (no Phase I): the raw measurements with their own errors
        sens = corrected_sensor_values(measured, {}, {})
    values = sens + fit.values
    defaults = {k: why for k, why in NOT_INFORMED.items()}
    defaults.update(fit.skipped)
    flagged = flagged_keys(check)
    values = [v for v in values if v.key not in flagged]
    defaults.update(flagged)
    record = {"version": CALIBRATE_VERSION, "recording": str(recording.resolve()), "check": check,
              "values": [v.to_json() for v in values],
              "defaults": [{"key": k, "why": w} for k, w in defaults.items()],
              "notes": notes + sens_notes + ([fit.stopped] if fit.stopped else []), "simulations": fit.simulations,
              "fit_seconds": fit.seconds, "residual_se": fit.residual, "estimated_s": fit.estimated_s,
              "budget_s": budget_s, "stopped": fit.stopped}
    text, _ = scenario_text(recording, name, calibrated={v.key: (v.value, v.source, v.comment()) for v in values},
                            defaults=defaults, calibration=record)
    _load_text(text)
    write_text(out_toml, text)
    record["seconds"] = time.perf_counter() - t0
    write_json(out_toml.with_suffix(".calibration.json"), record, nan_as_null=True)
    progress(f"wrote {out_toml} ({len(values)} values measured or fitted, {len(defaults)} left at the "
             f"twin's default) in {record['seconds']:.1f} s")
    return record


def _load_text(text: str) -> Scenario:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "scenario.toml"
        p.write_text(text, encoding="utf-8")
        try:
            return load(p)
        except ScenarioError as exc:
            raise CalibrationError(f"the calibrated scenario does not load: {exc}") from None


__all__ = ["CalibrationError", "Value", "calibrate", "fit_physical", "sensor_values"]
