"""The six error motions of a Phase II session from its IMU runs (paper section V).

:func:`session_error_motions` reads the runs of one session from ``measurements.h5`` and returns
:class:`analysis.phase2.traces.SessionErrorMotions`:

- ``combined``: E_XX, E_YX, E_ZX (m), E_AX, E_BX, E_CX (rad) against the commanded position, for
  each direction, from all speeds and both sensors combined per spatial frequency
  (:mod:`analysis.phase2.fusion`, derived here as in Vogl et al., PHM Society 2016), on a grid of step
  ``dx_m`` (0.5 mm by default) over the stretch every speed covers at constant velocity;
- ``slow``: the slow-speed component ``slow()`` of the paper: the same estimate from the slowest
  speed alone, on a fine grid (``slow_dx_m``, 10 µm by default) over the stretch that speed
  covers, keeping the whole sensor band (to 255 Hz of the accelerometer's 300 Hz: wavelengths
  down to 0.08 mm at 20 mm/s, 0.39 mm at 100 mm/s; see ``SLOW_LOWPASS_FRACTION``),
  forward and reverse each against its own commanded position, NOT shifted against each other.

Both are averaged over the usable runs of the session (the gridded signals are averaged, then
combined; the combination is linear, so this equals averaging the per-run estimates). Both have
the unobservable terms removed: a least-squares quadratic from E_XX, E_YX, E_ZX, the mean from the
angles.

Position reference: the commanded position ``position_cmd`` (proportional to the screw angle).
Screw-fixed features (lead error, ball pass) therefore stay in place between forward and reverse
traces, rail-fixed ones (straightness, angles) shift by the backlash; that lag is left in.

Per run (:mod:`analysis.phase2.imu_runs`): segmentation of the commanded profile, gyro bias from
the stationary parts, group-delay compensation, trimming of the ringing after each acceleration.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from analysis.dataset import DatasetError, Measurements
from analysis.dataset.axis import run_routine
from analysis.phase2 import fusion
from analysis.phase2.imu_runs import (
    BadRunError,
    butterworth2_delay_s,
    cruise_window,
    grid_motion,
    load_run,
    remove_bias,
    segment_run,
)
from analysis.phase2.strokes import imu_segments
from analysis.phase2.traces import DirectionalTraces, SessionErrorMotions

__all__ = ["SensorModel", "resolve_position_reference", "sensor_model", "session_error_motions"]

MICRO_G = 9.80665e-6  # m/s² per µg
#: Zero-phase low-pass before gridding: cutoff as a fraction of each sensor's bandwidth, at most
#: ANTIALIAS × the temporal frequency of the grid's Nyquist wavenumber; Butterworth order.
LOWPASS_FRACTION = 0.6
ANTIALIAS = 0.8
#: The same for ``slow`` (what the backlash correlation sees): the whole sensor bandwidth, with
#: ``slow_f_max_fraction`` = 1. At 100 mm/s the combined layer's 0.6 / 0.5 would cut the
#: accelerometer at 150 Hz, i.e. wavelengths below 0.67 mm, and leave only the transition band of
#: winfilt's 0.5 mm high-pass (0.67–2 mm), narrow and with the fusion's hard band edge at its top:
#: 3x the noise of the shift and seed-dependent errors of up to 0.75 µm without noise. Sensor
#: response errors at the band edge do not matter there: each direction is correlated with the
#: same direction of the first session, through the same sensor.
SLOW_LOWPASS_FRACTION = 1.0
LOWPASS_ORDER = 8
#: Zero-mean priors of the six error motions (rows DOFS) for the Wiener combination: generous
#: versions of the twin's guideway magnitudes (straightness a few µm over 0.5 m,
#: angles 5–20 µrad p-v; positioning larger: cumulative lead error).
PRIORS = (fusion.Prior(20e-6), fusion.Prior(5e-6), fusion.Prior(5e-6),
          fusion.Prior(20e-6), fusion.Prior(20e-6), fusion.Prior(20e-6))


#: The position axes a session's traces can be functions of.
POSITION_REFERENCES = ("command", "imu")


def resolve_position_reference(m: Measurements, position_reference: str) -> str:
    """``"auto"`` becomes "command" when the first Phase II run records ``position_cmd`` and "imu"
    when it does not (a stand-alone IMU, format_version 2); other values are checked and returned."""
    if position_reference == "auto":
        sessions = m.phase2_sessions()
        runs = m.phase2_runs(sessions[0]) if sessions else []
        if not runs:
            return "command"
        return "command" if "position_cmd" in m.phase2_channels(sessions[0], runs[0]) else "imu"
    if position_reference not in POSITION_REFERENCES:
        raise ValueError(f"position_reference is {position_reference!r}; expected 'auto' or one of "
                         f"{', '.join(POSITION_REFERENCES)}")
    return position_reference


@dataclass(frozen=True)
class SensorModel:
    """What the estimator assumes about the IMU (datasheet figures, SI).

    acc_noise, gyro_noise: white noise densities, (m/s²)/√Hz and (rad/s)/√Hz (relative weights of
    the fusion only). acc_bandwidth_hz, gyro_bandwidth_hz: half-power frequencies of their
    2nd-order low-pass. acc_delay_s, gyro_delay_s: their group delays, compensated.
    """

    acc_noise: float = 7.0 * MICRO_G
    gyro_noise: float = 35e-6
    acc_bandwidth_hz: float = 300.0
    gyro_bandwidth_hz: float = 200.0
    acc_delay_s: float = butterworth2_delay_s(300.0)
    gyro_delay_s: float = butterworth2_delay_s(200.0)


def sensor_model(m: Measurements) -> SensorModel:
    """The IMU figures from the file's axis contract (``sensors.imu_accelerometer`` /
    ``imu_gyroscope``: ``bandwidth_hz``, ``noise_ug_per_rthz`` / ``noise_urad_s_per_rthz``), the
    paper's figures (section III) where absent. Delays follow from the bandwidths."""
    from analysis.dataset.axis import axis_of

    d = SensorModel()
    axis = axis_of(m)
    abw = axis.get("sensors.imu_accelerometer.bandwidth_hz", d.acc_bandwidth_hz)
    gbw = axis.get("sensors.imu_gyroscope.bandwidth_hz", d.gyro_bandwidth_hz)
    acc_noise = axis.get("sensors.imu_accelerometer.noise_ug_per_rthz", 0.0) or d.acc_noise / MICRO_G
    gyro_noise = axis.get("sensors.imu_gyroscope.noise_urad_s_per_rthz", 0.0) or d.gyro_noise * 1e6
    return SensorModel(
        acc_noise=acc_noise * MICRO_G, gyro_noise=gyro_noise * 1e-6,
        acc_bandwidth_hz=abw, gyro_bandwidth_hz=gbw,
        acc_delay_s=butterworth2_delay_s(abw), gyro_delay_s=butterworth2_delay_s(gbw))


@dataclass(frozen=True)
class _Prepared:
    """One usable run: bias-free IMU signals and its cruises {(speed_mm_s, direction): Motion}."""

    run: str
    acc: np.ndarray
    acc_fs_hz: float
    gyro: np.ndarray
    gyro_fs_hz: float
    motions: dict


def _match_speed(speed_mm_s: float, expected: tuple[float, ...]) -> float | None:
    for s in expected:
        if abs(speed_mm_s - s) <= 0.01 * s:
            return s
    return None


def _prepare_run(m: Measurements, session: str, run: str, expected: tuple[float, ...] | None,
                 position_reference: str = "command",
                 sm: SensorModel | None = None,
                 stroke_timing: str = "travel") -> tuple[_Prepared, tuple[float, ...]]:
    """Read, check, segment and de-bias one run; raises :class:`BadRunError` naming the channel.

    ``position_reference``: "command" segments the run by ``position_cmd``; "imu" finds its
    strokes from the accelerometer and the run's routine metadata
    (:func:`analysis.phase2.strokes.imu_segments`)."""
    r = load_run(m, session, run)
    where = f"{m.label}: session {session}, run {run}"
    if position_reference == "imu":
        routine, speeds = run_routine(m, r)
        seg = imu_segments(r.imu_acc[:, 0], r.imu_acc_fs_hz, speeds, routine,
                           (sm or SensorModel()).acc_bandwidth_hz, timing=stroke_timing,
                           label=f"{where}, channel imu_acc")
    elif r.position_cmd is None:
        raise BadRunError(f"{where}, channel position_cmd: absent (a recording of a stand-alone IMU); "
                          "expected the controller's position for the command position reference, or "
                          "analyse with the IMU-based one (--position-reference imu)")
    else:
        seg = segment_run(r.position_cmd, r.position_cmd_fs_hz)
    if expected is None:
        expected = r.speeds_mm_s
    if expected is None:
        expected = tuple(sorted({round(mo.speed_m_s * 1e3, 6) for mo in seg.motions}))
    if not expected:
        raise BadRunError(f"{where}, channel position_cmd: no constant-velocity motion; expected "
                          "forward and reverse motions at each speed")
    acc = remove_bias(r.imu_acc, r.imu_acc_fs_hz, seg.still, drift=False,
                      label=f"{where}, channel imu_acc")
    gyro = remove_bias(r.imu_gyro, r.imu_gyro_fs_hz, seg.still, drift=True,
                       label=f"{where}, channel imu_gyro")
    motions: dict = {}
    for mo in seg.motions:
        s = _match_speed(mo.speed_m_s * 1e3, expected)
        if s is not None and (s, mo.direction) not in motions:
            motions[(s, mo.direction)] = mo  # a second pass at the same speed is not used
    for s in expected:
        for d, name in ((1, "forward"), (-1, "reverse")):
            if (s, d) not in motions:
                raise BadRunError(
                    f"{where}, channel position_cmd: no {name} constant-velocity motion at "
                    f"{s:g} mm/s; expected one per speed and direction (run cut short?)")
    return _Prepared(run, acc, r.imu_acc_fs_hz, gyro, r.imu_gyro_fs_hz, motions), tuple(expected)


def _grid(lo: float, hi: float, dx: float, what: str) -> np.ndarray:
    a = math.ceil(lo / dx - 1e-9)
    b = math.floor(hi / dx + 1e-9)
    if b - a < 16:
        raise DatasetError(f"the constant-velocity stretch [{lo:.6f}, {hi:.6f}] m common to {what} "
                           f"is too short for a grid of step {dx:g} m")
    return np.arange(a, b + 1) * dx


@dataclass
class _Layer:
    """Accumulated gridded signals of one output (combined or slow) over the runs."""

    grid: np.ndarray
    speeds: tuple[float, ...]
    acc: dict
    gyro: dict
    count: int = 0

    @property
    def dx(self) -> float:
        return float(self.grid[1] - self.grid[0])


def _cutoffs(sm: SensorModel, speed_m_s: float, dx: float, lowpass_fraction: float,
             antialias: float) -> tuple[float, float]:
    """Zero-phase low-pass cutoffs (acc, gyro), Hz: ``lowpass_fraction`` of each bandwidth, and at
    most ``antialias`` × the temporal frequency of the grid's Nyquist wavenumber."""
    nyq = antialias * speed_m_s / (2.0 * dx)
    return (min(lowpass_fraction * sm.acc_bandwidth_hz, nyq),
            min(lowpass_fraction * sm.gyro_bandwidth_hz, nyq))


def _new_layer(p: _Prepared, speeds: tuple[float, ...], dx: float, trim_s: float,
               trim_end_s: float, what: str) -> _Layer:
    lo, hi = -math.inf, math.inf
    for s in speeds:
        for d in (1, -1):
            a, b = cruise_window(p.motions[(s, d)], trim_s, trim_end_s)
            lo, hi = max(lo, a), min(hi, b)
    grid = _grid(lo + dx, hi - dx, dx, what)  # one step of margin
    zeros = {(s, d): np.zeros((grid.size, 3)) for s in speeds for d in (1, -1)}
    return _Layer(grid, speeds, zeros, {k: v.copy() for k, v in zeros.items()})


def _grid_run(p: _Prepared, layer: _Layer, sm: SensorModel, *, trim_s: float, trim_end_s: float,
              lowpass_fraction: float, antialias: float, order: int,
              label: str) -> tuple[dict, dict]:
    """The run's signals on the layer's grid; :class:`BadRunError` if they do not cover it."""
    accs, gyros = {}, {}
    for s in layer.speeds:
        fa, fg = _cutoffs(sm, s * 1e-3, layer.dx, lowpass_fraction, antialias)
        for d in (1, -1):
            mo = p.motions[(s, d)]
            kw = {"order": order, "trim_s": trim_s, "trim_end_s": trim_end_s}
            a = grid_motion(p.acc, p.acc_fs_hz, sm.acc_delay_s, mo, layer.grid, cutoff_hz=fa, **kw)
            g = grid_motion(p.gyro, p.gyro_fs_hz, sm.gyro_delay_s, mo, layer.grid, cutoff_hz=fg,
                            **kw)
            for name, arr in (("imu_acc", a), ("imu_gyro", g)):
                if not np.isfinite(arr).all():
                    raise BadRunError(
                        f"{label}, channel {name}: the {'forward' if d > 0 else 'reverse'} motion "
                        f"at {s:g} mm/s does not cover [{layer.grid[0]:.6f}, {layer.grid[-1]:.6f}] m "
                        "at constant velocity as the session's first run does; expected the same "
                        "routine in every run")
            accs[(s, d)], gyros[(s, d)] = a, g
    return accs, gyros


def _solve_streams(st: dict, dx: float) -> np.ndarray:
    """(6, n) error motions from the streams of :func:`_streams` (:func:`fusion.solve`)."""
    n = st["x"][0].data.size
    e = np.zeros((6, n))
    pt, pr = PRIORS[0], PRIORS[3]
    e[0], e[4] = fusion.solve(st["x"] + st["gy"], dx, coupling=-1.0,
                              prior_t=PRIORS[0], prior_r=PRIORS[4])
    e[1], e[3] = fusion.solve(st["y"] + st["gx"], dx, coupling=+1.0,
                              prior_t=PRIORS[1], prior_r=PRIORS[3])
    e[2], _ = fusion.solve(st["z"], dx, coupling=None, prior_t=PRIORS[2], prior_r=pr)
    _, e[5] = fusion.solve(st["gz"], dx, coupling=None, prior_t=pt, prior_r=PRIORS[5])
    return e


def _streams(layer: _Layer, sm: SensorModel, directions: tuple[int, ...], *,
             lowpass_fraction: float, antialias: float, order: int,
             f_max_fraction: float) -> dict:
    """The averaged gridded signals of ``directions`` as :class:`fusion.Stream` lists per channel
    ("x", "y", "z" accelerometer, "gx", "gy", "gz" gyro)."""
    st: dict[str, list[fusion.Stream]] = {k: [] for k in ("x", "y", "z", "gx", "gy", "gz")}
    n = layer.count
    for d in directions:
        for s in layer.speeds:
            acc = layer.acc[(s, d)] / n
            gyro = layer.gyro[(s, d)] / n
            fa, fg = _cutoffs(sm, s * 1e-3, layer.dx, lowpass_fraction, antialias)
            v = d * s * 1e-3
            for j, name in enumerate("xyz"):
                st[name].append(fusion.Stream(
                    acc[:, j] - acc[:, j].mean(), "acc", v, sm.acc_noise, sm.acc_bandwidth_hz,
                    f_max_fraction * sm.acc_bandwidth_hz, n, fa, order))
                st["g" + name].append(fusion.Stream(
                    gyro[:, j], "gyro", v, sm.gyro_noise, sm.gyro_bandwidth_hz,
                    f_max_fraction * sm.gyro_bandwidth_hz, n, fg, order))
    return st


#: The precision that defines the resolved wavelength band of the error motions
#: (:func:`fusion.resolved_band`): expected RMS error at most 0.2 µm for the translations and
#: 1 µrad for the angles over the band (rows :data:`DOFS`).
BAND_PRECISION = (0.2e-6, 0.2e-6, 0.2e-6, 1e-6, 1e-6, 1e-6)


def _error_psds(st: dict, dx: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """k (m,) 1/m and the posterior error PSD (m,) of each DOF (rows :data:`DOFS`) for the
    streams of :func:`_streams`, paired as in :func:`_solve_streams`."""
    out: list = [None] * 6
    k, out[0], out[4] = fusion.posterior_psd(st["x"] + st["gy"], dx, coupling=-1.0,
                                             prior_t=PRIORS[0], prior_r=PRIORS[4])
    _, out[1], out[3] = fusion.posterior_psd(st["y"] + st["gx"], dx, coupling=+1.0,
                                             prior_t=PRIORS[1], prior_r=PRIORS[3])
    _, out[2], _ = fusion.posterior_psd(st["z"], dx, coupling=None, prior_t=PRIORS[2], prior_r=PRIORS[3])
    _, _, out[5] = fusion.posterior_psd(st["gz"], dx, coupling=None, prior_t=PRIORS[0], prior_r=PRIORS[5])
    return k, out


def _bands(k: np.ndarray, psds: list[np.ndarray]) -> np.ndarray:
    """(6, 2) resolved band (shortest, longest wavelength, m) per DOF; NaN where none."""
    out = np.full((6, 2), np.nan)
    for i, p in enumerate(psds):
        b = fusion.resolved_band(k, p, BAND_PRECISION[i])
        if b is not None:
            out[i] = b
    return out


def _fuse(layer: _Layer, sm: SensorModel, *, pool_wavelength_m: float | None,
          **kw) -> DirectionalTraces:
    """Average the accumulated signals and combine them per direction; with
    ``pool_wavelength_m`` the wavelengths above it come from both directions together
    (:func:`fusion.pool_long_wavelengths`, applied to the error spectra as to the traces). The
    resolved band is that of the forward direction (the reverse has the same speeds and runs)."""
    streams = {d: _streams(layer, sm, (d,), **kw) for d in (1, -1)}
    out = {d: _solve_streams(streams[d], layer.dx) for d in (1, -1)}
    k, psds = _error_psds(streams[1], layer.dx)
    if pool_wavelength_m is not None:
        st_both = _streams(layer, sm, (1, -1), **kw)
        both = _solve_streams(st_both, layer.dx)
        for d in (1, -1):
            out[d] = fusion.pool_long_wavelengths(out[d], both, layer.dx, pool_wavelength_m)
        # the same crossover on the error spectra: own above 2/λ, pooled below 1/λ
        w_own = 0.5 - 0.5 * np.cos(np.pi * np.clip(np.log2(k * pool_wavelength_m), 0.0, 1.0))
        _, pooled = _error_psds(st_both, layer.dx)
        psds = [w_own * own + (1.0 - w_own) * pb for own, pb in zip(psds, pooled, strict=True)]
    return DirectionalTraces(layer.grid, fusion.remove_unobservable(out[1], layer.grid),
                             fusion.remove_unobservable(out[-1], layer.grid), band_m=_bands(k, psds))


def session_error_motions(m: Measurements, session: str, *, dx_m: float = 0.5e-3,
                          slow_dx_m: float = 10e-6, on_bad_run: str = "raise",
                          trim_s: float = 0.1, trim_end_s: float = 0.005,
                          f_max_fraction: float = 0.5, slow_f_max_fraction: float = 1.0,
                          pool_wavelength_m: float | None = 0.05,
                          sensors: SensorModel | None = None,
                          runs: Sequence[str] | None = None,
                          position_reference: str = "auto",
                          stroke_timing: str = "travel") -> SessionErrorMotions:
    """Error motions of one Phase II session, averaged over its runs.

    Args:
        m: an open ``measurements.h5`` (:func:`analysis.dataset.open_measurements`).
        session: session name, e.g. ``"s0003"``.
        dx_m: grid step of ``combined``, m.
        slow_dx_m: grid step of ``slow``, m (≤ 20 µm for sub-sample shift fitting).
        on_bad_run: "raise": a run with a missing dataset, cut short or with a non-finite channel
            raises :class:`analysis.dataset.DatasetError` naming session, run and channel;
            "skip": the run is left out and ``(run, reason)`` recorded in ``skipped``.
        trim_s: time dropped after the start of each constant-velocity part (carriage ringing), s.
        trim_end_s: time dropped before its end, s.
        f_max_fraction: highest temporal frequency used in ``combined``, as a fraction of each
            sensor's bandwidth.
        slow_f_max_fraction: the same for ``slow`` (with the low-pass at
            ``SLOW_LOWPASS_FRACTION`` of the bandwidth): 1, the whole band, so that at 100 mm/s
            the wavelengths around winfilt's 0.5 mm cutoff reach the backlash correlation.
        pool_wavelength_m: in ``combined``, wavelengths above this come from both directions
            together (halves their noise variance; a backlash shift of 20 µm is a phase of
            0.0025 rad at 50 mm); None keeps the directions apart. ``slow`` never pools.
        sensors: IMU figures; default :func:`sensor_model` of ``m``.
        runs: the run names to use (default all runs of the session); an unknown name raises
            :class:`analysis.dataset.DatasetError` naming it.
        position_reference: "auto" (default): "command" if the runs record ``position_cmd``, else
            "imu". "command": positions are the controller's ``position_cmd``;
            "imu": the IMU-based position, strokes found from the accelerometer and placed on the
            routine's nominal trapezoid (the run's metadata; ``position_cmd`` is not read).
        stroke_timing: how the IMU axis times the strokes
            (:data:`analysis.phase2.strokes.TIMINGS`; "travel" by default).

    Returns:
        :class:`SessionErrorMotions`; ``combined`` on the stretch every speed covers at constant
        velocity (grid multiples of ``dx_m``), ``slow`` on the stretch the slowest speed covers.
    """
    if on_bad_run not in ("raise", "skip"):
        raise ValueError(f"on_bad_run is {on_bad_run!r}; expected 'raise' or 'skip'")
    position_reference = resolve_position_reference(m, position_reference)
    if not (dx_m > 0 and slow_dx_m > 0):
        raise ValueError(f"grid steps must be > 0 m, got dx_m={dx_m!r}, slow_dx_m={slow_dx_m!r}")
    sm = sensors or sensor_model(m)
    hours = m.session_hours(session)
    names = m.phase2_runs(session)
    if runs is not None:
        unknown = [r for r in runs if r not in names]
        if unknown:
            raise DatasetError(f"{m.label}: session {session} has no run {', '.join(unknown)}; "
                               f"expected one of {', '.join(names)}")
        names = [r for r in names if r in set(runs)]
    if not names:
        raise DatasetError(f"{m.label}: session {session} has no runs; expected at least one")
    kw = {"trim_s": trim_s, "trim_end_s": trim_end_s, "lowpass_fraction": LOWPASS_FRACTION,
          "antialias": ANTIALIAS, "order": LOWPASS_ORDER}
    layer_kw = (kw, {**kw, "lowpass_fraction": SLOW_LOWPASS_FRACTION})  # combined, slow
    used: list[str] = []
    skipped: list[tuple[str, str]] = []
    expected: tuple[float, ...] | None = None
    layers: list[_Layer] = []
    for name in names:
        label = f"{m.label}: session {session}, run {name}"
        try:
            p, exp = _prepare_run(m, session, name, expected, position_reference, sm, stroke_timing)
            if not layers:
                speeds = tuple(sorted(exp))
                layers = [_new_layer(p, speeds, dx_m, trim_s, trim_end_s, "all speeds"),
                          _new_layer(p, speeds[:1], slow_dx_m, trim_s, trim_end_s,
                                     "the slowest speed")]
            gridded = [_grid_run(p, layer, sm, label=label, **lkw)
                       for layer, lkw in zip(layers, layer_kw, strict=True)]
        except BadRunError as e:
            if on_bad_run == "raise":
                raise
            skipped.append((name, str(e)))
            continue
        expected = exp
        for layer, (accs, gyros) in zip(layers, gridded, strict=True):
            for k in layer.acc:
                layer.acc[k] += accs[k]
                layer.gyro[k] += gyros[k]
            layer.count += 1
        used.append(name)
    if not used:
        reasons = "; ".join(f"{r}: {why}" for r, why in skipped)
        raise DatasetError(f"{m.label}: session {session} has no usable run ({reasons})")
    fkw = {"lowpass_fraction": LOWPASS_FRACTION, "antialias": ANTIALIAS,
           "order": LOWPASS_ORDER, "f_max_fraction": f_max_fraction}
    combined = _fuse(layers[0], sm, pool_wavelength_m=pool_wavelength_m, **fkw)
    slow = _fuse(layers[1], sm, pool_wavelength_m=None,
                 **{**fkw, "lowpass_fraction": SLOW_LOWPASS_FRACTION,
                    "f_max_fraction": slow_f_max_fraction})
    return SessionErrorMotions(session=session, hours=hours, runs=tuple(used),
                               combined=combined, slow=slow, skipped=tuple(skipped),
                               position_reference=position_reference)
