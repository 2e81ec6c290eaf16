"""Motor cogging / torque ripple beyond the one the twin knows.

A permanent-magnet servo motor's cogging torque comes from the attraction of the magnets to the
stator teeth; it repeats N_c = LCM(slots, poles) times per revolution (Zhu & Howe, "Influence of
design parameters on cogging torque in permanent magnet machines", IEEE Trans. Energy Convers.
15(4), 2000). The controller does not know it; the velocity loop rejects part of it, the rest
moves the screw and shows as a line at N_c × the rotational frequency in torque, speed and the
nut vibration.

Parameters: torque_Nm, the cogging amplitude (``effects.cogging_Nm``); per_rev, its order
(``effects.cogging_per_rev``, discrete: fitted by grid search over the orders of common
slot/pole combinations). It acts on Phase I torque/speed/acc at N_c·f_rot (f_rot = 40 Hz at
400 mm/s with a 10 mm lead).
"""

from twin.harness.diagnosis.candidates.base import Effect, Param, register_effect

#: cogging orders N_c = LCM(slots, poles) of common slot/pole combinations: 4/2, 3/2, 6/4, 9/6, 12/8
COMMON_ORDERS = (4.0, 6.0, 12.0, 18.0, 24.0)

EFFECT = register_effect(Effect(
    name="cogging",
    title="motor cogging torque",
    params=(Param("torque_Nm", keys=("effects.cogging_Nm",), mode="add", low=0.03, high=0.15,
                  grid=(0.0, 0.03, 0.07, 0.15), label="cogging torque", unit="N·m"),
            Param("per_rev", keys=("effects.cogging_per_rev",), mode="set", grid=COMMON_ORDERS,
                  low=min(COMMON_ORDERS), high=max(COMMON_ORDERS), off=None, discrete=True,
                  label="cogging order", unit="per revolution")),
    source="PM motor cogging, period LCM(slots, poles) per revolution (Zhu & Howe 2000)",
    amplitude="torque_Nm",
))
