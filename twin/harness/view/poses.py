"""The carriage's shapes and poses from the error motions (numpy only; no Rerun)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis.dataset import DatasetError
from analysis.phase2.error_motion_file import read_error_motions
from twin.harness.view.base import GREY, ViewError
from twin.sim.axis import Axis

# ---------------------------------------------------------------------------------------------
# Geometry and poses (numpy only)


@dataclass(frozen=True)
class _Shape:
    path: str
    kind: str  # "box" or "cylinder_x"
    center: tuple[float, float, float]
    size: tuple[float, float, float]  # box: half sizes; cylinder along x: (half length, radius, 0)
    color: tuple[int, int, int]
    label: str


def _geometry(axis: Axis) -> tuple[list[_Shape], list[_Shape], dict[str, float]]:
    """Static shapes in the world frame and shapes in the carriage frame (origin at the carriage's
    centre of mass, ``com_height`` above the rail plane z = 0), m. Dimensions from the axis where
    it has them (travel, rail and truck spacing, screw diameters, heights of the nut, centre of
    mass and IMU); the rest is schematic."""
    c, s, L = axis.carriage, axis.screw, axis.travel
    w, a = c.rail_spacing / 2.0, c.truck_spacing / 2.0
    zc = c.com_height
    world = [
        _Shape("base", "box", (L / 2, 0.0, -0.06), (L / 2 + 0.1, max(0.2, w + 0.06), 0.02), GREY,
               "base"),
        _Shape("rails/left", "box", (L / 2, -w, -0.02), (L / 2 + 0.1, 0.01, 0.02), (90, 90, 100),
               f"rail (spacing {c.rail_spacing * 1e3:g} mm)"),
        _Shape("rails/right", "box", (L / 2, w, -0.02), (L / 2 + 0.1, 0.01, 0.02), (90, 90, 100),
               "rail"),
        _Shape("screw", "cylinder_x", (L / 2, 0.0, c.nut_height), (L / 2 + 0.05, s.root_diameter / 2, 0.0),
               (180, 180, 190), f"screw {s.pitch_diameter * 1e3:g}x{s.lead * 1e3:g}"),
    ]
    top = 0.035  # rail plane to the underside of the plate: the trucks
    plate_t = 0.02
    load_h = max(c.imu_height - top - plate_t, 0.02)
    carriage = [
        *[_Shape(f"trucks/{n}", "box", (x, y, top / 2 - zc), (0.03, 0.02, top / 2), (70, 70, 80),
                 f"truck {n}") for n, x, y in (("FL", a, -w), ("FR", a, w), ("RL", -a, -w), ("RR", -a, w))],
        _Shape("plate", "box", (0.0, 0.0, top + plate_t / 2 - zc), (a + 0.04, w + 0.03, plate_t / 2),
               (80, 100, 200), "carriage"),
        _Shape("nut", "cylinder_x", (0.0, 0.0, c.nut_height - zc), (0.04, s.pitch_diameter / 2 + 0.012, 0.0),
               (200, 160, 60), "ball nut"),
        _Shape("load", "box", (0.0, 0.0, top + plate_t + load_h / 2 - zc), (0.09, 0.09, load_h / 2),
               (60, 60, 60), f"steel load (carriage with load {c.mass:g} kg)"),
        _Shape("imu", "box", (0.0, 0.0, c.imu_height - zc + 0.005), (0.015, 0.015, 0.005), (220, 40, 40),
               "IMU"),
    ]
    frame = {"com_height": zc, "imu_offset": c.imu_height - zc, "travel": L}
    return world, carriage, frame


def _quat_xyzw(roll, pitch, yaw) -> np.ndarray:
    """Quaternions (n, 4) x, y, z, w of R = Rz(yaw)·Ry(pitch)·Rx(roll) (angles (n,) rad)."""
    cr, sr = np.cos(np.asarray(roll) / 2), np.sin(np.asarray(roll) / 2)
    cp, sp = np.cos(np.asarray(pitch) / 2), np.sin(np.asarray(pitch) / 2)
    cy, sy = np.cos(np.asarray(yaw) / 2), np.sin(np.asarray(yaw) / 2)
    return np.stack([sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                     cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy], axis=1)


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate the vector v (3,) by each quaternion of q (n, 4) x, y, z, w; returns (n, 3)."""
    u, w = q[:, :3], q[:, 3:4]
    t = 2.0 * np.cross(u, np.broadcast_to(v, u.shape))
    return v + w * t + np.cross(u, t)


def carriage_poses(x_m: np.ndarray, errors: np.ndarray, exaggeration: float, com_height: float,
                   imu_offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Carriage frame poses: ``x_m`` (n,) carriage position along the rails in m; ``errors``
    (6, n) error motions at the IMU in DOFS order (m, m, m, rad, rad, rad). Returns translations
    (n, 3) in m and quaternions (n, 4) x, y, z, w of the carriage frame (origin at the centre of
    mass), such that the IMU point (``imu_offset`` above the origin) is at
    (x + k·E_XX, k·E_YX, com_height + imu_offset + k·E_ZX) and the carriage is turned by
    k·(E_AX, E_BX, E_CX) about x, y, z, with k = ``exaggeration``."""
    k = float(exaggeration)
    q = _quat_xyzw(k * errors[3], k * errors[4], k * errors[5])
    imu = np.stack([x_m + k * errors[0], k * errors[1],
                    np.full_like(x_m, com_height + imu_offset) + k * errors[2]], axis=1)
    return imu - _rotate(q, np.array([0.0, 0.0, imu_offset])), q


def _direction(x: np.ndarray) -> np.ndarray:
    """+1 moving forward (x increasing), −1 in reverse; a standstill keeps the last direction
    (forward before the first move)."""
    s = np.sign(np.diff(x, prepend=x[0]))
    idx = np.where(s != 0, np.arange(len(s)), 0)
    np.maximum.accumulate(idx, out=idx)
    d = s[idx]
    d[d == 0] = 1.0
    return d


def _estimated_error_motions(path: Path, session: str):
    """``(x_m (n,) m, forward (6, n), reverse (6, n))`` in DOFS order (m and rad) of ``session``
    in ``error_motions.h5`` (written by ``twin backlash``), or None if the session is absent."""
    try:
        return read_error_motions(path).get(session)
    except DatasetError as exc:
        raise ViewError(str(exc)) from None


def _stride(n: int, max_points: int) -> int:
    return max(1, -(-n // max_points))
