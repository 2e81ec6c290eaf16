"""Trend of the backlash estimates over operating hours and the remaining hours to a limit.

Model: a constant-velocity Kalman filter in operating hours (filterpy ``KalmanFilter`` with
``batch_filter`` and ``rts_smoother``; Labbe, *Kalman and Bayesian Filters in Python*, ch. 8 and
13): state [b (m), ḃ (m/h)], F(Δt) = [[1, Δt], [0, 1]], continuous white-noise acceleration of
spectral density q (filterpy ``Q_continuous_white_noise``: Q = q·[[Δt³/3, Δt²/2], [Δt²/2, Δt]]),
measurement z = b + v, v ~ N(0, r²). Sessions may be irregularly spaced.

- Smoothing: the Rauch–Tung–Striebel smoother over all sessions (the "smoothed" column of
  ``twin backlash``).
- Prognosis: from the filtered state at the last session (equal to the smoothed one there), the
  crossing of the limit (10 µm by default) by straight-line extrapolation,
  t* = t_last + (limit − b)/ḃ. Its uncertainty band is a **Monte Carlo** over the state's Gaussian
  N(x, P) (4000 draws from a seeded generator): the 2.5 and 97.5 percentiles of the draws'
  crossing hours (a draw with ḃ ≤ 0 never crosses and counts as +∞, so the upper end can be ∞).
  Future process noise is not added; the band is the uncertainty of the current level and rate.

Measurement noise r: given, or (default) estimated robustly from the data as
1.4826·MAD(second differences)/√6: for white noise of standard deviation r the second difference
z_{i+1} − 2z_i + z_{i−1} has variance 6r², 1.4826·MAD is a consistent estimate of a Gaussian's
standard deviation (Rousseeuw & Croux, "Alternatives to the median absolute deviation", JASA 88,
1993), and taking the MAD about the median of the second differences removes a constant
curvature, so a trend that grows, even faster and faster, does not pass for noise (floored at
0.05 µm; 1 µm with fewer than 4 sessions).

Process noise q: given, or with ``"ml"`` the value of a log grid (:data:`Q_GRID`, 1e-26 …
1e-16 m²/h³) that maximises the likelihood of the innovations (the prediction-error decomposition
of the Gaussian likelihood; Harvey, *Forecasting, Structural Time Series Models and the Kalman
Filter*, 3.4), or with ``"auto"`` (the default) a likelihood-ratio test between the two: the
null q₀ = :data:`DEFAULT_Q` (1e-23 m²/h³, a rate that wanders by about 0.1 µm/kh over 1000 h,
which holds a straight trend's rate steady over the paper's 103 sessions) is kept unless the
maximum-likelihood q beats it by more than :data:`LR_NATS` nats (half the 0.99 quantile of χ²
with one degree of freedom, Wilks' test at α = 0.01; with q₀ inside the grid's range this is
conservative, Self & Liang, JASA 82, 1987). A straight trend keeps q₀ (its crossing stays
stable); a trend that bends after an onset, or steps faster than a steady rate can follow
(six sessions of accelerating growth), rejects it and the smoothed values keep up.
Units: metres and operating hours (h) inside; the JSON record says µm and hours in its keys.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import KalmanFilter

LIMIT_M = 10e-6
"""Backlash limit of the prognosis, m (10 µm: the paper's backlash at the end of its campaign)."""


@dataclass(frozen=True)
class Trend:
    """Kalman-smoothed trend: hours (n,) h; smoothed (n,) m; smoothed_std (n,) m;
    rate (n,) m/h; filtered (n,) m; measurement_std m (the r used)."""

    hours: np.ndarray
    smoothed: np.ndarray
    smoothed_std: np.ndarray
    rate: np.ndarray
    filtered: np.ndarray
    measurement_std: float
    state: np.ndarray  # (2,) filtered state at the last session
    covariance: np.ndarray  # (2, 2)
    process_noise: float = float("nan")  # q used, m²/h³
    process_noise_choice: str = ""  # how q was chosen (given, "ml", the likelihood-ratio test)


@dataclass(frozen=True)
class Prognosis:
    """Remaining hours to the limit.

    Attributes:
        at_hours: hours of the last session used, h. level_m: filtered backlash there, m.
        rate_m_per_h: its rate, m/h. limit_m: the limit, m.
        crossing_hours: predicted operating hours at the crossing (inf if not rising), h.
        band_hours: (low, high) 95 % Monte Carlo band of the crossing, h.
        remaining_hours: crossing_hours − at_hours, h.
    """

    at_hours: float
    level_m: float
    rate_m_per_h: float
    limit_m: float
    crossing_hours: float
    band_hours: tuple[float, float]

    @property
    def remaining_hours(self) -> float:
        return self.crossing_hours - self.at_hours

    def to_json(self) -> dict:
        def num(v):
            return float(v) if math.isfinite(v) else None
        return {"at_hours": self.at_hours, "level_um": self.level_m * 1e6,
                "rate_um_per_kh": self.rate_m_per_h * 1e9, "limit_um": self.limit_m * 1e6,
                "crossing_hours": num(self.crossing_hours),
                "remaining_hours": num(self.remaining_hours),
                "band_hours": [num(self.band_hours[0]), num(self.band_hours[1])],
                "band": "95 % Monte Carlo over the filtered state's Gaussian at the last session "
                        "(level and rate; no future process noise); null = never (not rising)"}


Q_GRID = tuple(10.0 ** (e / 2) for e in range(-52, -31))
"""Candidate process-noise densities q for the maximum-likelihood choice, m²/h³ (1e-26 to 1e-16
in half decades)."""
DEFAULT_Q = 1e-23
"""The null process noise of ``"auto"``, m²/h³ (see the module's doc)."""
LR_NATS = 3.3174
"""Likelihood gain (nats) over :data:`DEFAULT_Q` that makes ``"auto"`` take the maximum-likelihood
q: χ²₁(0.99)/2 = 6.6349/2."""


def _q_matrix(dt: float, q: float) -> np.ndarray:
    return q * np.array([[dt ** 3 / 3.0, dt ** 2 / 2.0], [dt ** 2 / 2.0, dt]])


def innovation_loglik(t: np.ndarray, z: np.ndarray, q: float, r: float, rate_prior: float) -> float:
    """Log-likelihood of the measurements after the first under the constant-velocity model
    (sum of log N(innovation; 0, S) over the finite measurements), nats."""
    return float(innovation_loglik_grid(t, z, np.array([q]), r, rate_prior)[0])


def innovation_loglik_grid(t: np.ndarray, z: np.ndarray, qs: np.ndarray, r: float,
                           rate_prior: float) -> np.ndarray:
    """:func:`innovation_loglik` for every q of ``qs`` (k,) m²/h³ at once: (k,) nats. The filter
    is the one of :class:`BacklashTrend` (state [b, ḃ], x₀ = [z₀, 0], P₀ = diag(r², rate_prior²)),
    written out for the 2 × 2 case and vectorised over q."""
    t = np.asarray(t, dtype=float)
    z = np.asarray(z, dtype=float)
    q = np.asarray(qs, dtype=float)
    ok = np.flatnonzero(np.isfinite(z))
    r2 = r * r
    x0, x1 = np.full(q.shape, z[ok[0]]), np.zeros(q.shape)
    p00, p01, p11 = np.full(q.shape, r2), np.zeros(q.shape), np.full(q.shape, rate_prior ** 2)
    total, last = np.zeros(q.shape), t[ok[0]]
    for i in ok[1:]:
        dt = t[i] - last
        last = t[i]
        x0 = x0 + dt * x1
        n00 = p00 + 2 * dt * p01 + dt * dt * p11 + q * dt ** 3 / 3.0
        n01 = p01 + dt * p11 + q * dt ** 2 / 2.0
        n11 = p11 + q * dt
        S = n00 + r2
        nu = z[i] - x0
        total += -0.5 * (np.log(2.0 * math.pi * S) + nu * nu / S)
        k0, k1 = n00 / S, n01 / S
        x0, x1 = x0 + k0 * nu, x1 + k1 * nu
        p00, p01, p11 = n00 - k0 * n00, n01 - k0 * n01, n11 - k1 * n01
    return total


def robust_measurement_std(z: np.ndarray) -> float:
    """r estimated from the scatter of the second differences: 1.4826·MAD(Δ²z)/√6, m (see the
    module's doc)."""
    z = np.asarray(z, dtype=float)
    z = z[np.isfinite(z)]
    if z.size < 4:
        return 1e-6
    d = np.diff(z, 2)
    return max(0.05e-6, 1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(6.0))


def choose_process_noise(t: np.ndarray, z: np.ndarray, r: float, rate_prior: float,
                         how: str) -> tuple[float, str]:
    """q (m²/h³) for ``how`` = "ml" or "auto" (the module's doc) and a sentence saying why."""
    if np.isfinite(z).sum() < 3:
        return DEFAULT_Q, f"{DEFAULT_Q:g} m²/h³ (fewer than 3 sessions: no likelihood to choose by)"
    grid = np.array(Q_GRID)
    ll = innovation_loglik_grid(t, z, grid, r, rate_prior)
    k = int(np.argmax(ll))
    if how == "ml":
        return float(grid[k]), f"maximum likelihood over {grid[0]:g}…{grid[-1]:g} m²/h³"
    l0 = float(innovation_loglik_grid(t, z, np.array([DEFAULT_Q]), r, rate_prior)[0])
    gain = float(ll[k]) - l0
    if gain > LR_NATS:
        return float(grid[k]), (f"maximum likelihood: it beats {DEFAULT_Q:g} m²/h³ by {gain:.1f} nats "
                                f"(> {LR_NATS:.2f}, α = 0.01)")
    return DEFAULT_Q, (f"{DEFAULT_Q:g} m²/h³: the maximum-likelihood {grid[k]:g} beats it by {gain:.1f} nats "
                       f"(≤ {LR_NATS:.2f}, α = 0.01)")


class BacklashTrend:
    """Constant-velocity Kalman filter and RTS smoother over per-session estimates.

    Parameters:
        process_noise: q, spectral density of the rate's random walk, m²/h³ (1e-23: the rate
            may wander by about 0.1 µm/kh over 1000 h; 1e-21: by 1 µm/kh), or "ml": chosen
            from :data:`Q_GRID` by maximum likelihood of the innovations, or "auto" (default):
            :data:`DEFAULT_Q` unless the data reject it (likelihood-ratio test, module doc).
            "auto" meets check 5 on linear growth (tests/test_phase2_prognosis.py) and keeps up
            with accelerating growth (tests/test_trend_keeps_up.py); "ml" alone on long
            linear records sometimes picks a large q and meets the check-5 tolerance in fewer
            cases (docs/validation.md).
        measurement_std_m: r, m; None = estimated from the data (:func:`robust_measurement_std`).
        rate_prior_m_per_h: 1-sigma prior of the initial rate, m/h (default 1e-8 = 10 µm/kh).
    """

    def __init__(self, process_noise: float | str = "auto", measurement_std_m: float | None = None,
                 rate_prior_m_per_h: float = 1e-8):
        self.process_noise = process_noise
        self.measurement_std_m = measurement_std_m
        self.rate_prior_m_per_h = rate_prior_m_per_h

    def fit(self, hours, values) -> Trend:
        """Filter and smooth ``values`` (n,) m at ``hours`` (n,) h (ascending). NaN values are
        skipped (the state is only predicted through them)."""
        t = np.asarray(hours, dtype=float)
        z = np.asarray(values, dtype=float)
        if t.shape != z.shape or t.ndim != 1 or t.size == 0:
            raise ValueError(f"hours {t.shape} and values {z.shape} must be equal 1-D shapes, n ≥ 1")
        if np.any(np.diff(t) < 0):
            raise ValueError("hours must be ascending")
        ok = np.isfinite(z)
        if not ok.any():
            raise ValueError("no finite backlash estimate to trend")
        r = self.measurement_std_m if self.measurement_std_m is not None else robust_measurement_std(z)
        q = self.process_noise
        why = f"given: {q!r} m²/h³"
        if isinstance(q, str):
            if q not in ("ml", "auto"):
                raise ValueError(f"process_noise is {q!r}; expected a density in m²/h³, 'ml' or 'auto'")
            q, why = choose_process_noise(t, z, r, self.rate_prior_m_per_h, q)
        kf = KalmanFilter(dim_x=2, dim_z=1)
        first = int(np.flatnonzero(ok)[0])
        kf.x = np.array([[z[first]], [0.0]])
        kf.P = np.diag([r * r, self.rate_prior_m_per_h ** 2])
        kf.H = np.array([[1.0, 0.0]])
        kf.R = np.array([[r * r]])
        dts = np.diff(t, prepend=t[0])
        Fs = [np.array([[1.0, dt], [0.0, 1.0]]) for dt in dts]
        Qs = [Q_continuous_white_noise(2, dt=max(dt, 0.0), spectral_density=q)
              if dt > 0 else np.zeros((2, 2)) for dt in dts]
        zs = [np.array([[v]]) if np.isfinite(v) else None for v in z]
        mu, cov, _, _ = kf.batch_filter(zs, Fs=Fs, Qs=Qs)
        xs, ps, _, _ = kf.rts_smoother(mu, cov, Fs=Fs, Qs=Qs)
        return Trend(hours=t, smoothed=xs[:, 0, 0], smoothed_std=np.sqrt(ps[:, 0, 0]),
                     rate=xs[:, 1, 0], filtered=mu[:, 0, 0], measurement_std=float(r),
                     state=mu[-1, :, 0].copy(), covariance=cov[-1].copy(), process_noise=float(q),
                     process_noise_choice=why)


def prognosis(trend: Trend, limit_m: float = LIMIT_M, n_draws: int = 4000,
              seed: int = 0) -> Prognosis:
    """Crossing of ``limit_m`` from the filtered state at the last session (see module doc)."""
    b, v = float(trend.state[0]), float(trend.state[1])
    t_last = float(trend.hours[-1])
    crossing = t_last + (limit_m - b) / v if v > 0 else math.inf
    rng = np.random.default_rng(seed)
    draws = rng.multivariate_normal([b, v], trend.covariance, size=n_draws)
    with np.errstate(divide="ignore", invalid="ignore"):
        hours = np.where(draws[:, 1] > 0, t_last + (limit_m - draws[:, 0]) / draws[:, 1], np.inf)
    hours = np.sort(hours)
    lo = hours[math.floor(0.025 * (n_draws - 1))]
    hi = hours[math.ceil(0.975 * (n_draws - 1))]
    return Prognosis(at_hours=t_last, level_m=b, rate_m_per_h=v, limit_m=limit_m,
                     crossing_hours=float(crossing), band_hours=(float(lo), float(hi)))


def prognosis_history(hours, values, limit_m: float = LIMIT_M, min_sessions: int = 3,
                      **trend_kw) -> list[Prognosis]:
    """The prognosis as it would have been made after each session (from session
    ``min_sessions`` on), using only the sessions up to it."""
    t = np.asarray(hours, dtype=float)
    z = np.asarray(values, dtype=float)
    model = BacklashTrend(**trend_kw)
    return [prognosis(model.fit(t[:i + 1], z[:i + 1]), limit_m)
            for i in range(min_sessions - 1, t.size)]


#: Savitzky–Golay trend of Fig. 13: sessions in the window and polynomial order.
SAVGOL_WINDOW_SESSIONS = 11
SAVGOL_POLYORDER = 2


@dataclass(frozen=True)
class SavgolTrend:
    """The paper's trend filter (Fig. 13: "Savitzky–Golay filtered"): values (n,) m at the
    sessions (NaN where the estimate is missing); window: sessions in the window; polyorder."""

    values: np.ndarray
    window: int
    polyorder: int


def savgol_trend(values, window: int = SAVGOL_WINDOW_SESSIONS,
                 polyorder: int = SAVGOL_POLYORDER) -> SavgolTrend | None:
    """Savitzky–Golay smoothing of the per-session estimates ``values`` (n,) m, as the paper
    draws in Fig. 13 (Savitzky & Golay, Anal. Chem. 36, 1964; ``scipy.signal.savgol_filter``
    with ``mode="interp"``: the ends are the fitted polynomial of the first and last window).

    The filter runs over the session index: it assumes evenly spaced sessions, as the paper's
    (every 84 h). Missing (NaN) estimates are left out and stay NaN. With fewer finite sessions
    than ``window`` the window shrinks to the largest odd count available; with too few for a
    polynomial of ``polyorder`` (window ≤ polyorder) there is no trend (None). The paper gives
    neither window nor order; 11 sessions (924 h at its interval) and order 2 follow its curve's
    smoothness.
    """
    from scipy.signal import savgol_filter

    z = np.asarray(values, dtype=float)
    ok = np.isfinite(z)
    n = int(ok.sum())
    w = min(window, n if n % 2 else n - 1)
    if w <= polyorder:
        return None
    out = np.full(z.shape, np.nan)
    out[ok] = savgol_filter(z[ok], w, polyorder, mode="interp")
    return SavgolTrend(values=out, window=w, polyorder=polyorder)
