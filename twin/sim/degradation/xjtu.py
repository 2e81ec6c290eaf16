"""The XJTU ball-screw friction-torque data (:func:`load_xjtu`) and the least-squares fit of the wear
law's normalised drag torque to such a trend (:func:`fit_friction_trend`, :class:`FrictionTrendFit`).

Sources ([Archard], [Hertz], [Catalogue], [Paper], [XJTU]) and units: :mod:`twin.sim.degradation`.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from twin.sim.degradation.wear import WearLaw, _hours_array, normalised_drag_torque

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
    from scipy import optimize  # here, not at the top: the CLI starts without SciPy

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
