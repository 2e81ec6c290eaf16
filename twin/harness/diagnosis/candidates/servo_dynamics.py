"""Servo loop dynamics: the real position and velocity loops are slower (or faster) than the
twin's.

The cascaded P position / PI velocity controller of the drive follows the command with a
following error that grows as its bandwidth falls: during an acceleration a the error is about
a/(K_v·ω_p)-like and the speed overshoots at the end of the ramp (Ellis, Control System Design
Guide, 4th ed., ch. 17 on cascaded position/velocity loops; Altintas, Manufacturing Automation,
2nd ed., ch. 6). A drive tuned differently from the twin's nominal bandwidths changes the
transients of speed and torque and the band of the loop's resonance.

Parameter: bandwidth_factor, the ratio of the real to the twin's bandwidths, applied to both
loops (``axis.position_bandwidth_hz``, ``axis.velocity_bandwidth_hz``). It acts on the Phase I
speed and torque in the transients and at low frequencies.
"""

from twin.harness.diagnosis.candidates.base import Effect, Param, register_effect

EFFECT = register_effect(Effect(
    name="servo_dynamics",
    title="servo loop dynamics (following error)",
    params=(Param("bandwidth_factor", keys=("axis.position_bandwidth_hz", "axis.velocity_bandwidth_hz"),
                  mode="scale", low=0.35, high=0.75, grid=(0.3, 0.45, 0.6, 0.8, 1.0), off=1.0,
                  log=True, label="servo bandwidth factor", unit="×"),),
    source="cascaded position/velocity loop tuning (Ellis 2012, ch. 17)",
    amplitude="bandwidth_factor",
))
