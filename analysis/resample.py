"""Resampling of uniformly sampled signals: the not-a-knot cubic spline in O(n).

``scipy.interpolate.make_interp_spline(k=3)`` builds the same interpolant through a B-spline
collocation and a banded solve per call; on a uniform grid the spline's second derivatives
(moments) satisfy a tridiagonal Toeplitz system that two first-order recursions solve, which is
several times faster for the long signals of the sensor models and the Phase II gridding. The
relations are those of the cubic spline on a uniform grid (de Boor, *A Practical Guide to
Splines*, rev. ed. 2001, ch. IV; not-a-knot end conditions, ibid.).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy import signal

__all__ = ["not_a_knot_cubic_rows"]


@functools.lru_cache(maxsize=1)
def _pivots_141() -> np.ndarray:
    """Pivots of the LU (Thomas) factorisation of the tridiagonal Toeplitz matrix (1, 4, 1):
    ``d_0 = 4``, ``d_i = 4 - 1/d_{i-1}``, up to the first that equals its successor in floating
    point (``2 + √3``, reached after about 15 rows); every later pivot is that value."""
    d = [4.0]
    while (nxt := 4.0 - 1.0 / d[-1]) != d[-1]:
        d.append(nxt)
    return np.array(d)


def _solve_141(r: np.ndarray) -> np.ndarray:
    """Solve ``tridiag(1, 4, 1) x = r`` along the last axis of ``r`` (c, N).

    Thomas algorithm: past the first K ≈ 15 rows its pivots are constant, so the forward and
    back substitutions are first-order recursions with constant coefficients, run by
    ``scipy.signal.lfilter`` (the rows before K by hand). The matrix is strictly diagonally
    dominant, so no pivoting is needed; the result agrees with a banded LAPACK solve to a few
    units in the last place."""
    d = _pivots_141()
    k = d.size - 1
    n = r.shape[-1]
    piv = np.full(n, d[k])
    piv[:min(k, n)] = d[:min(k, n)]
    p = -1.0 / d[k]
    head = min(n, k + 1)
    z = np.empty_like(r)
    z[:, 0] = r[:, 0]
    for i in range(1, head):
        z[:, i] = r[:, i] - z[:, i - 1] / piv[i - 1]
    if n > head:
        z[:, head:], _ = signal.lfilter([1.0], [1.0, -p], r[:, head:], axis=-1,
                                        zi=(p * z[:, head - 1])[:, None])
    x = np.empty_like(r)
    if n > k:
        x[:, k:] = signal.lfilter([1.0 / d[k]], [1.0, -p], z[:, :k - 1:-1], axis=-1)[:, ::-1]
        start = k - 1
    else:
        x[:, n - 1] = z[:, n - 1] / piv[n - 1]
        start = n - 2
    for i in range(start, -1, -1):
        x[:, i] = (z[:, i] - x[:, i + 1]) / piv[i]
    return x


def not_a_knot_cubic_rows(y: np.ndarray, position: np.ndarray) -> np.ndarray:
    """The not-a-knot cubic spline through each row of ``y`` (c, n) (n >= 4, C-contiguous) on
    the grid 0..n-1, at the fractional indices ``position`` (m,): (c, m).

    The interpolant of ``make_interp_spline(k=3)`` (to rounding), computed from its second
    derivatives M (moments): ``M_{i-1} + 4 M_i + M_{i+1} = 6 δ²y_i`` inside, and on a unit grid
    the not-a-knot conditions give ``M_1 = δ²y_1``, ``M_{n-2} = δ²y_{n-2}`` and the end moments by
    linear extrapolation; the tridiagonal system is solved by :func:`_solve_141` in O(n)."""
    n = y.shape[1]
    moments = np.empty_like(y)
    rhs = y[:, 2:] - 2.0 * y[:, 1:-1]
    rhs += y[:, :-2]  # δ²y_1 .. δ²y_{n-2}
    moments[:, 1], moments[:, n - 2] = rhs[:, 0], rhs[:, -1]
    if n > 4:
        inner = rhs[:, 1:-1]
        inner *= 6.0
        inner[:, 0] -= moments[:, 1]
        inner[:, -1] -= moments[:, n - 2]
        moments[:, 2:n - 2] = _solve_141(inner)
    moments[:, 0] = 2.0 * moments[:, 1] - moments[:, 2]
    moments[:, n - 1] = 2.0 * moments[:, n - 2] - moments[:, n - 3]
    i = np.minimum(position.astype(np.intp), n - 2)
    u = position - i
    a = 1.0 - u
    ca, cu = (a * a * a - a) / 6.0, (u * u * u - u) / 6.0
    if 4 * position.size < n:  # few points: gather the four columns directly
        out = a * y[:, i]
        out += u * y[:, i + 1]
        out += ca * moments[:, i]
        out += cu * moments[:, i + 1]
        return out
    # many points: one table row per sample (values, then moments), so that each position
    # gathers two contiguous rows instead of four strided columns
    c = y.shape[0]
    table = np.empty((n, 2 * c))
    table[:, :c] = y.T
    table[:, c:] = moments.T
    left, right = table[i], table[i + 1]
    out = a[:, None] * left[:, :c]
    out += u[:, None] * right[:, :c]
    out += ca[:, None] * left[:, c:]
    out += cu[:, None] * right[:, c:]
    return out.T
