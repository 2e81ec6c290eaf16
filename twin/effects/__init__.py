"""The library of unmodelled effects for the sim-to-real gap diagnosis (one module per effect,
each with its physical parameters, prior ranges and physical source; see
:mod:`twin.effects.base`)."""

from twin.effects import (
                          ball_recirculation,
                          base_resonance,
                          cogging,
                          imu_misalignment,
                          origin_variability,
                          servo_dynamics,
                          stribeck_friction,
                          thermal_growth,
)
from twin.effects.base import Effect, Param

LIBRARY: dict[str, Effect] = {m.EFFECT.name: m.EFFECT for m in (
    thermal_growth, ball_recirculation, origin_variability, servo_dynamics, cogging,
    stribeck_friction, imu_misalignment, base_resonance)}

__all__ = ["LIBRARY", "Effect", "Param"]
