"""Stribeck friction at reversals.

Rail, seal and nut friction is higher at low sliding speed than the Coulomb level the twin
uses: F(v) = F_c + (F_s − F_c)·exp(−(v/v_s)²), falling from the static level F_s to F_c within a
Stribeck velocity v_s of a few mm/s (Armstrong-Hélouvry, Dupont & Canudas de Wit, "A survey of
models, analysis tools and compensation methods for the control of machines with friction",
Automatica 30(7), 1994). At every start and reversal the drive must overcome the excess
F_s − F_c: a torque spike and a small stick–slip jolt in the vibration.

Parameters: excess_N = F_s − F_c (``effects.stribeck_excess_N``) and velocity_mm_s = v_s
(``effects.stribeck_velocity_mm_s``). It acts on the Phase I torque and nut accelerations at
reversals and in the transients, and on the IMU at the motion starts.
"""

from twin.harness.diagnosis.candidates.base import Effect, Param, register_effect

EFFECT = register_effect(Effect(
    name="stribeck_friction",
    title="Stribeck friction at reversals",
    params=(Param("excess_N", keys=("effects.stribeck_excess_N",), mode="add", low=30.0, high=150.0,
                  grid=(0.0, 30.0, 70.0, 150.0), label="Stribeck excess friction", unit="N"),
            Param("velocity_mm_s", keys=("effects.stribeck_velocity_mm_s",), mode="set", low=1.0, high=6.0,
                  grid=(1.0, 3.0, 6.0), off=None, label="Stribeck velocity", unit="mm/s")),
    source="Stribeck curve (Armstrong-Hélouvry et al. 1994)",
    amplitude="excess_N",
))
