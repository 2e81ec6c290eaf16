"""The six ISO 230-1 error motions of the carriage's reference point (the IMU), quasi-static:
the rails seen through the trucks at the true carriage position, and the screw's axial
deviation at the screw angle (:func:`true_error_motions`). Frames and signs:
:mod:`twin.sim.geometry`. E_XX, E_YX, E_ZX in m; E_AX, E_BX, E_CX in rad.
"""

from __future__ import annotations

import numpy as np

from twin.sim.geometry.carriage import CarriageGeometry, error_motions_from_trucks, truck_displacements
from twin.sim.geometry.frames import (
    _as_1d,
)
from twin.sim.geometry.rails import RailProfiles
from twin.sim.geometry.screw import ScrewSpec, nut_axial_deviation


def true_error_motions(profiles: RailProfiles, geometry: CarriageGeometry, screw: ScrewSpec,
                       x_true, theta, *, include_ball_pass: bool = True,
                       method: str = "linear") -> np.ndarray:
    """The six ISO 230-1 error motions of the carriage reference point (quasi-static geometry).

    Reference point P: the IMU, at offset r_P = (reference_offset_x, reference_offset_y,
    reference_height) from the carriage centre C (:mod:`twin.sim.geometry`). The nut's axial load line
    passes through N at offset r_N = (0, screw_offset_y, screw_height).

    [D] With the pose (t, ε) of C from :func:`error_motions_from_trucks` (rails, looked up at the
    TRUE carriage position x_true) and the nut's axial deviation from :func:`nut_axial_deviation`
    (screw, at the screw angle θ):

        E_XX = e(θ) + E_BX·(z_P − z_N) − E_CX·(y_P − y_N)   (x of P relative to the nut, Abbe)
        E_YX = t_y + E_CX·x_P − E_AX·z_P                    (t + ε × r_P, y component)
        E_ZX = t_z + E_AX·y_P − E_BX·x_P                    (z component)
        E_AX, E_BX, E_CX = ε (the same for every point of the rigid carriage)

    E_XX is the deviation of P's X position from the nominal R·θ of a perfect screw with no
    clearance; backlash and elastic axial deflection (x_true − nut_position(θ) in a simulation)
    are NOT included -- the dynamics supply them. Rail errors follow x_true, screw errors follow
    θ, which is what makes backlash visible as a shift between the two (paper §V).

    Args:
        profiles: rails. geometry: carriage layout. screw: screw imperfections.
        x_true: scalar or (m,) true rail position of the carriage centre, m.
        theta: scalar or (m,) screw angle, rad.
        include_ball_pass: add the ball-pass modulation to e(θ).
        method: profile interpolation, "linear" or "cubic".

    Returns:
        (6, m) rows :data:`ERROR_MOTION_NAMES`: E_XX, E_YX, E_ZX in m; E_AX, E_BX, E_CX in rad.
    """
    x = _as_1d(x_true)
    th = _as_1d(theta)
    if th.shape != x.shape:
        raise ValueError(f"x_true {x.shape} and theta {th.shape} must have the same shape")
    t_y, t_z, e_ax, e_bx, e_cx = error_motions_from_trucks(
        truck_displacements(profiles, geometry, x, method), geometry)
    xp, yp, zp = geometry.reference_point_m
    yn, zn = geometry.screw_offset_y_m, geometry.screw_height_m
    e_xx = (nut_axial_deviation(th, screw, include_ball_pass)
            + e_bx * (zp - zn) - e_cx * (yp - yn))
    e_yx = t_y + e_cx * xp - e_ax * zp
    e_zx = t_z + e_ax * yp - e_bx * xp
    return np.stack([e_xx, e_yx, e_zx, e_ax, e_bx, e_cx])
