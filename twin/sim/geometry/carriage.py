"""The carriage on its four trucks: its layout (:class:`CarriageGeometry`), the rail deviations
under each truck (:func:`truck_displacements`), the carriage's pose that the four trucks give
(:func:`error_motions_from_trucks`) and the spatial filter of the truck spacing
(:func:`truck_filter_gains`). Frames and signs: :mod:`twin.sim.geometry`. SI units (m, rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twin.sim.geometry.frames import (
    _TRUCK_FRONT,
    _TRUCK_SIDE,
    _as_1d,
)
from twin.sim.geometry.rails import RailProfiles

if TYPE_CHECKING:
    from twin.sim.axis import Carriage


@dataclass(frozen=True)
class CarriageGeometry:
    """Layout of the carriage (all m, relative to the carriage centre C; see :mod:`twin.sim.geometry`).

    Attributes:
        truck_spacing_m: a, front-to-rear truck distance (the scenario's 120 mm: a 450 mm axis
            carrying 100 kg). Note a = 2 × the default bolt pitch, so bolt-pitch waviness reaches
            E_ZX at full gain and the pitch not at all (see :func:`truck_filter_gains`).
        rail_spacing_m: w, distance between the rails.
        reference_height_m: height of the reference point (the IMU on top of the steel load)
            above the rail plane.
        screw_height_m: height of the screw axis (the nut's axial load line) above the rail
            plane.
        reference_offset_x_m, reference_offset_y_m: horizontal offsets of the reference point
            from C (default 0).
        screw_offset_y_m: lateral position of the screw axis (default 0: midway between rails).
    """

    truck_spacing_m: float
    rail_spacing_m: float
    reference_height_m: float
    screw_height_m: float
    reference_offset_x_m: float = 0.0
    reference_offset_y_m: float = 0.0
    screw_offset_y_m: float = 0.0

    def __post_init__(self) -> None:
        if self.truck_spacing_m <= 0 or self.rail_spacing_m <= 0:
            raise ValueError("truck and rail spacing must be positive")

    @classmethod
    def from_carriage(cls, carriage: Carriage) -> CarriageGeometry:
        """The layout of the axis's carriage: its trucks, rails, IMU (the reference point) and screw."""
        return cls(truck_spacing_m=carriage.truck_spacing, rail_spacing_m=carriage.rail_spacing,
                   reference_height_m=carriage.imu_height, screw_height_m=carriage.nut_height)

    @property
    def reference_point_m(self) -> np.ndarray:
        """(3,) offset of the reference point from C, m."""
        return np.array([self.reference_offset_x_m, self.reference_offset_y_m,
                         self.reference_height_m])


def truck_offsets(geometry: CarriageGeometry) -> np.ndarray:
    """(4, 2) offsets (x, y) of the trucks FL, FR, RL, RR from the carriage centre, m."""
    half_a, half_w = geometry.truck_spacing_m / 2.0, geometry.rail_spacing_m / 2.0
    return np.column_stack([_TRUCK_FRONT * half_a, _TRUCK_SIDE * half_w])


def truck_displacements(profiles: RailProfiles, geometry: CarriageGeometry, x_carriage,
                        method: str = "linear") -> dict[str, np.ndarray]:
    """Rail deviation under each truck for carriage-centre positions x (rail coordinate).

    Truck i (FL, FR, RL, RR) sits on rail (0, 1, 0, 1) at u = x ± a/2 (front +, rear −); point
    contact (the finite length of a truck's ball rows is not averaged here).

    Args:
        profiles: the rails. geometry: the carriage layout.
        x_carriage: scalar or (m,) true rail position of the carriage centre, m.
        method: interpolation of the profiles ("linear" or "cubic").

    Returns:
        {"vertical": (4, m), "lateral": (4, m)} in m, rows in :data:`TRUCK_NAMES` order.
    """
    x = _as_1d(x_carriage)
    half_a = geometry.truck_spacing_m / 2.0
    v_front, l_front = profiles.at(x + half_a, method)
    v_rear, l_rear = profiles.at(x - half_a, method)
    vertical = np.stack([v_front[0], v_front[1], v_rear[0], v_rear[1]])
    lateral = np.stack([l_front[0], l_front[1], l_rear[0], l_rear[1]])
    return {"vertical": vertical, "lateral": lateral}


def error_motions_from_trucks(disp: dict[str, np.ndarray],
                              geometry: CarriageGeometry) -> np.ndarray:
    """Quasi-static pose of a rigid carriage on four equally stiff trucks.

    Model [D]: truck i at offset (x_i, y_i, 0) from C moves by t + ε × r_i, so its vertical
    displacement is z_i = E_ZX + E_AX·y_i − E_BX·x_i and its lateral one y_i' = E_YX + E_CX·x_i
    (roll does not move a point of the rail plane laterally). Equal stiffness → the pose is the
    least-squares fit (minimum contact energy); for the symmetric layout it is, exactly:

        E_YX = mean of the four lateral displacements
        E_ZX = mean of the four vertical displacements
        E_AX = (z̄_rail1 − z̄_rail0) / w          (rail-1 side up → positive roll)
        E_BX = −(z̄_front − z̄_rear) / a          (front up → negative pitch)
        E_CX = (ȳ_front − ȳ_rear) / a            (front to +Y → positive yaw)

    with bars the mean over the two trucks of a rail / an end. The remaining vertical
    combination (z_FL − z_FR − z_RL + z_RR, a twist) is not a rigid-body motion; it loads the
    trucks and is ignored here.

    Args:
        disp: {"vertical": (4, m), "lateral": (4, m)} in m, trucks FL, FR, RL, RR.
        geometry: supplies a and w.

    Returns:
        (5, m): E_YX (m), E_ZX (m), E_AX (rad), E_BX (rad), E_CX (rad) of the carriage centre C.
    """
    z = np.asarray(disp["vertical"], dtype=float)
    y = np.asarray(disp["lateral"], dtype=float)
    if z.shape[0] != 4 or y.shape != z.shape:
        raise ValueError("vertical and lateral must both have shape (4, m)")
    a, w = geometry.truck_spacing_m, geometry.rail_spacing_m
    e_yx = y.mean(axis=0)
    e_zx = z.mean(axis=0)
    e_ax = ((z[1] + z[3]) - (z[0] + z[2])) / (2.0 * w)
    e_bx = -((z[0] + z[1]) - (z[2] + z[3])) / (2.0 * a)
    e_cx = ((y[0] + y[1]) - (y[2] + y[3])) / (2.0 * a)
    return np.stack([e_yx, e_zx, e_ax, e_bx, e_cx])


def truck_filter_gains(wavelength_m, a: float) -> tuple[np.ndarray, np.ndarray]:
    """Spatial filter of the truck spacing for a sinusoid common to both rails.

    A profile A·sin(2πu/λ) seen by trucks at x ± a/2 [D]: the mean is A·cos(πa/λ)·sin(2πx/λ)
    and the difference over a is (2A/a)·sin(πa/λ)·cos(2πx/λ), so

        straightness gain  G_s = |cos(π a/λ)|       (E_ZX / A, or E_YX / A laterally)
        angle gain         G_a = (2/a)·|sin(π a/λ)|  (E_BX / A, or E_CX / A laterally), rad/m.

    Args:
        wavelength_m: scalar or array λ, m. a: truck spacing, m.

    Returns:
        (G_s dimensionless, G_a in rad/m), arrays of the shape of ``wavelength_m``.
    """
    lam = np.asarray(wavelength_m, dtype=float)
    arg = math.pi * a / lam
    return np.abs(np.cos(arg)), (2.0 / a) * np.abs(np.sin(arg))
