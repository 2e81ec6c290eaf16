"""Thermal growth of the screw after a pause.

While the axis runs, friction in the nut and the support bearings heats the screw towards a
steady rise ΔT above ambient with a time constant of the order of an hour; during a stop it cools
back. Two consequences are modelled (the twin's first-order temperature model,
:func:`twin.sim.campaign.temperature_at`, gives ΔT at every capture and session):

- the lead grows by α·ΔT (α = 11.5e-6 /K for steel): the carriage moves (1 + α·ΔT) times the
  commanded travel (ISO 230-3 thermal effects; Ramesh, Mannan & Poo, "Error compensation in
  machine tools — a review, part II: thermal errors", Int. J. Mach. Tools Manuf. 40, 2000);
- the lubricant thins: the viscosity of mineral oils and greases falls roughly exponentially with
  temperature, ν ∝ exp(−β·ΔT) with β ≈ 0.03 /K near room temperature (Reynolds' viscosity
  relation; e.g. Stachowiak & Batchelor, Engineering Tribology, 4th ed., ch. 2), so the nut's
  drag torque (the twin's Coulomb drag of the nut, ``frictionloss`` of the screw joint) falls as
  the screw warms (key ``degradation.drag_temperature_coefficient_per_K`` = 0.03 when the effect
  is present): a cold screw right after a pause pulls more torque than a warm one.

Parameter: rise_K, the steady temperature rise added to the scenario's. It acts on the Phase I
torque level (steady, transient) and, through the lead, on where rail features are seen.
"""

from twin.harness.diagnosis.candidates.base import Effect, Param, register_effect

EFFECT = register_effect(Effect(
    name="thermal_growth",
    title="thermal growth of the screw after a pause",
    params=(Param("rise_K", keys=("degradation.thermal_rise_K",), mode="add", low=4.0, high=20.0,
                  grid=(0.0, 5.0, 10.0, 20.0), label="temperature rise of the screw", unit="K"),),
    fixed={"degradation.drag_temperature_coefficient_per_K": 0.03},
    source="lead growth α·ΔT (ISO 230-3; Ramesh et al. 2000) and lubricant viscosity ∝ exp(−β·ΔT)",
    amplitude="rise_K",
))
