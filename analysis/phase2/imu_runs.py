"""One Phase II run: from IMU time series to IMU signals against commanded position.

Steps (time → position; the approach of Vogl et al., PHM Society 2016):

1. **Segmentation** of the commanded position ``position_cmd`` (k,) m at ``fs_hz``: the
   constant-velocity part (cruise) of every motion and the stationary parts (dwells). The
   commanded profile is exact, so the cruise is where the finite-difference velocity equals its
   plateau to 1e-3 relative.
2. **Bias removal** from the stationary parts: the gyro reads its bias there (the carriage does
   not rotate), so the mean rate over the dwells, interpolated linearly in time between dwells, is
   subtracted. The accelerometer reads bias + g·tilt at the dwell position; its stationary mean
   (z: g + bias) is subtracted too; for x and y this removes a constant only, and constants of
   angles are unobservable anyway.
3. **Time → position**: each IMU sample taken at t_s describes the motion at t_s − τ, τ the
   sensor's group delay (second-order Butterworth low-pass, τ = 1/(2π·f_c·sin(π/4)) =
   √2/(2π·f_c): 0.75 ms at 300 Hz, 1.13 ms at 200 Hz; ``twin.sim.sensors.instruments``
   ``butterworth_group_delay`` and any filter handbook). The commanded position at t_s − τ is
   read by linear interpolation of ``position_cmd``, exact in the cruise where it is linear in t.
   Samples within ``trim_s`` of the cruise start (the carriage pitch rings ~0.1 s after each
   acceleration) or ``trim_end_s`` of its end are dropped.
4. **Gridding** onto a uniform position grid: zero-phase low-pass in time (anti-aliasing for the
   grid; without it the ~450 Hz ball-pass vibration of the fast pass, sampled at 1613 Hz, folds
   into micrometre errors of the straightness), then cubic interpolation at the instant the
   command passes each grid point (binning would do too; the low-pass plays
   the role of the bin average without its sinc ripple).

Units SI: m, s, m/s, m/s², rad/s.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from analysis.dataset import DatasetError, Measurements, Phase2Run
from analysis.resample import not_a_knot_cubic_rows

__all__ = [
    "BadRunError",
    "Motion",
    "RunSegments",
    "butterworth2_delay_s",
    "cruise_window",
    "grid_motion",
    "load_run",
    "lowpass_power",
    "remove_bias",
    "segment_run",
]


class BadRunError(DatasetError):
    """A run that cannot be used (missing dataset, cut short, non-finite channel)."""


def butterworth2_delay_s(bandwidth_hz: float) -> float:
    """Low-frequency group delay of a 2nd-order Butterworth low-pass, s: √2/(2π·f_c)."""
    return math.sqrt(2.0) / (2.0 * math.pi * bandwidth_hz)


@dataclass(frozen=True)
class Motion:
    """The cruise of one motion.

    direction: +1 towards +X, −1 towards −X. speed_m_s: |v| fitted on the cruise, m/s.
    t0_s, t1_s: start and end of the cruise, s. x0_m, x1_m: commanded positions there, m.
    """

    direction: int
    speed_m_s: float
    t0_s: float
    t1_s: float
    x0_m: float
    x1_m: float

    @property
    def velocity_m_s(self) -> float:
        return self.direction * self.speed_m_s


@dataclass(frozen=True)
class RunSegments:
    """motions: the cruises in time order; still: (t0, t1) s of the stationary parts."""

    motions: tuple[Motion, ...]
    still: tuple[tuple[float, float], ...]


def _runs_of(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) index pairs of the True stretches of a boolean array."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def segment_run(position_cmd: np.ndarray, fs_hz: float, *, settle_s: float = 0.2,
                min_cruise_s: float = 0.05) -> RunSegments:
    """Cruises and stationary parts of a commanded position ``position_cmd`` (k,) m at ``fs_hz``.

    A stationary part is a stretch with zero commanded velocity, without its first ``settle_s``
    (the carriage still rings after stopping). Cruises shorter than ``min_cruise_s`` are ignored.
    """
    p = np.asarray(position_cmd, dtype=float)
    t = np.arange(p.size) / fs_hz
    v = np.diff(p) * fs_hz  # velocity over [t_i, t_i+1]
    scale = max(float(np.max(np.abs(v), initial=0.0)), 1e-12)
    moving = np.abs(v) > 1e-9 * scale + 1e-12
    motions: list[Motion] = []
    for i0, i1 in _runs_of(moving):
        vm = v[i0:i1]
        vpk = float(np.max(np.abs(vm)))
        cruise = np.abs(np.abs(vm) - vpk) <= 1e-3 * vpk
        # The longest cruise stretch of the motion.
        stretches = _runs_of(cruise)
        c0, c1 = max(stretches, key=lambda s: s[1] - s[0])
        a, b = i0 + c0, i0 + c1  # cruise over sample intervals [a, b) -> samples a..b
        if (b - a) / fs_hz < min_cruise_s:
            continue
        tt, pp = t[a:b + 1], p[a:b + 1]
        slope = float(np.polyfit(tt - tt[0], pp, 1)[0])
        motions.append(Motion(int(np.sign(slope)), abs(slope), float(t[a]), float(t[b]),
                              float(p[a]), float(p[b])))
    still = []
    for i0, i1 in _runs_of(~moving):
        t0 = t[i0] + (settle_s if i0 > 0 else 0.0)
        t1 = t[min(i1, p.size - 1)]
        if t1 - t0 > 0.05:
            still.append((float(t0), float(t1)))
    return RunSegments(tuple(motions), tuple(still))


def load_run(m: Measurements, session: str, run: str) -> Phase2Run:
    """Read a run, turning any reader error into :class:`BadRunError` naming session and run,
    and checking that the IMU channels cover the commanded motion (a run cut short; without
    ``position_cmd``, that both IMU channels cover the same time)."""
    try:
        r = m.phase2(session, run)
    except DatasetError as e:
        msg = str(e)
        if msg.startswith(f"{m.label}: "):
            msg = msg[len(m.label) + 2:]
        raise BadRunError(f"{m.label}: session {session}, run {run}: {msg}") from None
    if r.position_cmd is not None:
        t_cmd, ref = (r.position_cmd.size - 1) / r.position_cmd_fs_hz, "position_cmd"
    else:  # a stand-alone IMU: its two channels must cover the same time (a cut one is short)
        t_cmd, ref = max((r.imu_acc.shape[0] - 1) / r.imu_acc_fs_hz,
                         (r.imu_gyro.shape[0] - 1) / r.imu_gyro_fs_hz), "the other IMU channel"
    for name in ("imu_acc", "imu_gyro"):  # (the reader has refused non-finite samples)
        arr = getattr(r, name)
        fs = getattr(r, f"{name}_fs_hz")
        t_end = (arr.shape[0] - 1) / fs
        if t_end < t_cmd - 0.05:
            raise BadRunError(
                f"{m.label}: session {session}, run {run}, channel {name}: run cut short, "
                f"{name} ends at {t_end:.3f} s but {ref} at {t_cmd:.3f} s; expected the "
                f"IMU to cover the whole commanded motion")
    return r


def _still_slices(t: np.ndarray, still: tuple[tuple[float, float], ...]) -> list[slice]:
    """The samples of ``t`` (ascending, s) inside each stationary part [t0, t1], as slices."""
    return [slice(int(np.searchsorted(t, t0, "left")), int(np.searchsorted(t, t1, "right")))
            for t0, t1 in still]


def _still_mask(t: np.ndarray, still: tuple[tuple[float, float], ...]) -> np.ndarray:
    mask = np.zeros(t.size, dtype=bool)
    for part in _still_slices(t, still):
        mask[part] = True
    return mask


def remove_bias(values: np.ndarray, fs_hz: float, still: tuple[tuple[float, float], ...], *,
                drift: bool, label: str) -> np.ndarray:
    """Subtract the stationary reading from ``values`` (n, 3).

    drift=True (gyro): mean over each stationary part, interpolated linearly in time between
    their centres (held constant outside); drift=False (accelerometer): one mean over all
    stationary parts. Raises :class:`BadRunError` if there is no stationary part.
    """
    t = np.arange(values.shape[0]) / fs_hz
    if not still:
        raise BadRunError(f"{label}: no stationary part to estimate the bias from")
    if not drift:
        mask = _still_mask(t, still)
        if not mask.any():
            raise BadRunError(f"{label}: no stationary sample to estimate the bias from")
        return values - values[mask].mean(axis=0)
    centres, means = [], []
    for (t0, t1), part in zip(still, _still_slices(t, still), strict=True):
        if part.stop - part.start >= 10:
            centres.append(0.5 * (t0 + t1))
            means.append(values[part].mean(axis=0))
    if not centres:
        raise BadRunError(f"{label}: no stationary part to estimate the bias from")
    c = np.asarray(centres)
    mu = np.asarray(means)
    bias = np.column_stack([np.interp(t, c, mu[:, j]) for j in range(values.shape[1])])
    return values - bias


def cruise_window(motion: Motion, trim_s: float, trim_end_s: float) -> tuple[float, float]:
    """Commanded-position span (lo, hi) m of the trimmed cruise of ``motion``."""
    xa = motion.x0_m + motion.velocity_m_s * trim_s
    xb = motion.x1_m - motion.velocity_m_s * trim_end_s
    return min(xa, xb), max(xa, xb)


def lowpass_power(f_hz: np.ndarray, cutoff_hz: float, order: int) -> np.ndarray:
    """Magnitude of the zero-phase low-pass of :func:`grid_motion`: a Butterworth of ``order``
    run forward and backward (``scipy.signal.sosfiltfilt``), |H|² = 1/(1+(f/f_c)^(2·order))."""
    if not math.isfinite(cutoff_hz):
        return np.ones_like(np.asarray(f_hz, dtype=float))
    return 1.0 / (1.0 + (np.asarray(f_hz, dtype=float) / cutoff_hz) ** (2 * order))


def grid_motion(values: np.ndarray, fs_hz: float, delay_s: float, motion: Motion,
                grid: np.ndarray, *, cutoff_hz: float, order: int, trim_s: float,
                trim_end_s: float) -> np.ndarray:
    """Signal ``values`` (n, c) of one motion resampled onto the commanded-position ``grid`` (g,) m.

    The samples of the trimmed cruise, plus up to 20 ms of the cruise either side (the
    accelerations are left out: a zero-phase filter would smear them into the cruise), are low-passed with a zero-phase
    Butterworth at ``cutoff_hz`` (anti-aliasing for the grid and removal of content above the band
    the fusion uses; skipped when ``cutoff_hz`` is inf or above 0.45·fs), then read by cubic
    interpolation at the sample time of each grid point: t(x) = t0 + (x − x0)/v is when the
    command passes x (exact: the cruise command is linear in t), plus the sensor delay. Grid
    points outside the trimmed cruise are NaN. Returns (g, c).
    """
    v = motion.velocity_m_s
    lo, hi = cruise_window(motion, trim_s, trim_end_s)
    out = np.full((grid.size, values.shape[1]), np.nan)
    a, b = np.searchsorted(grid, lo - 1e-12, "left"), np.searchsorted(grid, hi + 1e-12, "right")
    if a >= b:
        return out
    t_samp = motion.t0_s + (grid[a:b] - motion.x0_m) / v + delay_s  # sample-clock time
    margin = 0.02  # s of cruise beyond the trimmed part, when there is, to pad the filter
    ta = max(motion.t0_s, motion.t0_s + trim_s - margin) + delay_s
    tb = min(motion.t1_s, motion.t1_s - trim_end_s + margin) + delay_s
    i0 = max(math.floor(ta * fs_hz) - 2, 0)
    i1 = min(math.ceil(tb * fs_hz) + 2, values.shape[0] - 1)
    seg = values[i0:i1 + 1]
    if seg.shape[0] < 8:
        return out
    rows = np.ascontiguousarray(seg.T)  # one row per channel: the layout of the filter and spline
    if math.isfinite(cutoff_hz) and cutoff_hz < 0.45 * fs_hz:
        rows = _zero_phase_lowpass(rows, order, float(cutoff_hz), float(fs_hz))
    pos = t_samp * fs_hz - i0  # monotonic along the grid: the samples it covers are one stretch
    ok = np.flatnonzero((pos >= 0) & (pos <= rows.shape[1] - 1))
    if ok.size:
        c0, c1 = int(ok[0]), int(ok[-1]) + 1
        out[a + c0:a + c1] = not_a_knot_cubic_rows(rows, pos[c0:c1]).T
    return out


@functools.lru_cache(maxsize=64)
def _lowpass(order: int, cutoff_hz: float, fs_hz: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The Butterworth low-pass of :func:`grid_motion` as second-order sections (s, 6), their
    steady-state initial conditions per unit step (s, 2) (``scipy.signal.sosfilt_zi``) and the
    edge padding of ``scipy.signal.sosfiltfilt`` (3 × its tap count), designed once per (order,
    cutoff, rate): a session grids every run with the same few filters."""
    sos = signal.butter(order, cutoff_hz, fs=fs_hz, output="sos")
    zi = signal.sosfilt_zi(sos)
    taps = 2 * sos.shape[0] + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum()))
    zi.flags.writeable = False  # (sos stays writeable: scipy's sosfilt takes a writeable buffer)
    return sos, zi, 3 * taps


def _zero_phase_lowpass(rows: np.ndarray, order: int, cutoff_hz: float, fs_hz: float) -> np.ndarray:
    """``scipy.signal.sosfiltfilt(sos, rows, axis=-1)`` with its defaults (odd extension of
    3 × taps samples at each end, steady-state initial conditions, forward then backward pass;
    Gustafsson, IEEE Trans. Signal Process. 44(4), 1996), the filter design and its initial
    conditions taken from :func:`_lowpass` instead of recomputed per call; the same arithmetic,
    so the same numbers. ``rows`` (c, n), n > 3 × taps; returns (c, n)."""
    sos, zi, pad = _lowpass(order, cutoff_hz, fs_hz)
    n = rows.shape[-1]
    if n <= pad:
        return signal.sosfiltfilt(sos, rows, axis=-1)  # scipy's own message for too short input
    first, last = rows[:, :1], rows[:, -1:]
    ext = np.concatenate((2 * first - rows[:, pad:0:-1], rows, 2 * last - rows[:, -2:-(pad + 2):-1]),
                         axis=-1)
    zi = zi[:, None, :]  # (s, 1, 2): broadcast over the rows
    y, _ = signal.sosfilt(sos, ext, axis=-1, zi=zi * ext[:, :1])
    y, _ = signal.sosfilt(sos, y[:, ::-1], axis=-1, zi=zi * y[:, -1:])
    return y[:, ::-1][:, pad:-pad]
