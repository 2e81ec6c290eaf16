"""A structural resonance of the machine base.

The bed that carries the rails and the screw's support bearings is not rigid: its lowest mode
along the axis (tens to a few hundred hertz for a table-top testbed) is excited by the drive's
reaction force at every acceleration and shows as a peak in the carriage's vibration; a single
modal mass–spring–damper along X represents it (modal model of machine-tool structures:
Altintas, Manufacturing Automation, 2nd ed., ch. 3; Ewins, Modal Testing, 2nd ed.).

Parameters: frequency_hz (``effects.base_frequency_hz``; discrete: fitted by grid search, a
resonance moving between bands does not interpolate) and modal_mass_kg
(``effects.base_modal_mass_kg``, 0 = rigid). It acts on the nut accelerometers and the IMU in
the band of the resonance, mostly in the transients and reversals.
"""

from twin.harness.diagnosis.candidates.base import Effect, Param, register_effect

EFFECT = register_effect(Effect(
    name="base_resonance",
    title="structural resonance of the base",
    params=(Param("frequency_hz", keys=("effects.base_frequency_hz",), mode="set", low=80.0, high=450.0,
                  grid=(80.0, 125.0, 175.0, 250.0, 350.0, 450.0), off=None, discrete=True,
                  label="base resonance frequency", unit="Hz", digits=3),
            Param("modal_mass_kg", keys=("effects.base_modal_mass_kg",), mode="set", low=300.0, high=3000.0,
                  grid=(0.0, 300.0, 1000.0, 3000.0), log=True, label="modal mass of the base",
                  unit="kg")),
    source="single-DOF modal model of the machine base (Altintas 2012, ch. 3)",
    amplitude="modal_mass_kg",
))
