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
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from sklearn.base import BaseEstimator

from analysis.params import InheritedParams
from analysis.phase2.shifts import THRESHOLD, ShiftResult, shift_between
from analysis.phase2.traces import DOFS, DirectionalTraces, SessionErrorMotions
from analysis.phase2.winfilt import CUTOFF_WAVELENGTH_M, winfilt
from analysis.registry import register

SIGMA = 4
"""Weighting exponent σ of Eqs. 6 and 8 (paper section V)."""

DIRECTIONS = ("forward", "reverse")
NON_POSITIONING = DOFS[1:]
"""The five DOFs of the paper's Eq. 6 (j = 2..6)."""
STRAIGHTNESS = ("E_YX", "E_ZX")
"""Default DOFs of Eq. 6 here (see :class:`BacklashEstimator`)."""
COMB_TOLERANCE = 0.01
"""A comb of correlation peaks counts as a pitch only if h·spacing is within 1 % of the nominal
lead and the peaks sit within 5 % of the spacing (rms) from their line."""
PITCH_BOUND_FACTOR = 3.0
"""Eq. 9 is withheld beyond this multiple of |ΔBacklash by shifts| (see the module's doc)."""
PITCH_BOUND_FLOOR_M = 5e-6
"""... but the bound is never below this, m."""
PITCH_BOUND_LEAD_FRACTION = 0.01
"""... nor above this fraction of the lead."""


@dataclass(frozen=True)
class SessionBacklash:
    """Backlash estimates of one session against the reference session.

    Attributes:
        session, hours: the session and its operating hours (h).
        shifts: {(dof, direction): ShiftResult} of every correlation.
        delta_position_shift_m: {dof: ΔPositionShift_ij} (Eq. 4), m.
        delta_backlash_dof_m: {dof: ΔBacklash_ij} (Eq. 5, this reference), m.
        gamma: {dof: γ_ij = min over directions} (Eq. 7).
        delta_backlash_shift_m: ΔBacklash_i by shifts (Eq. 6), m.
        observed_pitch_m: perceived pitch p_i (Eq. 8), m (NaN if no comb of peaks).
        delta_backlash_pitch_m: ΔBacklash_i by pitch (Eq. 9), m.
        pitch_by: {"dof/direction": p_ijk} used in Eq. 8, m (NaN: no comb).
        delta_backlash_pitch_raw_m: Eq. 9 before the plausibility bound, m.
        pitch_note: why ``delta_backlash_pitch_m`` is NaN ("" when it is a number).
    """

    session: str
    hours: float
    shifts: dict = field(repr=False)
    delta_position_shift_m: dict
    delta_backlash_dof_m: dict
    gamma: dict
    delta_backlash_shift_m: float
    observed_pitch_m: float
    delta_backlash_pitch_m: float
    pitch_by: dict = field(repr=False, default_factory=dict)
    delta_backlash_pitch_raw_m: float = float("nan")
    pitch_note: str = ""

    def to_json(self) -> dict:
        """The session record of ``backlash.json`` (µm and mm as the names say)."""
        def num(v, scale=1.0):
            return None if v is None or not math.isfinite(v) else float(v) * scale
        return {
            "session": self.session,
            "hours": float(self.hours),
            "delta_backlash_um_shift": num(self.delta_backlash_shift_m, 1e6),
            "delta_backlash_um_pitch": num(self.delta_backlash_pitch_m, 1e6),
            "observed_pitch_mm": num(self.observed_pitch_m, 1e3),
            "delta_backlash_um_pitch_unbounded": num(self.delta_backlash_pitch_raw_m, 1e6),
            "pitch_note": self.pitch_note or None,
            "gamma": {d: num(g) for d, g in self.gamma.items()},
            "gamma_by_direction": {f"{d}/{k}": num(r.gamma) for (d, k), r in self.shifts.items()},
            "position_shift_um": {f"{d}/{k}": num(r.shift_m, 1e6) for (d, k), r in self.shifts.items()},
            "delta_position_shift_um": {d: num(v, 1e6) for d, v in self.delta_position_shift_m.items()},
            "delta_backlash_um_by_dof": {d: num(v, 1e6) for d, v in self.delta_backlash_dof_m.items()},
        }


def _traces(X) -> tuple[DirectionalTraces, str, float]:
    if isinstance(X, SessionErrorMotions):
        return X.slow, X.session, X.hours
    if isinstance(X, DirectionalTraces):
        return X, "", float("nan")
    raise TypeError(f"expected SessionErrorMotions or DirectionalTraces, got {type(X).__name__}")


def weighted_sum(values, gammas, sigma: int = SIGMA) -> float:
    """Σ γ^σ v / Σ γ^σ over the finite entries (Eqs. 6 and 8); NaN if none (γ < 0 counts as 0)."""
    v = np.asarray(values, dtype=float)
    w = np.clip(np.asarray(gammas, dtype=float), 0.0, None) ** sigma
    ok = np.isfinite(v) & np.isfinite(w) & (w > 0)
    if not ok.any():
        return float("nan")
    return float(np.sum(w[ok] * v[ok]) / np.sum(w[ok]))


PITCH_METHODS = ("harmonic", "comb")
"""How Eq. 8's observed pitch is read from a comb of correlation peaks (see
:meth:`BacklashEstimator.comb_pitch` and :func:`tone_frequency`)."""


def tone_frequency(y: np.ndarray, dx: float, f0: float, half_range: float) -> float:
    """Frequency (cycles per m) of the sinusoid in ``y`` nearest ``f0``, searched within
    ``f0`` ± ``half_range``: the maximum of the periodogram |Σ y_n·exp(−j2πf·n·dx)|.

    The periodogram's maximum is the maximum-likelihood frequency of one sinusoid in white noise
    (Rife & Boorstyn, "Single-tone parameter estimation from discrete-time observations", IEEE
    Trans. Inf. Theory 20(5), 1974; Kay, *Fundamentals of Statistical Signal Processing:
    Estimation Theory*, 1993, sec. 7.10); its variance falls as N⁻³, so over a whole stroke it
    resolves a small part of a bin. No taper: the rectangular window is the likelihood's, and its
    slowly falling sidelobes (Harris, "On the use of windows for harmonic analysis with the
    discrete Fourier transform", Proc. IEEE 66(1), 1978) find little to leak here, because the
    traces come high-passed by winfilt (the long wavelengths, the largest content, are gone).
    The search: the periodogram on a grid of a quarter of a bin over the range, then a bounded
    scalar maximisation (``scipy.optimize.minimize_scalar``) within a quarter of a bin of the
    best grid point. NaN when the maximum lies on the range's edge.
    """
    from scipy.optimize import minimize_scalar

    y = np.asarray(y, dtype=float)
    y = y - y.mean()
    x = np.arange(y.size) * dx

    def mag(f: float) -> float:
        return -abs(np.sum(y * np.exp(-2j * np.pi * f * x)))

    step = 0.25 / (y.size * dx)
    grid = f0 + np.arange(-math.ceil(half_range / step), math.ceil(half_range / step) + 1) * step
    k = int(np.argmin([mag(f) for f in grid]))
    if k in (0, grid.size - 1):
        return float("nan")
    res = minimize_scalar(mag, bounds=(grid[k] - step, grid[k] + step), method="bounded",
                          options={"xatol": 1e-9 * f0})
    return float(res.x)


@register("backlash_estimators", "shift", label="Signal shifts (Eq. 6)", color="tab:blue",
          marker="o", default=True)
class BacklashEstimator(InheritedParams, BaseEstimator):
    """Change of backlash relative to a reference session (scikit-learn style).

    Registered as the backlash estimator ``shift`` (the default of ``twin backlash``).
    ``primary_estimate`` ("shift" or "pitch") names the estimate that is *the* estimate of the
    class: the Kalman trend, the prognosis and the score use it. ``get_params`` keeps the
    parameters of this class in a subclass whose ``__init__`` forwards ``**kwargs``.

    ``fit(reference)`` takes the first session (a :class:`SessionErrorMotions`, whose ``slow``
    traces are used, or :class:`DirectionalTraces`); ``estimate(session)`` returns a
    :class:`SessionBacklash`; ``transform(sessions)`` an (n, 2) array of [by shifts, by pitch] in m.

    Parameters:
        cutoff_wavelength_m: winfilt cutoff λc, m (0.5 mm). window_definition: see
            :mod:`analysis.phase2.winfilt`.
        threshold: peak threshold as a fraction of γ (0.75). fit_fraction: lobe part of each peak
            fit. upsample: lag-grid refinement. min_peaks: fewest peaks for a pitch.
        max_lag_m: search range of the main peak, m (5 mm: origins within ±2 mm plus backlash).
        sigma: weighting exponent (4).
        dofs: DOFs of the shift-based sum (Eq. 6). Default: the straightness pair E_YX, E_ZX.
            The paper sums the five non-positioning DOFs (``NON_POSITIONING``) and relies on
            γ^σ to silence poor ones; in the twin the gyro-based angles at 100 mm/s correlate
            only moderately while their shifts scatter by several µm (the winfilt band sits at
            the edge of the gyro's 200 Hz bandwidth), which with σ = 4 still weighs enough to
            spoil the sum by µm, whereas E_YX and E_ZX correlate almost perfectly and resolve a
            fraction of a µm (figures: docs/validation.md). At 20 mm/s the angles hardly
            correlate and the two choices agree.
        pitch_dofs: DOFs of the perceived pitch (Eq. 8).
        pitch_method: "harmonic" (default) or "comb": how each trace's pitch is read
            (:meth:`observed_pitch`).
        stationary: "command" (default) or "E_XX": what ΔPositionShift is referred to (Eq. 5).
        travel_m, lead_m: L and p of Eq. 9, m (the paper's 0.45 m and 10 mm).
        pitch_bound_factor, pitch_bound_floor_m, pitch_bound_lead_fraction: the plausibility
            bound of Eq. 9 (module doc; ``pitch_bound_lead_fraction=inf`` with
            ``pitch_bound_factor=inf`` switches it off).
    """

    primary_estimate = "shift"

    def __init__(self, *, cutoff_wavelength_m: float = CUTOFF_WAVELENGTH_M,
                 window_definition: str = "iso50", threshold: float = THRESHOLD,
                 fit_fraction: float = 0.8, upsample: int = 8, min_peaks: int = 3,
                 max_lag_m: float = 5e-3, sigma: int = SIGMA, dofs: tuple = STRAIGHTNESS,
                 pitch_dofs: tuple = DOFS, stationary: str = "command", travel_m: float = 0.45,
                 lead_m: float = 0.010, pitch_method: str = "harmonic",
                 pitch_bound_factor: float = PITCH_BOUND_FACTOR,
                 pitch_bound_floor_m: float = PITCH_BOUND_FLOOR_M,
                 pitch_bound_lead_fraction: float = PITCH_BOUND_LEAD_FRACTION):
        self.cutoff_wavelength_m = cutoff_wavelength_m
        self.window_definition = window_definition
        self.threshold = threshold
        self.fit_fraction = fit_fraction
        self.upsample = upsample
        self.min_peaks = min_peaks
        self.max_lag_m = max_lag_m
        self.sigma = sigma
        self.dofs = dofs
        self.pitch_dofs = pitch_dofs
        self.stationary = stationary
        self.travel_m = travel_m
        self.lead_m = lead_m
        self.pitch_method = pitch_method
        self.pitch_bound_factor = pitch_bound_factor
        self.pitch_bound_floor_m = pitch_bound_floor_m
        self.pitch_bound_lead_fraction = pitch_bound_lead_fraction

    # -- helpers ---------------------------------------------------------------------------
    def _check_params(self) -> None:
        if self.pitch_method not in PITCH_METHODS:
            raise ValueError(f"pitch_method is {self.pitch_method!r}; expected one of {PITCH_METHODS}")
        if self.stationary not in ("command", "E_XX"):
            raise ValueError(f"stationary is {self.stationary!r}; expected 'command' or 'E_XX'")
        for d in (*self.dofs, *self.pitch_dofs):
            if d not in DOFS:
                raise ValueError(f"unknown DOF {d!r}; expected one of {DOFS}")
        for k in ("pitch_bound_factor", "pitch_bound_floor_m", "pitch_bound_lead_fraction"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and v >= 0):
                raise ValueError(f"{k} is {v!r}; expected a number >= 0")
        if not (self.travel_m > 0 and self.lead_m > 0):
            raise ValueError(f"travel_m = {self.travel_m!r} and lead_m = {self.lead_m!r}: expected > 0 m")

    def _filtered(self, tr: DirectionalTraces, what: str) -> dict:
        dx = tr.dx_m
        out = {}
        for k in DIRECTIONS:
            arr = getattr(tr, k)
            if not np.all(np.isfinite(arr)):
                raise ValueError(f"{what}: the {k} slow traces have non-finite values")
            out[k] = winfilt(arr, dx, self.cutoff_wavelength_m, self.window_definition)
        return {"x0": float(tr.x_m[0]), "dx": dx, **out}

    def _shift(self, a: dict, b: dict, j: int, k: str) -> ShiftResult:
        return shift_between(a[k][j], b[k][j], a["dx"], a["x0"], b["x0"], upsample=self.upsample,
                             max_lag_m=self.max_lag_m, threshold=self.threshold,
                             fit_fraction=self.fit_fraction, min_peaks=self.min_peaks)

    def comb_pitch(self, r: ShiftResult) -> float:
        """Observed pitch (m) of a comb of correlation peaks: spacing × order, or NaN when the
        comb does not match a harmonic of the nominal lead (see ``COMB_TOLERANCE``)."""
        spacing = r.spacing_m
        if not math.isfinite(spacing) or spacing <= 0 or not r.comb_residual_m <= 0.05 * spacing:
            return float("nan")
        p = spacing * max(1, round(self.lead_m / spacing))
        return p if abs(p - self.lead_m) <= COMB_TOLERANCE * self.lead_m else float("nan")

    def observed_pitch(self, r: ShiftResult, trace: np.ndarray, dx: float) -> float:
        """Eq. 8's p_ijk of one (winfiltered) trace whose autocorrelation is ``r``, m.

        ``pitch_method="comb"``: :meth:`comb_pitch`, the spacing of the comb's line fit.
        ``"harmonic"`` (default): where the comb shows an h-per-revolution feature, the
        frequency f of that harmonic in the trace itself (:func:`tone_frequency`, searched
        within ± ``COMB_TOLERANCE`` of 1/spacing) gives p = h/f. The autocorrelation's peaks are
        the sum of every component and of the noise, so a broadband noise moves each peak's
        quadratic fit; the narrowband estimate reads only the harmonic."""
        p_comb = self.comb_pitch(r)
        if self.pitch_method == "comb" or not math.isfinite(p_comb):
            return p_comb
        h = max(1, round(self.lead_m / r.spacing_m))
        f = tone_frequency(trace, dx, 1.0 / r.spacing_m, COMB_TOLERANCE / r.spacing_m)
        return h / f if math.isfinite(f) and f > 0 else float("nan")

    # -- scikit-learn API ------------------------------------------------------------------
    def fit(self, X, y=None) -> BacklashEstimator:
        """Use ``X`` (the first session) as the reference. Returns self."""
        self._check_params()
        tr, name, hours = _traces(X)
        self.reference_ = self._filtered(tr, f"reference session {name or '(traces)'}")
        self.reference_session_ = name
        self.reference_hours_ = hours
        pitches, gammas = [], []
        for d in self.pitch_dofs:
            j = DOFS.index(d)
            for k in DIRECTIONS:
                r = self._shift(self.reference_, self.reference_, j, k)
                pitches.append(self.observed_pitch(r, self.reference_[k][j], self.reference_["dx"]))
                gammas.append(r.gamma)
        self.reference_pitch_m_ = weighted_sum(pitches, gammas, self.sigma)
        return self

    def estimate(self, X) -> SessionBacklash:
        """Estimates for one session (Eqs. 4–9) against the fitted reference."""
        if not hasattr(self, "reference_"):
            raise RuntimeError("BacklashEstimator: call fit(reference_session) first")
        tr, name, hours = _traces(X)
        cur = self._filtered(tr, f"session {name or '(traces)'}")
        if abs(cur["dx"] - self.reference_["dx"]) > 1e-6 * self.reference_["dx"]:
            raise ValueError(f"session {name}: slow grid step {cur['dx'] * 1e6:g} µm differs from "
                             f"the reference's {self.reference_['dx'] * 1e6:g} µm; expected equal steps")
        needed = sorted(set(self.dofs) | set(self.pitch_dofs) | {"E_XX"}, key=DOFS.index)
        shifts = {(d, k): self._shift(cur, self.reference_, DOFS.index(d), k)
                  for d in needed for k in DIRECTIONS}
        dps = {d: shifts[(d, "forward")].shift_m - shifts[(d, "reverse")].shift_m for d in needed}
        gamma = {d: min(shifts[(d, "forward")].gamma, shifts[(d, "reverse")].gamma) for d in needed}
        ref = dps["E_XX"] if self.stationary == "E_XX" else 0.0
        dbl = {d: dps[d] - ref for d in self.dofs}
        by_shift = weighted_sum([dbl[d] for d in self.dofs], [gamma[d] for d in self.dofs],
                                self.sigma)
        pitch_by = {(d, k): self.observed_pitch(self._shift(cur, cur, DOFS.index(d), k),
                                                cur[k][DOFS.index(d)], cur["dx"])
                    for d in self.pitch_dofs for k in DIRECTIONS}
        p_i = weighted_sum(list(pitch_by.values()),
                           [shifts[key].gamma for key in pitch_by], self.sigma)
        raw = self.travel_m / self.lead_m * (p_i - self.reference_pitch_m_)
        by_pitch, note = self.bounded_pitch_estimate(raw, by_shift, p_i)
        return SessionBacklash(session=name, hours=hours, shifts=shifts,
                               delta_position_shift_m=dps, delta_backlash_dof_m=dbl, gamma=gamma,
                               delta_backlash_shift_m=by_shift, observed_pitch_m=p_i,
                               delta_backlash_pitch_m=by_pitch,
                               pitch_by={f"{d}/{k}": v for (d, k), v in pitch_by.items()},
                               delta_backlash_pitch_raw_m=raw, pitch_note=note)

    def pitch_bound_m(self, by_shift_m: float) -> float:
        """The largest |Eq. 9| shown, m: min(fraction · lead, max(factor · |by shifts|, floor))
        (the module's doc); without a shift estimate, the lead's fraction."""
        lead_part = self.pitch_bound_lead_fraction * self.lead_m
        if not math.isfinite(by_shift_m) or math.isinf(self.pitch_bound_factor):
            return lead_part
        return min(lead_part, max(self.pitch_bound_factor * abs(by_shift_m), self.pitch_bound_floor_m))

    def bounded_pitch_estimate(self, raw_m: float, by_shift_m: float, pitch_m: float) -> tuple[float, str]:
        """(Eq. 9's change of backlash, m, or NaN; why NaN) after the plausibility bound."""
        if not math.isfinite(self.reference_pitch_m_):
            return float("nan"), (f"no comb of correlation peaks in the reference session (threshold "
                                  f"{self.threshold:g} of the main peak, {self.min_peaks} peaks, h·spacing within "
                                  f"{COMB_TOLERANCE:.0%} of the {self.lead_m * 1e3:g} mm lead): Eq. 8 has no pitch")
        if not math.isfinite(pitch_m):
            return float("nan"), (f"no comb of correlation peaks in this session (threshold {self.threshold:g}, "
                                  f"{self.min_peaks} peaks, within {COMB_TOLERANCE:.0%} of the lead): Eq. 8 has "
                                  "no pitch")
        bound = self.pitch_bound_m(by_shift_m)
        if abs(raw_m) > bound:
            why = (f"{self.pitch_bound_lead_fraction:g} of the {self.lead_m * 1e3:g} mm lead"
                   if bound == self.pitch_bound_lead_fraction * self.lead_m else
                   f"{self.pitch_bound_factor:g} × the {abs(by_shift_m) * 1e6:.2f} µm by shifts, at least "
                   f"{self.pitch_bound_floor_m * 1e6:g} µm")
            return float("nan"), (f"withheld: Eq. 9 gives {raw_m * 1e6:.2f} µm (pitch {pitch_m * 1e3:.6f} mm), "
                                  f"beyond the plausibility bound {bound * 1e6:.2f} µm ({why})")
        return raw_m, ""

    def transform(self, X) -> np.ndarray:
        """(n, 2) [ΔBacklash by shifts, by pitch] in m for the sessions ``X`` (a sequence)."""
        return np.array([[e.delta_backlash_shift_m, e.delta_backlash_pitch_m]
                         for e in (self.estimate(x) for x in X)]).reshape(-1, 2)


@register("backlash_estimators", "pitch", label="Perceived pitch (Eq. 9)", color="tab:orange",
          marker="s")
class PitchBacklash(BacklashEstimator):
    """The same estimates as :class:`BacklashEstimator`, with the perceived pitch (Eqs. 8–9) as
    the primary estimate (trend, prognosis, score). Registered as ``pitch``."""

    primary_estimate = "pitch"


def primary_m(s: SessionBacklash, estimator) -> float:
    """The estimator's primary change of backlash of session ``s`` (m): by shifts or by pitch."""
    which = getattr(estimator, "primary_estimate", "shift")
    if which not in ("shift", "pitch"):
        raise ValueError(f"{type(estimator).__qualname__}.primary_estimate = {which!r}; "
                         "expected 'shift' or 'pitch'")
    return s.delta_backlash_shift_m if which == "shift" else s.delta_backlash_pitch_m


@dataclass
class CampaignBacklash:
    """Backlash estimates of every session of a campaign against its first usable session.

    Attributes:
        sessions: one :class:`SessionBacklash` per usable session, in hours order (the first is
            the reference, with zero change by construction).
        error_motions: the :class:`SessionErrorMotions` they came from (same order).
        skipped_runs: (session, run, reason) of every run left out.
        skipped_sessions: (session, reason) of every session left out (no usable run).
        estimator: the fitted :class:`BacklashEstimator`.
        baseline_sessions: how many leading sessions define zero change (see
            :func:`rezero_on_baseline`); 1 is the paper's single reference.
        baseline_offset_m: (by shifts, by pitch) subtracted from every raw estimate, m.
    """

    sessions: list
    error_motions: list
    skipped_runs: list
    skipped_sessions: list
    estimator: BacklashEstimator
    baseline_sessions: int = 1
    baseline_offset_m: tuple = (0.0, 0.0)


def rezero_on_baseline(sessions: list, k: int) -> tuple[list, tuple[float, float]]:
    """Re-zero the estimates on the mean of the first ``k`` sessions.

    Every estimate is a difference against the reference session, so that session's noise enters
    every later estimate alike (a constant offset with the standard deviation of one session's
    estimate). When the first ``k`` sessions are known to share the initial backlash (before any
    wear, as the paper's first 2500 h), subtracting the mean of their estimates takes that offset
    down by √k. ``k = 1`` leaves the paper's single reference unchanged.

    Args:
        sessions: :class:`SessionBacklash` in hours order, the first being the reference.
        k: number of leading sessions assumed to have the reference's backlash, 1 ≤ k ≤ len.
    Returns:
        The re-zeroed sessions and the (by shifts, by pitch) offsets subtracted, m.
    Raises:
        ValueError: ``k`` outside 1..len(sessions).
    """
    if not 1 <= k <= len(sessions):
        raise ValueError(f"baseline sessions = {k}; expected 1 to {len(sessions)} (the number "
                         "of usable Phase II sessions)")
    if k == 1:
        return list(sessions), (0.0, 0.0)
    base = sessions[:k]
    off_shift = float(np.mean([s.delta_backlash_shift_m for s in base]))
    pitch = [s.delta_backlash_pitch_m for s in base if math.isfinite(s.delta_backlash_pitch_m)]
    off_pitch = float(np.mean(pitch)) if pitch else 0.0
    dofs = sessions[0].delta_backlash_dof_m.keys()
    off_dof = {d: float(np.nanmean([s.delta_backlash_dof_m[d] for s in base])) for d in dofs}
    out = [replace(s, delta_backlash_shift_m=s.delta_backlash_shift_m - off_shift,
                   delta_backlash_pitch_m=s.delta_backlash_pitch_m - off_pitch,
                   delta_backlash_dof_m={d: v - off_dof.get(d, 0.0)
                                         for d, v in s.delta_backlash_dof_m.items()})
           for s in sessions]
    return out, (off_shift, off_pitch)


def estimator_for(m, spec: str | None = None, **params) -> BacklashEstimator:
    """A backlash estimator for the axis of an open ``measurements.h5``: when the estimator takes
    them, travel L and lead p of Eq. 9 from the axis contract (``/@axis.travel_mm``,
    ``/@axis.lead_mm``, required: a missing one raises
    :class:`analysis.dataset.axis.MissingAxisKey` naming it); ``spec``: a registered backlash
    estimator or ``module:Class`` (default: the registered default, the paper's); ``params``:
    further parameters (e.g. ``stationary="E_XX"``), which take precedence."""
    from analysis import registry
    from analysis.dataset.axis import axis_of

    kind = "backlash_estimators"
    entry = registry.get(kind, spec) if spec else registry.default(kind)
    axis = axis_of(m)
    need = "the Phase II backlash estimate (Eq. 9: travel L and lead p)"
    for key, name in (("travel_mm", "travel_m"), ("lead_mm", "lead_m")):
        if name not in params and registry.accepts(entry.factory, name):
            params[name] = axis.require(key, need) * 1e-3
    return registry.create(kind, spec or entry.name, **params)


def session_error_motions_task(path: str, session: str, on_bad_run: str,
                               error_motion_kw: dict) -> tuple[SessionErrorMotions | None, str]:
    """The error motions of one session read from the ``measurements.h5`` at ``path``: the piece
    of :func:`campaign_backlash` a worker process runs (picklable arguments, opens the file
    itself). Returns ``(error motions, "")``, or ``(None, message)`` when the session cannot be
    used (the :class:`analysis.dataset.DatasetError` it raised)."""
    from analysis.dataset import DatasetError, open_measurements
    from analysis.phase2.error_motions import session_error_motions

    with open_measurements(path) as m:
        try:
            return session_error_motions(m, session, on_bad_run=on_bad_run, **error_motion_kw), ""
        except DatasetError as exc:
            return None, str(exc)


def campaign_backlash(m, *, on_bad_run: str = "skip", estimator: BacklashEstimator | None = None,
                      progress=None, baseline_sessions: int = 1, map_sessions=None,
                      **error_motion_kw) -> CampaignBacklash:
    """Error motions (:func:`analysis.phase2.error_motions.session_error_motions`) and backlash
    estimates for every Phase II session of an open ``measurements.h5``.

    Args:
        m: :class:`analysis.dataset.Measurements`.
        on_bad_run: "skip" (a bad run is left out and reported) or "raise" (the first bad run
            raises :class:`analysis.dataset.DatasetError` naming session, run and channel).
        estimator: default :func:`estimator_for` ``m`` (L and p from the axis contract's
            ``travel_mm`` and ``lead_mm``, required).
        progress: optional callable(done, total, session).
        baseline_sessions: leading sessions that define zero change (:func:`rezero_on_baseline`).
        map_sessions: optional ``map_sessions(fn, args)`` returning or yielding ``fn(*a)`` for
            each of ``args`` in order, that runs :func:`session_error_motions_task` for the
            sessions elsewhere (processes, a cluster: the caller's executor); None computes them
            here, one after the other. Each session is estimated as it arrives, so a generator
            lets this work overlap the next sessions'. The results are the same either way.
    Raises:
        DatasetError: a bad run with ``on_bad_run="raise"``, no Phase II session, or no usable
            run in any session.
    """
    from analysis.dataset import DatasetError

    names = m.phase2_sessions()
    if not names:
        raise DatasetError(f"{m.label}: /phase2 has no session; expected at least two sessions")
    if estimator is None:
        estimator = estimator_for(m)
    if map_sessions is None:
        from analysis.phase2.error_motions import session_error_motions

        def outcome(name):
            try:
                return session_error_motions(m, name, on_bad_run=on_bad_run, **error_motion_kw), ""
            except DatasetError as exc:
                if on_bad_run == "raise":
                    raise
                return None, str(exc)

        outcomes = (outcome(name) for name in names)
    else:
        outcomes = map_sessions(session_error_motions_task,
                                [(str(m.path.resolve()), name, on_bad_run, error_motion_kw)
                                 for name in names])
    ems, estimates, skipped_runs, skipped_sessions = [], [], [], []
    for i, (name, (em, why)) in enumerate(zip(names, outcomes, strict=True)):
        if em is None:
            if on_bad_run == "raise":
                raise DatasetError(why)
            skipped_sessions.append((name, why))
        else:
            if not ems:
                estimator.fit(em)  # the first usable session is the reference
            # estimated as it arrives, while the executor computes the next sessions
            estimates.append(estimator.estimate(em))
            ems.append(em)
            skipped_runs.extend((name, run, why) for run, why in em.skipped)
        if progress is not None:
            progress(i + 1, len(names), name)
    if not ems:
        raise DatasetError(f"{m.label}: no Phase II session has a usable run "
                           f"({'; '.join(w for _, w in skipped_sessions)})")
    sessions, offset = rezero_on_baseline(estimates, baseline_sessions)
    return CampaignBacklash(sessions=sessions, error_motions=ems, skipped_runs=skipped_runs,
                            skipped_sessions=skipped_sessions, estimator=estimator,
                            baseline_sessions=baseline_sessions, baseline_offset_m=offset)
