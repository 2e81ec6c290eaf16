"""The backlash estimator of one session (:class:`BacklashEstimator`, the paper's Eq. 9 and its
variants; the package's docstring gives the method) and its result (:class:`SessionBacklash`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from sklearn.base import BaseEstimator

from analysis.base.registry import register
from analysis.params import InheritedParams
from analysis.phase2.shifts import THRESHOLD, ShiftResult, shift_between
from analysis.phase2.traces import DOFS, DirectionalTraces, SessionErrorMotions
from analysis.phase2.winfilt import CUTOFF_WAVELENGTH_M, winfilt

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
        stationary: "command" (default) or "E_XX": what ΔPositionShift is referred to. With
            "E_XX", Eq. 5 as computed here: ΔBacklash_j = ΔPositionShift_j − ΔPositionShift_XX
            (the paper writes ΔPositionShift_XX − ΔPositionShift_j; its shifts have the opposite
            sign to ours, positive when the features sit at a larger commanded position, so both
            give more backlash as a positive change).
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


