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

The measurement models of the triaxial instruments are here; the pieces they are built from live
beside them in :mod:`twin.sim.sensors`: :mod:`~twin.sim.sensors.errors` (the error model),
:mod:`~twin.sim.sensors.specs` (the instruments' figures and the "g" constants),
:mod:`~twin.sim.sensors.sampling` (resampling and quantisation), :mod:`~twin.sim.sensors.chain`
(the sensor's response and noise), and :mod:`~twin.sim.sensors.controller` (motor speed and
torque). Every public name of those modules is importable from this one (``__all__``).
"""

from __future__ import annotations

import numpy as np

from twin.sim.sensors.chain import (
    _instrument_chain,
    _instrument_chains,
    _validate_fs,
    _validate_triaxial,
    butterworth_group_delay,
    sensor_group_delay,
    specific_force_in_sensor_frame,
)
from twin.sim.sensors.controller import measure_speed, measure_torque
from twin.sim.sensors.errors import ErrorModel
from twin.sim.sensors.sampling import _daq_quantise, decimate_to, quantise
from twin.sim.sensors.specs import (
    MICRO_G,
    MV_PER_G,
    STANDARD_GRAVITY,
    AnalogAccelerometerSpec,
    DigitalGyroSpec,
    NutAccelerometerSpec,
)

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
