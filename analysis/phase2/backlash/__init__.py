"""Change of backlash from the slow-speed error motions: by signal shifts (paper section V,
Eqs. 4–7) and by perceived ball-screw pitch (Eqs. 8–9).

Position reference and sign convention
--------------------------------------
The traces are functions of the *commanded* position (``position_cmd``, proportional to the screw
angle; :mod:`analysis.phase2.traces`). Under this reference

- screw-fixed features (lead error, ball passing, the motor's torque ripple) stay in place between
  the forward and reverse traces and between sessions, up to the origin set for the session;
- rail-fixed features (straightness E_YX, E_ZX and the angles E_AX, E_BX, E_CX from the rails'
  waviness) appear where the carriage, which trails the nut by half the clearance, meets them:
  at x_cmd = u + b/2 moving forward and u − b/2 moving in reverse (x_cmd − origin). Relative to the
  first session the forward trace shifts by +Δb/2 and the reverse trace by −Δb/2, on top of the
  common shift of the new origin.

The paper's text assumes the opposite reference (rail features stay, E_XX moves), which is why its
Eq. 5 subtracts ΔPositionShift of E_XX. Here the commanded position itself is screw-locked, so the
stationary part is the axis and (``stationary="command"``, the default)

    ΔPositionShift_ij = PositionShift_ij1 − PositionShift_ij2            (Eq. 4, forward − reverse)
    ΔBacklash_ij      = ΔPositionShift_ij                                 (Eq. 5, this reference)

With the shift convention of :mod:`analysis.phase2.shifts` (a positive shift = features at a larger
commanded position) a **positive change of backlash comes out positive**: ΔPositionShift = +Δb.
``stationary="E_XX"`` subtracts the shift of E_XX instead (ΔBacklash_ij = ΔPositionShift_ij −
ΔPositionShift_i1, Eq. 5 with the moving and stationary roles of this reference); it only makes
sense if the high-pass-filtered E_XX is purely screw-fixed. At the IMU it is not: its content above
the 0.5 mm cutoff mixes the motor's 8-per-revolution torque ripple and ball passing (screw-fixed)
with the Abbe terms of pitch and yaw (rail-fixed): in the twin it shifts by hardly any of the
backlash at 20 mm/s (torque ripple dominates) but by most of it at 100 mm/s (docs/validation.md),
so E_XX is left out of the default sum.

Weighted sum (Eqs. 6–7): γ_ij = min(γ_ij1, γ_ij2), ΔBacklash_i = Σ_j γ_ij^σ ΔBacklash_ij /
Σ_j γ_ij^σ with σ = 4 over ``dofs`` (by default the straightness pair E_YX, E_ZX; the paper's
five non-positioning DOFs with ``dofs=NON_POSITIONING``, see :class:`BacklashEstimator`).

Perceived pitch (Eqs. 8–9): for every DOF and direction whose correlation shows a comb of peaks
(:class:`analysis.phase2.shifts.ShiftResult.spacing_m`), the observed pitch p_ijk is h times the
period of the h-per-revolution feature, h = round(lead / spacing) (peaks of an h-per-revolution
feature are lead/h apart; the twin's comb is the motor's 8-per-revolution torque ripple,
1.25 mm). The comb finds the feature and its order; its period comes by default from the
feature's frequency in the trace (``pitch_method="harmonic"``, :func:`tone_frequency`, the
maximum-likelihood frequency of a sinusoid), with ``pitch_method="comb"`` from the spacing of the
comb's line fit, which the trace's broadband content and noise move through every peak. The comb
is taken from the session's own autocorrelation: the comb of the *cross*-correlation of two traces
with periods P_0 and P_i has the mean spacing (P_0 + P_i)/2 (the sum over x of two slightly
detuned combs; checked in tests/test_phase2_backlash.py), which would halve Eq. 9. Then
p_i = Σ γ_ijk^σ p_ijk / Σ γ_ijk^σ over (j, k) with the γ of the correlation against the reference
(Eq. 8), and ΔBacklash_i ≈ (L/p)(p_i − p_0) with L the travel, p the nominal lead and p_0 the
pitch of the first session. Eq. 9 assumes that backlash makes the IMU-based position scale with
L/(L − b), and recovers b on such traces; under the commanded reference the comb is locked to the
screw angle, so its spacing cannot change with backlash (nor with the lead's thermal growth), and
this estimate only shows its noise (its size on the paper's campaign: docs/validation.md).

Plausibility of Eq. 9: L/p multiplies the pitch's noise (45 on the paper's axis, 60 on a 300 mm
stroke with a 5 mm lead), so a comb read at 0.1 % off gives hundreds of µm. An Eq. 9 value is
withheld (NaN, with the reason in ``SessionBacklash.pitch_note``) when its magnitude exceeds
the bound min(``pitch_bound_lead_fraction`` · p, max(``pitch_bound_factor`` · |ΔBacklash by
shifts|, ``pitch_bound_floor_m``)): by default 1 % of the lead (100 µm on the paper's screw, ten
times the 10 µm change the paper reports at the end of its campaign, Pandhare et al. Fig. 13),
and three times the change the recording's shifts (Eqs. 4–6) show, but never below 5 µm. These
are the choices of this tool, not of the paper: what the recording can physically show is the
lost motion the shifts measure, and no ball screw keeps running with a clearance of a sizeable
part of its lead.

Units: SI inside (m, rad); results carry µm / mm only in the names of the JSON fields.

Modules: :mod:`.estimator` (one session), :mod:`.campaign` (a campaign's sessions, re-zeroed).
"""

from analysis.phase2.backlash.campaign import (
    CampaignBacklash,
    campaign_backlash,
    estimator_for,
    rezero_on_baseline,
    session_error_motions_task,
)
from analysis.phase2.backlash.estimator import (
    COMB_TOLERANCE,
    DIRECTIONS,
    NON_POSITIONING,
    PITCH_BOUND_FACTOR,
    PITCH_BOUND_FLOOR_M,
    PITCH_BOUND_LEAD_FRACTION,
    PITCH_METHODS,
    SIGMA,
    STRAIGHTNESS,
    BacklashEstimator,
    PitchBacklash,
    SessionBacklash,
    primary_m,
    tone_frequency,
    weighted_sum,
)

__all__ = [
    "BacklashEstimator", "COMB_TOLERANCE", "CampaignBacklash", "DIRECTIONS", "NON_POSITIONING",
    "PITCH_BOUND_FACTOR", "PITCH_BOUND_FLOOR_M", "PITCH_BOUND_LEAD_FRACTION", "PITCH_METHODS", "PitchBacklash",
    "SIGMA", "STRAIGHTNESS", "SessionBacklash", "campaign_backlash", "estimator_for", "primary_m",
    "rezero_on_baseline", "session_error_motions_task", "tone_frequency", "weighted_sum",
]
