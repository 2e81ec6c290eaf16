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

    Returns:
        :class:`Segmentation`; ``steady`` and ``transient`` may be empty (the caller decides
        whether that is an error).
    """
    v = np.abs(np.asarray(speed, dtype=float))
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
