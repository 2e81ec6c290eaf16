"""What layer (c) fits and how far it trusts it, the channels each calibrated key is read on,
what the recording cannot inform, and a calibrated value with its source and interval.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from analysis.calibration.drive import VELOCITY_BAND_HZ
from analysis.ingest.check import findings_by_channel

CALIBRATE_VERSION = 26  # 25: the trucks read on the pitch; 26: the misfit test, informed through any statistic
#: Phase I captures of the first sample the fit uses (the twin simulates as many).
FIT_CAPTURES = 4
#: Phase II runs of the first session the fit uses for the ripple (the twin simulates as many).
FIT_RUNS = 2
#: Finite-difference Jacobians a fit may make beyond the first and the one at its solution (each
#: simulates 1 + the parameters' count): one more each time the Jacobian at a solution found with
#: Broyden's updates still predicts a step (:data:`CONVERGED_CHI2`).
MAX_JACOBIANS = 2
#: Evaluations of the residual one Broyden fit may make (each simulates one point).
MAX_STEPS = 16
#: A fit has converged when the Gauss–Newton step of the finite-difference Jacobian at its
#: solution would lower the sum of squared residuals (in standard errors) by less than this.
CONVERGED_CHI2 = 0.25
#: Twin seeds simulated at the start point: their scatter is the machine-to-machine part of the
#: statistics' error (the twin's random geometry, ripple phase, ... at the same parameters).
SPREAD_SEEDS = 8
#: Twin seeds each evaluation averages (common to every evaluation: the residual stays
#: deterministic); one seed alone lets a component of random phase at the ripple's order
#: (the machine's draw) bias the ripple's fit.
FIT_SEEDS = 2
#: Standard errors a parameter's statistic must move for a factor 2 of it to be fitted.
MIN_SEEN = 3.0
#: A fit whose largest residual at its solution exceeds this many standard errors is started
#: again from the point each parameter's own statistic alone would give (the couplings between
#: the statistics can lead the joint steps into a second minimum), and the better kept.
RESTART_SE = 5.0
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
              "lateral_mode", "loop_response", "loop_ringing")
#: Statistics of :data:`STAT_NAMES` after the one of each fitted parameter (``STAT_NAMES[i]`` is
#: ``FITTED[i]``'s): fitted too, with no parameter of their own (the fit is least squares over
#: more statistics than parameters). The IMU's ringing at the starts and stops moves with the
#: velocity loop and the vertical trucks: beside the loop's tracking gain it tells a second
#: solution of the gain and the vertical trucks apart.
EXTRA_STATS = STAT_NAMES[len(FITTED):]

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
#: The noise floors of layer (b), each with the keys measured on the same rests' spectra (its
#: bandwidth): a floor above FLOOR_SPAN × the scenario's is not written into the calibrated
#: scenario, nor those (layer (c)'s twin reads them at the recording's values).
FLOORS = {"sensors.imu_acc_noise_ug_per_rthz": ("sensors.imu_acc_bandwidth_hz",),
          "sensors.imu_gyro_noise_urad_s_per_rthz": ("sensors.imu_gyro_bandwidth_hz",),
          "sensors.nut_acc_noise_ug_per_rthz": (), "sensors.torque_noise_Nm": ()}
#: A measured noise floor more than this factor above the scenario's, when the scenario's is
#: the twin's default (the paper's instruments), is an instrument noisier than its kind, or noise
#: added on its way (cable, connector, amplifier): kept out of the written scenario, so that
#: `twin diagnose` names it. Instruments of a kind differ by less (the calibrate benchmark draws the axes'
#: floors within a factor 2 of the twin's).
FLOOR_SPAN = 3.0
#: The same factor when the scenario's floor is the instrument's own data sheet (the recording's
#: ``/@axis``): units scatter around a data sheet's typical density by much less.
FLOOR_SPAN_DATASHEET = 1.5


#: The channels each calibrated key is fitted or measured on: a key whose channel `twin check`
#: flags keeps the twin's default (nothing is fitted to a flagged channel).
#: The channels each calibrated value is read on: layer (b)'s, and layer (c)'s when the fit reads
#: Phase II runs (:data:`FIT_CHANNELS`). Without runs (none recorded, or the IMU or the command
#: flagged by `twin check`) the fit reads the ripple on the torque, the lateral mode on the nut
#: accelerometers and the velocity loop on the speed's overshoot (:data:`FIT_CHANNELS_PHASE1`).
SENSOR_CHANNELS = {
    "sensors.imu_acc_noise_ug_per_rthz": ("imu_acc",), "sensors.imu_acc_bandwidth_hz": ("imu_acc",),
    "sensors.imu_gyro_noise_urad_s_per_rthz": ("imu_gyro",), "sensors.imu_gyro_bandwidth_hz": ("imu_gyro",),
    "sensors.nut_acc_noise_ug_per_rthz": ("acc1", "acc2"), "sensors.torque_noise_Nm": ("torque",),
}
_DRIVE = {
    "axis.carriage_mass_kg": ("speed", "torque"), "axis.rail_friction_N": ("speed", "torque"),
    "axis.drag_viscous_Nm_s_per_rad": ("speed", "torque"),
    "phase1.accel_mm_s2": ("speed",), "phase1.dwell_s": ("speed",),
    "axis.truck_stiffness_vertical_N_per_um": ("acc1", "acc2"),
}
FIT_CHANNELS = {**_DRIVE, "axis.torque_ripple_Nm": ("imu_acc", "position_cmd"),
                "axis.velocity_bandwidth_hz": ("imu_acc", "position_cmd"),
                "axis.truck_stiffness_lateral_N_per_um": ("imu_gyro",)}
FIT_CHANNELS_PHASE1 = {**_DRIVE, "axis.torque_ripple_Nm": ("speed", "torque"),
                       "axis.velocity_bandwidth_hz": ("speed",),
                       "axis.truck_stiffness_lateral_N_per_um": ("acc1", "acc2")}
#: Every value and its channels when the recording has Phase II runs (the owner's usual case).
CHANNELS = {**FIT_CHANNELS, **SENSOR_CHANNELS}
#: The Phase II channels layer (c) reads on its runs: one flagged, the fit leaves the runs out.
RUN_CHANNELS = ("imu_acc", "imu_gyro", "position_cmd")


def flagged_channels(check: dict | None) -> dict[str, str]:
    """{channel: its first finding, "where: what"} of the channels ``check`` (the record of ``twin
    check``: :func:`analysis.ingest.check.check_record`) flags: a finding whose HDF5 key ends in a
    channel's name flags that channel (one of its axes, ``imu_acc[x]``, the whole channel)."""
    return {ch: f"{fs[0]['where']}: {fs[0]['what']}" for ch, fs in findings_by_channel(check).items()}


def flagged_keys(check: dict | None, channels: dict[str, tuple[str, ...]] | None = None) -> dict[str, str]:
    """{calibrated key: why it keeps its default} for the keys of ``channels`` ({key: the channels
    it is read on}; default :data:`CHANNELS`) read on a channel ``check`` flags
    (:func:`flagged_channels`)."""
    flags = flagged_channels(check)
    out: dict[str, str] = {}
    for key, chans in (CHANNELS if channels is None else channels).items():
        ch = next((c for c in chans if c in flags), None)
        if ch is not None:
            out[key] = f"twin check flags the channel {ch} ({flags[ch]}): nothing fitted to it"
    return out


def fit_note(stat: str, captures: int, hours: float, runs: int, session_h: float | None,
             run_flag: str | None = None, pitch_band: tuple[float, float] | None = None) -> str:
    """How a layer (c) value was fitted, for the TOML: its statistic ``stat`` (:data:`STAT_NAMES`)
    on ``captures`` Phase I captures at ``hours`` and ``runs`` Phase II runs at ``session_h``;
    ``run_flag``: the channel `twin check` flags for which the runs were left out;
    ``pitch_band``: the band (Hz) the vertical trucks' pitch was read in, None: the centroid."""
    without = f" (the Phase II runs left out: twin check flags {run_flag})" if run_flag else ""
    if stat == "vertical_mode":
        how = (f"the carriage's pitch on its trucks (the vertical spectrum's peak within {pitch_band[0]:.0f}-"
               f"{pitch_band[1]:.0f} Hz)" if pitch_band else
               "the centroid of the vertical spectrum (its pitch does not stand out)")
        return f"fitted jointly to {how} of the nut accelerometers in {captures} Phase I captures at {hours:g} h"
    if stat in ("accel", "dwell"):
        return f"fitted through the twin's servo to the moves of {captures} Phase I captures"
    if stat == "loop_response" and runs:
        return (f"fitted jointly to the gain from the commanded to the IMU's axial acceleration at "
                f"{VELOCITY_BAND_HZ[0]:g}-{VELOCITY_BAND_HZ[1]:g} Hz and its ringing at the starts and stops "
                f"in {runs} Phase II runs at {session_h:g} h")
    if stat == "loop_response":
        return (f"fitted jointly to the motor speed's overshoot at the ramps' ends in {captures} Phase I "
                f"captures{without}")
    if stat == "lateral_mode" and runs:
        return f"fitted jointly to the IMU's yaw mode in {runs} Phase II runs at {session_h:g} h"
    if stat == "lateral_mode":
        return (f"fitted jointly to the lateral suspension mode of the nut accelerometers in {captures} "
                f"Phase I captures at {hours:g} h{without}")
    if stat == "ripple" and runs:
        return (f"fitted jointly to the IMU's axial acceleration at the ripple's order in {runs} Phase II "
                f"runs at {session_h:g} h")
    return (f"fitted jointly to the torque's {stat.replace('_', ' ')} of {captures} Phase I captures "
            f"at {hours:g} h" + (without if stat == "ripple" else ""))


@dataclass
class FitResult:
    """Layer (c)'s outcome: the fitted ``values``, the ``skipped`` ones and why, the twin
    ``simulations`` run, the ``seconds`` spent, the ``residual`` (standard errors) of the
    ``statistics`` (:data:`STAT_NAMES`) and, for layer (b)'s correction, the instruments the twin's
    own rests give at each of the spread's seeds (``instruments``: {key: [value per seed]});
    ``estimated_s``: the calibration's longest time as estimated after the first simulations
    (None when no fit ran); ``stopped``: why the fit stopped before it converged
    (``--budget-minutes``), or None; ``covariance``: {``keys``, ``log``: the joint covariance of
    the log values of the fitted parameters and of those kept at the default (their prior span)},
    or None; ``chi2``: the residuals' χ² with the kept parameters' span counted
    (:func:`twin.harness.calibration.misfit.profiled_chi2`)."""

    values: list[Value]
    skipped: dict[str, str]
    simulations: int
    seconds: float
    residual: list[float]
    statistics: list[str]
    instruments: dict[str, list[float]]
    first_sensors: dict[str, float]
    estimated_s: float | None = None
    stopped: str | None = None
    covariance: dict | None = None
    chi2: float | None = None


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

