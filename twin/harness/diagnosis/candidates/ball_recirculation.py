"""Ball recirculation in the nut.

Each ball leaves the loaded track through the deflector (or return tube) and re-enters it; the
re-entry of an unloaded ball into the loaded zone is an impact on the nut. The impacts repeat
with the passage of the balls past the deflector, i.e. at the ball-pass frequency of the nut,
and being short they carry its harmonics, which the smooth ball-pass waviness of the twin does
not (ball-pass kinematics: Harris & Kotzalas, Rolling Bearing Analysis, 5th ed., ch. 8;
recirculation impacts as a source of ball-screw vibration and noise: e.g. Wei & Lin,
"Kinematic analysis of the ball screw mechanism considering variable contact angles and
elastic deformations", J. Mech. Des. 125, 2003, for the ball motion in the nut).

Parameter: impulse_N, the peak axial force of the impacts (twin key
``effects.recirculation_impulse_N``; pulse width ``effects.recirculation_width`` of the
ball-pass period). It acts on the nut accelerometers (and torque) at the ball-pass harmonics.
"""

from twin.harness.diagnosis.candidates.base import Effect, Param, register_effect

EFFECT = register_effect(Effect(
    name="ball_recirculation",
    title="ball recirculation impacts in the nut",
    params=(Param("impulse_N", keys=("effects.recirculation_impulse_N",), mode="add", low=10.0,
                  high=60.0, grid=(0.0, 10.0, 25.0, 60.0), label="recirculation impulse", unit="N"),),
    source="impacts of balls re-entering the loaded zone at the ball-pass frequency",
    amplitude="impulse_N",
))
