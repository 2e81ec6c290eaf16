"""The campaign's world and the state of the axis over operating hours: the fixed imperfections
drawn once from the scenario seed (:func:`make_world`), the degradation law's preload and
backlash, the screw's thermal transient after pauses, and the :class:`~twin.sim.simulate.Condition`
of the axis at given hours (:func:`condition_at`), with the origin the operator sets before a
Phase II session. Hours in h; everything else SI unless the name carries its unit.
"""

from __future__ import annotations

import math

import numpy as np

from twin.sim import degradation as deg
from twin.sim import geometry as geo
from twin.sim.campaign.seeds import KIND_ORIGIN, KIND_WORLD, rng_for
from twin.sim.model import MechanicalState
from twin.sim.scenario import Scenario, to_axis
from twin.sim.sensors import instruments as ins
from twin.sim.sensors.instruments import MICRO_G
from twin.sim.simulate import (
    Condition,
    World,
)

RAIL_MARGIN = 0.15  # m of rail modelled beyond each end of the travel


def make_world(s: Scenario) -> World:
    """Draw the campaign's fixed imperfections (rails, screw phases) from the scenario seed."""
    axis = to_axis(s)
    g, se = s.geometry, s.sensors
    # Separate streams for the rails, the screw and the motor, so that no other scenario key
    # changes what is drawn for one of them.
    rails_rng, screw_rng, motor_rng = (rng_for(s.seed, KIND_WORLD, i) for i in range(3))
    # The effects' draws come from streams of their own (3: cogging phase), never from the above.
    cogging_rng = rng_for(s.seed, KIND_WORLD, 3)
    fx = s.effects
    rail_spec = geo.RailSpec(
        straightness_rms_vertical_m=g.straightness_rms_um * 1e-6,
        straightness_rms_lateral_m=g.lateral_straightness_rms_um * 1e-6,
        spectrum_exponent=g.spectrum_exponent, bolt_pitch_m=g.bolt_pitch_mm * 1e-3,
        bolt_amplitude_vertical_m=g.bolt_amplitude_um * 1e-6,
        bolt_amplitude_lateral_m=0.6 * g.bolt_amplitude_um * 1e-6)
    # A fixed extent beyond the travel (more than the largest allowed origin offset plus half
    # the truck spacing), so that nuisance settings do not change the rails.
    margin = RAIL_MARGIN
    rails = geo.make_rail_profiles(rail_spec, length_m=axis.travel + 2 * margin, rng=rails_rng,
                                   u_start_m=-margin)
    carriage = geo.CarriageGeometry.from_carriage(axis.carriage)
    screw = geo.draw_screw_phases(geo.ScrewSpec(
        lead_m=axis.screw.lead, cumulative_lead_error_m_per_m=g.cumulative_lead_error_um_per_m * 1e-6,
        cyclic_lead_error_m=tuple(a * 1e-6 for a in g.cyclic_lead_error_um),
        cyclic_lead_phase_rad=tuple(0.0 for _ in g.cyclic_lead_error_um),
        runout_m=g.runout_um * 1e-6, pitch_diameter_m=axis.screw.pitch_diameter,
        ball_diameter_m=g.ball_diameter_mm * 1e-3, contact_angle_rad=math.radians(g.contact_angle_deg),
        ball_pass_amplitude_m=g.ball_pass_amplitude_um * 1e-6), screw_rng)
    mis = np.zeros((3, 3))
    m = [v * 1e-6 for v in se.imu_misalignment_urad]
    # Small rotation (roll, pitch, yaw) of the IMU case: skew-symmetric cross-axis matrix.
    mis[0, 1], mis[1, 0] = -m[2], m[2]
    mis[0, 2], mis[2, 0] = m[1], -m[1]
    mis[1, 2], mis[2, 1] = -m[0], m[0]
    imu_acc = ins.AnalogAccelerometerSpec(
        fs_hz=se.imu_acc_fs_hz, bandwidth_hz=se.imu_acc_bandwidth_hz,
        noise_density=se.imu_acc_noise_ug_per_rthz * MICRO_G,
        error=ins.ErrorModel(bias=tuple(b * MICRO_G for b in se.imu_acc_bias_ug),
                             scale_error=tuple(se.imu_acc_scale_error),
                             misalignment=tuple(map(tuple, mis))))
    imu_gyro = ins.DigitalGyroSpec(
        fs_hz=se.imu_gyro_fs_hz, bandwidth_hz=se.imu_gyro_bandwidth_hz,
        noise_density=se.imu_gyro_noise_urad_s_per_rthz * 1e-6,
        error=ins.ErrorModel(bias=tuple(b * 1e-6 for b in se.imu_gyro_bias_urad_s),
                             misalignment=tuple(map(tuple, mis))))
    fs = s.phase1.fs_hz
    nut_acc = ins.NutAccelerometerSpec(fs_hz=fs, bandwidth_hz=0.4 * fs,
                                       noise_density=se.nut_acc_noise_ug_per_rthz * MICRO_G)
    return World(axis=axis, rails=rails, carriage=carriage, screw=screw,
                 ripple_torque=s.axis.torque_ripple_Nm, ripple_per_rev=s.axis.torque_ripple_per_rev,
                 ripple_phase=float(motor_rng.uniform(0, 2 * math.pi)),
                 thermal_expansion=s.degradation.thermal_expansion_per_K,
                 drag_temperature_coefficient=s.degradation.drag_temperature_coefficient_per_K,
                 imu_acc=imu_acc, imu_gyro=imu_gyro, nut_acc=nut_acc,
                 controller_fs=fs, encoder_counts_per_rev=se.encoder_counts_per_rev,
                 torque_noise=se.torque_noise_Nm, position_cmd_fs=se.position_cmd_fs_hz,
                 cogging_torque=fx.cogging_Nm, cogging_per_rev=fx.cogging_per_rev,
                 cogging_phase=float(cogging_rng.uniform(0, 2 * math.pi)),
                 recirculation_impulse=fx.recirculation_impulse_N,
                 recirculation_width=fx.recirculation_width,
                 stribeck_excess=fx.stribeck_excess_N,
                 stribeck_velocity=fx.stribeck_velocity_mm_s * 1e-3,
                 base_modal_mass=fx.base_modal_mass_kg, base_frequency=fx.base_frequency_hz,
                 base_damping_ratio=fx.base_damping_ratio)


def degradation_law(s: Scenario):
    """The scenario's degradation law (:mod:`twin.sim.laws`: ``degradation.law`` looked up in the
    registry, made with its parameters from ``[degradation]``)."""
    return s.degradation.make_law()


def degradation_at(s: Scenario, hours) -> tuple[np.ndarray, np.ndarray]:
    """(preload fraction (n,), backlash µm (n,)) at operating ``hours`` (n,)."""
    h = np.atleast_1d(np.asarray(hours, dtype=float))
    law = degradation_law(s)
    return law.preload_fraction(h), law.backlash(h) * 1e6


def onset_hours(s: Scenario) -> float:
    """The injected onset of degradation, h (NaN if the scenario never degrades): the law's
    ``injected_onset_hours()`` (for the table law, the last healthy point before the first
    degraded one)."""
    return float(degradation_law(s).injected_onset_hours())


def resume_hours(s: Scenario) -> list[float]:
    return [p.hours for p in s.campaign.pauses]


def temperature_at(s: Scenario, hours) -> np.ndarray:
    """Screw temperature rise above ambient at operating ``hours``, K: it warms towards the
    steady rise after every (re)start, from what remains after the stop cooled it for its
    ``days`` with the same time constant (a first-order thermal model)."""
    d = s.degradation
    h = np.atleast_1d(np.asarray(hours, float))
    since = deg.hours_since_resume(h, resume_hours(s))
    rise = deg.temperature_rise_K(since, d.thermal_rise_K, d.thermal_time_constant_hours)
    # Heat left at the restart: the temperature when the axis stopped, cooled over the pause.
    pauses = sorted(s.campaign.pauses, key=lambda p: p.hours)
    left = np.zeros_like(h)
    for i, p in enumerate(pauses):
        run_before = p.hours - (pauses[i - 1].hours if i else 0.0)
        at_stop = float(deg.temperature_rise_K(run_before, d.thermal_rise_K,
                                               d.thermal_time_constant_hours))
        since_this = h - p.hours
        active = (since_this >= 0) & (since_this == since)
        left[active] = at_stop * math.exp(-24.0 * p.days / d.thermal_time_constant_hours)
    return rise + left * np.exp(-since / d.thermal_time_constant_hours)


def condition_at(s: Scenario, hours: float, origin_offset: float = 0.0) -> Condition:
    law = degradation_law(s)
    h = np.atleast_1d(np.asarray(hours, dtype=float))
    pf, backlash = law.preload_fraction(h), law.backlash(h)  # (1,) fraction, (1,) m
    coupling = s.degradation.truck_wear_coupling
    mech = MechanicalState(preload=float(pf[0]) * s.axis.preload_N, backlash=float(backlash[0]),
                           truck_preload_fraction=1.0 - coupling * (1.0 - float(pf[0])))
    return Condition(mech=mech, temperature_rise=float(temperature_at(s, hours)[0]),
                     origin_offset=origin_offset)


def origin_offset(s: Scenario, session: int) -> float:
    """Origin set against the wooden block before a Phase II session: uniform within ±max, m."""
    lim = s.phase2.origin_offset_max_mm * 1e-3
    return float(rng_for(s.seed, KIND_ORIGIN, session).uniform(-lim, lim)) if lim > 0 else 0.0
