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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from scipy.interpolate import CubicSpline

from analysis.dataset import DOFS

if TYPE_CHECKING:
    from twin.sim.axis import Carriage

__all__ = [
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


# ---------------------------------------------------------------------------------------------
# Rails
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RailSpec:
    """Statistical description of the two rails' geometric deviations (SI units).

    Each rail profile (vertical and lateral, on each rail) is the sum of three parts:

    1. waviness ("straightness"): random-phase sum of sinusoids with PSD ∝ 1/k^p (k = 1/λ in
       1/m) for wavelengths from ``min_wavelength_m`` to ``max_wavelength_m`` (default: the rail
       length); p = 2 gives amplitudes ∝ 1/k, a "roughly 1/k" spectrum [M].
       Its rms over the generated rail is exactly ``straightness_rms_*_m``;
    2. bolt-pitch waviness: a sinusoid of period ``bolt_pitch_m`` and amplitude
       ``bolt_amplitude_*_m`` (about 60 mm, 0.2–1 µm [M]); the bolt positions of a
       rail are random (one phase per rail, shared by its vertical and lateral profiles);
    3. roughness: flat-PSD random-phase sum between ``min_wavelength_m`` and
       ``roughness_max_wavelength_m``, rms ``roughness_rms_m`` (both directions) [M].

    The waviness of rail 1 is correlated with that of rail 0 (coefficient ρ, a common part from
    the flatness/straightness of the machined base both rails are bolted to [M]):
    w_1 = ρ·w_0 + sqrt(1 − ρ²)·w_1', rescaled to the exact rms. ρ matters for roll (the
    rail-to-rail difference) and for the mean seen by the carriage.

    Attributes:
        straightness_rms_vertical_m: rms of the vertical waviness, m. Default 0.5 µm [M]: with
            the 1/k spectrum this gives a few µm p-v per rail over the 450 mm travel ("a few µm
            p-v over 0.5 m" [M]) and, with the default carriage, carriage angles p-v over the
            travel within [M]'s 5–20 µrad in roll but partly above it in pitch and yaw (per-seed
            figures: docs/validation.md): the two [M] figures are in mild tension, because a
            1/k spectrum puts most of the slope in the longest wavelengths.
        straightness_rms_lateral_m: rms of the lateral waviness, m. Default 0.5 µm [M].
        rail_correlation_vertical: ρ of the two rails' vertical waviness (default 0.8 [M]).
        rail_correlation_lateral: ρ of the two rails' lateral waviness (default 0.5 [M]: each
            rail is aligned to its own reference edge).
        spectrum_exponent: p in PSD ∝ 1/k^p (dimensionless), default 2.
        min_wavelength_m: shortest wavelength of waviness and roughness, m (default 0.5 mm, the
            paper's section V high-pass cutoff; 10 grid steps at the default grid).
        max_wavelength_m: longest waviness wavelength, m; None → the rail length.
        bolt_pitch_m: bolt spacing, m (default 0.060 [M]).
        bolt_amplitude_vertical_m: bolt-pitch amplitude in Z, m (default 0.5 µm, in the 0.2–1 µm
            range [M]).
        bolt_amplitude_lateral_m: bolt-pitch amplitude in Y, m (default 0.3 µm [M]).
        roughness_rms_m: rms of the short-wavelength roughness, m (default 0.02 µm [M]).
        roughness_max_wavelength_m: longest roughness wavelength, m (default 2 mm [M]).
        grid_step_m: spacing du of the stored profiles, m (default 0.05 mm).
    """

    straightness_rms_vertical_m: float = 0.5e-6
    straightness_rms_lateral_m: float = 0.5e-6
    rail_correlation_vertical: float = 0.8
    rail_correlation_lateral: float = 0.5
    spectrum_exponent: float = 2.0
    min_wavelength_m: float = 0.5e-3
    max_wavelength_m: float | None = None
    bolt_pitch_m: float = 0.060
    bolt_amplitude_vertical_m: float = 0.5e-6
    bolt_amplitude_lateral_m: float = 0.3e-6
    roughness_rms_m: float = 0.02e-6
    roughness_max_wavelength_m: float = 2.0e-3
    grid_step_m: float = 0.05e-3

    def __post_init__(self) -> None:
        if self.grid_step_m <= 0 or self.min_wavelength_m < 2 * self.grid_step_m:
            raise ValueError("min_wavelength_m must be at least two grid steps (Nyquist)")
        if self.bolt_pitch_m <= 0:
            raise ValueError("bolt_pitch_m must be positive")
        for rho in (self.rail_correlation_vertical, self.rail_correlation_lateral):
            if not -1.0 <= rho <= 1.0:
                raise ValueError("rail correlations must lie in [-1, 1]")

    def expected_rms_m(self, which: str) -> float:
        """Expected total rms of one rail profile, m: sqrt(s² + A_bolt²/2 + r²).

        ``which`` is "vertical" or "lateral". Exact for the waviness and roughness parts over the
        generated record; the bolt sinusoid's rms is A/√2 up to an end effect of order
        bolt_pitch / rail length."""
        if which == "vertical":
            s, b = self.straightness_rms_vertical_m, self.bolt_amplitude_vertical_m
        elif which == "lateral":
            s, b = self.straightness_rms_lateral_m, self.bolt_amplitude_lateral_m
        else:
            raise ValueError(f"which must be 'vertical' or 'lateral', got {which!r}")
        return math.sqrt(s**2 + b**2 / 2.0 + self.roughness_rms_m**2)


@dataclass(frozen=True, eq=False)
class RailProfiles:
    """Deviation profiles of the two rails on a uniform grid of rail coordinates.

    Attributes:
        u_m: (n,) rail coordinates of the samples, m, uniform step ``du``.
        vertical: (2, n) vertical (+Z) deviation of rail 0 (y = −w/2) and rail 1 (y = +w/2), m.
        lateral: (2, n) lateral (+Y) deviation of rail 0 and rail 1, m.
    """

    u_m: np.ndarray
    vertical: np.ndarray
    lateral: np.ndarray

    def __post_init__(self) -> None:
        u = np.array(self.u_m, dtype=float)  # private copies, then frozen read-only
        v = np.array(self.vertical, dtype=float)
        lat = np.array(self.lateral, dtype=float)
        if u.ndim != 1 or u.size < 2:
            raise ValueError("u_m must be 1-D with at least two samples")
        if v.shape != (2, u.size) or lat.shape != (2, u.size):
            raise ValueError(f"vertical/lateral must have shape (2, {u.size})")
        steps = np.diff(u)
        if np.any(steps <= 0) or np.ptp(steps) > 1e-6 * steps.mean():
            raise ValueError("u_m must be uniform and increasing")
        for name, arr in (("u_m", u), ("vertical", v), ("lateral", lat)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def du(self) -> float:
        """Grid step, m."""
        return float(self.u_m[1] - self.u_m[0])

    @property
    def u_range(self) -> tuple[float, float]:
        """(first, last) rail coordinate covered, m."""
        return float(self.u_m[0]), float(self.u_m[-1])

    @cached_property
    def _spline(self) -> CubicSpline:
        # Rows: vertical rail 0, rail 1, lateral rail 0, rail 1.
        return CubicSpline(self.u_m, np.vstack([self.vertical, self.lateral]), axis=1)

    def at(self, u, method: str = "linear") -> tuple[np.ndarray, np.ndarray]:
        """Profiles interpolated at rail coordinates u.

        Args:
            u: scalar or (m,) rail coordinates, m; must lie inside ``u_range``.
            method: "linear" (np.interp) or "cubic" (not-a-knot cubic spline).

        Returns:
            (vertical, lateral), each (2, m) in m: row 0 rail 0, row 1 rail 1.
        """
        uu = _as_1d(u)
        lo, hi = self.u_range
        tol = 1e-9 * max(1.0, abs(lo), abs(hi))
        if uu.size and (uu.min() < lo - tol or uu.max() > hi + tol):
            raise ValueError(
                f"rail coordinate outside the stored profiles [{lo:.6g}, {hi:.6g}] m: "
                f"[{uu.min():.6g}, {uu.max():.6g}]")
        if method == "linear":
            out = np.stack([np.interp(uu, self.u_m, row)
                            for row in (*self.vertical, *self.lateral)])
        elif method == "cubic":
            out = self._spline(uu)
        else:
            raise ValueError(f"method must be 'linear' or 'cubic', got {method!r}")
        return out[:2], out[2:]


def _uniform_grid(length_m: float, du: float, u_start_m: float | None) -> np.ndarray:
    """(n,) uniform grid, n = round(length/du) + 1, from u_start (None: travel centred), m."""
    if length_m <= 0:
        raise ValueError("length_m must be positive")
    start = -(length_m - TRAVEL_M) / 2.0 if u_start_m is None else float(u_start_m)
    n = int(round(length_m / du)) + 1
    return start + du * np.arange(n)


def _random_phase_profiles(n: int, du: float, k_min: float, k_max: float, exponent: float,
                           rms: float, rng: np.random.Generator, count: int) -> np.ndarray:
    """(count, n) random-phase profiles with one-sided PSD ∝ k^(−exponent) on k ∈ [k_min, k_max].

    Method [D]: harmonics k_j = j/(n·du) of the record; amplitude c_j ∝ k_j^(−exponent/2) (so
    c_j²/2, the power per bin, follows the PSD), uniform random phases φ_j from ``rng``;
    x(u_i) = Σ_j c_j cos(2π k_j u_i + φ_j), evaluated with an inverse real FFT. The harmonics are
    orthogonal over the record, so the rms is exactly sqrt(Σ c_j²/2), scaled to ``rms``.
    """
    out = np.zeros((count, n))
    if rms == 0.0:
        return out
    record = n * du
    j_lo = max(1, int(round(k_min * record)))
    j_hi = min((n - 1) // 2, int(math.floor(k_max * record + 1e-9)))
    if j_hi < j_lo:
        raise ValueError("empty wavelength band for this record length / grid step")
    j = np.arange(j_lo, j_hi + 1)
    c = (j / record) ** (-exponent / 2.0)
    c *= rms / math.sqrt(np.sum(c**2) / 2.0)
    phases = rng.uniform(0.0, 2.0 * math.pi, size=(count, j.size))
    spectrum = np.zeros((count, n // 2 + 1), dtype=complex)
    spectrum[:, j] = 0.5 * n * c * np.exp(1j * phases)
    out[:] = np.fft.irfft(spectrum, n=n, axis=1)
    return out


def _correlate_rails(pair: np.ndarray, rho: float) -> np.ndarray:
    """(2, n) → (2, n): rail 1 := ρ·rail 0 + sqrt(1 − ρ²)·rail 1, rescaled to rail 1's rms."""
    target = math.sqrt(np.mean(pair[1] ** 2))
    mixed = rho * pair[0] + math.sqrt(max(0.0, 1.0 - rho**2)) * pair[1]
    norm = math.sqrt(np.mean(mixed**2))
    return np.vstack([pair[0], mixed * (target / norm if norm > 0 else 0.0)])


def make_rail_profiles(spec: RailSpec, length_m: float = DEFAULT_RAIL_LENGTH_M,
                       rng: np.random.Generator | None = None, *,
                       u_start_m: float | None = None) -> RailProfiles:
    """Random rail profiles drawn from ``spec`` (see :class:`RailSpec` for the model).

    Args:
        spec: the rail description (SI).
        length_m: rail length covered by the profiles, m (default 0.70).
        rng: the caller's generator; all random draws come from it, in this order: waviness
            phases (vertical rail 0, rail 1, lateral rail 0, rail 1), bolt positions (rail 0,
            rail 1), roughness phases (same order as the waviness). Required.
        u_start_m: rail coordinate of the first sample, m; None → the travel [0, 0.45] m is
            centred on the rail (−0.125 m for the default length).

    Returns:
        RailProfiles on a grid of step ``spec.grid_step_m``. Deterministic for a given rng state.
    """
    if rng is None:
        raise ValueError("pass a numpy.random.Generator (all random draws come from the caller)")
    du = spec.grid_step_m
    u = _uniform_grid(length_m, du, u_start_m)
    n = u.size
    lam_max = spec.max_wavelength_m if spec.max_wavelength_m is not None else length_m
    k_lo, k_hi = 1.0 / lam_max, 1.0 / spec.min_wavelength_m

    wav_v = _correlate_rails(
        _random_phase_profiles(n, du, k_lo, k_hi, spec.spectrum_exponent,
                               spec.straightness_rms_vertical_m, rng, 2),
        spec.rail_correlation_vertical)
    wav_l = _correlate_rails(
        _random_phase_profiles(n, du, k_lo, k_hi, spec.spectrum_exponent,
                               spec.straightness_rms_lateral_m, rng, 2),
        spec.rail_correlation_lateral)
    # Bolt positions u_b (one per rail); the rail sinks at its bolts: −A·cos(2π(u − u_b)/P).
    bolt_at = rng.uniform(0.0, spec.bolt_pitch_m, size=(2, 1))
    bolt_shape = -np.cos(2.0 * math.pi * (u[None, :] - bolt_at) / spec.bolt_pitch_m)
    k_rough_lo = 1.0 / spec.roughness_max_wavelength_m
    rough = _random_phase_profiles(n, du, k_rough_lo, k_hi, 0.0, spec.roughness_rms_m, rng, 4)

    vertical = wav_v + spec.bolt_amplitude_vertical_m * bolt_shape + rough[:2]
    lateral = wav_l + spec.bolt_amplitude_lateral_m * bolt_shape + rough[2:]
    return RailProfiles(u_m=u, vertical=vertical, lateral=lateral)


def sinusoidal_rail_profiles(length_m: float, wavelength_m: float, amplitude_m: float,
                             which: str = "vertical", phase: float = 0.0, *,
                             grid_step_m: float = 0.05e-3,
                             u_start_m: float | None = None) -> RailProfiles:
    """The same sinusoid A·sin(2π u/λ + φ) on both rails (the other direction zero); for tests.

    Args:
        length_m: rail length, m. wavelength_m: λ, m. amplitude_m: A, m. phase: φ, rad.
        which: "vertical", "lateral" or "both".
        grid_step_m: du, m. u_start_m: first sample, m (None → travel centred, as
            :func:`make_rail_profiles`).
    """
    u = _uniform_grid(length_m, grid_step_m, u_start_m)
    wave = amplitude_m * np.sin(2.0 * math.pi * u / wavelength_m + phase)
    both = np.vstack([wave, wave])
    zero = np.zeros_like(both)
    if which == "vertical":
        return RailProfiles(u, both, zero)
    if which == "lateral":
        return RailProfiles(u, zero, both)
    if which == "both":
        return RailProfiles(u, both, both.copy())
    raise ValueError(f"which must be 'vertical', 'lateral' or 'both', got {which!r}")


# ---------------------------------------------------------------------------------------------
# Carriage on four trucks
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CarriageGeometry:
    """Layout of the carriage (all m, relative to the carriage centre C; see the module docstring).

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


# ---------------------------------------------------------------------------------------------
# Ball screw
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ScrewSpec:
    """Geometric imperfections of the ball screw and nut (SI).

    The screw angle θ (rad) is zero at the axis zero; the nominal nut travel is s = lead·θ/2π.

    Attributes:
        lead_m: nominal lead, m (0.010: paper sections III and V).
        cumulative_lead_error_m_per_m: travel deviation per unit travel, m/m (dimensionless);
            default +5 µm / 300 mm [M: the brief's P-grade example; precision-grade screws are
            specified at a few µm per 300 mm].
        cyclic_lead_error_m: amplitudes of the lead-error harmonics 1, 2, 3 per revolution, m
            (default 0.3, 0.15, 0.1 µm [M]): 40/80/120 Hz at 400 mm/s.
        cyclic_lead_phase_rad: their phases, rad (default 0).
        runout_m: radial runout of the screw axis at the nut, once per revolution, m
            (default 0.3 µm; 0.1–0.5 µm [M]).
        runout_phase_rad: its phase, rad.
        pitch_diameter_m: ball pitch-circle diameter D_pw, m (25×10 screw: 25.5 mm, THK catalogue).
        ball_diameter_m: D_w, m (3.969 mm = 5/32 in, THK catalogue).
        contact_angle_rad: α (45°, gothic-arch groove).
        ball_pass_amplitude_m: axial displacement modulation of the nut as balls pass, m
            (default 30 nm [M]: "tens of nm").
        ball_pass_phase_rad: its phase, rad.
    """

    lead_m: float = 0.010
    cumulative_lead_error_m_per_m: float = 8.0e-6
    cyclic_lead_error_m: tuple[float, ...] = (0.3e-6, 0.15e-6, 0.1e-6)
    cyclic_lead_phase_rad: tuple[float, ...] = (0.0, 0.0, 0.0)
    runout_m: float = 0.3e-6
    runout_phase_rad: float = 0.0
    pitch_diameter_m: float = 0.0255
    ball_diameter_m: float = 0.003969
    contact_angle_rad: float = math.pi / 4.0
    ball_pass_amplitude_m: float = 30e-9
    ball_pass_phase_rad: float = 0.0

    def __post_init__(self) -> None:
        if len(self.cyclic_lead_error_m) != len(self.cyclic_lead_phase_rad):
            raise ValueError("cyclic_lead_error_m and cyclic_lead_phase_rad differ in length")
        if self.lead_m <= 0:
            raise ValueError("lead_m must be positive")

    @property
    def radius_per_rad_m(self) -> float:
        """R = lead/2π, nominal nut travel per screw radian, m/rad."""
        return self.lead_m / (2.0 * math.pi)


def draw_screw_phases(spec: ScrewSpec, rng: np.random.Generator) -> ScrewSpec:
    """Copy of ``spec`` with uniform random phases (rad) for the cyclic lead error, runout and
    ball pass, drawn from ``rng`` in that order."""
    n = len(spec.cyclic_lead_error_m)
    phases = rng.uniform(0.0, 2.0 * math.pi, size=n + 2)
    return replace(spec, cyclic_lead_phase_rad=tuple(float(p) for p in phases[:n]),
                   runout_phase_rad=float(phases[n]), ball_pass_phase_rad=float(phases[n + 1]))


def lead_error(theta, spec: ScrewSpec) -> np.ndarray:
    """Lead error e(θ): axial deviation of the nut from its nominal position R·θ, m.

    e(θ) = c·R·θ + Σ_h A_h·sin(h·θ + φ_h), R = lead/2π, c = cumulative slope (m/m), h = 1, 2, 3…
    (cumulative part + cyclic part periodic with the screw revolution). Hence the
    nut travel between angles 2πk apart is exactly k·lead·(1 + c).

    Args:
        theta: scalar or (n,) screw angle, rad (0 at the axis zero).
    Returns:
        (n,) e in m.
    """
    th = _as_1d(theta)
    e = spec.cumulative_lead_error_m_per_m * spec.radius_per_rad_m * th
    for h, (amp, phase) in enumerate(zip(spec.cyclic_lead_error_m, spec.cyclic_lead_phase_rad, strict=True),
                                     start=1):
        e = e + amp * np.sin(h * th + phase)
    return e


def runout(theta, spec: ScrewSpec) -> np.ndarray:
    """Radial displacement of the screw axis at the nut, once per revolution, m.

    (y, z) = r·(cos(θ + φ), sin(θ + φ)): an eccentricity turning with the screw about +X
    (+Y toward +Z for positive θ). Amplitude [M]. This is a radial excitation
    of the nut (a force through the nut's radial stiffness in the dynamics), not a carriage
    error motion: the rails fix the carriage's lateral/vertical position, so it is not part of
    :func:`true_error_motions`.

    Args:
        theta: scalar or (n,) screw angle, rad.
    Returns:
        (n, 2) displacement (y, z) in m.
    """
    th = _as_1d(theta) + spec.runout_phase_rad
    return spec.runout_m * np.column_stack([np.cos(th), np.sin(th)])


def balls_per_turn(spec: ScrewSpec) -> float:
    """Z ≈ π·D_pw / (D_w·cos λ), λ = atan(lead/(π D_pw)) the lead angle [D].

    Kept non-integer (it is a count per helical turn, ≈ 20.3 for a 25×10 screw)."""
    lead_angle = math.atan(spec.lead_m / (math.pi * spec.pitch_diameter_m))
    return math.pi * spec.pitch_diameter_m / (spec.ball_diameter_m * math.cos(lead_angle))


def ball_pass_per_rev(spec: ScrewSpec) -> float:
    """Balls passing a point on the nut per screw revolution, Z·(1 − γ)/2, dimensionless.

    Rolling-bearing analogy [D] (Harris & Kotzalas, ch. 1): f = Z·(f_s/2)·(1 − γ), γ = D_w·cos α / D_pw."""
    gamma = spec.ball_diameter_m * math.cos(spec.contact_angle_rad) / spec.pitch_diameter_m
    return balls_per_turn(spec) * (1.0 - gamma) / 2.0


def ball_pass_period_m(spec: ScrewSpec) -> float:
    """Spatial period of ball passing in nut travel, m: lead / (Z(1 − γ)/2) [D].

    ≈ 1.105 mm for the 25×10 screw."""
    return spec.lead_m / ball_pass_per_rev(spec)


def ball_pass_frequency_hz(speed_m_s, spec: ScrewSpec):
    """Ball-pass frequency f = Z·(f_s/2)·(1 − γ) with f_s = |v|/lead, Hz [D].

    Args:
        speed_m_s: scalar or array carriage speed, m/s (sign ignored).
    Returns:
        frequency in Hz, same shape as ``speed_m_s``: 18, 90, 453 Hz at 20, 100, 500 mm/s.
    """
    return np.abs(np.asarray(speed_m_s, dtype=float)) / ball_pass_period_m(spec)


def ball_pass(theta, spec: ScrewSpec) -> np.ndarray:
    """Axial displacement excitation of the nut from ball passing, m.

    A·sin(N_bp·θ + φ), N_bp = :func:`ball_pass_per_rev`: a sinusoid of spatial period
    :func:`ball_pass_period_m` in nut travel (fixed in the spatial domain).
    For a nut travel s instead of an angle, pass θ = 2π·s/lead.

    Args:
        theta: scalar or (n,) screw angle, rad.
    Returns:
        (n,) axial displacement in m.
    """
    th = _as_1d(theta)
    return spec.ball_pass_amplitude_m * np.sin(ball_pass_per_rev(spec) * th
                                               + spec.ball_pass_phase_rad)


def nut_axial_deviation(theta, spec: ScrewSpec, include_ball_pass: bool = True) -> np.ndarray:
    """Total axial deviation of the nut from R·θ, m: :func:`lead_error` (+ :func:`ball_pass`).

    Args: theta scalar or (n,) rad. Returns (n,) m."""
    e = lead_error(theta, spec)
    if include_ball_pass:
        e = e + ball_pass(theta, spec)
    return e


def nut_position(theta, spec: ScrewSpec, include_ball_pass: bool = True) -> np.ndarray:
    """Kinematic axial position of the nut, m: R·θ + :func:`nut_axial_deviation`.

    Without backlash or elastic deflection this is also the carriage's true position (up to the
    sub-nm Abbe term E_BX·screw height at the carriage centre). Args: theta scalar or (n,) rad.
    Returns (n,) m."""
    th = _as_1d(theta)
    return spec.radius_per_rad_m * th + nut_axial_deviation(th, spec, include_ball_pass)


# ---------------------------------------------------------------------------------------------
# The six error motions of the reference point
# ---------------------------------------------------------------------------------------------


def true_error_motions(profiles: RailProfiles, geometry: CarriageGeometry, screw: ScrewSpec,
                       x_true, theta, *, include_ball_pass: bool = True,
                       method: str = "linear") -> np.ndarray:
    """The six ISO 230-1 error motions of the carriage reference point (quasi-static geometry).

    Reference point P: the IMU, at offset r_P = (reference_offset_x, reference_offset_y,
    reference_height) from the carriage centre C (module docstring). The nut's axial load line
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
