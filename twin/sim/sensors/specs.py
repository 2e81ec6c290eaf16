"""The instruments' specifications, the paper's figures as defaults: the IMU's analog accelerometer
and digital gyroscope, the ball-nut IEPE accelerometers and the DAQ channels that sample them; and
the constants that turn datasheet "g" figures into SI (m/s²).

Spec sources are tagged as in :mod:`twin.sim.sensors.instruments`: [S] stated in the source
(the paper, section III), [M] a model assumption, with the reason given where it is defined.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from twin.sim.sensors.errors import ErrorModel

#: Standard gravity g0 in m/s² (ISO 80000-3), used to convert datasheet "g" figures to SI.
STANDARD_GRAVITY = 9.80665
#: One µg in m/s²; a density of ``7 * MICRO_G`` is 7 µg/√Hz in (m/s²)/√Hz.
MICRO_G = 1e-6 * STANDARD_GRAVITY
#: One mV/g in V/(m/s²); a sensitivity of ``100 * MV_PER_G`` is 100 mV/g.
MV_PER_G = 1e-3 / STANDARD_GRAVITY


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
