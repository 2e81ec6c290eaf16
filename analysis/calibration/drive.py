"""The drive's statistics of a Phase I capture: the motor torque's rigid-body fit and its ripple.

The rigid-body friction model of a feed drive seen at the motor (B. Armstrong-Hélouvry, P. Dupont
and C. Canudas de Wit, "A survey of models, analysis tools and compensation methods for the
control of machines with friction", Automatica 30(7), 1994):

    torque = J·dω/dt + T_c·sign(ω) + c_v·ω

J is the inertia the motor drives (rotor, screw and the carriage mass reflected through the lead,
m·(lead/2π)²), T_c the constant drag (nut drag plus the rails' friction reflected), c_v the viscous
drag coefficient. The ramps of a capture separate the three: J acts only while accelerating, T_c
alike at every speed, c_v in proportion to it.

The torque ripple of a permanent-magnet motor is locked to the rotor angle θ = ∫ω dt (T. M. Jahns
and W. L. Soong, "Pulsating torque minimization techniques for permanent magnet AC motor
drives", IEEE Trans. Ind. Electron. 43(2), 1996): its amplitude at order k is read by
demodulating the torque with exp(−i·k·θ) over the cruise (a lock-in amplifier).

The carriage rides on the rails' trucks as a mass on springs: its vertical and lateral
suspension modes ring at f = (1/2π)·√(k/m) (k the trucks' contact stiffness in that direction, m
the moving mass; any text on vibration, e.g. S. S. Rao, "Mechanical Vibrations", ch. 2), and the
nut accelerometers' z and y channels carry them well above the motion's own content. Their
frequency is read as the centroid of the squared power spectral density over a fixed band
(:func:`suspension_mode`): the square weights the resonance far above the broadband floor, and
unlike the highest bin the centroid moves smoothly with k, which a least-squares fit through the
twin needs. A spectral line (mains pickup, a fixed-frequency disturbance) would pull the centroid
towards itself: the spectrum is read with fine bins (1-s segments), where a line is a few bins
wide and a mode tens, and a running median over :data:`LINE_WIDTH_HZ` removes the line and keeps
the mode (Tukey's running median: J. W. Tukey, "Exploratory Data Analysis", 1977, ch. 7).
On the vertical channel that centroid mixes the carriage's two vertical modes (its pitch and its
bounce on the trucks), the axial motion leaking into z and the excitation's lines: where the
pitch stands out, the vertical trucks are read on it instead (:func:`vertical_mode`), the
strongest peak in a band the caller fixes around it (:func:`mode_peak`).

The velocity loop's bandwidth shows in the motor speed's overshoot where a ramp ends: a
proportional-integral loop lets the speed overshoot the new set point by an amount that falls
as its crossover rises (G. Ellis, "Control System Design Guide", 4th ed., ch. 6: the step response
of a PI velocity loop); :func:`speed_overshoot` reads it. Where the recording has IMU runs with
their command, the gain from the commanded to the IMU's axial acceleration just above the loops'
crossovers (:func:`imu_command_gain`) shows the same loop far more precisely and rises
monotonically with its bandwidth. The carriage's axial acceleration around each start and stop
(:func:`imu_reversal`: the jerk of a start excites the carriage on the loop-stiffened screw)
moves with the loop too, but not monotonically (a slow loop and a fast one ring alike), and with
the vertical trucks.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

#: The speed is low-passed (zero phase) at this frequency before it is differentiated, Hz.
SPEED_LOWPASS_HZ = 100.0
#: Left out at each end of a capture: the zero-phase filter's edge transients, s.
EDGE_S = 0.05
#: Statistics of :func:`capture_statistics`, in order, with their units.
STATISTICS = ("inertia", "cruise_drag", "viscous_drag", "ripple")
UNITS = {"inertia": "kg·m²", "cruise_drag": "N·m", "viscous_drag": "N·m·s/rad", "ripple": "N·m"}


def _smoothed_speed(speed: np.ndarray, fs: float) -> np.ndarray:
    sos = signal.butter(2, min(SPEED_LOWPASS_HZ, 0.4 * fs), fs=fs, output="sos")
    return signal.sosfiltfilt(sos, speed)


def rigid_body_fit(speed: np.ndarray, torque: np.ndarray, fs: float) -> np.ndarray:
    """(3,) J (kg·m²), T_c (N·m) and c_v (N·m·s/rad): the least-squares fit of the model above on
    the samples where |ω| is above 5 % of its plateau, :data:`EDGE_S` from either end.

    ``speed`` (n,) motor speed, rad/s, low-passed at :data:`SPEED_LOWPASS_HZ` before it is
    differentiated; ``torque`` (n,) N·m; ``fs`` Hz. NaN for all three when the capture has no
    ramp (fewer than 1 % of the moving samples below 90 % of the plateau) or too few moving
    samples."""
    nan = np.full(3, np.nan)
    if speed.size < 64 + 2 * EDGE_S * fs:
        return nan
    w = _smoothed_speed(speed, fs)
    plateau = float(np.percentile(np.abs(w), 99))
    moving = np.abs(w) > 0.05 * plateau
    edge = int(round(EDGE_S * fs))
    moving[:edge] = False
    moving[moving.size - edge:] = False
    if plateau <= 0 or moving.sum() < 64 or (np.abs(w[moving]) < 0.9 * plateau).mean() < 0.01:
        return nan
    x = np.column_stack([np.gradient(w, 1.0 / fs), np.sign(w), w])[moving]
    coef, *_ = np.linalg.lstsq(x, torque[moving], rcond=None)
    return coef


def ripple_amplitude(speed: np.ndarray, torque: np.ndarray, fs: float, order: int) -> float:
    """Amplitude (N·m) of the torque component at ``order`` periods per motor revolution over
    the cruise (|ω| within 2 % of its plateau), by demodulation with exp(−i·order·θ), θ = ∫ω dt;
    NaN without a cruise of at least 4 ripple periods. ``speed`` (n,) rad/s, ``torque`` (n,) N·m."""
    w = _smoothed_speed(speed, fs)
    plateau = float(np.percentile(np.abs(w), 99))
    if not plateau > 0:
        return float("nan")
    cruise = np.abs(w) >= 0.98 * plateau
    theta = np.cumsum(speed) / fs
    periods = cruise.sum() / fs * plateau * order / (2 * np.pi)
    if periods < 4:
        return float("nan")
    tq = torque[cruise] - np.mean(torque[cruise])
    # each cruise direction has its own mean torque: remove it per direction
    sgn = np.sign(w[cruise])
    for s in (-1.0, 1.0):
        sel = sgn == s
        if sel.any():
            tq[sel] = torque[cruise][sel] - np.mean(torque[cruise][sel])
    z = np.mean(tq * np.exp(-1j * order * theta[cruise]))
    return float(2.0 * np.abs(z))


def cruise_torque(speed: np.ndarray, torque: np.ndarray, fs: float) -> float:
    """The mean of torque·sign(ω) (N·m) over the cruise (|ω| within 2 % of its plateau, the speed
    low-passed at :data:`SPEED_LOWPASS_HZ`): T_c + c_v·|ω| at the cruise speed, the drag the
    motor holds at constant speed, read without the ramps (where the servo's lag biases the
    rigid-body fit's T_c). NaN without motion. ``speed`` (n,) rad/s, ``torque`` (n,) N·m."""
    w = _smoothed_speed(speed, fs)
    plateau = float(np.percentile(np.abs(w), 99))
    if not plateau > 0:
        return float("nan")
    cruise = np.abs(w) >= 0.98 * plateau
    return float(np.mean(torque[cruise] * np.sign(w[cruise])))


def capture_statistics(speed: np.ndarray, torque: np.ndarray, fs: float, ripple_order: int) -> np.ndarray:
    """(4,) the :data:`STATISTICS` of one capture: J and c_v of :func:`rigid_body_fit`, the
    cruise's drag (:func:`cruise_torque`) in place of its T_c, and the ripple amplitude at
    ``ripple_order`` (:func:`ripple_amplitude`)."""
    fit = rigid_body_fit(speed, torque, fs)
    fit[1] = cruise_torque(speed, torque, fs) if np.isfinite(fit[1]) else np.nan
    return np.append(fit, ripple_amplitude(speed, torque, fs, ripple_order))


def recording_statistics(m, captures: list[str], ripple_order: int) -> tuple[np.ndarray, np.ndarray]:
    """(mean (4,), standard error of the mean (4,)) of :func:`capture_statistics` over the
    Phase I ``captures`` of the open recording ``m`` (:class:`analysis.dataset.Measurements`);
    a statistic NaN in every capture stays NaN."""
    rows = []
    for name in captures:
        c = m.phase1(name)
        rows.append(capture_statistics(np.asarray(c.speed, float), np.asarray(c.torque, float),
                                       float(c.fs_hz), ripple_order))
    x = np.array(rows)
    with np.errstate(invalid="ignore"):
        n = np.sum(np.isfinite(x), axis=0)
        mean = np.nanmean(x, axis=0) if len(rows) else np.full(4, np.nan)
        sd = np.nanstd(x, axis=0, ddof=1) if len(rows) > 1 else np.full(4, np.nan)
    return mean, sd / np.sqrt(np.maximum(n, 1))


#: The band the suspension modes are looked for in, Hz (below 0.45 of the sampling rate).
MODE_BAND_HZ = (100.0, 2000.0)
#: Welch segment of :func:`mode_centroid`, s (at most the signal's length): bins of 1 Hz.
MODE_SEGMENT_S = 1.0
#: The shortest signal a mode is read from, s.
MODE_MIN_S = 0.25
#: Width of the running median over frequency that removes spectral lines, Hz.
LINE_WIDTH_HZ = 9.0


def _mode_psd(signals: list[np.ndarray], fs: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(frequencies (m,) Hz, the summed Welch PSD (m,) of ``signals``) for :func:`mode_centroid`
    and :func:`mode_peak`: Hann segments of :data:`MODE_SEGMENT_S` (or the shortest signal), a
    running median over :data:`LINE_WIDTH_HZ` that removes narrow lines. None when a signal is
    shorter than :data:`MODE_MIN_S`."""
    from scipy import ndimage

    if not signals or min(len(x) for x in signals) < MODE_MIN_S * fs:
        return None
    nper = min(int(round(MODE_SEGMENT_S * fs)), min(len(x) for x in signals))
    psd = None
    for x in signals:
        f, p = signal.welch(np.asarray(x, float), fs, nperseg=nper)
        psd = p if psd is None else psd + p
    bins = int(round(LINE_WIDTH_HZ * nper / fs)) | 1
    return f, ndimage.median_filter(psd, size=bins, mode="nearest")


def _centroid(f: np.ndarray, psd: np.ndarray, sel: np.ndarray) -> float:
    w = psd[sel] ** 2
    total = float(np.sum(w))
    return float(np.sum(f[sel] * w) / total) if total > 0 else float("nan")


def _band_psd(signals: list[np.ndarray], fs: float, low_hz: float, high_hz: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(frequencies, PSD (:func:`_mode_psd`), the indices of the band ``low_hz`` to ``high_hz``
    capped at 0.45·``fs``), or None when the band or a signal is too short or it holds no power."""
    hi = min(high_hz, 0.45 * fs)
    spec = _mode_psd(signals, fs) if hi > low_hz else None
    if spec is None:
        return None
    f, psd = spec
    band = np.flatnonzero((f >= low_hz) & (f <= hi))
    return (f, psd, band) if band.size and np.any(psd[band] > 0) else None


def mode_centroid(signals: list[np.ndarray], fs: float, low_hz: float, high_hz: float) -> float:
    """Frequency (Hz) of the resonance in ``signals`` (each (n,), any unit, sampled at ``fs`` Hz):
    the centroid Σ f·P(f)² / Σ P(f)² over ``low_hz`` to ``high_hz`` (capped at 0.45·``fs``) of
    their summed PSD P (:func:`_mode_psd`). NaN when the band is empty, a signal is shorter than
    :data:`MODE_MIN_S` or the band holds no power."""
    spec = _band_psd(signals, fs, low_hz, high_hz)
    return float("nan") if spec is None else _centroid(spec[0], spec[1], spec[2])


#: Half width of the window around the highest bin :func:`mode_peak` takes its centroid over,
#: as a fraction of that bin's frequency.
PEAK_WINDOW = 0.10


def mode_peak(signals: list[np.ndarray], fs: float, low_hz: float, high_hz: float) -> tuple[float, float]:
    """(frequency Hz, how far it stands) of the strongest resonance of ``signals`` (each (n,), any
    unit, sampled at ``fs`` Hz) between ``low_hz`` and ``high_hz`` (capped at 0.45·``fs``): the
    highest bin of their summed PSD P (:func:`_mode_psd`) in that band, then the centroid
    Σ f·P² / Σ P² within ±:data:`PEAK_WINDOW` of it (it moves smoothly with the mode, where the
    highest bin jumps from bin to bin; over a wide band the other peaks and the broadband content
    would pull it). How far it stands: that bin's P over the band's median P, 0 when the bin is
    the band's first or last (the mode, or another's skirt, lies beyond the band). (NaN, 0) when
    the band is empty, a signal is shorter than :data:`MODE_MIN_S` or the band holds no power."""
    spec = _band_psd(signals, fs, low_hz, high_hz)
    if spec is None or spec[2].size < 3:
        return float("nan"), 0.0
    f, psd, band = spec
    k = int(np.argmax(psd[band]))
    stands = float(psd[band[k]] / np.median(psd[band])) if 0 < k < band.size - 1 else 0.0
    peak = f[band[k]]
    return _centroid(f, psd, np.abs(f - peak) <= PEAK_WINDOW * peak), stands


def suspension_mode(acc: list[np.ndarray], fs: float, column: int) -> float:
    """Frequency (Hz) of the carriage's suspension mode seen by the accelerometers ``acc`` (each
    (n, 3) m/s², columns x axial, y lateral, z vertical) in ``column`` (1: lateral, 2:
    vertical): :func:`mode_centroid` over :data:`MODE_BAND_HZ`."""
    return mode_centroid([np.asarray(a, float)[:, column] for a in acc], fs, *MODE_BAND_HZ)


def vertical_mode(acc: list[np.ndarray], fs: float, low_hz: float, high_hz: float) -> tuple[float, float]:
    """(frequency Hz, how far it stands: :func:`mode_peak`) of the carriage's pitch on the trucks'
    springs seen by the nut accelerometers ``acc`` (each (n, 3) m/s², columns x, y, z; the z
    column), looked for between ``low_hz`` and ``high_hz``. Four trucks of vertical stiffness
    k_v spaced a apart along the axis carry two vertical modes (S. S. Rao, "Mechanical
    Vibrations", ch. 5: a rigid bar on two springs): the pitch, (1/2π)·√(k_v·a²/I_yy), rocked by
    the screw's push at the nut's height at every ramp, and the bounce, (1/2π)·√(4·k_v/m), shaken
    by the rails' waviness; both move as √k_v. The caller fixes the band around the pitch and
    below the bounce: over a wide band the bounce, the axial motion leaking into z and lines of
    the excitation would be read instead."""
    return mode_peak([np.asarray(a, float)[:, 2] for a in acc], fs, low_hz, high_hz)


#: The speed is low-passed (zero phase) at this frequency before its overshoot is read, Hz.
OVERSHOOT_LOWPASS_HZ = 300.0


def speed_overshoot(speed: np.ndarray, fs: float) -> float:
    """The motor speed's overshoot over its cruise, as a fraction: (max |ω| − median |ω| over the
    cruise) / median |ω| over the cruise (|ω| within 2 % of its 99th percentile), ``speed`` (n,)
    rad/s low-passed at :data:`OVERSHOOT_LOWPASS_HZ` (zero phase), ``fs`` Hz. NaN without motion."""
    if speed.size < 64:
        return float("nan")
    sos = signal.butter(2, min(OVERSHOOT_LOWPASS_HZ, 0.4 * fs), fs=fs, output="sos")
    w = np.abs(signal.sosfiltfilt(sos, np.asarray(speed, float)))
    plateau = float(np.percentile(w, 99))
    if not plateau > 0:
        return float("nan")
    cruise = float(np.median(w[w >= 0.98 * plateau]))
    return float((w.max() - cruise) / cruise)


def _axial_on_command(run) -> tuple[float, np.ndarray, np.ndarray]:
    """(the IMU accelerometer's rate Hz, its axial acceleration (n,) m/s², ``position_cmd``
    interpolated to its clock (n,) m) of a Phase II run that has a ``position_cmd``."""
    fs, fs_x = float(run.imu_acc_fs_hz), float(run.position_cmd_fs_hz)
    acc = np.asarray(run.imu_acc, float)[:, 0]
    pos = np.asarray(run.position_cmd, float)
    x = np.interp(np.arange(acc.size) / fs, np.arange(pos.size) / fs_x, pos)
    return fs, acc, x


#: Half width of the window around each start and stop of :func:`imu_reversal`, s.
REVERSAL_WINDOW_S = 0.02
#: High-pass of the IMU's acceleration before :func:`imu_reversal`, Hz (gravity and drift out).
REVERSAL_HIGHPASS_HZ = 2.0


def near_edges(moving: np.ndarray, fs: float, window_s: float, ends: bool = False) -> np.ndarray:
    """Boolean (n,): the samples within ``window_s`` s (at least one sample) of a start or stop
    of ``moving`` (n,) sampled at ``fs`` Hz, and with ``ends`` of either end of the signal too."""
    edges = np.flatnonzero(np.diff(moving.astype(np.int8)) != 0)
    if ends:
        edges = np.concatenate([[0], edges, [moving.size - 1]])
    near = np.zeros(moving.shape, bool)
    w = max(1, int(round(window_s * fs)))
    for e in edges:
        near[max(0, e - w):e + w + 1] = True
    return near


def imu_reversal(run) -> float:
    """Log10 of the RMS (m/s²) of the IMU's axial acceleration, high-passed at
    :data:`REVERSAL_HIGHPASS_HZ` (zero phase), within ±:data:`REVERSAL_WINDOW_S` of every start
    and stop of the commanded motion (``position_cmd`` interpolated to the IMU's clock, moving
    where its speed exceeds 0.1 mm/s) of a Phase II run. NaN without ``position_cmd`` or motion."""
    if getattr(run, "position_cmd", None) is None:
        return float("nan")
    fs, acc, x = _axial_on_command(run)
    if acc.size < 64:
        return float("nan")
    near = near_edges(np.abs(np.gradient(x, 1.0 / fs)) > 1e-4, fs, REVERSAL_WINDOW_S)
    if not near.any():
        return float("nan")
    sos = signal.butter(4, REVERSAL_HIGHPASS_HZ, "highpass", fs=fs, output="sos")
    hp = signal.sosfiltfilt(sos, acc)
    return float(np.log10(np.sqrt(np.mean(hp[near] ** 2)) + 1e-15))


#: The band of :func:`imu_command_gain`, Hz: at and above the velocity loops of the calibrate
#: benchmark's axes (30-96 Hz as drawn), where the servo's tracking gain rises monotonically with
#: the loop's bandwidth (tests/test_calibrate.py::test_imu_statistics_follow_the_velocity_loop_and_the_lateral_trucks).
VELOCITY_BAND_HZ = (30.0, 60.0)


def imu_command_gain(run, low_hz: float = VELOCITY_BAND_HZ[0], high_hz: float = VELOCITY_BAND_HZ[1]) -> float:
    """The servo's tracking gain in a band: the mean over ``low_hz``-``high_hz`` of |H(f)|, H the
    frequency response from the commanded acceleration (``position_cmd`` interpolated to the
    IMU's clock, differentiated twice) to the IMU's axial acceleration (``imu_acc`` column x) of
    a Phase II run, both high-passed at :data:`REVERSAL_HIGHPASS_HZ` (zero phase: H is unchanged
    by a filter both pass), estimated as H1 = P_xy / P_xx from Welch's averaged periodograms of
    1-s segments (J. S. Bendat and A. G. Piersol, "Random Data", 4th ed., ch. 9). A cascaded
    position and velocity loop tracks its command with |H| near 1 well below its bandwidths;
    around and above the velocity loop's crossover the gain is set by that loop (G. Ellis,
    "Control System Design Guide", 4th ed., ch. 17). Unlike the phase, the gain does not move
    with a time offset between the IMU's clock and the controller's. Dimensionless; NaN without
    ``position_cmd``, without motion, when the run is shorter than two segments or the band
    reaches the IMU's Nyquist frequency."""
    if getattr(run, "position_cmd", None) is None:
        return float("nan")
    fs, acc, x = _axial_on_command(run)
    n = int(round(fs))
    if acc.size < 2 * n or high_hz >= 0.5 * fs:
        return float("nan")
    cmd = np.gradient(np.gradient(x, 1.0 / fs), 1.0 / fs)
    if not np.any(cmd):
        return float("nan")
    sos = signal.butter(4, REVERSAL_HIGHPASS_HZ, "highpass", fs=fs, output="sos")
    cmd, acc = signal.sosfiltfilt(sos, cmd), signal.sosfiltfilt(sos, acc)
    f, pxy = signal.csd(cmd, acc, fs=fs, nperseg=n)
    _, pxx = signal.welch(cmd, fs=fs, nperseg=n)
    band = (f >= low_hz) & (f < high_hz) & (pxx > 0)
    if not band.any():
        return float("nan")
    return float(np.mean(np.abs(pxy[band] / pxx[band])))


#: Lower end of the band :func:`imu_yaw_mode` looks in, Hz (below it, the motion's own content).
YAW_BAND_LOW_HZ = 20.0


def imu_yaw_mode(run) -> float:
    """Frequency (Hz) of the carriage's yaw mode on its trucks' lateral springs, read on the IMU's
    yaw rate (``imu_gyro`` column z, rad/s) of a Phase II run: :func:`mode_centroid` from
    :data:`YAW_BAND_LOW_HZ` to 0.45 of the rate, as :func:`suspension_mode` on the nut
    accelerometers. The IMU sits on the carriage, where the lateral mode shows as a rotation the
    nut accelerometers see mixed with the vertical one."""
    fs = float(run.imu_gyro_fs_hz)
    return mode_centroid([np.asarray(run.imu_gyro, float)[:, 2]], fs, YAW_BAND_LOW_HZ, 0.45 * fs)


def imu_ripple(run, lead_m: float, order: int, max_hz: float) -> float:
    """Log10 of the IMU's axial acceleration (m/s²) at ``order`` periods per motor revolution,
    averaged over the cruises of a Phase II run: the torque ripple shakes the carriage through the
    screw, and at the slow speeds of the IMU routine its frequency order·v/lead falls where the
    servo passes it on. The motor angle is 2π·x/lead from ``position_cmd`` (interpolated to the
    IMU's clock); each cruise (the commanded speed constant, 50 ms left out at each end) is
    demodulated with exp(−i·order·θ); cruises whose frequency is above ``max_hz`` (the
    accelerometer's band) or that span fewer than 4 periods are left out. NaN when none is left
    or the run has no ``position_cmd``."""
    if getattr(run, "position_cmd", None) is None:
        return float("nan")
    fs, acc, x = _axial_on_command(run)
    v = np.gradient(x, 1.0 / fs)
    vmax = float(np.max(np.abs(v))) if v.size else 0.0
    if not vmax > 0:
        return float("nan")
    # cruises: runs of (nearly) constant commanded speed away from rest
    dv = np.abs(np.gradient(v, 1.0 / fs))
    cruise = (np.abs(v) > 0.05 * vmax) & (dv < 1e-6 + 1e-3 * np.abs(v) * fs)
    edge = int(round(0.05 * fs))
    d = np.diff(np.concatenate(([0], cruise.astype(np.int8), [0])))
    logs = []
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
        a, b = a + edge, b - edge
        if b - a < 16:
            continue
        speed = float(np.median(np.abs(v[a:b])))
        f = order * speed / lead_m
        if f > max_hz or (b - a) / fs * f < 4:
            continue
        theta = 2 * np.pi * x[a:b] / lead_m
        seg = acc[a:b] - acc[a:b].mean()
        logs.append(np.log10(2.0 * np.abs(np.mean(seg * np.exp(-1j * order * theta))) + 1e-12))
    return float(np.mean(logs)) if logs else float("nan")
