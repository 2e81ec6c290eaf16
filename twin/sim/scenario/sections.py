"""The sections of a scenario file, one pydantic model each (``[axis]``, ``[geometry]``,
``[sensors]``, ``[degradation]``, ``[phase1]``, ``[phase2]``, ``[dial_indicator]``,
``[campaign]`` with its pauses, ``[effects]``): every key with its default, unit, range and
description, and the checks within a section. Units carry their name (``_mm``, ``_um``,
``_hours``, ``_hz``...).
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from analysis.base import registry
from twin.sim import laws


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


def _per_axis(description: str):
    """A field of three values, one per sensor axis (x, y, z), zero by default."""
    return Field(default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3, description=description)


class AxisConfig(_Section):
    """The testbed: drive, carriage, guideway and servo (the paper's section III; catalogue values
    of a 25×10 preloaded nut). Converted to the SI dataclasses of :mod:`twin.sim.axis` by :func:`to_axis`."""

    travel_mm: float = Field(450.0, gt=0, le=5000, description="length of rail the carriage travels, mm")
    lead_mm: float = Field(10.0, gt=0, le=100, description="screw lead: carriage travel per screw revolution, mm")
    pitch_diameter_mm: float = Field(25.5, gt=0, le=200, description="ball pitch-circle diameter D_pw of the screw, mm")
    root_diameter_mm: float = Field(21.5, gt=0, le=200, description=(
        "screw root diameter, mm; sets the shaft's axial stiffness A·E/L"))
    shaft_length_mm: float = Field(500.0, gt=0, le=6000, description=(
        "fixed bearing to the nut at mid-stroke, mm (fixed–free shaft stiffness)"))
    rated_dynamic_load_N: float = Field(21000.0, gt=0, description="catalogue rated dynamic load C_a of the nut, N")
    preload_N: float = Field(1500.0, gt=0, description="nominal preload when new; at most 10 % of rated_dynamic_load_N")
    nut_stiffness_N_per_um: float = Field(400.0, gt=0, description="catalogue nut stiffness at 10 % C_a")
    bearing_stiffness_N_per_um: float = Field(750.0, gt=0, description="axial stiffness of the support bearings, N/µm")
    screw_inertia_kg_m2: float = Field(1.8e-4, gt=0, description="rotational inertia of the screw, kg·m²")
    no_load_torque_Nm: float = Field(0.05, ge=0, description=(
        "seal and viscous drag torque of the nut without preload, N·m"))
    drag_viscous_Nm_s_per_rad: float = Field(2.0e-4, ge=0, description=(
        "viscous drag coefficient on the screw, N·m·s/rad"))
    contact_damping_ratio: float = Field(0.03, gt=0, lt=1, description="damping ratio of the axial ball-nut mode")
    radial_stiffness_N_per_um: float = Field(100.0, gt=0, description=(
        "radial nut stiffness through which the screw's runout pushes the carriage, N/µm"))
    carriage_mass_kg: float = Field(120.0, gt=0, description="moving mass: carriage plate, nut housing and load, kg")
    truck_spacing_mm: float = Field(120.0, gt=0, description=(
        "distance between the front and rear trucks along the axis, mm"))
    rail_spacing_mm: float = Field(200.0, gt=0, description="distance between the two rails, mm")
    truck_stiffness_vertical_N_per_um: float = Field(300.0, gt=0, description=(
        "vertical contact stiffness of one truck when new, N/µm"))
    truck_stiffness_lateral_N_per_um: float = Field(200.0, gt=0, description=(
        "lateral contact stiffness of one truck when new, N/µm"))
    truck_damping_ratio: float = Field(0.05, gt=0, lt=1, description=(
        "damping ratio of the carriage's suspension modes on the trucks"))
    rail_friction_N: float = Field(12.0, ge=0, description="Coulomb friction of the four trucks and their seals, N")
    imu_height_mm: float = Field(200.0, ge=0, description=(
        "height of the IMU (on top of the load) above the rail plane, mm"))
    motor_inertia_kg_m2: float = Field(1.5e-4, gt=0, description="rotor inertia of the servo motor, kg·m²")
    position_bandwidth_hz: float = Field(20.0, gt=0, description="position-loop gain Kp/2π of the servo, Hz")
    velocity_bandwidth_hz: float = Field(60.0, gt=0, description="velocity-loop crossover Kv/(2π·J_total), Hz")
    velocity_integral_time_s: float = Field(0.01, gt=0, description="velocity-loop integral time Kv/Ki, s")
    torque_ripple_Nm: float = Field(0.01, ge=0, description="motor torque ripple amplitude")
    torque_ripple_per_rev: int = Field(8, ge=1, description="motor torque ripple periods per motor revolution")
    friction_timeconst_ms: float | None = Field(None, gt=0, description=(
        "time constant of MuJoCo's soft friction constraint (the joints' solreffriction) of the "
        "nut drag and the rail friction, ms; null = MuJoCo's default (20 ms), under which the "
        "Coulomb friction acts as a damper at low speed; at least two simulation steps"))
    friction_impedance: float | None = Field(None, ge=0.0001, le=0.9999, description=(
        "impedance d of that constraint (solimpfriction): the fraction of an applied force that "
        "static friction cancels, the rest creeps; null = MuJoCo's default (0.9 to 0.95)"))

    @model_validator(mode="after")
    def _preload_rated(self) -> AxisConfig:
        limit = 0.1 * self.rated_dynamic_load_N
        if self.preload_N > limit:
            raise ValueError(
                f"preload_N = {self.preload_N:g} is beyond the rated range: allowed 0 < preload_N "
                f"<= {limit:g} N (10 % of rated_dynamic_load_N = {self.rated_dynamic_load_N:g} N)")
        return self


class GeometryConfig(_Section):
    """Geometric errors of the rails and the screw: waviness, bolt pitch, lead errors, runout."""

    straightness_rms_um: float = Field(0.5, ge=0, le=100, description="RMS of the rails' vertical waviness, µm")
    lateral_straightness_rms_um: float = Field(0.5, ge=0, le=100, description="RMS of the rails' lateral waviness, µm")
    spectrum_exponent: float = Field(2.0, ge=0, le=4, description="p of the waviness spectrum PSD ∝ 1/k^p")
    bolt_pitch_mm: float = Field(60.0, gt=0, description=(
        "spacing of the rail bolts, mm: period of the bolt-pitch waviness"))
    bolt_amplitude_um: float = Field(0.5, ge=0, le=20, description=(
        "vertical amplitude of the bolt-pitch waviness, µm (lateral: 0.6 of it)"))
    cumulative_lead_error_um_per_m: float = Field(8.0, ge=-200, le=200, description=(
        "cumulative lead error of the screw, µm per m of travel"))
    cyclic_lead_error_um: list[float] = Field(default_factory=lambda: [0.3, 0.15, 0.1],
                                              max_length=20)
    runout_um: float = Field(0.3, ge=0, le=50, description="radial runout of the screw, µm")
    ball_pass_amplitude_um: float = Field(0.03, ge=0, le=5, description=(
        "axial amplitude of the ball-passing excitation, µm"))
    ball_diameter_mm: float = Field(3.969, gt=0, description=(
        "ball diameter, mm; with the contact angle sets the ball-pass frequency"))
    contact_angle_deg: float = Field(45.0, gt=0, lt=90, description="ball contact angle, degrees")


class SensorsConfig(_Section):
    """Sensor models: the IMU on the carriage (Phase II), the nut accelerometers and the controller's
    signals (Phase I)."""

    imu_acc_fs_hz: float = Field(1613.0, gt=0, description="IMU accelerometer sampling rate, Hz")
    imu_acc_bandwidth_hz: float = Field(300.0, gt=0, description="IMU accelerometer bandwidth, Hz")
    imu_acc_noise_ug_per_rthz: float = Field(7.0, ge=0, description="IMU accelerometer noise density, µg/√Hz")
    imu_gyro_fs_hz: float = Field(1000.0, gt=0, description="IMU gyroscope sampling rate, Hz")
    imu_gyro_bandwidth_hz: float = Field(200.0, gt=0, description="IMU gyroscope bandwidth, Hz")
    imu_gyro_noise_urad_s_per_rthz: float = Field(35.0, ge=0, description="IMU gyroscope noise density, µrad/s/√Hz")
    imu_acc_bias_ug: list[float] = _per_axis("IMU accelerometer bias per axis (x, y, z), µg")
    imu_acc_scale_error: list[float] = _per_axis("IMU accelerometer scale-factor error per axis (fraction, 0 = exact)")
    imu_gyro_bias_urad_s: list[float] = _per_axis("IMU gyroscope bias per axis, µrad/s")
    imu_misalignment_urad: list[float] = _per_axis("rotation (roll, pitch, yaw) of the IMU case on the carriage, µrad")
    nut_acc_noise_ug_per_rthz: float = Field(20.0, ge=0, description=(
        "noise density of the two nut accelerometers, µg/√Hz"))
    encoder_counts_per_rev: int = Field(2**20, ge=16, description="motor encoder counts per revolution")
    torque_noise_Nm: float = Field(0.005, ge=0, description="RMS noise of the controller's torque signal, N·m")
    position_cmd_fs_hz: float = Field(1000.0, gt=0, description="rate of the recorded position command in Phase II, Hz")
    position_cmd_lead_ms_per_kh: float = Field(0.0, ge=-100.0, le=100.0, description=(
        "how far the recorded position_cmd runs ahead of the IMU's clock, ms per 1000 operating "
        "hours (a trigger latency between the controller and a separately clocked IMU that "
        "drifts over the campaign); it shifts forward traces by +v·τ and reverse ones by −v·τ on "
        "the command axis, common to every DOF. 0 = in sync"))


class DegradationConfig(_Section):
    """The degradation law and its parameters, and the thermal transient.

    ``law`` names a registered degradation law or ``module:Class`` (:mod:`twin.sim.laws`); the law
    reads its parameters from the keys of the same name here. The keys of the built-in laws are
    fields with their ranges (``wear``: onset, interference, wear rate, scatter, backlash gain;
    ``table``: the three lists); a law from elsewhere brings keys of its own, accepted only
    when it takes them."""

    model_config = ConfigDict(extra="allow", validate_assignment=True)

    law: str = Field(default_factory=laws.default_name, description=(
        "a registered degradation law (twin.sim.laws: built-in or installed; default: the "
        "registered default) or module:Class"))
    onset_hours: float = Field(2500.0, ge=0, description="running-in hours before wear removes interference")
    interference_um: float = Field(4.0, gt=0, le=100, description=(
        "mean initial elastic interference of the balls that makes the preload, µm"))
    wear_rate_um_per_kh: float = Field(1.4, ge=0, le=1000, description="Archard wear-depth rate after the onset, µm/kh")
    scatter_um: float = Field(2.0, ge=0, le=100, description=(
        "standard deviation of the balls' interference, µm (0: all lose contact at once)"))
    backlash_gain: float = Field(2.83, gt=0, le=20, description=(
        "axial clearance per unit of radial wear beyond the interference (2/sin 45° ≈ 2.83)"))
    truck_wear_coupling: float = Field(
        0.0, ge=0, le=1, description="fraction of the nut's preload loss that the trucks share")
    table_hours: list[float] = Field(default_factory=list, description=(
        "law 'table': operating hours of the table's rows"))
    table_preload_fraction: list[float] = Field(default_factory=list, description=(
        "law 'table': preload as a fraction of the nominal at those hours"))
    table_backlash_um: list[float] = Field(default_factory=list, description="law 'table': backlash at those hours, µm")
    thermal_rise_K: float = Field(3.0, ge=0, le=50, description="steady temperature rise of the screw in operation, K")
    thermal_time_constant_hours: float = Field(1.5, gt=0, description=(
        "time constant of the screw's warming and cooling, h"))
    thermal_expansion_per_K: float = Field(11.5e-6, ge=0, description=(
        "thermal expansion coefficient of the screw (lead growth), 1/K"))
    drag_temperature_coefficient_per_K: float = Field(0.0, ge=0, le=0.2, description=(
        "β in drag = drag(20 °C)·exp(−β·ΔT): the nut's lubricant thins as the screw warms "
        "(0 = drag independent of temperature; about 0.03 /K for mineral greases)"))

    @field_validator("law")
    @classmethod
    def _known_law(cls, v: str) -> str:
        registry.get(laws.KIND, v)  # RegistryError (a ValueError) names the value and the laws
        return v

    @model_validator(mode="after")
    def _law(self) -> DegradationConfig:
        entry = registry.get(laws.KIND, self.law)
        takes = laws.parameters(entry.factory)
        fields = type(self).model_fields
        own = [k for k in takes if k not in fields]  # the law's keys beyond the section's
        for key, value in (self.model_extra or {}).items():
            if key not in takes:
                raise ValueError(
                    f"{key} = {value!r}: unknown key; allowed keys in [degradation]: "
                    f"{', '.join(fields)}" + (f", and for the degradation law {self.law!r}: "
                                              f"{', '.join(own)}" if own else ""))
        laws.law_from_section(self.model_dump())  # the law's own checks (ValueError)
        return self

    def make_law(self):
        """The degradation law of this section (:func:`twin.sim.laws.law_from_section`)."""
        return laws.law_from_section(self.model_dump())


class Phase1Config(_Section):
    """Phase I: the online routine (back and forth at one speed) and its captures (Table I)."""

    speed_mm_s: float = Field(400.0, gt=0, le=2000, description="traverse speed of the Phase I routine, mm/s")
    accel_mm_s2: float = Field(4087.44, gt=0, le=100000, description="acceleration of the Phase I routine, mm/s²")
    start_mm: float = Field(110.0, ge=0, description="start of the Phase I stroke, mm from the travel's origin")
    end_mm: float = Field(330.0, ge=0, description="end of the Phase I stroke, mm")
    dwell_s: float = Field(1.0, ge=0, description="pause at each end of the Phase I stroke, s")
    capture_s: float = Field(10.0, gt=0, le=120, description="length of one Phase I capture, s")
    fs_hz: float = Field(
        10000.0, ge=2000, le=100000, description="DAQ and controller rate of all eight Phase I signals")
    captures_per_sample: int = Field(10, ge=1, description="captures of one Phase I sample")
    capture_interval_minutes: float = Field(30.0, gt=0, description="time between the captures of a sample, min")
    sample_interval_hours: float = Field(84.0, gt=0, description="operating hours between Phase I samples")
    sample_hours: list[float] = Field(
        default_factory=list, description=(
            "explicit operating hours of each sample's first capture; overrides the interval "
            "(the others follow capture_interval_minutes apart)"))
    timestep_s: float = Field(
        2e-4, gt=0, le=1e-3,
        description="simulation step; the nut accelerometers are upsampled to their DAQ rate when it is coarser")

    @model_validator(mode="after")
    def _hours(self) -> Phase1Config:
        if any(h < 0 for h in self.sample_hours):
            raise ValueError(f"sample_hours = {self.sample_hours}: allowed hours >= 0")
        return self


class Phase2Config(_Section):
    """Phase II: the IMU routine (forward and back at several speeds) and its sessions (Table I)."""

    speeds_mm_s: list[float] = Field(default_factory=lambda: [20.0, 100.0, 500.0], description=(
        "traverse speeds of the Phase II runs, mm/s (one run: forward and back at each)"))
    accel_mm_s2: float = Field(19600.0, gt=0, le=100000, description="acceleration of the Phase II routine, mm/s²")
    start_mm: float = Field(0.0, ge=0, description="start of the Phase II stroke, mm from the travel's origin")
    end_mm: float = Field(450.0, ge=0, description="end of the Phase II stroke, mm")
    dwell_s: float = Field(10.0, ge=0, description="pause at each end of the Phase II stroke, s")
    runs_per_session: int = Field(90, ge=1, description="runs of one Phase II session")
    session_interval_hours: float = Field(84.0, gt=0, description="operating hours between Phase II sessions")
    timestep_s: float = Field(2e-4, gt=0, le=1e-3, description="simulation step of the Phase II runs")
    origin_offset_max_mm: float = Field(2.0, ge=0, le=20, description=(
        "largest error of the origin set by hand before a session, mm (uniform ±)"))
    session_hours: list[float] = Field(
        default_factory=list, description="explicit session hours; overrides the interval")
    rail_passes: int = Field(2, ge=1, le=3, description=(
        "rollout passes of a session: 1 looks the rails up where the nut's flank contact puts "
        "the carriage, 2 at the first pass's true position (the fixed point to below a nm) at "
        "twice the rollout's cost; where the carriage rests in the clearance after a stop can "
        "move by a micrometre with one pass, by less than 0.1 µm on the paper's routine "
        "(docs/validation.md, 'Simulation speed')"))
    start_flank: Literal["first", "last"] = Field("first", description=(
        "the nut flank the carriage rests on before a run: that of the run's first motion "
        "(\"first\") or of its last (\"last\": the run follows an identical run, so every move "
        "starts by crossing the clearance)"))

    @model_validator(mode="after")
    def _speeds(self) -> Phase2Config:
        if any(h < 0 for h in self.session_hours):
            raise ValueError(f"session_hours = {self.session_hours}: allowed hours >= 0")
        if not self.speeds_mm_s or any(not 0 < s <= 2000 for s in self.speeds_mm_s):
            raise ValueError(f"speeds_mm_s = {self.speeds_mm_s}: allowed a non-empty list of "
                             "speeds with 0 < speed <= 2000 mm/s")
        return self


class DialConfig(_Section):
    """The dial-indicator backlash test, the reference of the Phase II estimates (the paper's ground truth)."""

    gradation_um: float = Field(12.7, gt=0, description="gradation of the dial indicator, µm")
    reading_noise_um: float = Field(1.5, ge=0, description="1-sigma error of a by-eye sub-gradation reading")
    step_um: float = Field(1.0, gt=0, description="step of the commanded position in the dial test, µm")
    repeats: int = Field(3, ge=1, description="repetitions of the dial test, averaged")
    every_n_sessions: int = Field(1, ge=0, description="a dial test after every n-th Phase II session "
                                  "(0: none)")


class PauseConfig(_Section):
    """A stop of the machine within the campaign."""

    hours: float = Field(ge=0, description="operating hours at which the axis stopped")
    days: float = Field(gt=0, description="length of the stop; the screw cools towards ambient meanwhile")


class CampaignConfig(_Section):
    """The run-to-failure campaign: its length, its stops and which phases it records."""

    scale: float = Field(
        1.0, gt=0, le=1, description="reduced scale: multiplies captures per sample and runs per session")
    total_hours: float = Field(8693.0, gt=0, description="operating hours of the whole campaign")
    warmup_hours: float = Field(2.0, ge=0, description="operating hours before the first sample")
    pauses: list[PauseConfig] = Field(default_factory=lambda: [
        PauseConfig(hours=855.5, days=78.0), PauseConfig(hours=4033.0, days=122.0)])
    phase1: bool = True
    phase2: bool = True


class EffectsConfig(_Section):
    """Physical effects the nominal twin leaves out (all off by default; off = the nominal twin,
    bit for bit). The sim-to-real gap diagnosis (docs/gap-diagnosis.md) adds them as candidate
    explanations."""

    cogging_Nm: float = Field(0.0, ge=0, le=1, description=(
        "amplitude of the motor cogging torque, N·m, a second ripple component "
        "cogging·sin(per_rev·θ + phase) on the motor (Zhu & Howe, IEEE Trans. Energy Conversion "
        "15(4), 2000: period LCM(slots, poles) per revolution)"))
    cogging_per_rev: int = Field(12, ge=1, le=100, description="cogging periods per motor revolution")
    recirculation_impulse_N: float = Field(0.0, ge=0, le=200, description=(
        "peak axial force on the nut of the raised-cosine impulses when balls re-enter the loaded "
        "zone through the return, once per ball-pass period, opposing the motion"))
    recirculation_width: float = Field(0.1, ge=0.02, le=0.5, description=(
        "width of a recirculation impulse as a fraction of the ball-pass period"))
    stribeck_excess_N: float = Field(0.0, ge=0, le=500, description=(
        "static friction of the rails in excess of their Coulomb friction, N: "
        "F = −ΔF·exp(−(v/v_s)²)·sign(v) at the commanded carriage velocity v "
        "(Armstrong-Hélouvry, Dupont, Canudas de Wit, Automatica 30(7), 1994)"))
    stribeck_velocity_mm_s: float = Field(2.0, ge=0.1, le=50, description=(
        "Stribeck velocity v_s, mm/s: the speed below which the excess friction acts"))
    base_frequency_hz: float = Field(120.0, ge=10, le=1000, description=(
        "natural frequency of a structural mode of the machine base along X, Hz"))
    base_modal_mass_kg: float = Field(0.0, ge=0, le=1e5, description=(
        "modal mass of the base mode, kg; 0 = rigid base (no extra degree of freedom)"))
    base_damping_ratio: float = Field(0.03, gt=0, lt=1, description="damping ratio of the base mode")
