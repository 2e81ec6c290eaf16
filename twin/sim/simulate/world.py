"""What is fixed over a whole campaign (:class:`World`: the axis, its rails, its screw, its
instruments and the unmodelled effects, drawn once from the scenario seed), and the open-loop
forces of two of those effects: the ball re-entry impulses (:func:`recirculation_force`) and the
Stribeck friction of the rails (:func:`stribeck_force`). SI units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.sim import geometry as geo
from twin.sim.axis import Axis
from twin.sim.model import (
    BaseMode,
)
from twin.sim.sensors import instruments as ins


@dataclass(frozen=True)
class World:
    """Everything fixed over a campaign.

    Attributes:
        axis: physical parameters (SI).
        rails: rail deviation profiles (rail coordinate = world X, m).
        carriage: carriage layout for the kinematic error motions.
        screw: lead error, runout and ball-pass geometry with their (seeded) phases.
        ripple_torque: amplitude of the motor torque ripple, N·m; ripple_per_rev: its order;
        ripple_phase: rad.
        thermal_expansion: screw expansion coefficient, 1/K.
        sensors: instrument specifications.

    Unmodelled effects (scenario section ``[effects]``; the defaults are off and leave every
    array of the nominal twin unchanged):
        cogging_torque: motor cogging amplitude, N·m, added to the ripple motor as
            cogging·sin(cogging_per_rev·θ + cogging_phase) (PM-motor cogging has the period
            LCM(slots, poles) per revolution: Zhu & Howe, IEEE Trans. Energy Conversion 15(4),
            2000); cogging_phase: rad.
        recirculation_impulse: peak axial force on the nut of the ball re-entry impulses, N;
            recirculation_width: pulse width as a fraction of the ball-pass period (see
            :func:`recirculation_force`).
        stribeck_excess: static rail friction in excess of the Coulomb friction ΔF, N;
            stribeck_velocity: Stribeck velocity v_s, m/s (see :func:`stribeck_force`).
        base_modal_mass: modal mass of the machine base's X mode, kg (0 = rigid base);
            base_frequency: its natural frequency, Hz; base_damping_ratio: ζ (see
            :class:`twin.sim.model.BaseMode`).
    """

    axis: Axis
    rails: geo.RailProfiles
    carriage: geo.CarriageGeometry
    screw: geo.ScrewSpec
    ripple_torque: float
    ripple_per_rev: int
    ripple_phase: float
    thermal_expansion: float
    drag_temperature_coefficient: float
    imu_acc: ins.AnalogAccelerometerSpec
    imu_gyro: ins.DigitalGyroSpec
    nut_acc: ins.NutAccelerometerSpec
    controller_fs: float
    encoder_counts_per_rev: int
    torque_noise: float
    position_cmd_fs: float
    cogging_torque: float
    cogging_per_rev: int
    cogging_phase: float
    recirculation_impulse: float
    recirculation_width: float
    stribeck_excess: float
    stribeck_velocity: float
    base_modal_mass: float
    base_frequency: float
    base_damping_ratio: float
    torque_resolution: float = 0.001

    @property
    def base_mode(self) -> BaseMode | None:
        """The compliant machine base of the model, None for a rigid base (modal mass 0)."""
        if self.base_modal_mass <= 0.0:
            return None
        return BaseMode(mass=self.base_modal_mass, frequency=self.base_frequency,
                        damping_ratio=self.base_damping_ratio)


def recirculation_force(theta: np.ndarray, v_cmd: np.ndarray, world: World) -> np.ndarray:
    """Axial force of the ball re-entry impulses on the nut, (n,) N, for the commanded screw
    angles ``theta`` (n,) rad and carriage velocities ``v_cmd`` (n,) m/s at the simulation
    steps (n ≥ 2).

    When balls re-enter the loaded zone through the return/deflector they strike the nut: one
    impulse per ball-pass period, at the ball-pass phase u = (N_bp·θ + φ_bp)/2π of
    :func:`twin.sim.geometry.ball_pass` (pulse centred where u is an integer). Each is a raised
    cosine p(d) = ½(1 + cos(2πd/w)) for |d| < w/2 (d = u − round(u), w the width as a fraction
    of the period), of peak F, opposing the motion: F·p·(−sign v). The mean, F·w/2, is kept
    (a one-sided contact force: it is a real drag of the recirculation). Zero at standstill.

    The control is held over a step, so each step carries the pulse's mean over the step,
    (C(u_{k+1}) − C(u_k))/(u_{k+1} − u_k) with C the integral of p: the impulse is delivered
    exactly even when the pulse is shorter than a step (w·T = 0.28 ms at 400 mm/s for w = 0.1),
    and the sampling does not alias its harmonics through the pulse's phase jitter."""
    w = world
    n_bp = geo.ball_pass_per_rev(w.screw)
    width = w.recirculation_width
    u = (n_bp * theta + w.screw.ball_pass_phase_rad) / (2.0 * math.pi)

    def pulse(u):
        d = u - np.round(u)
        return np.where(np.abs(d) < width / 2, 0.5 * (1.0 + np.cos(2.0 * np.pi * d / width)), 0.0)

    def integral(u):
        k = np.floor(u + 0.5)
        d = np.clip(u - k, -width / 2, width / 2)
        return k * width / 2 + 0.5 * (d + width / 2) + width / (4.0 * np.pi) * np.sin(2.0 * np.pi * d / width)

    # The last step continues the motion.
    u_next = np.append(u[1:], 2.0 * u[-1] - u[-2] if u.size > 1 else u[-1])
    du = u_next - u
    small = np.abs(du) < 1e-9
    mean = np.where(small, pulse(u),
                    (integral(u_next) - integral(u)) / np.where(small, 1.0, du))
    return -w.recirculation_impulse * mean * np.sign(v_cmd)


def stribeck_force(v_cmd: np.ndarray, world: World) -> np.ndarray:
    """Stribeck friction of the rails in excess of their Coulomb friction, (n,) N, on
    ``carriage_x``: F = −ΔF·exp(−(v/v_s)²)·sign(v) (Stribeck curve: Armstrong-Hélouvry, Dupont,
    Canudas de Wit, Automatica 30(7), 1994), of magnitude ΔF at the start of a motion and at
    reversals, vanishing in the cruise.

    Approximation: v is the COMMANDED carriage velocity ``v_cmd`` (n,) m/s, so the force is an
    open-loop input (the model's Coulomb part, ``frictionloss``, is the true-velocity one). The
    carriage follows the command within µm; its velocity differs from the commanded one by a
    fraction of a mm/s over the Phase I routine, with transients of a few mm/s at the
    acceleration steps (where the axial mode rings; see docs/validation.md).
    For v_s of a few mm/s the force is therefore the Stribeck friction of the ideal motion, not
    the flicker the ringing would give; a true stick phase (a carriage held by static friction
    while the servo winds up) is not modelled."""
    v = np.asarray(v_cmd, dtype=float)
    return -world.stribeck_excess * np.exp(-(v / world.stribeck_velocity) ** 2) * np.sign(v)
