"""Physical description of the linear-axis testbed (the paper's section III) and its derived figures.

Everything here is a plain parameter with an SI unit. The numbers come from one place, the
scenario (:class:`twin.sim.scenario.AxisConfig`, in the units of the file), and are converted into
these dataclasses by :func:`twin.sim.scenario.to_axis`; the few defaults here are parameters a
scenario does not expose. The MuJoCo model is built from them by :mod:`twin.sim.model`.

Sources: Pandhare et al., "Ball Screw Health Monitoring with Inertial Sensors", section III
(450 mm travel, 10 mm lead, four trucks on two rails, 100 kg of steel load); THK and HIWIN ball
screw catalogues (nut stiffness K_N = 0.8·K·(F_a0 / (0.1·C_a))^(1/3), shaft stiffness
K_S = A·E/L, series total 1/K = Σ 1/K_i).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from twin.sim import degradation as deg

# The reference carriage (plate, nut housing and the paper's 100 kg load) whose inertia scales
# with the mass of a scenario's carriage.
_REFERENCE_MASS = 120.0  # kg
_REFERENCE_INERTIA = (2.4, 2.0, 3.6)  # kg·m²


@dataclass(frozen=True)
class ScrewDrive:
    """Ball screw, nut and support bearings.

    Attributes:
        lead: screw lead in m (10 mm nominal).
        pitch_diameter: ball pitch-circle diameter D_pw in m (25×10 screw: 25.5 mm).
        root_diameter: screw root diameter in m, for the shaft's axial stiffness.
        shaft_length: distance from the fixed bearing to the nut at mid-stroke in m; the shaft
            stiffness is evaluated there (fixed–free support, K_S = A·E/L).
        young_modulus: Pa (steel 2.06e11).
        rated_dynamic_load: C_a in N (catalogue).
        preload: nominal nut preload F_a0 in N when new.
        nut_stiffness_catalogue: catalogue nut stiffness K at 0.1·C_a in N/m.
        bearing_stiffness: axial stiffness of the support bearings K_B in N/m.
        screw_inertia: screw rotational inertia in kg·m².
        screw_mass: screw mass in kg (for visualisation only).
        no_load_torque: seal/viscous drag torque of the nut without preload, N·m.
        drag_viscous: viscous drag coefficient on the screw hinge, N·m·s/rad.
        contact_damping_ratio: damping ratio of the axial ball-nut mode (structural damping).
        radial_stiffness: radial nut stiffness through which screw runout pushes the carriage, N/m.
    """

    lead: float
    pitch_diameter: float
    root_diameter: float
    shaft_length: float
    rated_dynamic_load: float
    preload: float
    nut_stiffness_catalogue: float
    bearing_stiffness: float
    screw_inertia: float
    no_load_torque: float
    drag_viscous: float
    contact_damping_ratio: float
    radial_stiffness: float
    young_modulus: float = 2.06e11
    screw_mass: float = 2.3

    @property
    def radius_per_rad(self) -> float:
        """R = lead / 2π in m/rad: carriage travel per screw radian."""
        return self.lead / (2.0 * math.pi)

    @property
    def shaft_stiffness(self) -> float:
        """Axial shaft stiffness K_S = A·E/L in N/m (fixed–free; THK catalogue)."""
        area = math.pi * self.root_diameter**2 / 4.0
        return area * self.young_modulus / self.shaft_length

    @property
    def nut_stiffness_new(self) -> float:
        """Nut contact stiffness at the nominal preload, N/m: the catalogue rule
        K_N = 0.8·K·(F_a0/(0.1·C_a))^(1/3) (THK catalogue)."""
        ref = 0.1 * self.rated_dynamic_load
        return 0.8 * self.nut_stiffness_catalogue * (self.preload / ref) ** (1.0 / 3.0)

    def nut_stiffness(self, preload_N: float) -> float:
        """Nut contact stiffness at preload ``preload_N``, N/m: Hertz k ∝ F^(1/3) from the new
        nut's value, floored (see :func:`twin.sim.degradation.contact_stiffness`)."""
        return float(deg.contact_stiffness(self.nut_stiffness_new, preload_N, self.preload))

    def axial_stiffness(self, preload_N: float) -> float:
        """Total axial stiffness 1/K = 1/K_S + 1/K_N + 1/K_B in N/m (THK catalogue)."""
        return float(deg.series_stiffness(self.shaft_stiffness, self.nut_stiffness(preload_N),
                                          self.bearing_stiffness))

    @property
    def lead_angle(self) -> float:
        """Lead angle β = atan(lead / (π·D_pw)) in rad."""
        return float(deg.lead_angle(self.lead, self.pitch_diameter))

    def drag_torque(self, preload_N: float) -> float:
        """Nut drag torque in N·m: no-load torque + catalogue preload torque
        (:func:`twin.sim.degradation.drag_torque_Nm`)."""
        kp = float(deg.preload_torque_coefficient(self.lead, self.pitch_diameter))
        return float(deg.drag_torque_Nm(max(preload_N, 0.0), self.lead, self.no_load_torque, kp))


@dataclass(frozen=True)
class Carriage:
    """Carriage, load and guideway.

    Attributes:
        mass: carriage plate + nut housing + the paper's 100 kg steel load, kg.
        inertia: principal inertia (Ixx, Iyy, Izz) about the centre of mass, kg·m².
        truck_spacing: along-axis distance between front and rear trucks a, m.
        rail_spacing: distance between the two rails w, m.
        truck_stiffness_vertical / truck_stiffness_lateral: per-truck contact stiffness when new, N/m.
        truck_damping_ratio: damping ratio of the carriage's suspension modes on the trucks.
        rail_friction: Coulomb friction force of the four trucks and seals, N.
        com_height: height of the centre of mass above the rail plane, m.
        imu_height: height of the IMU (on top of the steel load) above the rail plane, m.
        nut_height: height of the screw axis (and nut accelerometers) above the rail plane, m
            (negative: below the rail plane is not used here; the screw sits between the rails).
    """

    mass: float
    inertia: tuple[float, float, float]
    truck_spacing: float
    rail_spacing: float
    truck_stiffness_vertical: float
    truck_stiffness_lateral: float
    truck_damping_ratio: float
    rail_friction: float
    imu_height: float
    com_height: float = 0.08
    nut_height: float = 0.03

    @property
    def suspension_omega(self) -> float:
        """ω = √(4·k/m), rad/s, of the carriage bouncing on its four trucks' springs, k the
        stiffer of the vertical and the lateral stiffness: its stiffest translational mode."""
        return math.sqrt(4.0 * max(self.truck_stiffness_vertical, self.truck_stiffness_lateral) / self.mass)

    @staticmethod
    def inertia_of(mass: float) -> tuple[float, float, float]:
        """Principal inertia (Ixx, Iyy, Izz) in kg·m² of a carriage of ``mass`` kg: the reference
        carriage's (2.4, 2.0, 3.6) kg·m² at 120 kg, scaled with the mass."""
        return tuple(i * mass / _REFERENCE_MASS for i in _REFERENCE_INERTIA)


@dataclass(frozen=True)
class Servo:
    """Position/velocity cascade of the servo drive (P position loop, PI velocity loop).

    tau = Kv·[Kp·(θc − θ) + (ωc − ω)] + Ki·∫[Kp·(θc − θ) + (ωc − ω)] + τ_ff, which is exactly a PID
    on the motor angle with k_p = Kv·Kp + Ki, k_i = Ki·Kp, k_d = Kv and velocity feed-forward; this
    maps onto MuJoCo's ``<pid input="pos vel ff">`` actuator.

    Attributes:
        motor_inertia: rotor inertia, kg·m².
        position_bandwidth_hz: position-loop gain Kp / 2π, Hz.
        velocity_bandwidth_hz: velocity-loop crossover Kv / (2π·J_total), Hz.
        velocity_integral_time: velocity-loop integral time Kv/Ki, s.
        torque_feedforward: fraction of the inertial feed-forward torque J_total·α_cmd applied.
        torque_limit: peak motor torque, N·m.
    """

    motor_inertia: float
    position_bandwidth_hz: float
    velocity_bandwidth_hz: float
    velocity_integral_time: float
    torque_feedforward: float = 1.0
    torque_limit: float = 20.0


@dataclass(frozen=True)
class Axis:
    """The whole testbed: travel, drive, carriage, servo and simulation settings.

    friction_timeconst (s) and friction_impedance: the time constant and impedance d of MuJoCo's
    soft constraint for the Coulomb friction of the nut drag and of the rails (the joints'
    ``solreffriction`` and ``solimpfriction``; MuJoCo documentation, "Solver parameters");
    None = MuJoCo's defaults (0.02 s; d from 0.9 to 0.95). A soft friction constraint cancels
    only the fraction d of an applied force below the friction limit (the rest creeps) and
    decelerates a sliding joint to rest over about the time constant, like a damper."""

    travel: float
    screw: ScrewDrive
    carriage: Carriage
    servo: Servo
    friction_timeconst: float | None = None
    friction_impedance: float | None = None

    def total_inertia(self) -> float:
        """Rotational inertia seen by the motor: J_m + J_s + m·R², kg·m²."""
        r = self.screw.radius_per_rad
        return self.servo.motor_inertia + self.screw.screw_inertia + self.carriage.mass * r * r

    def servo_gains(self) -> tuple[float, float, float]:
        """(k_p N·m/rad, k_i N·m/(rad·s), k_d N·m·s/rad) of the equivalent PID, see :class:`Servo`."""
        s = self.servo
        kv = 2.0 * math.pi * s.velocity_bandwidth_hz * self.total_inertia()
        kpos = 2.0 * math.pi * s.position_bandwidth_hz
        ki_v = kv / s.velocity_integral_time
        return kv * kpos + ki_v, ki_v * kpos, kv
