"""The whole scenario (:class:`Scenario`: its sections, the checks across them, its JSON) and its
conversion to the SI dataclasses used inside the simulator (:func:`to_axis`) and to what a machine
owner knows of the axis (:func:`nominal_axis_description`, written into ``measurements.h5``).
"""

from __future__ import annotations

import json
from typing import Any

from pydantic import Field, model_validator

from twin.sim.axis import Axis, Carriage, ScrewDrive, Servo
from twin.sim.scenario.sections import (
    AxisConfig,
    CampaignConfig,
    DegradationConfig,
    DialConfig,
    EffectsConfig,
    GeometryConfig,
    Phase1Config,
    Phase2Config,
    SensorsConfig,
    _Section,
)


class Scenario(_Section):
    name: str = "unnamed"
    description: str = ""
    seed: int = Field(0, ge=0, le=2**32 - 1)
    axis: AxisConfig = Field(default_factory=AxisConfig)
    geometry: GeometryConfig = Field(default_factory=GeometryConfig)
    sensors: SensorsConfig = Field(default_factory=SensorsConfig)
    degradation: DegradationConfig = Field(default_factory=DegradationConfig)
    phase1: Phase1Config = Field(default_factory=Phase1Config)
    phase2: Phase2Config = Field(default_factory=Phase2Config)
    dial_indicator: DialConfig = Field(default_factory=DialConfig)
    campaign: CampaignConfig = Field(default_factory=CampaignConfig)
    effects: EffectsConfig = Field(default_factory=EffectsConfig)
    calibration: dict[str, Any] = Field(default_factory=dict, exclude=True, description=(
        "what `twin calibrate` measured or fitted and from what recording (metadata: not part "
        "of the simulated scenario, its hash or its JSON)"))

    @model_validator(mode="after")
    def _strokes(self) -> Scenario:
        if self.campaign.warmup_hours > self.campaign.total_hours:
            raise ValueError(f"campaign.warmup_hours = {self.campaign.warmup_hours:g} exceeds "
                             f"campaign.total_hours = {self.campaign.total_hours:g}: allowed "
                             "0 <= warmup_hours <= total_hours")
        travel = self.axis.travel_mm
        for key, val in (("phase1.start_mm", self.phase1.start_mm), ("phase1.end_mm", self.phase1.end_mm),
                         ("phase2.start_mm", self.phase2.start_mm), ("phase2.end_mm", self.phase2.end_mm)):
            if val > travel:
                raise ValueError(f"{key} = {val:g} is a stroke beyond the travel: allowed "
                                 f"0 <= {key.split('.')[1]} <= axis.travel_mm = {travel:g} mm")
        for key, (a, b) in (("phase1", (self.phase1.start_mm, self.phase1.end_mm)),
                            ("phase2", (self.phase2.start_mm, self.phase2.end_mm))):
            if a == b:
                raise ValueError(f"{key}.start_mm = {a:g} equals {key}.end_mm: the stroke must "
                                 "have a non-zero length")
        return self

    @model_validator(mode="after")
    def _friction_timeconst(self) -> Scenario:
        tc = self.axis.friction_timeconst_ms
        step = max(self.phase1.timestep_s, self.phase2.timestep_s)
        if tc is not None and tc * 1e-3 < 2.0 * step - 1e-15:
            raise ValueError(f"axis.friction_timeconst_ms = {tc:g} is shorter than two simulation "
                             f"steps: allowed >= {2e3 * step:g} ms (2 × the larger of "
                             "phase1.timestep_s and phase2.timestep_s)")
        return self

    @model_validator(mode="after")
    def _base_mode(self) -> Scenario:
        fx = self.effects
        if fx.base_modal_mass_kg > 0:
            from twin.sim.model import BaseMode, check_base_mode
            base = BaseMode(fx.base_modal_mass_kg, fx.base_frequency_hz, fx.base_damping_ratio)
            for cfg in (self.phase1, self.phase2):
                check_base_mode(to_axis(self), cfg.timestep_s, base)
        return self

    @property
    def captures_per_sample(self) -> int:
        """Phase I captures per sample after ``campaign.scale`` (at least 1)."""
        return max(1, round(self.phase1.captures_per_sample * self.campaign.scale))

    @property
    def runs_per_session(self) -> int:
        """Phase II runs per session after ``campaign.scale`` (at least 1)."""
        return max(1, round(self.phase2.runs_per_session * self.campaign.scale))

    def to_json(self) -> str:
        return json.dumps(self.model_dump(mode="json"), sort_keys=True)


def to_axis(s: Scenario) -> Axis:
    a = s.axis
    screw = ScrewDrive(
        lead=a.lead_mm * 1e-3, pitch_diameter=a.pitch_diameter_mm * 1e-3,
        root_diameter=a.root_diameter_mm * 1e-3, shaft_length=a.shaft_length_mm * 1e-3,
        rated_dynamic_load=a.rated_dynamic_load_N, preload=a.preload_N,
        nut_stiffness_catalogue=a.nut_stiffness_N_per_um * 1e6,
        bearing_stiffness=a.bearing_stiffness_N_per_um * 1e6, screw_inertia=a.screw_inertia_kg_m2,
        no_load_torque=a.no_load_torque_Nm, drag_viscous=a.drag_viscous_Nm_s_per_rad,
        contact_damping_ratio=a.contact_damping_ratio,
        radial_stiffness=a.radial_stiffness_N_per_um * 1e6)
    carriage = Carriage(
        mass=a.carriage_mass_kg, inertia=Carriage.inertia_of(a.carriage_mass_kg),
        truck_spacing=a.truck_spacing_mm * 1e-3,
        rail_spacing=a.rail_spacing_mm * 1e-3,
        truck_stiffness_vertical=a.truck_stiffness_vertical_N_per_um * 1e6,
        truck_stiffness_lateral=a.truck_stiffness_lateral_N_per_um * 1e6,
        truck_damping_ratio=a.truck_damping_ratio, rail_friction=a.rail_friction_N,
        imu_height=a.imu_height_mm * 1e-3)
    servo = Servo(motor_inertia=a.motor_inertia_kg_m2, position_bandwidth_hz=a.position_bandwidth_hz,
                  velocity_bandwidth_hz=a.velocity_bandwidth_hz,
                  velocity_integral_time=a.velocity_integral_time_s)
    return Axis(travel=a.travel_mm * 1e-3, screw=screw, carriage=carriage, servo=servo,
                friction_timeconst=None if a.friction_timeconst_ms is None else a.friction_timeconst_ms * 1e-3,
                friction_impedance=a.friction_impedance)


def nominal_axis_description(s: Scenario) -> dict[str, Any]:
    """What a machine owner knows of the axis (no degradation state): goes into measurements.h5."""
    a, se = s.axis, s.sensors
    return {
        "travel_mm": a.travel_mm, "lead_mm": a.lead_mm, "screw": f"{a.pitch_diameter_mm:g}x{a.lead_mm:g}",
        "carriage_mass_kg": a.carriage_mass_kg, "truck_spacing_mm": a.truck_spacing_mm,
        "rail_spacing_mm": a.rail_spacing_mm,
        "sensors": {
            "nut_accelerometers": {"count": 2, "axes": 3, "sensitivity_mV_per_g": 100.0,
                                   "fs_hz": s.phase1.fs_hz},
            "imu_accelerometer": {"sensitivity_mV_per_g": 2000.0, "bandwidth_hz": se.imu_acc_bandwidth_hz,
                                  "noise_ug_per_rthz": se.imu_acc_noise_ug_per_rthz, "fs_hz": se.imu_acc_fs_hz},
            "imu_gyroscope": {"bandwidth_hz": se.imu_gyro_bandwidth_hz,
                              "noise_urad_s_per_rthz": se.imu_gyro_noise_urad_s_per_rthz,
                              "fs_hz": se.imu_gyro_fs_hz},
            "controller": {"fs_hz": s.phase1.fs_hz, "encoder_counts_per_rev": se.encoder_counts_per_rev},
        },
        "phase1_routine": s.phase1.model_dump(include={"speed_mm_s", "accel_mm_s2", "start_mm", "end_mm", "dwell_s"}),
        "phase2_routine": s.phase2.model_dump(include={"speeds_mm_s", "accel_mm_s2", "start_mm", "end_mm", "dwell_s"}),
    }
