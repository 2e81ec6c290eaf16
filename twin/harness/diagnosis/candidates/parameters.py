"""Twin parameters as candidates of the gap diagnosis: a scenario key that describes the axis and
is uncertain on a real machine, set wrong in the twin.

A real axis mostly differs from its twin not by an unmodelled effect but by a number: the
carriage is heavier than the drawing says, the nut softer than the catalogue, the seals drag
more, the drive was tuned otherwise, a sensor is noisier than its data sheet. Each candidate here
is one such key (or keys that one cause moves alike), multiplied by a fitted factor: mode
``scale``, ``off`` = 1.0 (the scenario as it is), a fit grid around 1 and a prior range of the
factor on a real machine. The diagnosis fits, tests and ranks it like the physical effects (its
response is the twin simulated with the factor on its grid, first seed) and says the fit in the
owner's words with the nominal value of the scenario it was run with: "carriage mass 165 kg, not
120 kg (interval 158–171 kg)" (:func:`analysis.diagnosis.wording.owner_phrase`). The candidate's
name is its scenario key (``axis.carriage_mass_kg``): what to fix.

The keys (``twin/sim/scenario/sections.py``) and the physical ground of each prior range (the factor, real
over nominal):

- **Masses and inertias.** ``axis.carriage_mass_kg`` 0.75–1.5: the nominal is the carriage of
  the drawing; fixtures, cables, the IMU's mount and a payload add to it, and a machined part
  is lighter than the CAD's solid (the carriage mass of a test bench is typically known to
  10–40 %; the guide and screw catalogues size the axis for a mass the user states: THK General
  Catalog, "LM Guide", load calculation; HIWIN "Ballscrews technical information", motor
  selection). ``axis.motor_inertia_kg_m2`` 0.9–1.6: the data sheet's rotor inertia (±10 %) without
  the coupling, the encoder and a brake, which add 10–50 % on small servo motors (e.g. R+W
  BK2 bellows couplings 0.7–2.0 × 10⁻⁴ kg·m² against a 1.5 × 10⁻⁴ kg·m² rotor; Siemens
  1FK7/Yaskawa Σ-7 catalogues list the brake's extra inertia).
- **Stiffnesses.** ``axis.nut_stiffness_N_per_um`` 0.5–1.1: the catalogue's nut stiffness is
  measured at 10 % of C_a on a rigid rig; THK's General Catalog ("Ball Screw", axial rigidity of
  the nut) tells the user to take about 80 % of the table value, and a lighter preload than
  10 % C_a lowers it further (K ∝ (F_a0/0.1 C_a)^(1/3)). ``axis.bearing_stiffness_N_per_um``
  0.4–1.1: the support bearings' catalogue stiffness (NSK "Ball screw support bearings", TAC B
  series) without the housing and its bolts, which in an assembled machine leave 40–80 % of it
  (Weck & Brecher, Werkzeugmaschinen 2, ch. 3 on feed drive stiffness; Altintas, Manufacturing
  Automation, 2nd ed., ch. 2). ``axis.truck_stiffness_vertical_N_per_um`` and
  ``axis.truck_stiffness_lateral_N_per_um`` together 0.6–1.6: the guide block's stiffness is set
  by its preload class, which changes both alike (THK HSR radial clearance classes normal/C1/C0
  span about a factor 2 in rigidity; HIWIN "Linear guideway technical information", preload
  classes Z0/ZA/ZB).
- **Frictions.** ``axis.rail_friction_N`` 0.5–2.5 (log): four blocks' rolling friction (μ ≈
  0.002–0.003) plus the seals' resistance, which the catalogue gives per seal type (THK "LM
  Guide", seal resistance: 2–15 N per block by size and seal) and which doubles with dirt or
  dry seals. ``axis.no_load_torque_Nm`` 0.6–1.5: the nut's dynamic preload torque, toleranced
  ±30–50 % of its reference value by JIS B 1192-3 / ISO 3408-3 (the band depends on the torque
  and the stroke). ``axis.drag_viscous_Nm_s_per_rad`` 0.5–2 (log): the grease's viscosity,
  one ISO VG grade (×1.5) or 10 K of temperature (×0.6–1.7) away from the twin's.
- **Ripple.** ``axis.torque_ripple_Nm`` 0.3–3 (log): the motor's torque ripple at the twin's
  ripple order, which data sheets bound (“< 1–2 % of rated torque”) rather than state (Jahns &
  Soong, "Pulsating torque minimization techniques for PM AC motor drives", IEEE Trans. Ind.
  Electron. 43(2), 1996).
- **Servo gains.** ``axis.velocity_bandwidth_hz`` 0.5–1.6 and ``axis.position_bandwidth_hz``
  0.5–1.6, each alone: a drive's tuning (auto-tuned or by hand) lands anywhere within a factor
  of about 2 of a nominal bandwidth, set by the load-inertia ratio and the resonances it must
  stay below (Ellis, Control System Design Guide, 4th ed., ch. 17; the ``servo_dynamics``
  effect scales both loops alike and only downwards, 0.3–1).
- **Sensor noise floors.** ``sensors.nut_acc_noise_ug_per_rthz``, ``sensors.imu_acc_noise_ug_per_rthz``,
  ``sensors.imu_gyro_noise_urad_s_per_rthz``, ``sensors.torque_noise_Nm`` 0.5–4 (log): a data
  sheet gives the typical density of the sensor alone; cable, conditioning and the DAQ's own
  noise and a unit's spread put the installed floor at up to a few times it, a quiet unit below
  (e.g. ADXL355: 22.5 µg/√Hz typical; PCB 352C33: 0.5 µg/√Hz at 1 kHz but 8 µg at 10 Hz; a
  drive's current measurement is quantised to its ADC). The ``noise`` artefact adds white noise
  to a recording; a noise-floor parameter scales the twin's own (band-limited) floor, also
  below 1.

Not candidates: the sensitivities of the nut accelerometers and of the torque signal are not
scenario keys (the ``gain`` artefact is each channel's sensitivity error, ``imu_misalignment``
the IMU's); the preload is the degradation state the campaign monitors, not a setting; the
geometry (lead, diameters, travel) is known from the drawing; damping ratios are left for
later (their cost, below, and a prior without a catalogue figure).

Cost: each candidate adds its grid's non-nominal points as campaigns of the first twin seed
(4 per candidate, 60 in all: docs/gap-diagnosis.md gives the measured time).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.harness.diagnosis.candidates.base import Effect, Param
from twin.sim.config import get_dotted
from twin.sim.scenario import Scenario

#: The least mis-setting the blind benchmark draws (a factor of 1.15 or 1/1.15), or the
#: parameter's ``least_seen`` on that side when larger.
MIN_DEVIATION = 1.15


@dataclass(frozen=True)
class TwinParameter(Effect):
    """A twin parameter set wrong: one ``factor`` (mode scale, off 1.0) on ``keys``.
    ``quantity``, ``unit``, ``digits``: how a person reads the absolute value ("carriage
    mass", "kg", 3). ``least_seen``: (below 1, above 1) the least deviation of the factor the
    diagnosis sees on the benchmark's scenario (a factor of 1.4 for (1.4, …) means 1/1.4 below
    and 1.4 above; None: not seen on that side within the prior), as
    ``benchmarks/bench_parameter_detection.py`` measures it (docs/gap-diagnosis.md): the blind
    benchmark draws its mis-settings from there outwards, a smaller one being within the twin's
    own seed-to-seed spread, where "no significant gap" is the right answer and nothing can
    be named. ``same_above_one``: the signal artefact that makes the same recording as a factor
    above 1 (the torque's white noise per sample and ``noise:torque``), which the benchmark
    scores as the same answer."""

    quantity: str = ""
    unit: str = ""
    digits: int = 3
    least_seen: tuple[float | None, float | None] = (MIN_DEVIATION, MIN_DEVIATION)
    same_above_one: str | None = None

    @property
    def factor(self) -> Param:
        return self.params[0]

    def nominal(self, s: Scenario) -> list[float]:
        """The scenario's value of each key (what the factor multiplies)."""
        data = s.model_dump(mode="json")
        return [float(get_dotted(data, k, source=f"parameter {self.name}")) for k in self.factor.keys]

    def draw(self, rng: np.random.Generator, magnitude: str) -> dict[str, float]:
        """A mis-set factor inside the prior range, away from 1 by at least
        :data:`MIN_DEVIATION` and the side's ``least_seen``: the side (below or above 1) drawn
        among those the prior and ``least_seen`` leave, then log-uniformly in the half of that
        side's log range nearer 1 ("low") or farther ("high")."""
        p = self.factor
        least = {side: max(MIN_DEVIATION, seen) if seen else math.inf
                 for side, seen in zip(("down", "up"), self.least_seen, strict=True)}
        end = {"down": 1 / p.low, "up": p.high}
        sides = [s for s in ("down", "up") if least[s] < end[s]]
        if not sides:
            raise ValueError(f"parameter {self.name}: no side of its prior {p.low}-{p.high} lies beyond "
                             f"its least seen deviation {self.least_seen}")
        side = str(rng.choice(sides))
        near, far = math.log(least[side]), math.log(end[side])
        mid = 0.5 * (near + far)
        a, b = (near, mid) if magnitude == "low" else (mid, far)
        dev = math.exp(rng.uniform(a, b))
        return {p.name: float(dev if side == "up" else 1.0 / dev)}


_GRID = (0.6, 0.8, 1.0, 1.25, 1.6)
_GRID_WIDE = (0.4, 0.7, 1.0, 1.6, 2.5)
_GRID_NOISE = (0.5, 1.0, 2.0, 3.0, 4.0)
_GRID_HIGH = (0.8, 1.0, 1.25, 1.5, 1.8)
_GRID_SOFT = (0.35, 0.6, 0.8, 1.0, 1.25)
_GRID_SERVO = (0.45, 0.7, 1.0, 1.3, 1.7)


def _p(name: str, keys: tuple[str, ...], quantity: str, unit: str, low: float, high: float,
       grid: tuple[float, ...], source: str, digits: int = 3,
       least_seen: tuple[float | None, float | None] = (MIN_DEVIATION, MIN_DEVIATION),
       same_above_one: str | None = None) -> TwinParameter:
    factor = Param("factor", keys=keys, mode="scale", low=low, high=high, grid=grid, off=1.0, log=True,
                   label=f"{quantity}, times the scenario's", unit="×", digits=2)
    return TwinParameter(name=name, title=quantity, params=(factor,), source=source,
                         amplitude="factor", quantity=quantity, unit=unit, digits=digits,
                         least_seen=least_seen, same_above_one=same_above_one)


_ALL = (
    _p("axis.carriage_mass_kg", ("axis.carriage_mass_kg",), "carriage mass", "kg", 0.75, 1.5, _GRID,
       "fixtures, cables and payload on the drawing's carriage (THK LM Guide load calculation)"),
    _p("axis.motor_inertia_kg_m2", ("axis.motor_inertia_kg_m2",), "motor and coupling inertia", "kg·m²",
       0.9, 1.6, _GRID_HIGH, "rotor inertia ±10 % plus coupling, encoder, brake (servo motor catalogues)"),
    _p("axis.nut_stiffness_N_per_um", ("axis.nut_stiffness_N_per_um",), "nut stiffness", "N/µm", 0.5, 1.1,
       _GRID_SOFT, "about 80 % of the catalogue value, less at a lighter preload (THK Ball Screw, nut rigidity)",
       least_seen=(1.2, None)),
    _p("axis.bearing_stiffness_N_per_um", ("axis.bearing_stiffness_N_per_um",), "support bearing stiffness",
       "N/µm", 0.4, 1.1, _GRID_SOFT, "support bearings in their housing: 40–80 % of the catalogue (Weck & Brecher)",
       least_seen=(1.4, None)),
    _p("axis.truck_stiffness", ("axis.truck_stiffness_vertical_N_per_um", "axis.truck_stiffness_lateral_N_per_um"),
       "guide block stiffness (vertical, lateral)", "N/µm", 0.6, 1.6, _GRID,
       "guide block preload class (THK/HIWIN linear guide catalogues)"),
    _p("axis.rail_friction_N", ("axis.rail_friction_N",), "rail and seal friction", "N", 0.5, 2.5, _GRID_WIDE,
       "seal resistance per block by seal type and state (THK LM Guide)"),
    _p("axis.no_load_torque_Nm", ("axis.no_load_torque_Nm",), "nut drag torque without preload", "N·m",
       0.6, 1.5, _GRID, "dynamic preload torque tolerance ±30–50 % (JIS B 1192-3, ISO 3408-3)"),
    _p("axis.drag_viscous_Nm_s_per_rad", ("axis.drag_viscous_Nm_s_per_rad",), "viscous drag of the screw",
       "N·m·s/rad", 0.5, 2.0, _GRID_WIDE, "grease viscosity: one ISO VG grade or 10 K away"),
    _p("axis.torque_ripple_Nm", ("axis.torque_ripple_Nm",), "motor torque ripple", "N·m", 0.3, 3.0,
       (0.25, 0.5, 1.0, 2.0, 4.0), "ripple bounded, not stated, by motor data sheets (Jahns & Soong 1996)",
       least_seen=(2.0, 1.4)),
    _p("axis.velocity_bandwidth_hz", ("axis.velocity_bandwidth_hz",), "velocity loop bandwidth", "Hz",
       0.5, 1.6, _GRID_SERVO, "drive tuning within about 2× of nominal (Ellis 2012, ch. 17)",
       least_seen=(1.2, 1.2)),
    _p("axis.position_bandwidth_hz", ("axis.position_bandwidth_hz",), "position loop bandwidth", "Hz",
       0.5, 1.6, _GRID_SERVO, "drive tuning within about 2× of nominal (Ellis 2012, ch. 17)",
       least_seen=(1.4, 1.4)),
    _p("sensors.nut_acc_noise_ug_per_rthz", ("sensors.nut_acc_noise_ug_per_rthz",),
       "nut accelerometers' noise floor", "µg/√Hz", 0.5, 4.0, _GRID_NOISE,
       "installed noise floor vs the data sheet's typical density"),
    _p("sensors.imu_acc_noise_ug_per_rthz", ("sensors.imu_acc_noise_ug_per_rthz",),
       "IMU accelerometer's noise floor", "µg/√Hz", 0.5, 4.0, _GRID_NOISE,
       "installed noise floor vs the data sheet's typical density"),
    _p("sensors.imu_gyro_noise_urad_s_per_rthz", ("sensors.imu_gyro_noise_urad_s_per_rthz",),
       "IMU gyroscope's noise floor", "µrad/s/√Hz", 0.5, 4.0, _GRID_NOISE,
       "installed noise floor vs the data sheet's typical density", least_seen=(1.2, 1.2)),
    _p("sensors.torque_noise_Nm", ("sensors.torque_noise_Nm",), "torque signal's noise", "N·m", 0.5, 4.0,
       _GRID_NOISE, "the drive's current measurement: ADC quantisation and noise",
       least_seen=(None, 2.0), same_above_one="noise:torque"),
)

#: The twin-parameter candidates by name (the scenario key, or ``axis.truck_stiffness`` for the
#: guide blocks' two stiffnesses).
PARAMETERS: dict[str, TwinParameter] = {p.name: p for p in _ALL}


def library_entry(p: TwinParameter, nominal: Scenario | None) -> dict:
    """The candidate's entry of ``diagnosis.json``'s ``library``: kind, title, source, the keys,
    the quantity and its unit and digits, the nominal value of each key in the scenario the
    diagnosis ran with, the signal artefact a factor above 1 makes the same recording as
    (``same_recording_above_one``, or None), and the factor's prior range and display."""
    from analysis.diagnosis.artefacts import KIND_PARAMETER

    f = p.factor
    return {"kind": KIND_PARAMETER, "title": p.title, "source": p.source, "keys": list(f.keys),
            "quantity": p.quantity, "unit": p.unit, "digits": p.digits,
            "nominal": p.nominal(nominal) if nominal is not None else None,
            "same_recording_above_one": p.same_above_one,
            "params": {f.name: {"low": f.low, "high": f.high, **f.display()}}}
