"""The strokes of a Phase II run found from the IMU alone: when each acceleration and deceleration
of the carriage happened, from the pulses they leave in the accelerometer's x axis.

This is the first step of an IMU-based position reference (the paper's ref. [34], Vogl et al.,
"Inertial Measurement Unit for On-Machine Diagnostics of Machine Tool Linear Axes", PHM Society
2016): the stroke events are found in the IMU's own clock, without the controller's
``position_cmd``, and the routine's nominal trapezoid is placed between them.

Method (derived here). The routine is known from the recording's metadata: the speeds v, the
acceleration a, and the order of the moves (forward then reverse at each speed, a dwell after each
move). Each move leaves two rectangular pulses of height ±a and length T = v/a in the carriage's
acceleration: + then − forward, − then + in reverse. The pulses are looked for in that order,
each within a window around where the nominal routine puts it after the previous one (the
cruise takes (L − v²/a)/v, the dwell is known), by a matched filter (a moving sum of length T of
the signed acceleration). Each pulse is then timed (``timing``):

- ``half_velocity``: the instant the velocity change, integrated from before the pulse, reaches
  v/2, less the sensor's delay for such a pulse (:func:`half_velocity_delay`). Precise for short
  pulses (the paper's 19.6 m/s²: within 0.1 IMU sample), but on a slow ramp it does not move with
  the travel the carriage makes: a carriage that first crosses a clearance b reaches half speed
  when it would have without it.
- ``centroid``: the pulse's centroid ∫t·a dt / ∫a dt, less the filter's DC group delay
  (:func:`centroid_delay`). The centroid is t_end − (travel during the pulse)/v, so it moves by
  b/v with the travel; but the window's edges weigh the cruise's vibration (the velocity there
  times half the window), which moves it with the origin, and its noise grows as the window^1.5.
- ``travel`` (default): pulses shorter than ``EDGE_MIN_S`` as ``half_velocity``; longer ones (a
  slow ramp) by the two things that decide where the cruise lies on the carriage's path. (1) The
  pulse's *cruise-side* edge (the end of an acceleration, the start of a deceleration), which a
  clearance does not move: a step detector, then a least-squares fit of the sensor's step
  response with a local level and slope (:func:`edge_time`). (2) The travel the carriage lost
  against the nominal ramp on its *rest* side, where it first crosses the clearance: the velocity
  integrated from the rest (zero there) against the ramp placed by the edge, over the first
  ``deficit_window_s`` of the ramp (:func:`rest_side_deficit`). The pulse is placed where a
  nominal pulse with the same travel would lie (the centroid's definition, without its window):
  start = edge − T + lost/v for an acceleration, edge − lost/v for a deceleration. A carriage
  that travels D = L − b between rests then stretches the axis by L/(L − b), as Eq. 9 of
  Pandhare et al., "Ball Screw Health Monitoring with Inertial Sensors", assumes.

A linear low-pass of unit DC gain moves any pulse's centroid, and delays a ramp, by exactly its
group delay at DC, which is removed. The carriage's axial mode rings after each edge and biases
the timing by a fixed amount for a given axis state; the bias is common to every session with
the same dynamics.

Units SI: s, m/s, m/s².
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from analysis.phase2.imu_runs import BadRunError, Motion, RunSegments

__all__ = ["Pulse", "StrokeError", "TIMINGS", "centroid_delay", "find_pulses", "half_velocity_delay",
           "imu_segments", "routine_pulses", "imu_run_segments"]

TIMINGS = ("travel", "centroid", "half_velocity")
"""How :func:`find_pulses` times a pulse (see the module docstring): ``travel`` (default; pulses
shorter than ``EDGE_MIN_S`` by their half-velocity instant), ``centroid``, ``half_velocity``."""
EDGE_MIN_S = 0.05
"""Pulses at least this long (s) are timed by their cruise-side edge and rest-side travel."""


class StrokeError(BadRunError):
    """The expected pulses of the routine could not be found in the accelerometer signal."""


@dataclass(frozen=True)
class Pulse:
    """One acceleration pulse of the carriage.

    sign: +1 (acceleration towards +X) or −1; speed_m_s: the cruise speed of its move;
    start_s: when the pulse began (IMU clock, sensor delay removed), s; length_s: its nominal
    length v/a, s; area_m_s: the measured velocity change over the window, m/s (≈ sign·v).
    """

    sign: int
    speed_m_s: float
    start_s: float
    length_s: float
    area_m_s: float

    @property
    def end_s(self) -> float:
        return self.start_s + self.length_s


def routine_pulses(speeds_m_s: tuple[float, ...], accel_m_s2: float, stroke_m: float,
                   dwell_s: float) -> list[tuple[int, float, float]]:
    """The nominal pulse sequence of one run: ``(sign, speed, time after the previous pulse's
    start)`` per pulse, forward then reverse at each speed (the first pulse's delay is 0)."""
    out = []
    prev_t_acc = 0.0
    for v in speeds_m_s:
        t_acc = min(v / accel_m_s2, math.sqrt(stroke_m / accel_m_s2))
        v_pk = accel_m_s2 * t_acc
        cruise = max((stroke_m - v_pk * t_acc) / v_pk, 0.0)
        for sign in (1, -1):
            # accel: after the previous deceleration and the dwell; decel: after accel and cruise
            out.append((sign, v, prev_t_acc + dwell_s if out else 0.0))
            out.append((-sign, v, t_acc + cruise))
            prev_t_acc = t_acc
    return out


def find_pulses(acc_x: np.ndarray, fs_hz: float, delay_s: float | Mapping[float, float],
                speeds_m_s: tuple[float, ...],
                accel_m_s2: float, stroke_m: float, dwell_s: float, *, first_after_s: float = 0.0,
                window_fraction: float = 0.02, timing: str = "travel",
                bandwidth_hz: float | None = None, edge_min_s: float = EDGE_MIN_S,
                deficit_window_s: float = 0.05, label: str = "imu_acc") -> list[Pulse]:
    """Find and time every acceleration pulse of a run (see the module docstring).

    Args:
        acc_x: (n,) accelerometer samples along the travel, m/s² (bias included; the median,
            the standstill reading of a run that mostly rests or cruises, is removed).
        fs_hz: its sampling rate, Hz; delay_s: how late the sensor shows the pulses of each
            speed, s, or {speed: delay}: the half-velocity instant's delay
            (:func:`half_velocity_delay`) for pulses timed by it, the DC group delay
            (:func:`centroid_delay`) for those timed by their travel or centroid.
        speeds_m_s, accel_m_s2, stroke_m, dwell_s: the routine (from the recording's metadata).
        first_after_s: the first pulse is searched after this time, s.
        window_fraction: each later pulse is searched within ± (50 ms + this fraction of its
            nominal delay after the previous one); a window must not reach the pulse after it.
        timing: ``travel``, ``centroid`` or ``half_velocity`` (module docstring).
        bandwidth_hz: the sensor's half-power frequency, Hz (2nd-order Butterworth): needed by
            ``travel`` for pulses of ``edge_min_s`` or longer (the step response of their edges).
        edge_min_s: pulses at least this long are timed by their travel (``travel``), s.
        deficit_window_s: the part of a slow ramp next to the rest over which the travel lost to
            a clearance is measured, s (0.05 s at 0.05 m/s² covers a clearance of 62 µm; the
            double integral's noise grows as its 1.5 power).
        label: names the channel in errors.

    Returns:
        The pulses in time order, four per speed.

    Raises:
        StrokeError: a pulse is missing, of the wrong sign or too small (less than half the
            expected velocity change), naming the channel, the pulse and the time searched.
    """
    if timing not in TIMINGS:
        raise ValueError(f"timing is {timing!r}; expected one of {TIMINGS}")
    a = np.asarray(acc_x, dtype=float)
    if a.ndim != 1 or a.size < 16 or not np.all(np.isfinite(a)):
        raise StrokeError(f"{label}: expected a finite 1-D signal of at least 16 samples")
    a = a - np.median(a)
    t = np.arange(a.size) / fs_hz
    csum = np.concatenate([[0.0], np.cumsum(a)]) / fs_hz  # ∫a dt up to each sample
    plan = routine_pulses(tuple(speeds_m_s), accel_m_s2, stroke_m, dwell_s)
    response = None
    if timing == "travel" and any(v / accel_m_s2 >= edge_min_s for v in speeds_m_s):
        if bandwidth_hz is None:
            raise ValueError(f"timing 'travel' with pulses of {edge_min_s:g} s or longer needs the "
                             "sensor's bandwidth_hz (its step response times the edges)")
        response = _step_response(bandwidth_hz)
    pulses: list[Pulse] = []
    prev_start = None
    for k, (sign, v, after) in enumerate(plan):
        delay = float(delay_s) if isinstance(delay_s, (int, float)) else delay_s[v]
        length = v / accel_m_s2
        w = max(int(round(length * fs_hz)), 1)
        if prev_start is None:
            lo, hi = first_after_s, t[-1]
        else:
            slack = 0.05 + window_fraction * after
            lo, hi = prev_start + after - slack, prev_start + after + slack
        i0 = max(int(math.floor((lo + delay) * fs_hz)), 0)
        i1 = min(int(math.ceil((hi + delay) * fs_hz)) + w, a.size - 1)
        if i1 - i0 <= w:
            raise StrokeError(f"{label}: pulse {k + 1} of {len(plan)} ({'+' if sign > 0 else '−'}"
                              f"{accel_m_s2:g} m/s² at {v * 1e3:g} mm/s) expected at "
                              f"{lo:.3f}–{hi:.3f} s, after the end of the recording ({t[-1]:.3f} s)")
        # matched filter: the signed velocity change over w samples starting at each index
        dv = sign * (csum[i0 + w:i1 + 1] - csum[i0:i1 + 1 - w])
        if prev_start is None:  # the first pulse: the earliest window that changes v by half
            above = np.flatnonzero(dv >= 0.5 * v)
            j = int(above[0]) if above.size else int(np.argmax(dv))
            j += int(np.argmax(dv[j:j + w + 1]))
        else:
            j = int(np.argmax(dv))
        if dv[j] < 0.5 * v:
            raise StrokeError(f"{label}: pulse {k + 1} of {len(plan)} ({'+' if sign > 0 else '−'}"
                              f"{accel_m_s2:g} m/s² at {v * 1e3:g} mm/s) not found in "
                              f"{lo:.3f}–{hi:.3f} s: the largest velocity change there is "
                              f"{dv[j] * 1e3:+.1f} mm/s; expected about {v * 1e3:g} mm/s")
        pad = int(math.ceil(max(3.0 * delay, 0.01) * fs_hz)) + 2  # 10 ms: the axial mode's period
        c0, c1 = max(i0 + j - pad, 0), min(i0 + j + w + pad, a.size - 1)
        rise = sign * (csum[c0:c1 + 1] - csum[c0])
        area = float(rise[-1])
        if timing == "travel" and length >= edge_min_s:
            # the cruise-side edge (unaffected by the clearance), then the travel lost near the
            # rest side: the pulse is placed where a nominal ramp with the same travel would be
            from_rest = k % 2 == 0
            t_w = (i0 + j) / fs_hz - delay  # the matched window's start, true time
            guess = t_w + length if from_rest else t_w
            edge = edge_time(a, fs_hz, guess + delay, -sign if from_rest else sign, response,
                             search_s=min(0.25 * length, 0.1))
            if not math.isfinite(edge):
                raise StrokeError(f"{label}: pulse {k + 1} of {len(plan)}: its cruise-side edge near "
                                  f"{guess:.3f} s is outside the recording")
            rest_edge = edge - length if from_rest else edge + length
            lost = rest_side_deficit(a, fs_hz, sign, accel_m_s2, length, rest_edge, delay, from_rest,
                                     deficit_window_s, pad / fs_hz)
            centre = (edge - 0.5 * length + lost / v) if from_rest else (edge + 0.5 * length - lost / v)
        elif timing == "centroid":
            # the pulse's centroid ∫t·a dt / ∫a dt over the window (samples at t_i = i/fs)
            seg = a[c0:c1]
            centre = float(np.sum(t[c0:c1] * seg) / np.sum(seg)) - delay
        else:
            # half-velocity time: when the velocity change, integrated from before the pulse,
            # reaches half the nominal v (sub-sample by linear interpolation)
            k_half = int(np.argmax(rise >= 0.5 * v))
            if k_half == 0:
                raise StrokeError(f"{label}: pulse {k + 1} of {len(plan)} at {t[c0]:.3f} s: the velocity "
                                  f"change does not rise through half of {v * 1e3:g} mm/s")
            frac = (0.5 * v - rise[k_half - 1]) / (rise[k_half] - rise[k_half - 1])
            # csum[i] sums samples 0..i-1, each standing for ±half a sample about its instant
            centre = (c0 + k_half - 1 + frac - 0.5) / fs_hz - delay
        start = centre - 0.5 * length
        pulses.append(Pulse(sign, v, start, length, sign * area))
        prev_start = start
    return pulses


def _step_response(bandwidth_hz: float, order: int = 2):
    """The unit-step response s(t) of the analog Butterworth low-pass (``scipy.signal.butter``
    with ``analog=True``, ``scipy.signal.step``) as a callable of t (s), 0 before the step."""
    from scipy import signal

    wc = 2.0 * math.pi * bandwidth_hz
    tt = np.linspace(0.0, 40.0 / wc * order, 4001)
    _, y = signal.step(signal.butter(order, wc, analog=True), T=tt)
    return lambda x: np.interp(x, tt, y, left=0.0, right=float(y[-1]))


def edge_time(a: np.ndarray, fs_hz: float, guess_s: float, step: float, response, *,
              search_s: float, half_window_s: float = 0.005) -> float:
    """The instant of a step of the acceleration (true time, the sensor's response removed), s.

    Two stages. First a step detector (the difference of the means over ``half_window_s``
    before and after each sample, signed by ``step``) locates the edge to a sample within
    ``guess_s`` ± ``search_s``. Then the step is timed by nonlinear least squares
    (maximum likelihood in white noise; Kay, *Fundamentals of Statistical Signal Processing:
    Estimation Theory*, 1993, ch. 7, and its time-delay example of ch. 3): the samples within
    ``half_window_s`` either side are fitted by c0 + c1·(t − τ) + A·s(t − τ), with s the sensor's
    step response (``response``), the local level and slope free (they take up the slow
    vibration of the cruise), and τ the only nonlinear parameter. Bounded scalar minimisation
    over τ within ± two samples of the detector's edge (``scipy.optimize.minimize_scalar``).
    """
    from scipy.optimize import minimize_scalar

    h = max(int(round(half_window_s * fs_hz)), 2)
    n = a.size
    i_lo = max(int(math.floor((guess_s - search_s) * fs_hz)), h)
    i_hi = min(int(math.ceil((guess_s + search_s) * fs_hz)), n - h - 1)
    if i_hi <= i_lo:
        return float("nan")
    cs = np.concatenate([[0.0], np.cumsum(a)])
    idx = np.arange(i_lo, i_hi + 1)
    detector = step * ((cs[idx + h] - cs[idx]) - (cs[idx] - cs[idx - h])) / h
    i_e = int(idx[np.argmax(detector)])
    j0, j1 = max(i_e - h, 0), min(i_e + h + 1, n)
    tj = np.arange(j0, j1) / fs_hz
    yj = a[j0:j1]

    def rss(tau: float) -> float:
        design = np.column_stack([np.ones_like(tj), tj - tau, response(tj - tau)])
        coef, *_ = np.linalg.lstsq(design, yj, rcond=None)
        r = yj - design @ coef
        return float(r @ r)

    res = minimize_scalar(rss, bounds=((i_e - 2) / fs_hz, (i_e + 2) / fs_hz), method="bounded",
                          options={"xatol": 1e-7})
    return float(res.x)


def rest_side_deficit(a: np.ndarray, fs_hz: float, sign: int, accel_m_s2: float, length_s: float,
                      rest_edge_s: float, delay_s: float, from_rest: bool, window_s: float,
                      pad_s: float) -> float:
    """How much less the carriage travelled than the nominal ramp near the pulse's rest side, m.

    The ramp's velocity v_nom(t) (acceleration ``sign``·``accel_m_s2`` for ``length_s``, its rest
    side at ``rest_edge_s``, true time) is compared with the velocity integrated from the rest
    (v = 0 there exactly): forward from ``pad_s`` before a pulse that starts from rest
    (``from_rest``), backward from ``pad_s`` after one that ends at rest. The deficit
    ∫(v_nom − v) dt, in the direction of motion, runs over the ``window_s`` of the ramp next to
    the rest plus the pads, where a carriage that first crosses the clearance (or coasts across
    it) departs from the ramp; there the double integral's noise grows only as window^1.5. The
    sensor's response delays the measured velocity of a ramp by its DC group delay ``delay_s``,
    which the nominal is shifted by. Samples at t_i = i/fs, each standing for ±half a sample.
    """
    n = a.size
    span = min(window_s, length_s)
    if from_rest:
        t_lo, t_hi = rest_edge_s + delay_s - pad_s, rest_edge_s + delay_s + span + pad_s
    else:
        t_lo, t_hi = rest_edge_s + delay_s - span - pad_s, rest_edge_s + delay_s + pad_s
    i0, i1 = max(int(math.floor(t_lo * fs_hz)), 0), min(int(math.ceil(t_hi * fs_hz)), n - 1)
    seg = a[i0:i1 + 1]
    ti = np.arange(i0, i1 + 1) / fs_hz - delay_s  # true time of each sample's content
    if from_rest:
        v = (np.cumsum(seg) - 0.5 * seg) / fs_hz
        v_nom = accel_m_s2 * np.clip(ti - rest_edge_s, 0.0, length_s)
        direction = sign
    else:
        v = -(np.cumsum(seg[::-1])[::-1] - 0.5 * seg) / fs_hz
        v_nom = accel_m_s2 * np.clip(rest_edge_s - ti, 0.0, length_s)
        direction = -sign
    v_nom = direction * v_nom
    return float(direction * np.sum(v_nom - v) / fs_hz)


def centroid_delay(bandwidth_hz: float, order: int = 2) -> float:
    """How much later a Butterworth low-pass of ``order`` and half-power ``bandwidth_hz`` shows
    the centroid ∫t·a dt / ∫a dt of any pulse, s: its group delay at DC.

    A linear filter of impulse response h and unit DC gain moves the centroid of any input by the
    centroid of h (the first moment of a convolution is the sum of the first moments: Papoulis,
    *The Fourier Integral and its Applications*, 1962, ch. 2, moments of a convolution), which is
    the group delay at zero frequency, −dφ/dω(0). For the analog Butterworth with poles
    p_k = ω_c·exp(jπ(2k + n − 1)/(2n)) it is Σ −Re(p_k)/|p_k|² = 1/(ω_c·sin(π/(2n)))
    (e.g. Williams & Taylor, *Electronic Filter Design Handbook*, 4th ed., ch. 2): √2/(2π·f_c)
    for order 2, independent of the pulse's length (unlike :func:`half_velocity_delay`).
    """
    if not (bandwidth_hz > 0 and order >= 1):
        raise ValueError(f"bandwidth_hz = {bandwidth_hz!r}, order = {order!r}: expected > 0 Hz and >= 1")
    return 1.0 / (2.0 * math.pi * bandwidth_hz * math.sin(math.pi / (2 * order)))


def half_velocity_delay(length_s: float, bandwidth_hz: float, order: int = 2) -> float:
    """How much later a Butterworth low-pass of ``order`` and half-power ``bandwidth_hz`` shows
    the half-velocity instant of a rectangular acceleration pulse of ``length_s``, s.

    Computed by filtering the pulse on a fine clock (``scipy.signal.butter`` + ``lfilter``, a
    causal filter as in the sensor). For pulses much longer than 1/bandwidth it tends to the
    filter's group delay at DC (√2/(2π·f_c) for order 2).
    """
    from scipy import signal

    fs = max(200.0 * bandwidth_hz, 20.0 / length_s)
    n_pulse = max(int(round(length_s * fs)), 1)
    n = n_pulse + int(40.0 * fs / bandwidth_hz)
    x = np.zeros(n)
    x[:n_pulse] = 1.0
    b, a = signal.butter(order, bandwidth_hz, fs=fs)
    y = np.cumsum(signal.lfilter(b, a, x)) / fs
    half = 0.5 * n_pulse / fs
    k = int(np.argmax(y >= half))
    t_half = (k - 1 + (half - y[k - 1]) / (y[k] - y[k - 1])) / fs + 1.0 / fs
    return float(t_half - 0.5 * n_pulse / fs)


def imu_segments(acc_x: np.ndarray, fs_hz: float, speeds_mm_s: tuple[float, ...], routine: Mapping[str, float],
                 acc_bandwidth_hz: float, *, settle_s: float = 0.2, timing: str = "travel",
                 edge_min_s: float = EDGE_MIN_S, label: str = "imu_acc") -> RunSegments:
    """The cruises and stationary parts of a run on the IMU-based position axis.

    The strokes are timed from the accelerometer (:func:`find_pulses`, the sensor's delay from its
    bandwidth, a 2nd-order Butterworth); between the end of each acceleration and the start of the
    deceleration the carriage is taken to cruise along the routine's nominal trapezoid: from
    start + v²/2a to end − v²/2a forward (the reverse mirrored), at the speed that covers that
    nominal length in the time the IMU saw. The axis is the nominal stroke mapped onto the
    carriage's own motion: rail-fixed features stay put, and a carriage that travels D ≠ L
    between rests stretches onto L (what the paper's Eq. 9 reads).

    Args:
        acc_x: (n,) accelerometer samples along the travel, m/s²; fs_hz: its rate, Hz.
        speeds_mm_s: the routine's speeds, mm/s; routine: ``accel_mm_s2``, ``start_mm``,
            ``end_mm``, ``dwell_s`` (the run's metadata).
        acc_bandwidth_hz: the accelerometer's half-power frequency, Hz.
        settle_s: time left out after each stop before a stationary part begins, s.

    Raises:
        BadRunError: routine metadata missing (naming the keys), or a pulse not found.
    """
    missing = [k for k in ("accel_mm_s2", "start_mm", "end_mm", "dwell_s") if k not in routine]
    if missing or not speeds_mm_s:
        what = ", ".join(missing + ([] if speeds_mm_s else ["speeds_mm_s"]))
        raise BadRunError(f"{label}: the run's routine metadata lacks {what}; expected the attributes "
                          "speeds_mm_s, accel_mm_s2, start_mm, end_mm, dwell_s to find the strokes from "
                          "the IMU (or analyse with the command position reference)")
    accel = routine["accel_mm_s2"] * 1e-3
    start, end = routine["start_mm"] * 1e-3, routine["end_mm"] * 1e-3
    speeds = tuple(v * 1e-3 for v in speeds_mm_s)
    # the pulses timed by their travel or centroid show the filter's DC group delay, the short ones
    # timed by their half-velocity instant a little more (see find_pulses)
    delays = {v: centroid_delay(acc_bandwidth_hz)
              if timing == "centroid" or (timing == "travel" and v / accel >= edge_min_s)
              else half_velocity_delay(v / accel, acc_bandwidth_hz) for v in speeds}
    pulses = find_pulses(acc_x, fs_hz, delays, speeds, accel, abs(end - start), routine["dwell_s"],
                         timing=timing, bandwidth_hz=acc_bandwidth_hz, edge_min_s=edge_min_s, label=label)
    motions = []
    for acc_p, dec_p in zip(pulses[0::2], pulses[1::2], strict=True):
        v = acc_p.speed_m_s
        ramp = 0.5 * v * v / accel
        forward = acc_p.sign > 0
        x0, x1 = (start + ramp, end - ramp) if forward else (end - ramp, start + ramp)
        t0, t1 = acc_p.end_s, dec_p.start_s
        if t1 - t0 <= 0:
            raise BadRunError(f"{label}: the {v * 1e3:g} mm/s {'forward' if forward else 'reverse'} stroke "
                              f"has no constant-velocity part between {t0:.3f} s and {t1:.3f} s")
        motions.append(Motion(1 if forward else -1, abs(x1 - x0) / (t1 - t0), t0, t1, x0, x1))
    t_end = (np.asarray(acc_x).size - 1) / fs_hz
    bounds = [(0.0, pulses[0].start_s)]
    bounds += [(dec.end_s + settle_s, nxt.start_s) for dec, nxt in zip(pulses[1::2], pulses[2::2], strict=False)]
    bounds.append((pulses[-1].end_s + settle_s, t_end))
    still = tuple((a, b) for a, b in bounds if b - a > 0.05)
    return RunSegments(tuple(motions), still)



def imu_run_segments(run, acc_bandwidth_hz: float, *, timing: str = "travel", label: str = "imu_acc"
                     ) -> tuple[RunSegments, list[tuple[float, float]]]:
    """:func:`imu_segments` of a Phase II run (an :class:`analysis.dataset.Phase2Run`, its
    speeds and routine metadata), and the intervals (t0, t1) s in which the axis moves: each
    cruise widened by its ramp time v/a. ``acc_bandwidth_hz``: the accelerometer's half-power
    frequency, Hz."""
    seg = imu_segments(run.imu_acc[:, 0], run.imu_acc_fs_hz, run.speeds_mm_s or (), run.routine,
                       acc_bandwidth_hz, timing=timing, label=label)
    accel = run.routine["accel_mm_s2"] * 1e-3
    return seg, [(mo.t0_s - mo.speed_m_s / accel, mo.t1_s + mo.speed_m_s / accel) for mo in seg.motions]
