"""The wear law of a preloaded ball nut over operating hours: Archard wear depth, and the preload
and backlash of a ball population whose interferences scatter (:class:`WearLaw`,
:func:`preload_fraction`, :func:`backlash_um`, :func:`normalised_drag_torque`); and the check of
an hours argument every module of the package uses.

Sources ([Archard], [Hertz], [Catalogue], [Paper], [XJTU]) and units: :mod:`twin.sim.degradation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_HERTZ_EXPONENT = 1.5  # Q ∝ delta^(3/2) for a point contact [Hertz]
_N_HERMITE = 48  # Gauss–Hermite nodes for the smooth (no-truncation) branch of the 3/2 moment
_HERMITE_X, _HERMITE_W = np.polynomial.hermite_e.hermegauss(_N_HERMITE)  # weight exp(-x²/2)
_HERMITE_W = _HERMITE_W / math.sqrt(2.0 * math.pi)  # now a probability measure of N(0, 1)
_Z_SWITCH = 25.0  # beyond mean/std = 25 the truncation at 0 is below 1e-137: use quadrature


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
        from scipy import special  # here, not at the top: the CLI starts without SciPy

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
    from scipy import special

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


def _hours_array(hours, name: str = "hours") -> np.ndarray:
    """``hours`` as a float ndarray (any shape); raises if any value is negative or not finite."""
    h = np.asarray(hours, dtype=float)
    if not np.all(np.isfinite(h)) or np.any(h < 0.0):
        raise ValueError(f"{name} must be finite and >= 0")
    return h
