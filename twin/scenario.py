"""Scenarios: TOML files describing the axis, its sensors, its degradation, the routines and the
campaign, validated with errors that name the key, the value and what is allowed.

Units at this edge carry their name (``_mm``, ``_um``, ``_hours``, ``_hz``...); :func:`to_axis`
and friends convert to the SI dataclasses used inside.

Overrides (``--set KEY=VALUE`` on the CLI) use dotted keys, e.g. ``phase2.runs_per_session=10``;
the value is parsed as TOML (``1e-3``, ``[20, 100]``, ``"table"``) and falls back to a string.
"""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from analysis import registry
from twin import laws
from twin.axis import Axis, Carriage, ScrewDrive, Servo
from twin.config import explain_errors, set_dotted


class ScenarioError(ValueError):
    """A scenario that cannot be used; the message is one paragraph naming key, value, allowed."""


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True)


class AxisConfig(_Section):
    travel_mm: float = Field(450.0, gt=0, le=5000)
    lead_mm: float = Field(10.0, gt=0, le=100)
    pitch_diameter_mm: float = Field(25.5, gt=0, le=200)
    root_diameter_mm: float = Field(21.5, gt=0, le=200)
    shaft_length_mm: float = Field(500.0, gt=0, le=6000)
    rated_dynamic_load_N: float = Field(21000.0, gt=0)
    preload_N: float = Field(1500.0, gt=0, description="nominal preload when new; at most 10 % of rated_dynamic_load_N")
    nut_stiffness_N_per_um: float = Field(400.0, gt=0, description="catalogue nut stiffness at 10 % C_a")
    bearing_stiffness_N_per_um: float = Field(750.0, gt=0)
    screw_inertia_kg_m2: float = Field(1.8e-4, gt=0)
    no_load_torque_Nm: float = Field(0.05, ge=0)
    drag_viscous_Nm_s_per_rad: float = Field(2.0e-4, ge=0)
    contact_damping_ratio: float = Field(0.03, gt=0, lt=1)
    radial_stiffness_N_per_um: float = Field(100.0, gt=0)
    carriage_mass_kg: float = Field(120.0, gt=0)
    truck_spacing_mm: float = Field(120.0, gt=0)
    rail_spacing_mm: float = Field(200.0, gt=0)
    truck_stiffness_vertical_N_per_um: float = Field(300.0, gt=0)
    truck_stiffness_lateral_N_per_um: float = Field(200.0, gt=0)
    truck_damping_ratio: float = Field(0.05, gt=0, lt=1)
    rail_friction_N: float = Field(12.0, ge=0)
    imu_height_mm: float = Field(200.0, ge=0)
    motor_inertia_kg_m2: float = Field(1.5e-4, gt=0)
    position_bandwidth_hz: float = Field(20.0, gt=0)
    velocity_bandwidth_hz: float = Field(60.0, gt=0)
    velocity_integral_time_s: float = Field(0.01, gt=0)
    torque_ripple_Nm: float = Field(0.01, ge=0, description="motor torque ripple amplitude")
    torque_ripple_per_rev: int = Field(8, ge=1)
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
    straightness_rms_um: float = Field(0.5, ge=0, le=100)
    lateral_straightness_rms_um: float = Field(0.5, ge=0, le=100)
    spectrum_exponent: float = Field(2.0, ge=0, le=4)
    bolt_pitch_mm: float = Field(60.0, gt=0)
    bolt_amplitude_um: float = Field(0.5, ge=0, le=20)
    cumulative_lead_error_um_per_m: float = Field(8.0, ge=-200, le=200)
    cyclic_lead_error_um: list[float] = Field(default_factory=lambda: [0.3, 0.15, 0.1],
                                              max_length=20)
    runout_um: float = Field(0.3, ge=0, le=50)
    ball_pass_amplitude_um: float = Field(0.03, ge=0, le=5)
    ball_diameter_mm: float = Field(3.969, gt=0)
    contact_angle_deg: float = Field(45.0, gt=0, lt=90)


class SensorsConfig(_Section):
    imu_acc_fs_hz: float = Field(1613.0, gt=0)
    imu_acc_bandwidth_hz: float = Field(300.0, gt=0)
    imu_acc_noise_ug_per_rthz: float = Field(7.0, ge=0)
    imu_gyro_fs_hz: float = Field(1000.0, gt=0)
    imu_gyro_bandwidth_hz: float = Field(200.0, gt=0)
    imu_gyro_noise_urad_s_per_rthz: float = Field(35.0, ge=0)
    imu_acc_bias_ug: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3)
    imu_acc_scale_error: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3)
    imu_gyro_bias_urad_s: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3)
    imu_misalignment_urad: list[float] = Field(default_factory=lambda: [0.0, 0.0, 0.0], min_length=3, max_length=3)
    nut_acc_noise_ug_per_rthz: float = Field(20.0, ge=0)
    encoder_counts_per_rev: int = Field(2**20, ge=16)
    torque_noise_Nm: float = Field(0.005, ge=0)
    position_cmd_fs_hz: float = Field(1000.0, gt=0)
    position_cmd_lead_ms_per_kh: float = Field(0.0, ge=-100.0, le=100.0, description=(
        "how far the recorded position_cmd runs ahead of the IMU's clock, ms per 1000 operating "
        "hours (a trigger latency between the controller and a separately clocked IMU that "
        "drifts over the campaign); it shifts forward traces by +v·τ and reverse ones by −v·τ on "
        "the command axis, common to every DOF. 0 = in sync"))


class DegradationConfig(_Section):
    """The degradation law and its parameters, and the thermal transient.

    ``law`` names a registered degradation law or ``module:Class`` (:mod:`twin.laws`); the law
    reads its parameters from the keys of the same name here. The keys of the built-in laws are
    fields with their ranges (``wear``: onset, interference, wear rate, scatter, backlash gain;
    ``table``: the three lists); a law from elsewhere brings keys of its own, accepted only
    when it takes them."""

    model_config = ConfigDict(extra="allow", validate_assignment=True)

    law: str = Field(default_factory=laws.default_name, description=(
        "a registered degradation law (twin.laws: built-in or installed; default: the "
        "registered default) or module:Class"))
    onset_hours: float = Field(2500.0, ge=0)
    interference_um: float = Field(4.0, gt=0, le=100)
    wear_rate_um_per_kh: float = Field(1.4, ge=0, le=1000)
    scatter_um: float = Field(2.0, ge=0, le=100)
    backlash_gain: float = Field(2.83, gt=0, le=20)
    truck_wear_coupling: float = Field(
        0.0, ge=0, le=1, description="fraction of the nut's preload loss that the trucks share")
    table_hours: list[float] = Field(default_factory=list)
    table_preload_fraction: list[float] = Field(default_factory=list)
    table_backlash_um: list[float] = Field(default_factory=list)
    thermal_rise_K: float = Field(3.0, ge=0, le=50)
    thermal_time_constant_hours: float = Field(1.5, gt=0)
    thermal_expansion_per_K: float = Field(11.5e-6, ge=0)
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
        """The degradation law of this section (:func:`twin.laws.law_from_section`)."""
        return laws.law_from_section(self.model_dump())


class Phase1Config(_Section):
    speed_mm_s: float = Field(400.0, gt=0, le=2000)
    accel_mm_s2: float = Field(4087.44, gt=0, le=100000)
    start_mm: float = Field(110.0, ge=0)
    end_mm: float = Field(330.0, ge=0)
    dwell_s: float = Field(1.0, ge=0)
    capture_s: float = Field(10.0, gt=0, le=120)
    fs_hz: float = Field(
        10000.0, ge=2000, le=100000, description="DAQ and controller rate of all eight Phase I signals")
    captures_per_sample: int = Field(10, ge=1)
    capture_interval_minutes: float = Field(30.0, gt=0)
    sample_interval_hours: float = Field(84.0, gt=0)
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
    speeds_mm_s: list[float] = Field(default_factory=lambda: [20.0, 100.0, 500.0])
    accel_mm_s2: float = Field(19600.0, gt=0, le=100000)
    start_mm: float = Field(0.0, ge=0)
    end_mm: float = Field(450.0, ge=0)
    dwell_s: float = Field(10.0, ge=0)
    runs_per_session: int = Field(90, ge=1)
    session_interval_hours: float = Field(84.0, gt=0)
    timestep_s: float = Field(2e-4, gt=0, le=1e-3)
    origin_offset_max_mm: float = Field(2.0, ge=0, le=20)
    session_hours: list[float] = Field(
        default_factory=list, description="explicit session hours; overrides the interval")
    rail_passes: int = Field(2, ge=1, le=3, description=(
        "rollout passes of a session: 1 looks the rails up at the command shifted by the known "
        "backlash lag, 2 at the first pass's true position (the fixed point to below a nm; "
        "docs/validation.md, 'Simulation speed': one pass is 2.5 s of a 90-run session faster "
        "and moves the carriage by at most 41 nm)"))
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
    gradation_um: float = Field(12.7, gt=0)
    reading_noise_um: float = Field(1.5, ge=0, description="1-sigma error of a by-eye sub-gradation reading")
    step_um: float = Field(1.0, gt=0)
    repeats: int = Field(3, ge=1)
    every_n_sessions: int = Field(1, ge=1)


class PauseConfig(_Section):
    hours: float = Field(ge=0, description="operating hours at which the axis stopped")
    days: float = Field(gt=0, description="length of the stop; the screw cools towards ambient meanwhile")


class CampaignConfig(_Section):
    scale: float = Field(
        1.0, gt=0, le=1, description="reduced scale: multiplies captures per sample and runs per session")
    total_hours: float = Field(8693.0, gt=0)
    warmup_hours: float = Field(2.0, ge=0)
    pauses: list[PauseConfig] = Field(default_factory=lambda: [
        PauseConfig(hours=855.5, days=78.0), PauseConfig(hours=4033.0, days=122.0)])
    phase1: bool = True
    phase2: bool = True


class EffectsConfig(_Section):
    """Physical effects the nominal twin leaves out (all off by default; off = the nominal twin,
    bit for bit). Used by the sim-to-real gap diagnosis (issue 6) as candidate explanations."""

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
    stribeck_velocity_mm_s: float = Field(2.0, ge=0.1, le=50, description="Stribeck velocity v_s, mm/s")
    base_frequency_hz: float = Field(120.0, ge=10, le=1000, description=(
        "natural frequency of a structural mode of the machine base along X, Hz"))
    base_modal_mass_kg: float = Field(0.0, ge=0, le=1e5, description=(
        "modal mass of the base mode, kg; 0 = rigid base (no extra degree of freedom)"))
    base_damping_ratio: float = Field(0.03, gt=0, lt=1, description="damping ratio of the base mode")


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
            from twin.model import BaseMode, check_base_mode
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


# ---------------------------------------------------------------------------------------------
# Loading with readable errors


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``KEY=VALUE`` (VALUE as TOML, else a plain string)."""
    if "=" not in text:
        raise ScenarioError(f"--set {text!r}: expected KEY=VALUE, e.g. phase2.runs_per_session=10")
    key, raw = text.split("=", 1)
    key = key.strip()
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()
    return key, value


def from_dict(data: dict[str, Any], source: str = "scenario") -> Scenario:
    """Validate a scenario dict; raises :class:`ScenarioError` with one paragraph per problem."""
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(explain_errors(exc, data, source, Scenario)) from None


def read_toml(path: str | Path, what: str, error: type[Exception] = ValueError) -> dict[str, Any]:
    """The TOML document of ``path`` (a scenario or a sweep file, named ``what`` in messages);
    an unreadable file or invalid TOML raises ``error`` naming the file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror}).") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}.") from None


#: The scenarios shipped with the package (``scenarios/`` of the checkout, package data once
#: installed): found by name, e.g. ``twin simulate quick``.
SHIPPED = Path(__file__).parent / "scenarios"


def shipped_names() -> list[str]:
    """Names of the shipped scenarios (file stems), sorted."""
    return sorted(p.stem for p in SHIPPED.glob("*.toml"))


def find_scenario(path: str | Path) -> Path:
    """``path`` if it exists, else the shipped scenario of that name (``quick`` or
    ``quick.toml``); an unknown name raises :class:`ScenarioError` listing the shipped ones."""
    path = Path(path)
    if path.exists() or len(path.parts) != 1:
        return path
    shipped = SHIPPED / (path.name if path.suffix == ".toml" else f"{path.name}.toml")
    if shipped.is_file():
        return shipped
    raise ScenarioError(f"{path}: no such file, nor a shipped scenario; shipped scenarios: "
                        f"{', '.join(shipped_names())}")


def load(path: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> Scenario:
    """Read a TOML scenario (a file, or a shipped scenario by name: :func:`find_scenario`) and
    apply ``KEY=VALUE`` overrides."""
    path = find_scenario(path)
    data = copy.deepcopy(read_toml(path, "scenario file", ScenarioError))
    for item in overrides:
        key, value = parse_override(item)
        set_dotted(data, key, value, source=f"{path}: --set", error=ScenarioError)
    return from_dict(data, source=str(path))


# ---------------------------------------------------------------------------------------------
# Conversion to the SI dataclasses


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
