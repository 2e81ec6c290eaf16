"""The axis's constants shared by the geometry modules: its travel, the extent of the stored rail
profiles, the row orders of the trucks and of the error motions, the trucks' sign conventions, and
the array helper every function of the package uses. The frames and sign conventions themselves
are described in :mod:`twin.sim.geometry`. Lengths in m.
"""

from __future__ import annotations

import numpy as np

from analysis.dataset import DOFS

TRAVEL_M = 0.450
"""Total travel of the axis, m (paper section III)."""

DEFAULT_RAIL_LENGTH_M = 0.70
"""Default length of the stored rail profiles, m: travel + 2 × 0.125 m margin [M] (covers the
trucks at x ± a/2 over the full travel plus overtravel)."""

DEFAULT_RAIL_START_M = -(DEFAULT_RAIL_LENGTH_M - TRAVEL_M) / 2.0
"""Default rail coordinate of the first profile sample, m (travel centred on the rail)."""

ERROR_MOTION_NAMES = DOFS
"""Row order of :func:`true_error_motions` (ISO 230-1 names), the dataset's order."""

TRUCK_NAMES = ("FL", "FR", "RL", "RR")
"""Row order of :func:`truck_displacements`; rail index of each truck is (0, 1, 0, 1)."""

_TRUCK_FRONT = np.array([+1.0, +1.0, -1.0, -1.0])  # sign of the x offset (front = +X)
_TRUCK_SIDE = np.array([-1.0, +1.0, -1.0, +1.0])  # sign of the y offset (rail 0 = −Y)


def _as_1d(values) -> np.ndarray:
    """Float array of shape (m,) from a scalar or 1-D array-like."""
    arr = np.atleast_1d(np.asarray(values, dtype=float))
    if arr.ndim != 1:
        raise ValueError(f"expected a scalar or a 1-D array, got shape {arr.shape}")
    return arr
