"""The optional compliant machine base: a single-DOF modal model of a base/column mode along X
(:class:`BaseMode`, see :mod:`twin.sim.model`, "Machine base") and the check that the explicit
time step can carry it (:func:`check_base_mode`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from twin.sim.axis import Axis

BASE_MODE_MAX_OMEGA_DT = 1.0  # stability margin of the explicit base spring (limit 2)


@dataclass(frozen=True)
class BaseMode:
    """A structural mode of the machine base along X as a single-DOF modal model.

    Attributes:
        mass: modal mass M, kg (> 0).
        frequency: natural frequency of the base alone, f, Hz.
        damping_ratio: ζ (0 < ζ < 1).
    """

    mass: float
    frequency: float
    damping_ratio: float

    @property
    def stiffness(self) -> float:
        """k = M·(2πf)², N/m."""
        return self.mass * (2.0 * math.pi * self.frequency) ** 2

    @property
    def damping(self) -> float:
        """c = 2ζ·√(k·M), N·s/m."""
        return 2.0 * self.damping_ratio * math.sqrt(self.stiffness * self.mass)


def check_base_mode(axis: Axis, timestep: float, base: BaseMode) -> None:
    """Raise ValueError (naming the scenario keys) when the base cannot be simulated at
    ``timestep`` s: its mode coupled to the carriage through the ball nut of the new axis,
    ω² ≤ (k_base + k_axial)/M, must keep ω·dt ≤ 1 for the explicit spring, i.e.
    M ≥ k_axial·dt²/(1 − (ω_b·dt)²) and ω_b·dt < 1."""
    k_axial = axis.screw.axial_stiffness(axis.screw.preload)
    wdt = 2.0 * math.pi * base.frequency * timestep / BASE_MODE_MAX_OMEGA_DT
    m_min = k_axial * (timestep / BASE_MODE_MAX_OMEGA_DT) ** 2 / max(1.0 - wdt**2, 1e-12)
    if base.mass <= 0 or wdt >= 1.0 or base.mass < m_min:
        raise ValueError(
            f"effects.base_modal_mass_kg = {base.mass:g} with effects.base_frequency_hz = "
            f"{base.frequency:g} cannot be simulated at a {timestep:g} s step: the base "
            f"mode coupled to the ball nut (k = {k_axial:.3g} N/m) needs a modal mass >= "
            f"{m_min:.3g} kg and 2π·f·dt < {BASE_MODE_MAX_OMEGA_DT:g} (explicit spring); use a "
            "heavier base or a smaller time step")
