"""Geometric imperfections of the linear axis as functions of position (quasi-static kinematics).

Pure numpy/scipy; no MuJoCo. The dynamics (:mod:`twin.sim.model`) apply these errors as prescribed
displacements; this module is also the kinematic truth (what a perfect, infinitely stiff axis
would do), stored next to the simulated signals.

Frames and sign conventions
---------------------------
- Rail-fixed frame: X along travel, Z up, Y = Z × X (right-handed). The rail coordinate u (m)
  is the X coordinate of a point on the rails; the carriage centre at nominal position x sits at
  u = x. Travel is x ∈ [0, 0.45] m (paper section III / Table I); the rails extend beyond it by a
  margin so the trucks at x ± a/2 always stay on the stored profiles.
- Rail 0 at y = −w/2, rail 1 at y = +w/2 (w: rail spacing). The truck order is FL, FR, RL, RR:
  front = +X, "left" = rail 0 (−Y), "right" = rail 1 (+Y) -- left/right as seen by an observer
  at the +X end looking back along −X; the same order as :mod:`twin.sim.model`. The truck offsets
  from the carriage centre are (x, y) = (+a/2, −w/2), (+a/2, +w/2), (−a/2, −w/2), (−a/2, +w/2).
- Carriage centre C: midway between the four trucks, in the rail plane (the plane through the
  truck–rail reference points, z = 0). Profiles are rail deviations in that plane: "vertical"
  is +Z, "lateral" is +Y.
- Error motions use the ISO 230-1 names of an X axis: E_XX positioning, E_YX horizontal (Y)
  straightness, E_ZX vertical (Z) straightness, E_AX roll (about X), E_BX pitch (about Y), E_CX
  yaw (about Z). They are the displacement and small rotation of the carriage relative to the
  rail-fixed frame, angles positive by the right-hand rule:
  * E_AX > 0: rail-1 side (+Y) of the carriage goes up;
  * E_BX > 0: the front (+X) end goes DOWN;
  * E_CX > 0: the front (+X) end moves to +Y.
  A point at offset r from C then moves by E_T + ε × r (small angles), ε = (E_AX, E_BX, E_CX).

Sources (tags: [S] stated in the cited source, [D] derived here, [M] a model assumption, a
plausible magnitude without a citation):
- Pandhare, Miller, Vogl, Lee, "Ball Screw Health Monitoring with Inertial Sensors", section III:
  450 mm travel, 10 mm lead, two rails, four trucks; section V: the nominal pitch of 1 cm.
- [M] guideway magnitudes (straightness a few µm p-v over 0.5 m with a ~1/k spectrum, bolt-pitch
  waviness ~60 mm with 0.2–1 µm, angles 5–20 µrad p-v, screw runout 0.1–0.5 µm), in the range of
  the running-parallelism grades of THK LM-guide catalogues.
- [D] the ball-pass formula, by the rolling-bearing analogy (Harris & Kotzalas, "Rolling Bearing
  Analysis", 5th ed., 2007, ch. 1).
- Design of the twin: waviness fixed to the rail, seen through the truck spacing (a spatial
  filter); lead error = cumulative + cyclic (periodic with the screw revolution).

Modules: :mod:`~twin.sim.geometry.frames` (constants and row orders),
:mod:`~twin.sim.geometry.rails`, :mod:`~twin.sim.geometry.carriage` (four trucks),
:mod:`~twin.sim.geometry.screw`, :mod:`~twin.sim.geometry.error_motions` (the six error motions of
the reference point). Every public name is importable from this package.
"""

from twin.sim.geometry.carriage import (
    CarriageGeometry,
    error_motions_from_trucks,
    truck_displacements,
    truck_filter_gains,
    truck_offsets,
)
from twin.sim.geometry.error_motions import true_error_motions
from twin.sim.geometry.frames import (
    DEFAULT_RAIL_LENGTH_M,
    DEFAULT_RAIL_START_M,
    ERROR_MOTION_NAMES,
    TRAVEL_M,
    TRUCK_NAMES,
)
from twin.sim.geometry.rails import (
    RailProfiles,
    RailRangeError,
    RailSpec,
    make_rail_profiles,
    sinusoidal_rail_profiles,
)
from twin.sim.geometry.screw import (
    ScrewSpec,
    ball_pass,
    ball_pass_frequency_hz,
    ball_pass_per_rev,
    ball_pass_period_m,
    balls_per_turn,
    draw_screw_phases,
    lead_error,
    nut_axial_deviation,
    nut_position,
    runout,
)

__all__ = [
    "RailRangeError",
    "TRAVEL_M",
    "DEFAULT_RAIL_LENGTH_M",
    "DEFAULT_RAIL_START_M",
    "ERROR_MOTION_NAMES",
    "TRUCK_NAMES",
    "RailSpec",
    "RailProfiles",
    "make_rail_profiles",
    "sinusoidal_rail_profiles",
    "CarriageGeometry",
    "truck_offsets",
    "truck_displacements",
    "error_motions_from_trucks",
    "truck_filter_gains",
    "ScrewSpec",
    "draw_screw_phases",
    "lead_error",
    "runout",
    "balls_per_turn",
    "ball_pass_per_rev",
    "ball_pass_period_m",
    "ball_pass_frequency_hz",
    "ball_pass",
    "nut_axial_deviation",
    "nut_position",
    "true_error_motions",
]
