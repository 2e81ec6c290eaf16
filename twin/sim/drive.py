"""Commanded motion: trapezoidal point-to-point moves with dwells (the routines of Table I).

A routine is a list of :class:`Move` segments; :func:`command_profile` samples the commanded
position, velocity and acceleration of the carriage on a uniform clock. Positions are in the
controller's frame (m, zero at the origin set by the operator).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Move:
    """One point-to-point move followed by a dwell.

    Attributes:
        start, end: commanded positions, m.
        speed: cruise speed, m/s (> 0).
        accel: acceleration and deceleration, m/s² (> 0).
        dwell: standstill after the move, s.
    """

    start: float
    end: float
    speed: float
    accel: float
    dwell: float

    @property
    def accel_time(self) -> float:
        """Time to reach cruise speed, s (shorter for a triangular profile)."""
        dist = abs(self.end - self.start)
        return min(self.speed / self.accel, math.sqrt(dist / self.accel))

    @property
    def move_time(self) -> float:
        """Duration of the motion without the dwell, s."""
        dist = abs(self.end - self.start)
        ta = self.accel_time
        vpk = self.accel * ta
        cruise = (dist - vpk * ta) / vpk if vpk > 0 else 0.0
        return 2.0 * ta + max(cruise, 0.0)

    @property
    def duration(self) -> float:
        return self.move_time + self.dwell


@dataclass(frozen=True)
class Profile:
    """Sampled command. t (n,) s; x (n,) m; v (n,) m/s; a (n,) m/s².

    rest_direction: sign (+1 or −1) of the motion that brought the axis to its rest before the
    first sample, which decides the nut flank the carriage rests on; 0 = that of the first
    motion (the carriage brought into contact by a move in the direction it starts in).
    moves, lead_in: the routine the profile samples (:func:`command_profile`), to sample it again
    at another clock (:meth:`position_at`)."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    rest_direction: float = 0.0
    moves: tuple[Move, ...] = ()
    lead_in: float = 0.0

    def position_at(self, fs: float, n: int, shift: float = 0.0) -> np.ndarray:
        """(n,) the commanded position sampled exactly at ``fs`` (k/fs + ``shift``, s), from the
        moves themselves: a controller's recorded command is the profile at its own clock, not
        an interpolation of the simulation's samples (which bends the short ramps' parabolas
        between samples). Without moves: linear interpolation of ``x``."""
        if not self.moves:
            return np.interp(np.arange(n) / fs + shift, self.t, self.x)
        return command_profile(list(self.moves), fs, lead_in=self.lead_in - shift, duration=n / fs).x


def _move_samples(move: Move, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position offset from start, velocity and acceleration of one move at local times tau."""
    sign = 1.0 if move.end >= move.start else -1.0
    dist = abs(move.end - move.start)
    ta = move.accel_time
    acc = move.accel
    vpk = acc * ta
    tm = move.move_time
    tc = tm - 2.0 * ta
    x = np.empty_like(tau)
    v = np.empty_like(tau)
    a = np.empty_like(tau)
    p1 = tau < ta
    p2 = (tau >= ta) & (tau < ta + tc)
    p3 = (tau >= ta + tc) & (tau < tm)
    p4 = tau >= tm
    x[p1], v[p1], a[p1] = 0.5 * acc * tau[p1] ** 2, acc * tau[p1], acc
    x[p2] = 0.5 * acc * ta**2 + vpk * (tau[p2] - ta)
    v[p2], a[p2] = vpk, 0.0
    rem = tm - tau[p3]
    x[p3], v[p3], a[p3] = dist - 0.5 * acc * rem**2, acc * rem, -acc
    x[p4], v[p4], a[p4] = dist, 0.0, 0.0
    return sign * x, sign * v, sign * a


def command_profile(moves: list[Move], fs: float, lead_in: float = 0.0,
                    duration: float | None = None) -> Profile:
    """Sample a routine at ``fs`` Hz.

    Args:
        moves: consecutive moves; each starts where the previous ended.
        fs: sample rate, Hz.
        lead_in: standstill at the first move's start before it begins, s.
        duration: total length, s (default: lead-in plus all moves). A longer duration holds the
            last position; a shorter one truncates.
    Returns:
        :class:`Profile` with n = round(duration·fs) samples.
    """
    total = lead_in + sum(m.duration for m in moves)
    if duration is None:
        duration = total
    n = int(round(duration * fs))
    t = np.arange(n) / fs
    x = np.full(n, moves[0].start if moves else 0.0)
    v = np.zeros(n)
    a = np.zeros(n)
    t0 = lead_in
    for i, mv in enumerate(moves):
        sel = t >= t0
        if i + 1 < len(moves):
            sel &= t < t0 + mv.duration
        if np.any(sel):
            dx, dv, da = _move_samples(mv, t[sel] - t0)
            x[sel] = mv.start + dx
            v[sel], a[sel] = dv, da
        t0 += mv.duration
    return Profile(t=t, x=x, v=v, a=a, moves=tuple(moves), lead_in=float(lead_in))


def reciprocating(start: float, end: float, speed: float, accel: float, dwell: float,
                  cycles: int) -> list[Move]:
    """Back-and-forth between ``start`` and ``end``: 2·cycles moves."""
    moves = []
    for _ in range(cycles):
        moves.append(Move(start, end, speed, accel, dwell))
        moves.append(Move(end, start, speed, accel, dwell))
    return moves
