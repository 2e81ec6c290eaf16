"""Origin-setting variability between sessions.

Before each Phase II session the operator sets the axis origin by hand (against a block, as in
the paper's testbed), so the controller's zero moves by up to a few millimetres from session to
session. Every feature of the error motions (rail waviness and the screw's lead errors alike)
then appears at a shifted commanded position; error motions of different sessions must be
correlated rather than subtracted (paper, section V; ISO 230-2 on the repeatability of the
reference position).

Parameter: spread_mm, the half-width of the uniform distribution of the origin, added to the
scenario's ``phase2.origin_offset_max_mm``. It acts on the shift of the E_XX profile between
sessions (``lag`` statistics) and the dwell positions.
"""

from twin.harness.diagnosis.candidates.base import Effect, Param, register_effect

EFFECT = register_effect(Effect(
    name="origin_variability",
    title="origin-setting variability between sessions",
    params=(Param("spread_mm", keys=("phase2.origin_offset_max_mm",), mode="add", low=0.5, high=3.0,
                  grid=(0.0, 0.5, 1.5, 3.0), label="origin spread between sessions (±)",
                  unit="mm"),),
    source="manual origin setting before each session (paper section III/V; ISO 230-2)",
    amplitude="spread_mm",
    random=True,
))
