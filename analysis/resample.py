"""Resampling of uniformly sampled signals: the not-a-knot cubic spline in O(n).

``scipy.interpolate.make_interp_spline(k=3)`` builds the same interpolant through a B-spline
collocation and a banded solve per call; on a uniform grid the spline's second derivatives
(moments) satisfy a tridiagonal Toeplitz system whose factors are computed once and solved by
LAPACK for all channels at once, which is several times faster for the long signals of the
sensor models and the Phase II gridding. The
relations are those of the cubic spline on a uniform grid (de Boor, *A Practical Guide to
Splines*, rev. ed. 2001, ch. IV; not-a-knot end conditions, ibid.).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

__all__ = ["not_a_knot_cubic_rows"]


_FACTOR_141: tuple[np.ndarray, np.ndarray] = (np.empty(0), np.empty(0))


def _factor_141(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The L·D·Lᵀ factors (d (n,), e (n − 1,)) of the n × n tridiagonal Toeplitz matrix (1, 4, 1),
    from LAPACK's ``dpttrf`` (Anderson et al., *LAPACK Users' Guide*, 3rd ed. 1999). The
    factorisation runs from the top, so the factors of a smaller matrix are the leading part of
    a larger one's: they are computed once for a power-of-two size and sliced."""
    global _FACTOR_141
    d, e = _FACTOR_141
    if d.size < n:
        size = 1 << max(n - 1, 1).bit_length()
        d, e, info = lapack.dpttrf(np.full(size, 4.0), np.ones(size - 1))
        if info != 0:  # pragma: no cover - the matrix is strictly diagonally dominant
            raise RuntimeError(f"dpttrf failed on tridiag(1, 4, 1) of size {size} (info {info})")
        d.flags.writeable = e.flags.writeable = False
        _FACTOR_141 = (d, e)
    return d[:n], e[:n - 1]


def _solve_141(r: np.ndarray) -> np.ndarray:
    """Solve ``tridiag(1, 4, 1) x = r`` along the last axis of ``r`` (c, N): LAPACK's ``dpttrs``
    with the factors of :func:`_factor_141`, all rows at once (the matrix is symmetric positive
    definite, so no pivoting). Returns (c, N)."""
    if r.shape[-1] == 1:
        return r / 4.0
    d, e = _factor_141(r.shape[-1])
    x, info = lapack.dpttrs(d, e, r.T)
    if info != 0:  # pragma: no cover - only for malformed arguments
        raise RuntimeError(f"dpttrs failed (info {info})")
    return x.T


def not_a_knot_cubic_rows(y: np.ndarray, position: np.ndarray) -> np.ndarray:
    """The not-a-knot cubic spline through each row of ``y`` (c, n) on the grid 0..n-1, at the
    fractional indices ``position`` (m,): (c, m). Raises ValueError for n < 4 (a cubic needs
    four samples).

    The interpolant of ``make_interp_spline(k=3)`` (to rounding), computed from its second
    derivatives M (moments): ``M_{i-1} + 4 M_i + M_{i+1} = 6 δ²y_i`` inside, and on a unit grid
    the not-a-knot conditions give ``M_1 = δ²y_1``, ``M_{n-2} = δ²y_{n-2}`` and the end moments by
    linear extrapolation; the tridiagonal system is solved by :func:`_solve_141` in O(n)."""
    y = np.ascontiguousarray(y, dtype=float)
    n = y.shape[1]
    if n < 4:
        raise ValueError(f"a not-a-knot cubic spline needs at least 4 samples per row, got {n}")
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
