"""The ball screw's geometric imperfections as functions of the screw angle θ: their description
(:class:`ScrewSpec`, with seeded phases by :func:`draw_screw_phases`), the lead error, the
runout, the ball pass and the nut's axial deviation and position. SI units (m, rad, Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from twin.sim.geometry.frames import (
    _as_1d,
)


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
