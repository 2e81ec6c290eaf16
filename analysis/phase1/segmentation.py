"""Speed-based segmentation of one Phase I capture (paper section IV, Fig. 3).

The motor speed is the reference: a *steady* segment is a stretch where ``|speed|`` stays at the
plateau of the reciprocating routine (constant 400 mm/s in Table I); a *transient* segment is an
acceleration from standstill up to that plateau. Accelerometer and torque signals are cut with the
same index ranges. Only the measured speed is used (no scenario or command), so recordings of a
real testbed segment the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Segment", "Segmentation", "segment_capture"]


@dataclass(frozen=True)
class Segment:
    """Index range ``[start, stop)`` of a capture and the direction of motion (+1 or -1)."""

    start: int
    stop: int
    direction: int

    @property
    def slice(self) -> slice:
        return slice(self.start, self.stop)

    def __len__(self) -> int:
        return self.stop - self.start


@dataclass(frozen=True)
class Segmentation:
    """Segments of one capture.

    plateau_rad_s: plateau of |speed| (rad/s); f_rot_hz: rotational frequency plateau/(2 pi) (Hz);
    steady: constant-speed segments (trimmed); transient: accelerations from rest to the plateau,
    each starting where |speed| leaves rest and ending where the steady segment begins.
    """

    plateau_rad_s: float
    f_rot_hz: float
    steady: tuple[Segment, ...]
    transient: tuple[Segment, ...]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of every run of True in a boolean (n,) array."""
    d = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def segment_capture(
    speed: np.ndarray,
    fs_hz: float,
    *,
    steady_tol: float = 0.02,
    rest_tol: float = 0.02,
    trim_s: float = 0.02,
    min_steady_s: float = 0.1,
) -> Segmentation:
    """Segment a capture by its speed signal.

    Args:
        speed: (n,) motor speed in rad/s.
        fs_hz: sampling rate in Hz.
        steady_tol: a sample is steady when ``|speed| >= (1 - steady_tol) * plateau``; the plateau
            is the 99th percentile of ``|speed|``.
        rest_tol: a sample is at rest when ``|speed| < rest_tol * plateau``.
        trim_s: seconds cut from both ends of each steady run (settling after the acceleration,
            start of the deceleration).
        min_steady_s: steady runs shorter than this after trimming are dropped.

    A transient segment is kept only when the motion starts inside the capture (the speed is at
    rest before it); a steady run touching the capture's end is kept if long enough.

    A speed whose ripple (cogging, torque ripple: orders of the motor's revolution) breaks the
    plateau into pieces shorter than ``min_steady_s`` is segmented on its moving average over one
    revolution at the plateau speed, which removes every order of the revolution (the segments
    of a speed without such ripple are those of the raw speed, unchanged).

    Returns:
        :class:`Segmentation`; ``steady`` and ``transient`` may be empty (the caller decides
        whether that is an error).
    """
    speed = np.asarray(speed, dtype=float)
    seg = _segment(speed, np.abs(speed), fs_hz, steady_tol, rest_tol, trim_s, min_steady_s)
    if not seg.plateau_rad_s > 0.0:
        return seg
    rev = int(round(2.0 * np.pi / seg.plateau_rad_s * fs_hz))  # samples of one revolution
    if rev < 2 or rev >= speed.size:
        return seg
    smooth = _segment(speed, np.abs(_moving_mean(speed, rev)), fs_hz, steady_tol, rest_tol, trim_s,
                      min_steady_s)
    # the mean over a revolution rounds the ramps' corners, so on a speed without ripple its
    # plateau is a little shorter than the raw speed's; only a plateau the ripple broke up gains
    return smooth if _steady_samples(smooth) > RIPPLE_GAIN * _steady_samples(seg) else seg


#: How much longer the steady segments of the speed's mean over a revolution must be than the
#: raw speed's for the ripple to be taken as what broke the plateau up.
RIPPLE_GAIN = 1.5


def _steady_samples(seg: Segmentation) -> int:
    return sum(len(s) for s in seg.steady)


def _moving_mean(x: np.ndarray, k: int) -> np.ndarray:
    """Centred moving average of ``x`` (n,) over ``k`` samples (zeros beyond the ends), (n,)."""
    padded = np.concatenate([np.zeros(k // 2), x, np.zeros(k - 1 - k // 2)])
    c = np.concatenate([[0.0], np.cumsum(padded)])
    return (c[k:] - c[:-k]) / k


def _segment(speed: np.ndarray, v: np.ndarray, fs_hz: float, steady_tol: float, rest_tol: float,
             trim_s: float, min_steady_s: float) -> Segmentation:
    """:func:`segment_capture` on ``v`` (n,), the magnitude of ``speed`` or of its mean over a
    revolution; the directions come from ``speed``."""
    plateau = float(np.percentile(v, 99)) if v.size else 0.0
    if not np.isfinite(plateau) or plateau <= 0.0:
        return Segmentation(plateau, 0.0, (), ())
    trim = int(round(trim_s * fs_hz))
    min_len = int(round(min_steady_s * fs_hz))
    steady, transient = [], []
    for a, b in _runs(v >= (1.0 - steady_tol) * plateau):
        direction = 1 if speed[(a + b) // 2] > 0 else -1
        s0, s1 = a + trim, b - trim
        if s1 - s0 >= min_len:
            steady.append(Segment(s0, s1, direction))
        # Walk back from the start of the plateau to the last sample at rest.
        rest = np.flatnonzero(v[:a] < rest_tol * plateau)
        if rest.size and b - a >= min_len:
            m = int(rest[-1]) + 1
            # The motion must be a single acceleration in one direction (no reversal in between).
            if np.all(np.sign(speed[m:a]) == direction):
                transient.append(Segment(m, a, direction))
    return Segmentation(plateau, plateau / (2.0 * np.pi), tuple(steady), tuple(transient))
