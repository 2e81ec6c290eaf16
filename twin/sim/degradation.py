"""Degradation of a preloaded ball nut over operating hours, and the thermal transient after pauses.

The wear state drives the twin's preload, backlash, contact stiffness and drag torque over
operating hours. The chain is:

    operating hours --(Archard)--> wear depth w --(Hertz, ball population)--> preload F, backlash b
    preload F --(catalogue)--> drag torque T, contact stiffness k

Physical picture. The nut is preloaded by oversized balls (or an equivalent offset): each ball is
squeezed into the grooves by an elastic interference delta. Wear of the raceways and balls removes
material at depth w, reducing every interference by w. A ball carries the Hertz point-contact force
Q proportional to delta^(3/2) while delta > 0, and none once delta <= 0; once the balls have lost
contact, the further wear is free axial clearance (backlash). The balls' interferences scatter
(ball-size grade, raceway profile, uneven wear), modelled as a normal distribution, so preload
fades and backlash opens gradually instead of at one instant.

Units: SI everywhere except the names that carry their unit (``hours``, ``_um``, ``_um_per_kh``,
``_K``), which are the units of scenario files and of the paper (operating hours, micrometres).

Sources cited in the docstrings:
- [Archard] J. F. Archard, "Contact and rubbing of flat surfaces", J. Appl. Phys. 24 (1953) 981:
  worn volume (hence depth, at constant contact geometry) proportional to load x sliding distance.
- [Hertz] H. Hertz (1882); K. L. Johnson, *Contact Mechanics*, CUP 1985, ch. 4: for a point contact
  the approach delta and the load Q obey Q = K delta^(3/2), so the contact stiffness
  dQ/ddelta = (3/2) K^(2/3) Q^(1/3) grows as the cube root of the load.
- [Catalogue] THK General Catalog, Ball Screw, "Preload torque" (dynamic preload torque of a
  preloaded nut: T_p = 0.05 (tan beta)^(-1/2) F_a0 Ph / (2 pi)); the same form is in NSK's
  "Precision Machine Components" catalogue. Nut stiffness K_N = 0.8 K (F_a0 / 0.1 C_a)^(1/3)
  (THK/HIWIN catalogues).
- [Paper] Pandhare et al., "Ball Screw Health Monitoring with Inertial Sensors": Table II
  (campaign timeline), section IV (preload loss detected ~2972 h, essentially gone ~6000 h),
  section V / Fig. 13 (backlash ~0 until ~2500 h, rising around 4000 h, ~10 um at 8000 h),
  section III.C (thermal transients after resuming, nominal 2 h warm-up).
- [XJTU] XJTU Ball Screw Degradation Dataset, friction torque per stage
  (Xi'an Jiaotong University ball screw degradation data set, public).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy import optimize, special

__all__ = [
    "WearLaw",
    "wear_depth_um",
    "preload_fraction",
    "backlash_um",
    "normalised_drag_torque",
    "lead_angle",
    "preload_torque_coefficient",
    "drag_torque_Nm",
    "contact_stiffness",
    "series_stiffness",
    "temperature_rise_K",
    "hours_since_resume",
    "XjtuSeries",
    "XJTU_FILES",
    "load_xjtu",
    "load_xjtu_directory",
    "FrictionTrendFit",
    "fit_friction_trend",
]


_HERTZ_EXPONENT = 1.5  # Q ∝ delta^(3/2) for a point contact [Hertz]
_N_HERMITE = 48  # Gauss–Hermite nodes for the smooth (no-truncation) branch of the 3/2 moment
_HERMITE_X, _HERMITE_W = np.polynomial.hermite_e.hermegauss(_N_HERMITE)  # weight exp(-x²/2)
_HERMITE_W = _HERMITE_W / math.sqrt(2.0 * math.pi)  # now a probability measure of N(0, 1)
_Z_SWITCH = 25.0  # beyond mean/std = 25 the truncation at 0 is below 1e-137: use quadrature


# ----------------------------------------------------------------------------------------------
# Wear law
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class WearLaw:
    """Wear of a preloaded ball nut: preload loss, then backlash, over operating hours.

    Defaults reproduce the shape of the paper's run-to-failure campaign [Paper]: wear starts at
    2500 h (where the paper suspects a fault; preload is down ~22 % at its T² detection, ~2972 h),
    preload is below 10 % at 6000 h and ~0 beyond ~7000 h; backlash is 0 until 2500 h, below
    0.5 µm until 4000 h, then grows (about 1.6 µm at 5000 h) to ~10.5 µm at 8000 h (paper: about
    10 µm). Figures: ``preload_fraction`` 0.783 / 0.430 / 0.068 at 3000 / 4000 / 6000 h;
    ``backlash_um`` 0.47 / 3.71 / 10.49 µm at 4000 / 6000 / 8000 h. The life δ0/rate = 2860 h is
    of the order of what the XJTU upper screw's friction-torque trend gives when fitted
    (``fit_friction_trend``, see docs/validation.md; that screw ran at a higher load and speed, and its
    ~1000 h of data do not pin the scatter). δ0 = 4 µm is the order of the ball oversize of a
    preloaded single nut.

    Attributes:
        onset_hours: running-in / incubation time before wear starts removing interference [h].
        interference_um: mean initial elastic interference delta0 of the balls that creates the
            preload [µm].
        wear_rate_um_per_kh: Archard wear-depth rate after the onset [µm per 1000 h].
        scatter_um: standard deviation of the balls' interference (ball-size grade, uneven wear)
            [µm]; 0 gives the sharp law (all balls lose contact at the same wear depth).
        backlash_gain: axial clearance per unit of radial wear beyond the interference [-];
            2/sin(45°) ≈ 2.83 for a 45° contact angle (clearance on both flanks, projected on
            the axis).
        residual_preload_fraction: floor of the preload fraction that wear does not remove [-],
            in [0, 1).
    """

    onset_hours: float = 2500.0
    interference_um: float = 4.0
    wear_rate_um_per_kh: float = 1.4
    scatter_um: float = 2.0
    backlash_gain: float = 2.0 / math.sin(math.radians(45.0))
    residual_preload_fraction: float = 0.0

    def __post_init__(self) -> None:
        checks = (
            ("onset_hours", self.onset_hours, self.onset_hours >= 0.0, ">= 0"),
            ("interference_um", self.interference_um, self.interference_um > 0.0, "> 0"),
            ("wear_rate_um_per_kh", self.wear_rate_um_per_kh, self.wear_rate_um_per_kh >= 0.0, ">= 0"),
            ("scatter_um", self.scatter_um, self.scatter_um >= 0.0, ">= 0"),
            ("backlash_gain", self.backlash_gain, self.backlash_gain > 0.0, "> 0"),
            (
                "residual_preload_fraction",
                self.residual_preload_fraction,
                0.0 <= self.residual_preload_fraction < 1.0,
                "in [0, 1)",
            ),
        )
        for name, value, ok, allowed in checks:
            if not (math.isfinite(value) and ok):
                raise ValueError(f"WearLaw.{name} = {value!r} is out of range; allowed: {allowed}")


def wear_depth_um(hours, law: WearLaw) -> np.ndarray:
    """Wear depth w(h) = rate · max(0, h − onset) [µm], shape of ``hours``.

    Archard's law [Archard]: worn volume ∝ normal load × sliding distance. At the constant speed
    and stroke of the campaign the sliding distance is proportional to the operating hours, and at
    constant contact geometry the depth is proportional to the volume, so the depth grows linearly
    with hours after the running-in / incubation time ``onset_hours`` (the wear rate lumps the
    Archard coefficient, the contact pressure and the sliding speed).

    Args:
        hours: operating hours, any shape [h], >= 0.
        law: the wear law.

    Returns:
        Wear depth, same shape as ``hours`` [µm].
    """
    h = _hours_array(hours)
    return law.wear_rate_um_per_kh * 1e-3 * np.maximum(h - law.onset_hours, 0.0)


def _positive_part_moment(mean: np.ndarray, std: float) -> np.ndarray:
    """E[(X)_+^(3/2)] for X ~ N(mean, std²), elementwise over ``mean`` (any shape, any unit u).

    Closed form (Gaussian integral of a power, Gradshteyn & Ryzhik 3.462.1):
        ∫_0^∞ x^ν exp(−(x − m)²/(2 s²)) dx / (s √(2π))
            = s^ν Γ(ν + 1) exp(−z²/4) D_{−ν−1}(−z) / √(2π),   z = m/s,
    with D the parabolic cylinder function (scipy.special.pbdv). For z > 25 the mass below 0 is
    negligible (< 1e-137) and D overflows, so there E[X^(3/2)] is computed by Gauss–Hermite
    quadrature of the smooth integrand (m + s x)^(3/2) (exact to rounding for that smooth case).
    With std = 0 it is max(m, 0)^(3/2).

    Returns:
        Array of the shape of ``mean`` [u^(3/2)].
    """
    m = np.asarray(mean, dtype=float)
    if std == 0.0:
        return np.maximum(m, 0.0) ** _HERTZ_EXPONENT
    nu = _HERTZ_EXPONENT
    z = m / std
    out = np.empty_like(z)
    far = z > _Z_SWITCH
    near = ~far
    if np.any(near):
        zn = z[near]
        d, _ = special.pbdv(-nu - 1.0, -zn)
        val = std**nu * special.gamma(nu + 1.0) / math.sqrt(2.0 * math.pi) * np.exp(-0.25 * zn * zn) * d
        out[near] = np.maximum(val, 0.0)
    if np.any(far):
        mf = m[far][..., None]
        out[far] = np.sum(_HERMITE_W * (mf + std * _HERMITE_X) ** nu, axis=-1)
    return out


def _population_preload_fraction(wear_um: np.ndarray, law: WearLaw) -> np.ndarray:
    """E[(δ − w)_+^(3/2)] / E[δ_+^(3/2)], δ ~ N(interference, scatter²); shape of ``wear_um``."""
    f0 = _positive_part_moment(np.array([law.interference_um]), law.scatter_um)[0]
    return _positive_part_moment(law.interference_um - wear_um, law.scatter_um) / f0


def preload_fraction(hours, law: WearLaw) -> np.ndarray:
    """Preload relative to the new nut, F(h)/F0 [-], shape of ``hours``.

    Hertz point contact [Hertz]: a ball squeezed by the interference δ carries Q ∝ δ_+^(3/2).
    Wear w(h) (``wear_depth_um``) reduces every interference by w, so for one ball
    F/F0 = ((1 − w/δ0)_+)^(3/2). Averaged over the population of balls with
    δ ~ N(δ0, σ²) (σ = ``scatter_um``):

        F/F0 = r + (1 − r) · E[(δ − w)_+^(3/2)] / E[δ_+^(3/2)],

    with r = ``residual_preload_fraction``; the expectations are exact (``_positive_part_moment``).
    The result is 1 for h ≤ onset, non-increasing in h, and tends to r.

    Args:
        hours: operating hours, any shape [h].
        law: the wear law.

    Returns:
        Preload fraction in [r, 1], same shape as ``hours`` [-].
    """
    w = wear_depth_um(hours, law)
    r = law.residual_preload_fraction
    frac = np.clip(_population_preload_fraction(w, law), 0.0, 1.0)
    return r + (1.0 - r) * frac


def _expected_clearance_um(wear_um: np.ndarray, law: WearLaw) -> np.ndarray:
    """E[(w − δ)_+] for δ ~ N(δ0, σ²) [µm], shape of ``wear_um``.

    Closed form of the Gaussian partial expectation: with ζ = (w − δ0)/σ,
    E[(w − δ)_+] = σ (ζ Φ(ζ) + φ(ζ)) (Φ, φ standard normal CDF and density); (w − δ0)_+ if σ = 0.
    """
    d = wear_um - law.interference_um
    s = law.scatter_um
    if s == 0.0:
        return np.maximum(d, 0.0)
    zeta = d / s
    return s * (zeta * special.ndtr(zeta) + np.exp(-0.5 * zeta * zeta) / math.sqrt(2.0 * math.pi))


def backlash_um(hours, law: WearLaw) -> np.ndarray:
    """Axial backlash opened by wear, b(h) [µm], shape of ``hours``.

    A ball whose interference δ has been worn through (w > δ) leaves a radial clearance w − δ;
    projected on the axis over both flanks of a gothic-arch groove it gives
    ``backlash_gain`` · (w − δ) ≈ 2/sin(α) · (w − δ) of axial play (α contact angle, 45°). The
    nut's backlash is taken as the population average over δ ~ N(δ0, σ²):

        b(h) = gain · (E[(w(h) − δ)_+] − E[(0 − δ)_+]),   clipped at >= 0,

    so b(0) = 0 exactly (balls that start without interference are not counted as wear) and b is
    non-decreasing in h. For σ = 0 it is gain · (w − δ0)_+. Wear depth from [Archard]; the
    expectation in closed form (``_expected_clearance_um``).

    Args:
        hours: operating hours, any shape [h].
        law: the wear law.

    Returns:
        Backlash >= 0, same shape as ``hours`` [µm].
    """
    w = wear_depth_um(hours, law)
    base = _expected_clearance_um(np.zeros(1), law)[0]
    return np.maximum(law.backlash_gain * (_expected_clearance_um(w, law) - base), 0.0)


def normalised_drag_torque(hours, law: WearLaw, no_load_fraction: float) -> np.ndarray:
    """Drag torque relative to the new nut, T(h)/T(0) = c0 + (1 − c0) · F(h)/F0 [-].

    Follows from ``drag_torque_Nm``: T = T_0 + K_p F_a0 l/(2π) is affine in the preload, so with
    c0 = T_0/T(0) (the no-load seal/viscous share of the new nut's torque) the normalised torque
    is c0 + (1 − c0) F/F0 [Catalogue]; F/F0 from ``preload_fraction``.

    Args:
        hours: operating hours, any shape [h].
        law: the wear law.
        no_load_fraction: c0 in [0, 1] [-].

    Returns:
        Normalised torque, same shape as ``hours`` [-].
    """
    if not 0.0 <= no_load_fraction <= 1.0:
        raise ValueError(f"no_load_fraction = {no_load_fraction!r} is out of range; allowed: [0, 1]")
    return no_load_fraction + (1.0 - no_load_fraction) * preload_fraction(hours, law)


# ----------------------------------------------------------------------------------------------
# Drag torque and stiffness
# ----------------------------------------------------------------------------------------------


def lead_angle(lead_m, pitch_diameter_m) -> np.ndarray:
    """Lead angle β = atan(l / (π D_pw)) [rad] (helix geometry).

    Args:
        lead_m: screw lead l, scalar or array [m], > 0.
        pitch_diameter_m: ball pitch-circle diameter D_pw, broadcastable with ``lead_m`` [m], > 0.

    Returns:
        Lead angle, broadcast shape [rad].
    """
    lead = np.asarray(lead_m, dtype=float)
    dpw = np.asarray(pitch_diameter_m, dtype=float)
    if np.any(lead <= 0.0) or np.any(dpw <= 0.0):
        raise ValueError(f"lead_m = {lead_m!r} and pitch_diameter_m = {pitch_diameter_m!r} must be > 0")
    return np.arctan(lead / (np.pi * dpw))


def preload_torque_coefficient(lead_m, pitch_diameter_m) -> np.ndarray:
    """Catalogue preload-torque coefficient K_p = 0.05 / sqrt(tan β) [-].

    Source: [Catalogue] (THK General Catalog, ball screw "preload torque"; NSK catalogue), with β
    the lead angle from ``lead_angle``. For a 25×10 screw (D_pw 25.5 mm) K_p ≈ 0.142.

    Args:
        lead_m: screw lead [m].
        pitch_diameter_m: ball pitch-circle diameter [m].

    Returns:
        K_p, broadcast shape [-].
    """
    return 0.05 / np.sqrt(np.tan(lead_angle(lead_m, pitch_diameter_m)))


def drag_torque_Nm(preload_N, lead_m, no_load_torque_Nm, coefficient) -> np.ndarray:
    """Drag (friction) torque of a preloaded nut, T = T_0 + K_p · F_a0 · l / (2π) [N·m].

    Source: [Catalogue] dynamic preload torque T_p = K_p F_a0 Ph/(2π) with
    K_p = 0.05 (tan β)^(-1/2) (``preload_torque_coefficient``), plus a preload-independent no-load
    torque T_0 (seals, grease churning). With F_a0 in N and l in m the result is in N·m.

    Args:
        preload_N: axial preload F_a0, any shape [N], >= 0.
        lead_m: screw lead l [m], > 0.
        no_load_torque_Nm: T_0 [N·m], >= 0.
        coefficient: K_p [-], >= 0 (e.g. from ``preload_torque_coefficient``).

    Returns:
        Drag torque, broadcast shape [N·m].
    """
    f = np.asarray(preload_N, dtype=float)
    if np.any(f < 0.0):
        raise ValueError(f"preload_N must be >= 0, got min {np.min(f)!r}")
    if lead_m <= 0.0 or no_load_torque_Nm < 0.0 or coefficient < 0.0:
        raise ValueError(
            f"need lead_m > 0, no_load_torque_Nm >= 0, coefficient >= 0; got {lead_m!r}, "
            f"{no_load_torque_Nm!r}, {coefficient!r}"
        )
    return no_load_torque_Nm + coefficient * f * lead_m / (2.0 * np.pi)


def contact_stiffness(k_ref_N_per_m, preload_N, preload_ref_N, min_fraction: float = 0.1) -> np.ndarray:
    """Hertzian contact stiffness k = k_ref · max((F/F_ref)^(1/3), min_fraction) [N/m].

    Hertz point contact [Hertz]: Q = K δ^(3/2) gives dQ/dδ ∝ Q^(1/3), hence the catalogue rule
    K_N = 0.8 K (F_a0/(0.1 C_a))^(1/3) [Catalogue], written here relative
    to a reference preload F_ref at which the stiffness is k_ref.

    Floor: a nut (or truck) that has lost all preload still has contact stiffness once the working
    load presses the balls against one flank; the floor ``min_fraction`` is that stiffness. The
    default 0.1 equals the Hertz stiffness at a load of 0.1³ = 1e-3 F_ref, i.e. a few newtons for a
    kN preload — the order of the rolling/inertial load the nut carries on the paper's horizontal
    axis while moving. Must be > 0, so the stiffness is strictly positive.

    Args:
        k_ref_N_per_m: stiffness at the reference preload, scalar or array [N/m], > 0.
        preload_N: preload F, any shape broadcastable with k_ref [N], >= 0.
        preload_ref_N: reference preload F_ref [N], > 0.
        min_fraction: floor as a fraction of k_ref, in (0, 1] [-].

    Returns:
        Stiffness, broadcast shape [N/m], > 0.
    """
    k_ref = np.asarray(k_ref_N_per_m, dtype=float)
    f = np.asarray(preload_N, dtype=float)
    if np.any(k_ref <= 0.0) or preload_ref_N <= 0.0 or not 0.0 < min_fraction <= 1.0:
        raise ValueError(
            f"need k_ref_N_per_m > 0, preload_ref_N > 0, 0 < min_fraction <= 1; got {k_ref_N_per_m!r}, "
            f"{preload_ref_N!r}, {min_fraction!r}"
        )
    if np.any(f < 0.0):
        raise ValueError(f"preload_N must be >= 0, got min {np.min(f)!r}")
    return k_ref * np.maximum(np.cbrt(f / preload_ref_N), min_fraction)


def series_stiffness(*ks) -> np.ndarray:
    """Stiffness of springs in series, 1/k = Σ 1/k_i [N/m] (THK catalogue: total axial
    stiffness 1/K = 1/K_S + 1/K_N + 1/K_B + 1/K_H).

    Args:
        *ks: one or more stiffnesses, scalars or broadcastable arrays [N/m], > 0.

    Returns:
        Series stiffness, broadcast shape [N/m].
    """
    if not ks:
        raise ValueError("series_stiffness needs at least one stiffness")
    arrays = [np.asarray(k, dtype=float) for k in ks]
    if any(np.any(a <= 0.0) for a in arrays):
        raise ValueError("series_stiffness: every stiffness must be > 0")
    return 1.0 / sum(1.0 / a for a in arrays)


# ----------------------------------------------------------------------------------------------
# Thermal transient and campaign timeline
# ----------------------------------------------------------------------------------------------


def temperature_rise_K(hours_since_resume, steady_rise_K: float, time_constant_hours: float) -> np.ndarray:
    """Warm-up after a cold restart, ΔT(t) = ΔT_ss · (1 − exp(−t/τ)) [K].

    First-order (lumped-capacitance) heating of the axis by its friction losses: C dT/dt =
    P − (T − T_amb)/R gives this exponential approach to the steady rise ΔT_ss = P R with
    τ = R C (Newton's law of cooling; e.g. Incropera, *Fundamentals of Heat and Mass Transfer*,
    lumped capacitance). After a pause the machine restarts cold [Paper, section III.C]; steady
    state is reached after a few τ (95 % at 3τ).

    Args:
        hours_since_resume: operating time since the restart t, any shape [h], >= 0.
        steady_rise_K: steady-state rise ΔT_ss [K].
        time_constant_hours: τ [h], > 0.

    Returns:
        Temperature rise, shape of ``hours_since_resume`` [K].
    """
    t = _hours_array(hours_since_resume, name="hours_since_resume")
    if not time_constant_hours > 0.0:
        raise ValueError(f"time_constant_hours = {time_constant_hours!r} is out of range; allowed: > 0")
    return steady_rise_K * -np.expm1(-t / time_constant_hours)


def hours_since_resume(hours, resume_hours) -> np.ndarray:
    """Operating hours since the most recent resume at or before ``hours``, or since start [h].

    Operating hours stop during a pause, so a pause and its resume share one operating-hour value
    (Table II of [Paper]: 855.5 h and 4033 h). At a resume the result is 0.

    Args:
        hours: operating hours, any shape [h], >= 0.
        resume_hours: operating hours of the resumes, any order [h].

    Returns:
        Hours since the last (re)start, shape of ``hours`` [h].
    """
    h = _hours_array(hours)
    starts = np.unique(np.concatenate([[0.0], np.asarray(list(resume_hours), dtype=float)]))
    idx = np.searchsorted(starts, h, side="right") - 1
    return h - starts[idx]


# ----------------------------------------------------------------------------------------------
# XJTU friction-torque data and the fit of the law
# ----------------------------------------------------------------------------------------------

#: The two screws of the XJTU friction-torque data: upper and lower [XJTU].
XJTU_FILES: tuple[str, ...] = ("Up_FT.txt", "Down_FT.txt")


@dataclass(frozen=True)
class XjtuSeries:
    """One screw's friction-torque trend [XJTU].

    Attributes:
        name: file stem, e.g. "Up_FT".
        hours: operating hours of each stage, shape (n,) [h].
        torque: mean friction torque per stage, shape (n,) [unit not stated, most likely N·m].
    """

    name: str
    hours: np.ndarray
    torque: np.ndarray

    @property
    def torque_normalised(self) -> np.ndarray:
        """Torque / first value (new screw), shape (n,) [-]."""
        return self.torque / self.torque[0]


def load_xjtu(path, hours_per_stage: float = 35.0) -> XjtuSeries:
    """Read one XJTU friction-torque file (``Up_FT.txt`` or ``Down_FT.txt``): one float per line.

    Stage i (0 = new screw) is placed at hours = ``hours_per_stage`` · i; 35 h per stage follows
    the dataset's description (7-hour tests, torque measured every five tests) [XJTU].

    Args:
        path: the text file.
        hours_per_stage: operating hours between stages [h], > 0.

    Returns:
        The series, with ``hours`` and ``torque`` of shape (n,).
    """
    path = Path(path)
    if not hours_per_stage > 0.0:
        raise ValueError(f"hours_per_stage = {hours_per_stage!r} is out of range; allowed: > 0")
    torque = np.loadtxt(path, dtype=float, ndmin=1)
    if torque.ndim != 1 or torque.size < 2 or not np.all(np.isfinite(torque)) or torque[0] <= 0.0:
        raise ValueError(f"{path}: expected one finite float per line, at least 2, first > 0")
    hours = hours_per_stage * np.arange(torque.size, dtype=float)
    return XjtuSeries(name=path.stem, hours=hours, torque=torque)


def load_xjtu_directory(directory, hours_per_stage: float = 35.0) -> dict[str, XjtuSeries]:
    """Both screws of the XJTU data in ``directory``, keyed by file stem ("Up_FT", "Down_FT")."""
    directory = Path(directory)
    return {Path(f).stem: load_xjtu(directory / f, hours_per_stage) for f in XJTU_FILES}


@dataclass(frozen=True)
class FrictionTrendFit:
    """Least-squares fit of the wear law's normalised drag torque to a measured trend.

    Only ratios are identifiable from a normalised torque trend, so the law is fitted in the
    parameters below; ``wear_law`` turns them into a ``WearLaw`` for a chosen interference.

    Attributes:
        onset_hours: fitted onset of wear [h].
        life_hours: interference / wear rate, hours of wear after the onset that remove the mean
            interference [h].
        scatter_fraction: scatter / interference [-].
        no_load_fraction: c0, no-load share of the new nut's drag torque [-].
        initial_ratio: A, the new nut's torque relative to the first reading [-] (the first
            reading is one noisy measurement, like every other stage, so the curve need not pass
            through it exactly -- as a straight line's intercept need not).
        rms_residual: RMS of (model − data) of the normalised torque, i.e. as a fraction of the
            first value [-].
        n_points: number of data points.
    """

    onset_hours: float
    life_hours: float
    scatter_fraction: float
    no_load_fraction: float
    initial_ratio: float
    rms_residual: float
    n_points: int

    def wear_law(self, interference_um: float = WearLaw.interference_um, **overrides) -> WearLaw:
        """The fitted law with the given interference [µm] (rate and scatter scaled from it)."""
        law = WearLaw(
            onset_hours=self.onset_hours,
            interference_um=interference_um,
            wear_rate_um_per_kh=1e3 * interference_um / self.life_hours,
            scatter_um=self.scatter_fraction * interference_um,
            residual_preload_fraction=0.0,
        )
        return replace(law, **overrides) if overrides else law

    def predict(self, hours) -> np.ndarray:
        """Fitted torque relative to the first reading [-], shape of ``hours``."""
        return self.initial_ratio * normalised_drag_torque(hours, self.wear_law(),
                                                           self.no_load_fraction)


def fit_friction_trend(
    hours,
    torque_normalised,
    *,
    onset_bounds_hours: tuple[float, float] | None = None,
    life_bounds_hours: tuple[float, float] | None = None,
    scatter_fraction_bounds: tuple[float, float] = (0.0, 1.0),
    no_load_fraction_bounds: tuple[float, float] = (0.0, 0.9),
    initial_ratio_bounds: tuple[float, float] = (0.9, 1.1),
) -> FrictionTrendFit:
    """Fit T(h)/T_first = A·[c0 + (1 − c0) F(h)/F0] of the wear law to a normalised trend.

    Model: ``normalised_drag_torque`` (drag torque affine in preload [Catalogue]; preload from the
    Hertz/Archard population law, ``preload_fraction``), with the interference fixed at 1 (only
    ratios are identifiable) and parameters θ = (onset_hours, life_hours = δ0/rate,
    scatter_fraction = σ/δ0, c0, A), A the new nut's torque relative to the (noisy) first
    reading. Solved with ``scipy.optimize.least_squares`` (trust-region
    reflective, bounded) from a fixed grid of 16 starting points (deterministic multi-start); the
    best cost wins.

    Default bounds, with H = max(hours): onset in [0, H] h, life in [0.05 H, 50 H] h,
    scatter_fraction in [0, 1], c0 in [0, 0.9].

    XJTU figures (35 h per stage): see ``tests/test_degradation.py`` (printed with -s).

    Args:
        hours: operating hours, shape (n,) [h].
        torque_normalised: measured torque / first value, shape (n,) [-].

    Returns:
        The best fit, with ``rms_residual`` as a fraction of the first value.
    """
    h = _hours_array(hours)
    y = np.asarray(torque_normalised, dtype=float)
    if h.ndim != 1 or h.shape != y.shape or h.size < 4 or not np.all(np.isfinite(y)):
        raise ValueError("hours and torque_normalised must be finite 1-D arrays of equal length >= 4")
    span = float(np.max(h))
    if span <= 0.0:
        raise ValueError("hours must span a positive interval")
    onset_b = onset_bounds_hours or (0.0, span)
    life_b = life_bounds_hours or (0.05 * span, 50.0 * span)
    lower = np.array([onset_b[0], life_b[0], scatter_fraction_bounds[0], no_load_fraction_bounds[0],
                      initial_ratio_bounds[0]])
    upper = np.array([onset_b[1], life_b[1], scatter_fraction_bounds[1], no_load_fraction_bounds[1],
                      initial_ratio_bounds[1]])
    if np.any(lower >= upper) or lower[1] <= 0.0 or lower[2] < 0.0 or lower[3] < 0.0 or upper[3] > 1.0:
        raise ValueError(f"invalid fit bounds: lower {lower.tolist()}, upper {upper.tolist()}")

    def model(theta: np.ndarray) -> np.ndarray:
        onset, life, scatter, c0, ratio = theta
        law = WearLaw(
            onset_hours=onset, interference_um=1.0, wear_rate_um_per_kh=1e3 / life, scatter_um=scatter
        )
        return ratio * normalised_drag_torque(h, law, c0)

    def residual(theta: np.ndarray) -> np.ndarray:
        return model(theta) - y

    starts = itertools.product(
        (0.0, 0.3 * span),  # onset [h]
        (1.0 * span, 4.0 * span),  # life [h]
        (0.1, 0.5),  # scatter fraction
        (0.2, 0.6),  # c0
        (1.0,),  # initial ratio
    )
    best = None
    for x0 in starts:
        x0 = np.clip(np.array(x0, dtype=float), lower, upper)
        x0 = np.where(x0 == upper, lower + 0.999 * (upper - lower), x0)
        sol = optimize.least_squares(
            residual, x0, bounds=(lower, upper), x_scale=np.maximum(upper - lower, 1e-12) / 10.0
        )
        if best is None or sol.cost < best.cost:
            best = sol
    onset, life, scatter, c0, ratio = (float(v) for v in best.x)
    rms = float(np.sqrt(np.mean(best.fun**2)))
    return FrictionTrendFit(onset, life, scatter, c0, ratio, rms, int(h.size))


# ----------------------------------------------------------------------------------------------


def _hours_array(hours, name: str = "hours") -> np.ndarray:
    """``hours`` as a float ndarray (any shape); raises if any value is negative or not finite."""
    h = np.asarray(hours, dtype=float)
    if not np.all(np.isfinite(h)) or np.any(h < 0.0):
        raise ValueError(f"{name} must be finite and >= 0")
    return h
