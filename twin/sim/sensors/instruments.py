"""Measurement models: what the testbed's instruments record, given the true simulated motion.

The simulator delivers true signals on a uniform grid at ``fs_sim`` (10 kHz for Phase I, 5 kHz for
Phase II): specific force and angular rate in a sensor frame, motor angle and motor torque. The
functions here turn them into the samples a real instrument would deliver: sensor errors, white
noise at the datasheet density, the sensor's own (causal) low-pass, sampling at the instrument's
own rate, and the DAQ's quantisation. Everything is pure numpy/scipy; every random draw comes from
the ``numpy.random.Generator`` the caller passes in (derived from the scenario seed).

Spec sources of the defaults ([S] stated in the source, [M] a model assumption):

- [S: paper, section III] IMU accelerometer: analog, 2000 mV/g, half-power bandwidth 0-300 Hz,
  7 µg rms/√Hz, sampled at about 1613 Hz. IMU rate gyroscope: digital, half-power bandwidth
  0-200 Hz, 35 (µrad/s)/√Hz, about 1000 Hz. Ball-nut accelerometers: triaxial, 100 mV/g; Phase I
  data at 10 kHz (section III.A). Controller speed and torque at 10 kHz.
- [M] everything the paper does not state: filter orders, DAQ range and resolution, the nut
  accelerometer's noise density and AC-coupling corner, encoder resolution, current-sensor noise.
  Each such default says why it was chosen where it is defined.

Conventions: SI units throughout (m/s², rad/s, rad, N·m, V, s, Hz); sample ``i`` of a simulated
signal is at time ``t0 + i / fs_sim``; instrument sample ``k`` is at ``t0 + k / fs_hz``. All
``measure_*`` functions return ``(t, samples)``.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

from analysis.resample import not_a_knot_cubic_rows

try:  # the in-place filter behind scipy.signal.sosfilt (see _sosfilt_rows)
    from scipy.signal._sosfilt import _sosfilt
except ImportError:  # pragma: no cover
    _sosfilt = None

__all__ = [
    "STANDARD_GRAVITY",
    "MICRO_G",
    "MV_PER_G",
    "ErrorModel",
    "AnalogAccelerometerSpec",
    "DigitalGyroSpec",
    "NutAccelerometerSpec",
    "specific_force_in_sensor_frame",
    "butterworth_group_delay",
    "sensor_group_delay",
    "quantise",
    "decimate_to",
    "measure_imu_accelerometer",
    "measure_imu_accelerometer_runs",
    "measure_gyroscope",
    "measure_gyroscope_runs",
    "measure_nut_accelerometer",
    "measure_nut_accelerometer_runs",
    "measure_speed",
    "measure_torque",
]

#: Standard gravity g0 in m/s² (ISO 80000-3), used to convert datasheet "g" figures to SI.
STANDARD_GRAVITY = 9.80665
#: One µg in m/s²; a density of ``7 * MICRO_G`` is 7 µg/√Hz in (m/s²)/√Hz.
MICRO_G = 1e-6 * STANDARD_GRAVITY
#: One mV/g in V/(m/s²); a sensitivity of ``100 * MV_PER_G`` is 100 mV/g.
MV_PER_G = 1e-3 / STANDARD_GRAVITY


# --------------------------------------------------------------------------------------------
# Sensor error model
# --------------------------------------------------------------------------------------------


def _as_tuple_vector(value, name: str) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return tuple(float(v) for v in arr)


def _as_tuple_matrix(value, name: str) -> tuple[tuple[float, ...], ...]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3, 3) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite 3x3 matrix, got {value!r}")
    return tuple(tuple(float(v) for v in row) for row in arr)


@dataclass(frozen=True)
class ErrorModel:
    """Deterministic errors of a triaxial sensor: bias, scale-factor error, misalignment.

    ``s_meas = (I + diag(scale_error) + offdiag(misalignment)) @ s + bias``, applied per sample.

    Attributes:
        bias: (3,) offset per axis, in the unit of the signal (m/s² or rad/s).
        scale_error: (3,) fractional scale-factor error per axis (0.01 = reads 1 % high).
        misalignment: (3, 3) small-angle cross-axis matrix, dimensionless (rad for small angles).
            Element ``[i, j]`` is the sensitivity of output axis ``i`` to input axis ``j``; the
            diagonal is ignored (scale errors live in ``scale_error``).

    All zero by default (the error terms the twin models: "bias, scale, misalignment and cross-axis
    sensitivity as parameters (zero by default)"). Stored as tuples so the model is immutable and
    hashable; pass any array-like.
    """

    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale_error: tuple[float, float, float] = (0.0, 0.0, 0.0)
    misalignment: tuple[tuple[float, ...], ...] = ((0.0,) * 3,) * 3

    def __post_init__(self) -> None:
        object.__setattr__(self, "bias", _as_tuple_vector(self.bias, "bias"))
        object.__setattr__(self, "scale_error", _as_tuple_vector(self.scale_error, "scale_error"))
        matrix = _as_tuple_matrix(self.misalignment, "misalignment")
        object.__setattr__(self, "misalignment", matrix)

    @property
    def matrix(self) -> np.ndarray:
        """(3, 3) gain matrix ``I + diag(scale_error) + offdiag(misalignment)``, dimensionless."""
        cross = np.array(self.misalignment)
        np.fill_diagonal(cross, 0.0)
        return np.eye(3) + np.diag(self.scale_error) + cross

    def apply(self, values: np.ndarray) -> np.ndarray:
        """Apply the errors to a triaxial signal.

        Args:
            values: (n, 3) true signal in the sensor frame (any unit; bias is in the same unit).

        Returns:
            (n, 3) signal as the erroneous sensor reports it.
        """
        values = np.asarray(values, dtype=float)
        if values.ndim != 2 or values.shape[1] != 3:
            raise ValueError(f"signal must have shape (n, 3), got {values.shape}")
        return values @ self.matrix.T + np.asarray(self.bias)


# --------------------------------------------------------------------------------------------
# Instrument specifications (paper figures as defaults)
# --------------------------------------------------------------------------------------------


def _check_common_spec(spec) -> None:
    for name in ("fs_hz", "bandwidth_hz"):
        value = getattr(spec, name)
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{type(spec).__name__}.{name} must be positive, got {value!r}")
    if not (np.isfinite(spec.noise_density) and spec.noise_density >= 0):
        raise ValueError(
            f"{type(spec).__name__}.noise_density must be >= 0, got {spec.noise_density!r}"
        )
    if int(spec.filter_order) != spec.filter_order or not 1 <= spec.filter_order <= 8:
        raise ValueError(
            f"{type(spec).__name__}.filter_order must be an integer in 1..8, "
            f"got {spec.filter_order!r}"
        )
    if not isinstance(spec.error, ErrorModel):
        raise TypeError(f"{type(spec).__name__}.error must be an ErrorModel")


def _check_daq(spec) -> None:
    if not (spec.sensitivity > 0 and spec.daq_range > 0):
        raise ValueError(
            f"{type(spec).__name__}: sensitivity and daq_range must be positive, "
            f"got {spec.sensitivity!r}, {spec.daq_range!r}"
        )
    bits = spec.daq_bits
    if bits != 0 and not (int(bits) == bits and 2 <= bits <= 32):
        raise ValueError(
            f"{type(spec).__name__}.daq_bits must be 0 (off) or an integer in 2..32, got {bits!r}"
        )


@dataclass(frozen=True)
class _DaqAccelerometer:
    """What the two analog accelerometers share: the DAQ channel that samples their voltage and
    their error model. ``daq_range``: input range ±daq_range, V (outside it the reading clips);
    ``daq_bits``: resolution over 2·daq_range (0 = no quantisation or clipping); ``error``: bias
    (m/s²), scale and misalignment errors."""

    daq_range: float = 10.0
    daq_bits: int = 24
    error: ErrorModel = field(default_factory=ErrorModel)

    def __post_init__(self) -> None:
        _check_common_spec(self)
        _check_daq(self)


@dataclass(frozen=True)
class AnalogAccelerometerSpec(_DaqAccelerometer):
    """The IMU's analog triaxial accelerometer and the DAQ channel that samples it.

    Defaults [S: paper, section III]: 2000 mV/g, half-power bandwidth 0-300 Hz, 7 µg rms/√Hz,
    sampled at about 1613 Hz. [M] second-order response (a typical MEMS/servo accelerometer output
    stage; it keeps aliasing of the noise into 1-100 Hz below 0.5 %); DAQ ±10 V, 24 bit (a common
    delta-sigma input; 1.2 µV = 0.6 µg LSB, quantisation noise 0.006 µg/√Hz; ±10 V at 2 V/g is
    ±5 g).

    Attributes:
        fs_hz: output sampling rate, Hz.
        bandwidth_hz: half-power (-3 dB) frequency of the sensor's low-pass, Hz.
        noise_density: one-sided white noise density referred to the output, (m/s²)/√Hz.
        filter_order: order of the Butterworth low-pass modelling the sensor's response.
        sensitivity: output voltage per acceleration, V/(m/s²) (``2000 * MV_PER_G``).
        daq_range: DAQ input range ±daq_range, V; outside it the reading clips.
        daq_bits: DAQ resolution in bits over 2·daq_range (0 = no quantisation or clipping).
        error: bias (m/s²), scale and misalignment errors.
    """

    fs_hz: float = 1613.0
    bandwidth_hz: float = 300.0
    noise_density: float = 7.0 * MICRO_G
    filter_order: int = 2
    sensitivity: float = 2000.0 * MV_PER_G


@dataclass(frozen=True)
class DigitalGyroSpec:
    """The IMU's digital triaxial rate gyroscope.

    Defaults [S: paper, section III]: half-power bandwidth 0-200 Hz, 35 (µrad/s)/√Hz, about
    1000 Hz. [M] second-order response (digital gyros use a low-order IIR low-pass before
    decimation); no LSB quantisation and no range limit unless given (the paper's gyro is not
    named; a 16-bit ±300 °/s part would have ``lsb`` = 1.6e-4 rad/s, which is well below the
    noise of 35e-6·√500 = 7.8e-4 rad/s rms).

    Attributes:
        fs_hz: output data rate, Hz.
        bandwidth_hz: half-power (-3 dB) frequency of the low-pass, Hz.
        noise_density: one-sided white rate-noise density at the output, (rad/s)/√Hz.
        filter_order: order of the Butterworth low-pass.
        lsb: output resolution, rad/s (0 = off).
        full_scale: measurement range ±full_scale, rad/s (inf = no clipping).
        error: bias (rad/s), scale and misalignment errors.
    """

    fs_hz: float = 1000.0
    bandwidth_hz: float = 200.0
    noise_density: float = 35e-6
    filter_order: int = 2
    lsb: float = 0.0
    full_scale: float = math.inf
    error: ErrorModel = field(default_factory=ErrorModel)

    def __post_init__(self) -> None:
        _check_common_spec(self)
        if not self.lsb >= 0:
            raise ValueError(f"DigitalGyroSpec.lsb must be >= 0, got {self.lsb!r}")
        if not self.full_scale > 0:
            raise ValueError(f"DigitalGyroSpec.full_scale must be > 0, got {self.full_scale!r}")


@dataclass(frozen=True)
class NutAccelerometerSpec(_DaqAccelerometer):
    """A triaxial IEPE (ICP) accelerometer on the ball nut and its DAQ channel.

    Defaults: [S: paper, section III] 100 mV/g, 10 kHz (Phase I rate).
    [M] the rest:
    - ``noise_density`` 20 µg/√Hz: IEPE datasheets quote noise as "broadband resolution" (g rms
      over 1 Hz-10 kHz) and "spectral noise" at 10 Hz / 100 Hz / 1 kHz; for miniature triaxial
      100 mV/g ceramic-shear sensors the broadband figure is of the order of 1-2 mg rms, i.e.
      10-20 µg/√Hz flat over 10 kHz; 20 µg/√Hz is the conservative end and leaves room for the
      DAQ input noise. The 1/f rise of IEPE noise below about 10 Hz is not modelled. The
      ball-nut vibration at 400 mm/s is orders of magnitude above this floor.
    - anti-alias: Butterworth, 4th order, half-power at 0.4·fs (4 kHz).
    - ``highpass_hz`` 0.5 Hz, first order: IEPE sensors and their AC-coupled DAQ inputs do not
      pass DC (datasheet low-frequency limits are 0.3-2 Hz at -3 dB), so gravity and slow tilt
      do not appear in these channels. 0 turns it off (DC-coupled).
    - DAQ ±10 V, 24 bit (1.2 µV LSB = 12 µg at 100 mV/g; its quantisation noise, 0.05 µg/√Hz,
      is negligible; 16 bit would add 12 µg/√Hz). ±10 V at 100 mV/g is ±100 g.

    Attributes:
        fs_hz: DAQ sampling rate, Hz.
        bandwidth_hz: half-power frequency of the anti-alias low-pass, Hz.
        noise_density: one-sided white noise density at the output, (m/s²)/√Hz.
        filter_order: order of the anti-alias Butterworth low-pass.
        highpass_hz: half-power frequency of the first-order AC-coupling high-pass, Hz (0 = off).
        sensitivity: V/(m/s²) (``100 * MV_PER_G``).
        daq_range: ±daq_range input range, V.
        daq_bits: DAQ resolution in bits (0 = no quantisation or clipping).
        error: bias (m/s²), scale and misalignment (cross-axis) errors.
    """

    fs_hz: float = 10_000.0
    bandwidth_hz: float = 4_000.0
    noise_density: float = 20.0 * MICRO_G
    filter_order: int = 4
    highpass_hz: float = 0.5
    sensitivity: float = 100.0 * MV_PER_G

    def __post_init__(self) -> None:
        super().__post_init__()
        if not (self.highpass_hz >= 0 and self.highpass_hz < self.bandwidth_hz):
            raise ValueError(
                "NutAccelerometerSpec.highpass_hz must be in [0, bandwidth_hz), "
                f"got {self.highpass_hz!r}"
            )


# --------------------------------------------------------------------------------------------
# Shared pieces
# --------------------------------------------------------------------------------------------


def specific_force_in_sensor_frame(acceleration_world: np.ndarray,
                                   rotation_world_from_sensor: np.ndarray,
                                   gravity: float = STANDARD_GRAVITY) -> np.ndarray:
    """What an ideal accelerometer senses: ``R^T (a - g_vec)`` with ``g_vec = (0, 0, -gravity)``.

    Exactly kinematic (no modelling shortcut): an accelerometer at rest and level reads +g on z;
    a sensor rotated by a small angle θ about +y (right-hand rule) reads ``-g·sin θ`` on x, which is
    the ``f_x = ... - g·E_BX`` term of the IMU measurement model (:mod:`analysis.phase2.fusion`).

    Args:
        acceleration_world: (n, 3) or (3,) acceleration of the sensor point in the world frame
            (z up), m/s².
        rotation_world_from_sensor: (n, 3, 3) or (3, 3) rotation matrices whose columns are the
            sensor axes in world coordinates.
        gravity: magnitude of gravity, m/s².

    Returns:
        (n, 3) (or (3,)) specific force in the sensor frame, m/s².
    """
    acc = np.asarray(acceleration_world, dtype=float)
    rot = np.asarray(rotation_world_from_sensor, dtype=float)
    f_world = acc - np.array([0.0, 0.0, -gravity])
    return np.einsum("...ji,...j->...i", rot, f_world)


def butterworth_group_delay(order: int, cutoff_hz: float) -> float:
    """Group delay at low frequency of an analog Butterworth low-pass, s.

    ``tau(0) = 1 / (2π·f_c·sin(π / (2·order)))``: the sum of ``-Re(p)/|p|²`` over its poles on the
    circle of radius ``2π·f_c``. Second order at 300 Hz: 0.75 ms; at 200 Hz: 1.13 ms. The digital
    filters used here (bilinear, prewarped at the cutoff) match it within 1 % for the IMU
    defaults at fs_sim >= 5 kHz; when the cutoff nears fs_sim/2 they do not (the nut's 4 kHz
    anti-alias at 10 kHz: 42 µs digital against 104 µs analog); use :func:`sensor_group_delay`
    for the filter actually applied.
    """
    return 1.0 / (2.0 * math.pi * cutoff_hz * math.sin(math.pi / (2 * order)))


def sensor_group_delay(spec, fs_sim: float) -> float:
    """Group delay of the response a measurement function applies for ``spec`` at ``fs_sim``, s.

    Evaluated on the digital filter itself at 0.1·bandwidth_hz (flat to well under 1 % below
    that for the IMU defaults; there the AC-coupling high-pass of the nut accelerometer adds
    under 1 µs). The measurement functions leave this delay in their output, as a real sensor
    does; an estimator that aligns IMU data with position may subtract it.
    """
    sos = _sensor_filter(spec, fs_sim)
    b, a = signal.sos2tf(sos)
    _, delay = signal.group_delay((b, a), w=[0.1 * spec.bandwidth_hz], fs=fs_sim)
    return float(delay[0]) / fs_sim


def quantise(values: np.ndarray, step: float, limit: float = math.inf) -> np.ndarray:
    """Round to the nearest multiple of ``step`` and clip to ``[-limit, limit]``.

    Args:
        values: array of any shape, in any unit.
        step: quantisation step in that unit (0 = no rounding).
        limit: clipping level in that unit (inf = none).

    Returns:
        Array of the same shape.
    """
    out = np.asarray(values, dtype=float)
    if step > 0:
        out = np.round(out / step) * step
    if np.isfinite(limit):
        out = np.clip(out, -limit, limit)
    return out


def _daq_quantise(
    values: np.ndarray, sensitivity: float, daq_range: float, bits: int
) -> np.ndarray:
    """Voltage = sensitivity·value, quantised by a ``bits``-bit ADC over ±daq_range, converted back.

    Codes run from ``-2**(bits-1)`` to ``2**(bits-1) - 1`` with LSB ``2·daq_range / 2**bits``, V;
    readings outside the range clip to the end codes.
    """
    if bits == 0:
        return np.asarray(values, dtype=float)
    lsb = 2.0 * daq_range / 2.0**bits
    half = 2.0 ** (bits - 1)
    # In one buffer, operation by operation as codes = clip(round(v·S/lsb)), codes·lsb/S.
    out = np.multiply(values, sensitivity, dtype=float)
    np.divide(out, lsb, out=out)
    np.round(out, out=out)
    np.clip(out, -half, half - 1, out=out)
    np.multiply(out, lsb, out=out)
    return np.divide(out, sensitivity, out=out)


def _output_count(n_in: int, fs_in: float, fs_out: float) -> int:
    """Number of instants ``k / fs_out`` inside ``[0, (n_in - 1) / fs_in]``."""
    span = (n_in - 1) / fs_in
    return int(math.floor(span * fs_out * (1.0 + 1e-12))) + 1


def decimate_to(values: np.ndarray, fs_in: float, fs_out: float, t0: float = 0.0,
                kind: str = "cubic") -> tuple[np.ndarray, np.ndarray]:
    """Sample a uniformly sampled signal at the instants ``t0 + k / fs_out``.

    This is a pure resampler: it applies **no** anti-alias filter. Callers (the instrument models
    below) pass a signal that their own low-pass has already band-limited, so this reads the value
    of that filtered signal at the instrument's sampling instants, which need not fall on the
    simulation grid (1613 Hz from 10 kHz). Any aliasing that results is the instrument's own.

    Accuracy: the cubic spline (not-a-knot) reproduces a sinusoid of frequency f with relative error
    about ``(5/384)·(2π f / fs_in)**4``: 2e-5 at 300 Hz from 10 kHz, 3e-4 at 300 Hz from 5 kHz.
    Linear interpolation errs by up to ``(π f / fs_in)**2 / 2`` (0.4 % at 300 Hz from 10 kHz); it is
    meant for smooth, slowly varying signals (motor angle, torque at the controller rate). When
    ``fs_out`` equals ``fs_in`` or divides it, samples are picked from the grid, exactly.

    Args:
        values: (n,) or (n, c) signal at ``fs_in``, sample i at ``t0 + i / fs_in``.
        fs_in: input sampling rate, Hz.
        fs_out: output sampling rate, Hz (may be above fs_in: then it interpolates).
        t0: time of the first input sample, s.
        kind: "cubic" or "linear".

    Returns:
        t_out: (m,) sample instants, s, all within the input's time span.
        out: (m,) or (m, c) signal at those instants.
    """
    values = np.asarray(values, dtype=float)
    if values.ndim not in (1, 2) or values.shape[0] < 2:
        raise ValueError(f"signal must have shape (n,) or (n, c) with n >= 2, got {values.shape}")
    if not (fs_in > 0 and fs_out > 0 and np.isfinite(fs_in) and np.isfinite(fs_out)):
        raise ValueError(f"sampling rates must be positive, got fs_in={fs_in!r}, fs_out={fs_out!r}")
    if kind not in ("cubic", "linear"):
        raise ValueError(f"kind must be 'cubic' or 'linear', got {kind!r}")
    n_in = values.shape[0]
    t_out, step, position = _sampling_plan(n_in, fs_in, fs_out, t0)
    if step:
        return t_out, values[: (t_out.size - 1) * step + 1 : step].copy()
    if kind == "linear":
        grid = np.arange(n_in, dtype=float)
        if values.ndim == 1:
            return t_out, np.interp(position, grid, values)
        return t_out, np.column_stack([np.interp(position, grid, col) for col in values.T])
    if values.ndim == 1:
        return t_out, not_a_knot_cubic_rows(values[None, :], position)[0]
    return t_out, not_a_knot_cubic_rows(values.T, position).T


def _sampling_plan(n_in: int, fs_in: float, fs_out: float, t0: float
                   ) -> tuple[np.ndarray, int, np.ndarray | None]:
    """Output instants (m,) s of :func:`decimate_to`, and either the grid step of an exact pick
    (``fs_out`` divides ``fs_in``; position None) or 0 and the fractional input indices (m,)."""
    m = _output_count(n_in, fs_in, fs_out)
    t_out = t0 + np.arange(m) / fs_out
    ratio = fs_in / fs_out
    step = round(ratio)
    if step >= 1 and abs(ratio - step) <= 1e-12 * ratio:
        return t_out, step, None
    position = np.arange(m) * ratio  # fractional index into the input grid
    return t_out, 0, np.minimum(position, n_in - 1)


def _validate_triaxial(values, name: str) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    if values.ndim != 2 or values.shape[1] != 3 or values.shape[0] < 2:
        raise ValueError(f"{name} must have shape (n, 3) with n >= 2, got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} contains NaN or inf")
    return values


def _validate_fs(fs_sim: float) -> None:
    if not (np.isfinite(fs_sim) and fs_sim > 0):
        raise ValueError(f"fs_sim must be a positive sampling rate in Hz, got {fs_sim!r}")


def _sensor_filter(spec, fs_sim: float) -> np.ndarray:
    """Second-order sections of the sensor's response designed at ``fs_sim``: the Butterworth
    low-pass (half-power at ``spec.bandwidth_hz``), plus the AC-coupling high-pass if the spec has
    a nonzero ``highpass_hz``. A fresh copy of the cached design (:func:`_filter_design`)."""
    return _filter_design(spec, float(fs_sim))[0].copy()


@functools.lru_cache(maxsize=64)
def _filter_design(spec, fs_sim: float) -> tuple[np.ndarray, np.ndarray]:
    """(sos (s, 6), zi (s, 2)) of the sensor's response at ``fs_sim``: designed once per
    (spec, rate), since specs are frozen (hashable) dataclasses; ``zi`` is ``sosfilt_zi`` (the
    steady state for a unit input). Read-only arrays shared by every caller."""
    nyquist = fs_sim / 2.0
    if spec.bandwidth_hz >= 0.9 * nyquist:
        raise ValueError(
            f"{type(spec).__name__}: bandwidth {spec.bandwidth_hz} Hz needs a simulation rate "
            f"above {spec.bandwidth_hz / 0.45:.0f} Hz, got fs_sim={fs_sim} Hz"
        )
    order = int(spec.filter_order)
    sections = [signal.butter(order, spec.bandwidth_hz, btype="low", fs=fs_sim, output="sos")]
    highpass_hz = getattr(spec, "highpass_hz", 0.0)
    if highpass_hz > 0:
        sections.append(signal.butter(1, highpass_hz, btype="high", fs=fs_sim, output="sos"))
    sos = np.vstack(sections)
    zi = signal.sosfilt_zi(sos)
    sos.flags.writeable = False
    zi.flags.writeable = False
    return sos, zi


#: Upper bound on the float64 working array of one block of runs in :func:`_instrument_chains`
#: (samples × columns × 8 bytes); a block's transient memory is a few times this.
_BLOCK_BYTES = 4 * 2**20


def _noise_rate(spec, fs_sim: float) -> float:
    """Rate at which the instrument's noise is drawn and filtered, Hz: its output rate
    ``spec.fs_hz`` when it decimates (``fs_hz < fs_sim``) and its response can be designed there
    (``bandwidth_hz < 0.45·fs_hz``), else ``fs_sim``. Noise drawn at the output rate has the same
    in-band density ``noise_density·|H(f)|`` and needs no resampling (the IMU channels of Phase II);
    what it lacks is the small share of noise above ``fs_hz/2`` that would alias into the band."""
    fs_out = float(spec.fs_hz)
    if fs_out < fs_sim and spec.bandwidth_hz < 0.45 * fs_out:
        return fs_out
    return float(fs_sim)


def _sosfilt_rows(sos: np.ndarray, rows: np.ndarray, zi: np.ndarray) -> None:
    """``scipy.signal.sosfilt`` of each row of ``rows`` (r, n) float64 C-contiguous, in place,
    from the states ``zi`` (r, s, 2) (s sections of ``sos`` (s, 6)). Scipy's own routine without
    the copy ``sosfilt`` makes of its input (the same arithmetic: bit for bit its output)."""
    if _sosfilt is None:  # a scipy without the private routine
        rows[...] = signal.sosfilt(sos, rows, axis=-1, zi=np.moveaxis(zi, 1, 0))[0]
        return
    _sosfilt(np.array(sos, dtype=float, order="C"), rows, np.ascontiguousarray(zi, dtype=float))


def _instrument_chain(true_values: np.ndarray, fs_sim: float, spec, rng: np.random.Generator,
                      t0: float) -> tuple[np.ndarray, np.ndarray]:
    """The chain shared by all triaxial instruments, before their output quantisation.

    1. error model on the true signal (bias, scale, misalignment);
    2. the sensor's causal response (``sosfilt``, Butterworth low-pass of ``spec.filter_order``
       with half-power at ``spec.bandwidth_hz``, plus the high-pass when the spec has one) on that
       signal at ``fs_sim``, started in the steady state of its first value, so a constant input
       gives a constant output from the first sample;
    3. sampling at ``t0 + k / spec.fs_hz`` (:func:`decimate_to`: an exact pick when ``fs_hz``
       divides ``fs_sim``, else the not-a-knot cubic spline);
    4. white noise of one-sided density ``spec.noise_density``, drawn at the rate of
       :func:`_noise_rate` (std ``noise_density·sqrt(rate / 2)`` per sample), run through the same
       response designed at that rate (a warm-up of ``10 / bandwidth_hz`` seconds discarded, so it
       is stationary from the first sample) and added; at ``fs_sim`` the noise is added before the
       response and sampled with the signal (the instrument's aliasing of it included).

    The response is linear, so filtering signal and noise apart equals filtering their sum; the
    filter's group delay (:func:`sensor_group_delay`) is left in, as in the real sensor. In band
    the output noise density is ``noise_density·|H(f)|`` either way.

    Returns:
        t_out: (m,) sample instants, s.
        samples: (m, 3) filtered, noisy signal at those instants, unit of the input.
    """
    t_out, out = _instrument_chains([true_values], fs_sim, spec, [rng], t0)
    return t_out, out[0]


def _sample_rows(rows: np.ndarray, fs_sim: float, fs_out: float, t0: float) -> np.ndarray:
    """Rows (c, n) of a signal at ``fs_sim`` read at the instants of :func:`decimate_to`:
    (c, m), by an exact pick or the cubic spline (:func:`analysis.resample.not_a_knot_cubic_rows`)."""
    t_out, step, position = _sampling_plan(rows.shape[1], fs_sim, fs_out, t0)
    if step:
        return rows[:, : (t_out.size - 1) * step + 1: step]
    return not_a_knot_cubic_rows(rows, position)


def _instrument_chains(true_values: list[np.ndarray], fs_sim: float, spec,
                       rngs: list[np.random.Generator], t0: float, finish=None, dtype=None
                       ) -> tuple[np.ndarray, list[np.ndarray]]:
    """:func:`_instrument_chain` for several recordings of one instrument at once.

    Recording j is ``true_values[j]`` (n, 3) measured with noise drawn from ``rngs[j]`` (the
    same array object may appear several times: the runs of a Phase II session share their
    motion; its error model, response and sampling are then computed once). Noise is processed in
    blocks of recordings: one filter design (cached per spec and rate) and one ``sosfilt`` per
    block. Each recording's noise is drawn from its own generator in list order, one
    ``(n_warm + n_noise, 3)`` block per recording, so the draws and every output array are bit
    for bit those of one :func:`_instrument_chain` call per recording in the same order
    (``sosfilt``, the banded solve and the spline evaluation act on each row alone; checked by
    tests/test_sensors.py). ``finish``, if given, is an elementwise map (the output
    quantisation) applied to a block's samples as soon as they are filtered, and ``dtype`` the
    type each recording's samples are then cast to, so that only one block's float64 samples
    are held at a time.

    Returns:
        t_out: (m,) sample instants, s.
        samples: list of (m, 3) arrays, one per recording, unit of the input (or what
        ``finish`` and ``dtype`` make of them).
    """
    if len(true_values) != len(rngs):
        raise ValueError(f"{len(true_values)} recordings but {len(rngs)} generators")
    sos, zi_unit = _filter_design(spec, float(fs_sim))
    n = true_values[0].shape[0]
    if any(v.shape != (n, 3) for v in true_values):
        raise ValueError("recordings of one call must share their shape (n, 3)")
    t_out = _sampling_plan(n, fs_sim, spec.fs_hz, t0)[0]
    fs_noise = _noise_rate(spec, fs_sim)
    separate = fs_noise != fs_sim
    if separate:
        n_noise = t_out.size
        sos_noise = _filter_design(spec, fs_noise)[0]
    else:
        n_noise = n
        sos_noise = sos
    n_warm = int(math.ceil(10.0 / spec.bandwidth_hz * fs_noise))
    noise_std = spec.noise_density * math.sqrt(fs_noise / 2.0)
    # Deterministic part (the signal with its sensor errors), once per distinct true signal: at
    # fs_sim with a warm-up at its first value when the noise joins it before the response, else
    # already filtered and sampled.
    prepared: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for v in true_values:
        if id(v) not in prepared:
            det = spec.error.apply(v)
            zi = zi_unit[:, None, :] * det[0][None, :, None]
            if separate:
                filtered, _ = signal.sosfilt(sos.copy(), np.ascontiguousarray(det.T), axis=-1, zi=zi)
                prepared[id(v)] = (_sample_rows(filtered, fs_sim, spec.fs_hz, t0), zi)
            else:
                driven = np.concatenate([np.broadcast_to(det[0], (n_warm, 3)), det])
                prepared[id(v)] = (driven.T, zi)
    per_block = max(1, _BLOCK_BYTES // ((n_warm + n_noise) * 3 * 8))
    outputs = []
    noise = np.empty((n_warm + n_noise, 3))  # reused: standard_normal(out=) fills it as a new one
    for start in range(0, len(rngs), per_block):
        block = range(start, min(start + per_block, len(rngs)))
        # One row per channel (3 per recording): the layout sosfilt and the spline work in.
        driven = np.empty((3 * len(block), n_warm + n_noise))
        zi = np.zeros((3 * len(block), sos_noise.shape[0], 2))
        for j, i in enumerate(block):
            rngs[i].standard_normal(out=noise)
            if separate:
                np.multiply(noise.T, noise_std, out=driven[3 * j:3 * j + 3])
            else:
                noise *= noise_std
                det, zi_det = prepared[id(true_values[i])]
                zi[3 * j:3 * j + 3] = np.moveaxis(zi_det, 1, 0)
                np.add(det, noise.T, out=driven[3 * j:3 * j + 3])
        _sosfilt_rows(sos_noise, driven, zi)
        samples = driven[:, n_warm:]
        if separate:
            for j, i in enumerate(block):
                samples[3 * j:3 * j + 3] += prepared[id(true_values[i])][0]
        else:
            samples = _sample_rows(samples, fs_sim, spec.fs_hz, t0)
        del driven
        if finish is not None:
            samples = finish(samples)
        for j in range(len(block)):
            rows = samples[3 * j:3 * j + 3].T
            outputs.append(rows if dtype is None else rows.astype(dtype))
    return t_out, outputs


# --------------------------------------------------------------------------------------------
# Instruments
# --------------------------------------------------------------------------------------------


def measure_imu_accelerometer(specific_force: np.ndarray, fs_sim: float,
                              spec: AnalogAccelerometerSpec, rng: np.random.Generator,
                              t0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Samples of the IMU's analog triaxial accelerometer as the DAQ records them.

    Chain: error model, white noise at ``spec.noise_density`` (7 µg/√Hz), causal Butterworth
    low-pass with half-power at ``spec.bandwidth_hz`` (300 Hz) and its uncompensated group delay
    (:func:`sensor_group_delay`, 0.75 ms for the defaults), sampling at ``spec.fs_hz`` (about
    1613 Hz, not a divisor of fs_sim; cubic interpolation of the filtered signal, error below
    3e-4 at 300 Hz for fs_sim >= 5 kHz), then the DAQ: voltage = sensitivity·a, clipped to
    ±daq_range, quantised to daq_bits, converted back to m/s² with the nominal sensitivity.
    [S: paper, section III for the figures.]

    Args:
        specific_force: (n, 3) true specific force (acceleration minus gravity, see
            :func:`specific_force_in_sensor_frame`) in the sensor frame at fs_sim, m/s².
        fs_sim: simulation sampling rate, Hz (must exceed bandwidth_hz / 0.45).
        spec: accelerometer and DAQ figures.
        rng: the caller's generator (derived from the scenario seed); the only source of noise.
        t0: time of the first simulated sample, s.

    Returns:
        t: (m,) sample instants ``t0 + k / spec.fs_hz``, s.
        samples: (m, 3) measured specific force, m/s².
    """
    specific_force = _validate_triaxial(specific_force, "specific_force")
    _validate_fs(fs_sim)
    t_out, samples = _instrument_chain(specific_force, fs_sim, spec, rng, t0)
    return t_out, _daq_quantise(samples, spec.sensitivity, spec.daq_range, spec.daq_bits)


def measure_gyroscope(angular_velocity: np.ndarray, fs_sim: float, spec: DigitalGyroSpec,
                      rng: np.random.Generator, t0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Samples of the IMU's digital triaxial rate gyroscope.

    Chain: error model, white noise at ``spec.noise_density`` (35 (µrad/s)/√Hz), causal
    Butterworth low-pass with half-power at ``spec.bandwidth_hz`` (200 Hz; group delay 1.13 ms
    for the defaults, uncompensated), sampling at ``spec.fs_hz`` (about 1000 Hz; cubic), then
    rounding to ``spec.lsb`` and clipping at ``spec.full_scale`` when set.
    [S: paper, section III for the figures.]

    Args:
        angular_velocity: (n, 3) true angular velocity in the sensor frame at fs_sim, rad/s.
        fs_sim: simulation sampling rate, Hz.
        spec: gyroscope figures.
        rng: the caller's generator; the only source of noise.
        t0: time of the first simulated sample, s.

    Returns:
        t: (m,) sample instants, s.
        samples: (m, 3) measured angular velocity, rad/s.
    """
    angular_velocity = _validate_triaxial(angular_velocity, "angular_velocity")
    _validate_fs(fs_sim)
    t_out, samples = _instrument_chain(angular_velocity, fs_sim, spec, rng, t0)
    return t_out, quantise(samples, spec.lsb, spec.full_scale)


def measure_nut_accelerometer(acceleration: np.ndarray, fs_sim: float, spec: NutAccelerometerSpec,
                              rng: np.random.Generator, t0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Samples of a triaxial IEPE accelerometer on the ball nut, as the 10 kHz DAQ records them.

    Chain: error model (cross-axis sensitivity in ``misalignment``), white noise at
    ``spec.noise_density``, the AC-coupling high-pass (``spec.highpass_hz``; removes gravity and
    DC), the anti-alias Butterworth low-pass (``spec.bandwidth_hz``, 4 kHz), sampling at
    ``spec.fs_hz`` (exact pick when fs_sim equals or is a multiple of it), then DAQ clipping and
    quantisation as for :func:`measure_imu_accelerometer`.
    [S: paper, section III: 100 mV/g, 10 kHz; the rest see :class:`NutAccelerometerSpec`.]

    Args:
        acceleration: (n, 3) true specific force (or acceleration: the high-pass removes the
            difference) at the nut in the sensor frame at fs_sim, m/s².
        fs_sim: simulation rate, Hz; must exceed bandwidth_hz / 0.45 (about 8.9 kHz for the
            defaults), so Phase II's 5 kHz simulations cannot feed this channel.
        spec: accelerometer and DAQ figures.
        rng: the caller's generator; the only source of noise.
        t0: time of the first simulated sample, s.

    Returns:
        t: (m,) sample instants, s.
        samples: (m, 3) measured acceleration, m/s².
    """
    acceleration = _validate_triaxial(acceleration, "acceleration")
    _validate_fs(fs_sim)
    t_out, samples = _instrument_chain(acceleration, fs_sim, spec, rng, t0)
    return t_out, _daq_quantise(samples, spec.sensitivity, spec.daq_range, spec.daq_bits)


def _validated_recordings(true_values, rngs, name: str) -> list[np.ndarray]:
    """Validate each distinct array of ``true_values`` once (the runs of a session pass the same
    object) and return the list of validated arrays, same objects for the same inputs."""
    true_values, rngs = list(true_values), list(rngs)
    if len(true_values) != len(rngs) or not rngs:
        raise ValueError(f"{name}: need one generator per recording and at least one, got "
                         f"{len(true_values)} recordings and {len(rngs)} generators")
    seen: dict[int, np.ndarray] = {}
    out = []
    for v in true_values:
        if id(v) not in seen:
            seen[id(v)] = _validate_triaxial(v, name)
        out.append(seen[id(v)])
    return out


def measure_imu_accelerometer_runs(specific_force, fs_sim: float, spec: AnalogAccelerometerSpec,
                                   rngs, t0: float = 0.0, dtype=None
                                   ) -> tuple[np.ndarray, list[np.ndarray]]:
    """:func:`measure_imu_accelerometer` of several recordings at once: ``specific_force`` is a
    sequence of (n, 3) arrays (the same object repeated for runs that share their motion: its
    error model, response and sampling are computed once), ``rngs`` one generator per recording.
    Returns ``(t, [samples (m, 3), ...])``, each array bit for bit what
    :func:`measure_imu_accelerometer` returns for that recording and generator, cast to
    ``dtype`` if given (block by block: a session's runs are never all held in float64)."""
    values = _validated_recordings(specific_force, rngs, "specific_force")
    _validate_fs(fs_sim)
    return _instrument_chains(values, fs_sim, spec, list(rngs), t0, lambda o: _daq_quantise(
        o, spec.sensitivity, spec.daq_range, spec.daq_bits), dtype)


def measure_gyroscope_runs(angular_velocity, fs_sim: float, spec: DigitalGyroSpec, rngs,
                           t0: float = 0.0, dtype=None) -> tuple[np.ndarray, list[np.ndarray]]:
    """:func:`measure_gyroscope` of several recordings at once (as
    :func:`measure_imu_accelerometer_runs`; bit for bit the single-recording outputs)."""
    values = _validated_recordings(angular_velocity, rngs, "angular_velocity")
    _validate_fs(fs_sim)
    return _instrument_chains(values, fs_sim, spec, list(rngs), t0,
                              lambda o: quantise(o, spec.lsb, spec.full_scale), dtype)


def measure_nut_accelerometer_runs(acceleration, fs_sim: float, spec: NutAccelerometerSpec, rngs,
                                   t0: float = 0.0, dtype=None
                                   ) -> tuple[np.ndarray, list[np.ndarray]]:
    """:func:`measure_nut_accelerometer` of several recordings at once (as
    :func:`measure_imu_accelerometer_runs`; bit for bit the single-recording outputs). Phase I
    measures its two nut accelerometers with one call and the capture's generator twice."""
    values = _validated_recordings(acceleration, rngs, "acceleration")
    _validate_fs(fs_sim)
    return _instrument_chains(values, fs_sim, spec, list(rngs), t0, lambda o: _daq_quantise(
        o, spec.sensitivity, spec.daq_range, spec.daq_bits), dtype)


# --------------------------------------------------------------------------------------------
# Controller signals
# --------------------------------------------------------------------------------------------


def _validate_scalar_signal(values, name: str) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    if values.ndim != 1 or values.shape[0] < 2:
        raise ValueError(f"{name} must have shape (n,) with n >= 2, got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{name} contains NaN or inf")
    return values


def measure_speed(motor_angle: np.ndarray, fs_sim: float, encoder_counts_per_rev: int,
                  fs_hz: float, rng: np.random.Generator, average_samples: int = 1,
                  t0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Motor speed as a servo drive computes it from its encoder.

    At each controller instant ``t_k = t0 + k / fs_hz`` the drive latches the encoder counter
    ``c_k = floor(θ(t_k)·cpr / 2π + φ)`` (θ read off the simulation grid: exact when fs_hz divides
    fs_sim, else linearly interpolated, which errs by at most ``θ''·h²/8`` for a grid step h; φ is
    a random count phase in [0, 1) drawn from ``rng``: where the count edges fall relative to the
    simulated zero is arbitrary). The speed is the backward difference over
    ``average_samples`` = M periods, ``ω_k = (c_k - c_{k-M})·(2π / cpr)·fs_hz / M``, which is the
    moving average of M one-period differences. Its resolution is ``2π·fs_hz / (cpr·M)`` rad/s
    (e.g. 0.48 rad/s for a 17-bit encoder at 10 kHz, M = 1) and it lags the true speed by
    ``M / (2·fs_hz)`` s. Before the record starts the motor is taken to turn at its initial speed
    (linear extrapolation), so the first M outputs are defined. The paper does not state the drive
    or encoder; typical servo encoders have 2**17 to 2**23 counts/rev.

    Args:
        motor_angle: (n,) true, unwrapped motor angle at fs_sim, rad.
        fs_sim: simulation rate, Hz.
        encoder_counts_per_rev: counts per motor revolution after quadrature/interpolation.
        fs_hz: controller sampling rate, Hz (10 kHz in the paper).
        rng: the caller's generator (draws one number: the count phase).
        average_samples: M, the number of controller periods of the difference (>= 1).
        t0: time of the first simulated sample, s.

    Returns:
        t: (m,) controller instants, s.
        speed: (m,) measured motor speed, rad/s.
    """
    angle = _validate_scalar_signal(motor_angle, "motor_angle")
    _validate_fs(fs_sim)
    if int(encoder_counts_per_rev) != encoder_counts_per_rev or encoder_counts_per_rev < 1:
        raise ValueError(
            f"encoder_counts_per_rev must be a positive integer, got {encoder_counts_per_rev!r}"
        )
    if int(average_samples) != average_samples or average_samples < 1:
        raise ValueError(f"average_samples must be a positive integer, got {average_samples!r}")
    m_avg = int(average_samples)
    t_out, angle_k = decimate_to(angle, fs_sim, fs_hz, t0=t0, kind="linear")
    initial_speed = (angle[1] - angle[0]) * fs_sim
    history = angle[0] - initial_speed * np.arange(m_avg, 0, -1) / fs_hz
    counts_per_rad = encoder_counts_per_rev / (2.0 * math.pi)
    phase = rng.uniform(0.0, 1.0)
    counts = np.floor(np.concatenate([history, angle_k]) * counts_per_rad + phase)
    speed = (counts[m_avg:] - counts[:-m_avg]) * fs_hz / (m_avg * counts_per_rad)
    return t_out, speed


def measure_torque(torque: np.ndarray, fs_sim: float, noise_Nm: float, resolution_Nm: float,
                   fs_hz: float, rng: np.random.Generator, t0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Motor torque as the drive reports it (torque constant × measured current).

    The true torque is read at the controller instants (linear interpolation; exact when fs_hz
    equals fs_sim), white Gaussian current-sensor noise of ``noise_Nm`` rms per sample is added,
    and the result is rounded to ``resolution_Nm`` (the current ADC's LSB times the torque
    constant). No current-loop dynamics are modelled. The paper gives no figures; as an example,
    a 12-bit current ADC spanning ±3 × a 1.3 N·m rated torque gives a resolution of about
    2 mN·m, with noise of a few LSB.

    Args:
        torque: (n,) true motor torque at fs_sim, N·m.
        fs_sim: simulation rate, Hz.
        noise_Nm: noise standard deviation per output sample, N·m (0 = none).
        resolution_Nm: output step, N·m (0 = no rounding).
        fs_hz: controller sampling rate, Hz.
        rng: the caller's generator; the only source of noise.
        t0: time of the first simulated sample, s.

    Returns:
        t: (m,) controller instants, s.
        torque: (m,) measured torque, N·m.
    """
    torque = _validate_scalar_signal(torque, "torque")
    _validate_fs(fs_sim)
    if not (noise_Nm >= 0 and resolution_Nm >= 0):
        raise ValueError(
            f"noise_Nm and resolution_Nm must be >= 0, got {noise_Nm!r}, {resolution_Nm!r}"
        )
    t_out, sampled = decimate_to(torque, fs_sim, fs_hz, t0=t0, kind="linear")
    noisy = sampled + rng.standard_normal(sampled.shape[0]) * noise_Nm
    return t_out, quantise(noisy, resolution_Nm)
