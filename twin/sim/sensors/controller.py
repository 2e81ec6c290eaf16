"""What the servo drive's controller records: the motor speed from its encoder counter
(:func:`measure_speed`) and the motor torque from its current sensor (:func:`measure_torque`),
at the controller rate. SI units (rad, rad/s, N·m, s, Hz); each returns ``(t, samples)``.
"""

from __future__ import annotations

import math

import numpy as np

from twin.sim.sensors.chain import _validate_fs
from twin.sim.sensors.sampling import decimate_to, quantise


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
