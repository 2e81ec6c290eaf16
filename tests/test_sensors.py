"""Tests of the instrument measurement models (twin/sim/sensors/).

Check 7 of the project's issue: at standstill the IMU's noise densities, sampling rates and the
sensing of gravity tilt match the paper's section III figures.
"""

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from twin.sim.sensors import chain, instruments
from twin.sim.sensors.instruments import (
    MICRO_G,
    MV_PER_G,
    STANDARD_GRAVITY,
    AnalogAccelerometerSpec,
    DigitalGyroSpec,
    ErrorModel,
    NutAccelerometerSpec,
    butterworth_group_delay,
    decimate_to,
    measure_gyroscope,
    measure_gyroscope_runs,
    measure_imu_accelerometer,
    measure_imu_accelerometer_runs,
    measure_nut_accelerometer,
    measure_nut_accelerometer_runs,
    measure_speed,
    measure_torque,
    sensor_group_delay,
    specific_force_in_sensor_frame,
)

FS_SIM = 10_000.0  # Phase I simulation rate, Hz
G = STANDARD_GRAVITY


def _rot_y(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _level_at_rest(n, pitch=0.0):
    """(n, 3) specific force of a sensor at rest, pitched by ``pitch`` rad about +y."""
    return np.tile(specific_force_in_sensor_frame(np.zeros(3), _rot_y(pitch)), (n, 1))


def _band_density(samples, fs, f_lo=1.0, f_hi=100.0):
    """Amplitude noise density per axis, averaged as power over [f_lo, f_hi] (Welch)."""
    freq, psd = signal.welch(samples, fs=fs, nperseg=4096, axis=0)
    band = (freq >= f_lo) & (freq <= f_hi)
    return np.sqrt(psd[band].mean(axis=0))


def _sine_amplitude(t, y, freq):
    """Least-squares amplitude of a sinusoid of known frequency (with offset) in y(t)."""
    phase = 2 * np.pi * freq * t
    basis = np.column_stack([np.sin(phase), np.cos(phase), np.ones_like(t)])
    coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
    return float(np.hypot(coef[0], coef[1]))


# ---------------------------------------------------------------------------------------------
# Check 7: IMU at standstill
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module", params=[FS_SIM, 5_000.0], ids=["phase1-10kHz", "phase2-5kHz"])
def imu_standstill(request):
    """60 s at standstill, level sensor, default (paper) specs, at both simulation rates."""
    fs_sim = request.param
    n = int(60 * fs_sim)
    rng = np.random.default_rng(2024)
    force = _level_at_rest(n)
    t_acc, acc = measure_imu_accelerometer(force, fs_sim, AnalogAccelerometerSpec(), rng)
    t_gyr, gyr = measure_gyroscope(np.zeros((n, 3)), fs_sim, DigitalGyroSpec(), rng)
    return t_acc, acc, t_gyr, gyr


@pytest.mark.quoted
def test_check7_accelerometer_noise_density_and_rate(imu_standstill, quote):
    """Check 7: the IMU accelerometer at rest, 60 s at 1613 Hz: its 1–100 Hz density within 10 %
    of 7 µg/√Hz on every axis, gravity on z."""
    t_acc, acc, _, _ = imu_standstill
    rate = 1.0 / np.mean(np.diff(t_acc))
    density_ug = _band_density(acc, rate) / MICRO_G
    print(f"\nIMU accelerometer: rate {rate:.3f} Hz, 1-100 Hz density x/y/z (µg/√Hz) = "
          f"{np.round(density_ug, 3)}")
    assert rate == pytest.approx(1613.0, rel=1e-9)
    assert np.allclose(np.diff(t_acc), 1.0 / 1613.0)
    assert t_acc[-1] <= 60.0
    assert acc.shape == (t_acc.size, 3) and t_acc.size == pytest.approx(60 * 1613, abs=2)
    assert np.all(np.abs(density_ug / 7.0 - 1.0) < 0.10)
    quote("imu_acc_density_ug_per_rthz", float(np.mean(density_ug)), f"{np.mean(density_ug):.1f} µg/√Hz")
    assert np.mean(acc[:, 2]) == pytest.approx(G, rel=1e-5)  # +1 g up, level and at rest


@pytest.mark.quoted
def test_check7_gyroscope_noise_density_and_rate(imu_standstill, quote):
    """Check 7: the IMU gyroscope at rest, 60 s at 1000 Hz: its 1–100 Hz density within 10 % of
    35 µrad/s/√Hz on every axis."""
    _, _, t_gyr, gyr = imu_standstill
    rate = 1.0 / np.mean(np.diff(t_gyr))
    density_urad = _band_density(gyr, rate) / 1e-6
    print(f"\nIMU gyroscope: rate {rate:.3f} Hz, 1-100 Hz density x/y/z (µrad/s/√Hz) = "
          f"{np.round(density_urad, 3)}")
    assert rate == pytest.approx(1000.0, rel=1e-9)
    assert t_gyr.size == 60_000  # instants k/1000 s within the 60 s record
    assert np.all(np.abs(density_urad / 35.0 - 1.0) < 0.10)
    quote("imu_gyro_density_urad_s_per_rthz", float(np.mean(density_urad)),
          f"{np.mean(density_urad):.1f} µrad/s/√Hz")


def test_check7_gravity_tilt_is_sensed():
    pitch = 1e-3
    n = int(20 * FS_SIM)
    force = _level_at_rest(n, pitch)
    rng = np.random.default_rng(7)
    _, acc = measure_imu_accelerometer(force, FS_SIM, AnalogAccelerometerSpec(), rng)
    expected = -G * math.sin(pitch)  # right-hand rotation about +y tilts gravity into -x
    print(f"\n1 mrad pitch: mean x = {np.mean(acc[:, 0]) / MICRO_G:.2f} µg, "
          f"expected {expected / MICRO_G:.2f} µg")
    assert np.mean(acc[:, 0]) == pytest.approx(expected, rel=0.01)
    assert np.mean(acc[:, 2]) == pytest.approx(G * math.cos(pitch), rel=1e-5)


def test_specific_force_convention():
    # At rest, level: +g on z. Free fall: nothing. Accelerating +x at 1 m/s²: +1 on x.
    eye = np.eye(3)
    assert np.allclose(specific_force_in_sensor_frame([0, 0, 0], eye), [0, 0, G])
    assert np.allclose(specific_force_in_sensor_frame([0, 0, -G], eye), [0, 0, 0])
    moving = specific_force_in_sensor_frame([[1.0, 0, 0]] * 2, np.stack([eye, eye]))
    assert np.allclose(moving, [[1, 0, G]] * 2)


# ---------------------------------------------------------------------------------------------
# Sensor response
# ---------------------------------------------------------------------------------------------


HALF_POWER = 1 / math.sqrt(2)
QUIET_ACC = AnalogAccelerometerSpec(noise_density=0.0)
QUIET_GYRO = DigitalGyroSpec(noise_density=0.0)


@pytest.mark.parametrize(
    "measure, spec, freq, expected, tol",
    [
        (measure_imu_accelerometer, QUIET_ACC, 300.0, HALF_POWER, 0.03),
        (measure_imu_accelerometer, QUIET_ACC, 20.0, 1.0, 0.01),
        (measure_gyroscope, QUIET_GYRO, 200.0, HALF_POWER, 0.03),
        (measure_gyroscope, QUIET_GYRO, 20.0, 1.0, 0.01),
    ],
)
@pytest.mark.parametrize("fs_sim", [FS_SIM, 5_000.0])
def test_lowpass_half_power_and_passband(measure, spec, freq, expected, tol, fs_sim):
    amplitude = 1.0
    t = np.arange(int(2 * fs_sim)) / fs_sim
    true = np.zeros((t.size, 3))
    true[:, 1] = amplitude * np.sin(2 * np.pi * freq * t)
    t_out, out = measure(true, fs_sim, spec, np.random.default_rng(0))
    settled = t_out > 0.2
    gain = _sine_amplitude(t_out[settled], out[settled, 1], freq) / amplitude
    assert gain == pytest.approx(expected, rel=tol)
    assert np.max(np.abs(out[:, [0, 2]])) < 1e-12  # no cross-talk with a zero error model


def test_no_startup_transient_for_constant_input():
    force = _level_at_rest(5000, pitch=2e-3)
    spec = AnalogAccelerometerSpec(noise_density=0.0, daq_bits=0)
    _, acc = measure_imu_accelerometer(force, FS_SIM, spec, np.random.default_rng(0))
    assert np.allclose(acc, force[0], rtol=0, atol=1e-12)


def test_group_delay_is_left_in():
    spec = AnalogAccelerometerSpec(noise_density=0.0, daq_bits=0)
    freq = 10.0
    t = np.arange(int(2 * FS_SIM)) / FS_SIM
    true = np.zeros((t.size, 3))
    true[:, 0] = np.sin(2 * np.pi * freq * t)
    t_out, out = measure_imu_accelerometer(true, FS_SIM, spec, np.random.default_rng(0))
    settled = t_out > 0.2
    phase = 2 * np.pi * freq * t_out[settled]
    basis = np.column_stack([np.sin(phase), np.cos(phase)])
    (c_sin, c_cos), *_ = np.linalg.lstsq(basis, out[settled, 0], rcond=None)
    delay = -math.atan2(c_cos, c_sin) / (2 * np.pi * freq)
    assert delay == pytest.approx(sensor_group_delay(spec, FS_SIM), rel=0.02)
    assert delay == pytest.approx(butterworth_group_delay(2, 300.0), rel=0.02)  # 0.75 ms


# ---------------------------------------------------------------------------------------------
# Error model
# ---------------------------------------------------------------------------------------------


def test_error_model_hand_example():
    model = ErrorModel(
        bias=[0.1, -0.2, 0.3],
        scale_error=[0.01, 0.0, -0.02],
        misalignment=[[5.0, 0.001, 0.0], [0.0, 7.0, -0.002], [0.003, 0.0, 9.0]],  # diagonal ignored
    )
    s = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 10.0]])
    expected = np.array(
        [
            [
                1.01 * 1.0 + 0.001 * 2.0 + 0.1,
                2.0 - 0.002 * 3.0 - 0.2,
                0.003 * 1.0 + 0.98 * 3.0 + 0.3,
            ],
            [0.0 + 0.1, -0.002 * 10.0 - 0.2, 0.98 * 10.0 + 0.3],
        ]
    )
    assert np.allclose(model.apply(s), expected, rtol=0, atol=1e-15)
    assert np.array_equal(ErrorModel().apply(s), s)
    assert hash(model) == hash(ErrorModel(model.bias, model.scale_error, model.misalignment))


def test_error_model_rejects_bad_shapes():
    with pytest.raises(ValueError, match="bias"):
        ErrorModel(bias=[1.0, 2.0])
    with pytest.raises(ValueError, match="misalignment"):
        ErrorModel(misalignment=np.eye(2))


def test_bias_reaches_the_output():
    spec = AnalogAccelerometerSpec(noise_density=0.0, error=ErrorModel(bias=[1e-3, 0.0, 0.0]))
    _, acc = measure_imu_accelerometer(np.zeros((2000, 3)), FS_SIM, spec, np.random.default_rng(0))
    lsb = 20.0 / 2**24 / spec.sensitivity  # 24-bit DAQ over ±10 V at 2000 mV/g: 0.6 µg
    assert np.allclose(acc[:, 0], 1e-3, rtol=0, atol=lsb / 2)


# ---------------------------------------------------------------------------------------------
# Nut accelerometer and DAQ
# ---------------------------------------------------------------------------------------------


def test_nut_accelerometer_rate_noise_quantisation_and_ac_coupling():
    spec = NutAccelerometerSpec()
    n = int(10 * FS_SIM)
    t, acc = measure_nut_accelerometer(_level_at_rest(n), FS_SIM, spec, np.random.default_rng(3))
    assert t.size == n and np.allclose(np.diff(t), 1e-4)  # fs_sim == fs_hz: no resampling
    density_ug = _band_density(acc, 1e4, 10.0, 1000.0) / MICRO_G
    print(f"\nnut accelerometer: density 10-1000 Hz (µg/√Hz) x/y/z = {np.round(density_ug, 3)}")
    assert np.all(np.abs(density_ug / 20.0 - 1.0) < 0.10)
    assert abs(np.mean(acc[:, 2])) < 1e-3 * G  # IEPE: gravity does not pass
    lsb = 20.0 / 2**24 / spec.sensitivity  # m/s² per DAQ code
    codes = acc / lsb
    assert np.allclose(codes, np.round(codes), atol=1e-6)


def test_daq_quantisation_and_clipping_16_bit():
    spec = NutAccelerometerSpec(noise_density=0.0, daq_bits=16, highpass_hz=0.0)
    n = 20_000
    t = np.arange(n) / FS_SIM
    true = np.zeros((n, 3))
    true[:, 0] = 0.37 * np.sin(2 * np.pi * 50 * t)
    true[:, 1] = 200.0 * G  # beyond ±100 g (±10 V at 100 mV/g): clips
    _, acc = measure_nut_accelerometer(true, FS_SIM, spec, np.random.default_rng(0))
    lsb = 20.0 / 2**16 / (100 * MV_PER_G)
    assert np.allclose(acc[:, 0] / lsb, np.round(acc[:, 0] / lsb), atol=1e-9)
    assert np.max(np.abs(acc[:, 0] - true[:, 0])) < 0.2  # 4th order at 4 kHz barely touches 50 Hz
    assert np.allclose(acc[:, 1], (2**15 - 1) * lsb)


def test_nut_accelerometer_needs_a_fast_enough_simulation():
    with pytest.raises(ValueError, match="simulation rate"):
        measure_nut_accelerometer(
            np.zeros((100, 3)), 5_000.0, NutAccelerometerSpec(), np.random.default_rng(0)
        )


def test_gyro_lsb_and_range():
    spec = DigitalGyroSpec(noise_density=0.0, lsb=1e-3, full_scale=0.5)
    true = np.tile([0.01234, -2.0, 0.0], (3000, 1))
    _, out = measure_gyroscope(true, FS_SIM, spec, np.random.default_rng(0))
    assert np.allclose(out, [0.012, -0.5, 0.0])


# ---------------------------------------------------------------------------------------------
# Controller signals
# ---------------------------------------------------------------------------------------------


def test_encoder_speed_mean_at_40_rev_per_s():
    speed = 251.3  # rad/s (40 rev/s: 400 mm/s with a 10 mm lead)
    t = np.arange(int(1 * FS_SIM)) / FS_SIM
    t_out, measured = measure_speed(speed * t, FS_SIM, 2**17, 10_000.0, np.random.default_rng(1))
    assert t_out.size == t.size
    assert np.mean(measured) == pytest.approx(speed, rel=1e-3)
    step = 2 * np.pi * 1e4 / 2**17  # speed resolution, rad/s
    assert np.all(np.abs(measured - speed) <= step + 1e-9)
    _, averaged = measure_speed(
        speed * t, FS_SIM, 2**17, 10_000.0, np.random.default_rng(1), average_samples=4
    )
    assert np.std(averaged) < np.std(measured)
    assert np.mean(averaged) == pytest.approx(speed, rel=1e-3)


def test_encoder_quantisation_visible_at_slow_speed():
    speed = 0.5  # rad/s with 4096 counts/rev at 10 kHz: 0.033 counts per period
    cpr = 4096
    t = np.arange(int(2 * FS_SIM)) / FS_SIM
    _, measured = measure_speed(speed * t, FS_SIM, cpr, 10_000.0, np.random.default_rng(1))
    step = 2 * np.pi * 1e4 / cpr
    assert set(np.unique(np.round(measured / step)).tolist()) == {0.0, 1.0}
    assert np.mean(measured) == pytest.approx(speed, rel=0.02)


def test_speed_at_a_different_controller_rate():
    speed = 100.0
    t = np.arange(int(1 * FS_SIM)) / FS_SIM
    t_out, measured = measure_speed(speed * t, FS_SIM, 2**20, 4_000.0, np.random.default_rng(2))
    assert np.allclose(np.diff(t_out), 1 / 4000.0)
    assert np.mean(measured) == pytest.approx(speed, rel=1e-3)


def test_torque_noise_and_resolution():
    true = np.full(200_000, 0.8)
    _, torque = measure_torque(true, FS_SIM, 0.01, 0.002, 10_000.0, np.random.default_rng(5))
    assert np.allclose(torque / 0.002, np.round(torque / 0.002))
    assert np.mean(torque) == pytest.approx(0.8, abs=2e-4)
    assert np.std(torque) == pytest.approx(math.hypot(0.01, 0.002 / math.sqrt(12)), rel=0.02)


# ---------------------------------------------------------------------------------------------
# Resampling helper
# ---------------------------------------------------------------------------------------------


def test_decimate_to_integer_ratio_is_exact_pick():
    x = np.random.default_rng(0).standard_normal((1001, 2))
    t, y = decimate_to(x, 10_000.0, 1_000.0, t0=1.5)
    assert np.array_equal(y, x[::10]) and np.allclose(t, 1.5 + np.arange(101) / 1000.0)
    t, y = decimate_to(x, 10_000.0, 10_000.0)
    assert np.array_equal(y, x) and t.size == 1001


@pytest.mark.parametrize("fs_in", [10_000.0, 5_000.0])
def test_decimate_to_non_integer_ratio_is_accurate(fs_in):
    freq = 300.0
    t_in = np.arange(int(fs_in)) / fs_in
    t, y = decimate_to(np.sin(2 * np.pi * freq * t_in), fs_in, 1613.0)
    interior = (t > 0.01) & (t < t_in[-1] - 0.01)  # away from the spline's end conditions
    assert np.max(np.abs(y[interior] - np.sin(2 * np.pi * freq * t[interior]))) < 5e-4
    assert t[-1] <= t_in[-1]


@pytest.mark.parametrize("n", [4, 5, 6, 16, 17, 40, 5001])
def test_cubic_resampling_is_the_not_a_knot_spline(n):
    """The O(n) spline of decimate_to is scipy's not-a-knot interpolant (make_interp_spline,
    k=3) to rounding, short records (the end rows of its tridiagonal solve) included."""
    from scipy import interpolate

    y = np.cumsum(np.random.default_rng(n).standard_normal((n, 3)), axis=0) + 9.8
    t, out = decimate_to(y, 5_000.0, 1613.0)
    ref = interpolate.make_interp_spline(np.arange(n, dtype=float), y, k=3, axis=0)(t * 5_000.0)
    assert np.max(np.abs(out - ref)) <= 1e-13 * np.max(np.abs(y))
    _, one = decimate_to(y[:, 1], 5_000.0, 1613.0)
    assert np.array_equal(one, out[:, 1])


def test_runs_are_bit_for_bit_the_single_recordings():
    """The *_runs functions (the runs of a session in blocks, one filter design, one error-model
    application) give each run exactly what one call per run gives, with the same generators in
    the same order (accelerometer, then gyroscope, per run)."""
    n = 4001
    rng = np.random.default_rng(5)
    force = _level_at_rest(n, 0.01) + 0.05 * rng.standard_normal((n, 3))
    rate = 0.01 * rng.standard_normal((n, 3))
    acc_spec = AnalogAccelerometerSpec(error=ErrorModel(bias=(1e-4, 0, 2e-4),
                                                       scale_error=(0.01, 0, -0.01)))
    gyro_spec = DigitalGyroSpec(fs_hz=1000.0, lsb=1e-6)
    single = []
    for r in range(5):
        g = np.random.default_rng([9, r])
        single.append((measure_imu_accelerometer(force, 5_000.0, acc_spec, g)[1],
                       measure_gyroscope(rate, 5_000.0, gyro_spec, g)[1]))
    gens = [np.random.default_rng([9, r]) for r in range(5)]
    old_block = chain._BLOCK_BYTES
    # The accelerometer's noise is drawn at its 1613 Hz: 1291 samples after a 54-sample warm-up;
    # two runs per block for it (blocks and a remainder), three for the gyroscope.
    chain._BLOCK_BYTES = 2 * (1291 + 54) * 3 * 8
    try:
        _, accs = measure_imu_accelerometer_runs([force] * 5, 5_000.0, acc_spec, gens)
        _, gyros = measure_gyroscope_runs([rate] * 5, 5_000.0, gyro_spec, gens)
    finally:
        chain._BLOCK_BYTES = old_block
    for (acc, gyro), a, g in zip(single, accs, gyros, strict=True):
        assert np.array_equal(acc, a) and np.array_equal(gyro, g)
    # Phase I: the two nut accelerometers from one generator in one call.
    nut1, nut2 = force, force[::-1].copy()
    g = np.random.default_rng(3)
    one = measure_nut_accelerometer(nut1, FS_SIM, NutAccelerometerSpec(), g)[1]
    two = measure_nut_accelerometer(nut2, FS_SIM, NutAccelerometerSpec(), g)[1]
    g = np.random.default_rng(3)
    _, both = measure_nut_accelerometer_runs([nut1, nut2], FS_SIM, NutAccelerometerSpec(), [g, g])
    assert np.array_equal(one, both[0]) and np.array_equal(two, both[1])
    with pytest.raises(ValueError, match="need one generator per recording"):
        measure_gyroscope_runs([rate] * 2, 5_000.0, gyro_spec, gens[:1])


@pytest.mark.parametrize("measure, spec, fs_sim, draws_at", [
    (measure_imu_accelerometer, AnalogAccelerometerSpec(), 5_000.0, 1613.0),
    (measure_gyroscope, DigitalGyroSpec(), 5_000.0, 1000.0),
    (measure_nut_accelerometer, NutAccelerometerSpec(), FS_SIM, FS_SIM),
])
def test_noise_spectrum_follows_the_sensor_response(measure, spec, fs_sim, draws_at):
    """The noise is drawn at the instrument's output rate where it decimates (the IMU: no
    resampling of noise), at the simulation rate otherwise (the nut accelerometers), and in both
    cases its density follows the sensor's response: flat at ``noise_density`` in band, 1/√2 of it
    at the half-power frequency (within 5 %)."""
    n = int(120 * fs_sim)
    rng = np.random.default_rng(21)
    t, out = measure(np.zeros((n, 3)), fs_sim, spec, rng)
    fs_out = 1.0 / np.mean(np.diff(t))
    warm = math.ceil(10.0 / spec.bandwidth_hz * draws_at)
    drawn = (warm + (t.size if draws_at != fs_sim else n)) * 3
    twin_rng = np.random.default_rng(21)
    twin_rng.standard_normal(drawn)
    assert rng.bit_generator.state == twin_rng.bit_generator.state  # exactly these draws
    freq, psd = signal.welch(out, fs=fs_out, nperseg=8192, axis=0)
    in_band = np.sqrt(psd[(freq >= 5.0) & (freq <= 50.0)].mean(axis=0)) / spec.noise_density
    edge = np.sqrt(psd[np.abs(freq - spec.bandwidth_hz) <= 5.0].mean(axis=0)) / spec.noise_density
    assert np.all(np.abs(in_band - 1.0) < 0.05), in_band
    assert np.all(np.abs(edge - 2 ** -0.5) < 0.05), edge


# ---------------------------------------------------------------------------------------------
# Determinism and purity
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "call",
    [
        lambda rng: measure_imu_accelerometer(
            _level_at_rest(3000), FS_SIM, AnalogAccelerometerSpec(), rng
        ),
        lambda rng: measure_gyroscope(np.zeros((3000, 3)), FS_SIM, DigitalGyroSpec(), rng),
        lambda rng: measure_nut_accelerometer(
            _level_at_rest(3000), FS_SIM, NutAccelerometerSpec(), rng
        ),
        lambda rng: measure_speed(np.linspace(0, 30, 3000), FS_SIM, 2**17, 1e4, rng),
        lambda rng: measure_torque(np.zeros(3000), FS_SIM, 0.01, 0.0, 1e4, rng),
    ],
)
def test_determinism(call):
    _, a = call(np.random.default_rng(11))
    _, b = call(np.random.default_rng(11))
    _, c = call(np.random.default_rng(12))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_module_is_pure_numpy_scipy():
    """The sensor models need no simulator: numpy, scipy, the analysis package's resampler and the
    modules of their own package (twin/sim/sensors/)."""
    imported = set()
    for path in Path(instruments.__file__).parent.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                imported |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and not (node.module or "").startswith("twin.sim.sensors."):
                imported.add((node.module or "").split(".")[0])
    assert imported <= {"__future__", "functools", "math", "dataclasses", "numpy", "scipy", "analysis"}
