"""Multi-speed, multi-sensor combination of IMU signals into error motions, per spatial frequency.

Measurement model at constant signed speed v (derived here from rigid-body kinematics, as in
Vogl et al., PHM Society 2016; ′ = d/dx):

    f_x = v²·E_XX'' − g·E_BX        ω_x = v·E_AX'
    f_y = v²·E_YX'' + g·E_AX        ω_y = v·E_BX'
    f_z = v²·E_ZX''  (+ g, removed)  ω_z = v·E_CX'

In the spatial Fourier domain (wavenumber κ = 2πk, rad/m) a translation T and the angle R coupled
to it through gravity obey, for every speed s,

    F_s(κ) = H_a(vκ)·(−v²κ²·T(κ) + c·g·R(κ))      Ω_s(κ) = H_g(vκ)·(iκv·R(κ))

(c = +1 for the pair (E_YX, E_AX), −1 for (E_XX, E_BX)); H the magnitude of the sensor low-pass
(2nd-order Butterworth |H| = 1/√(1+(f/f_c)⁴)) at the temporal frequency f = |v|κ/2π. Per κ the
unknowns (T, R) are the weighted least-squares solution over all speeds and both sensors with
weights 1/(|v|·n²) (white time noise of density n maps to the position-domain density |v|·n²,
derived here) and weight 0 above ``f_max`` (the sensor response is no longer
known well enough; each speed resolves only κ ≤ 2π·f_max/|v|). With one sensor that is the
first-order complementary filter; E_ZX uses f_z alone, E_CX ω_z alone.

Records are not periodic: accelerometer and tilt signals are mirrored evenly, rates oddly
(half-sample symmetric extension to length 2n), which makes the model exact up to a quadratic of
the translations (the kinks of an evenly mirrored straightness), removed afterwards together with
the other unobservable terms (non-periodic records).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.phase2.imu_runs import lowpass_power

G = 9.80665  # m/s², standard gravity (the IMU's reference)

__all__ = ["G", "Prior", "Stream", "band_limit", "butterworth2_magnitude", "pool_long_wavelengths",
           "posterior_psd", "remove_unobservable", "resolved_band", "solve"]


def butterworth2_magnitude(f_hz: np.ndarray, bandwidth_hz: float) -> np.ndarray:
    """|H(f)| of a 2nd-order Butterworth low-pass with half-power at ``bandwidth_hz``."""
    return 1.0 / np.sqrt(1.0 + (np.asarray(f_hz) / bandwidth_hz) ** 4)


@dataclass(frozen=True)
class Stream:
    """One measured signal on the position grid.

    data: (n,) signal, m/s² (accelerometer) or rad/s (gyro), averaged over ``count`` records.
    kind: "acc" (model −v²κ²T + c·g·R) or "gyro" (model iκv·R).
    velocity_m_s: signed traverse speed. noise_density: of one record, unit/√Hz.
    bandwidth_hz: sensor half-power frequency; f_max_hz: highest temporal frequency used.
    count: number of records averaged. lowpass_hz, lowpass_order: the zero-phase low-pass
    applied before gridding (:func:`analysis.phase2.imu_runs.lowpass_power`), compensated.
    """

    data: np.ndarray
    kind: str
    velocity_m_s: float
    noise_density: float
    bandwidth_hz: float
    f_max_hz: float
    count: int = 1
    lowpass_hz: float = float("inf")
    lowpass_order: int = 8


def _extend(y: np.ndarray, odd: bool) -> np.ndarray:
    return np.concatenate([y, -y[::-1] if odd else y[::-1]])


@dataclass(frozen=True)
class Prior:
    """Zero-mean prior of an error motion: one-sided position-domain PSD S(k) = rms²·k_min/k²
    for k ≥ k_min (amplitude ∝ 1/k, "roughly 1/k" spectrum of guideways), so that
    ``rms`` is the RMS of the wavelengths up to 1/k_min. Units m or rad."""

    rms: float
    k_min_per_m: float = 2.0

    def psd(self, k_per_m: np.ndarray) -> np.ndarray:
        k = np.maximum(np.abs(k_per_m), self.k_min_per_m)
        return self.rms ** 2 * self.k_min_per_m / k ** 2


def _normal_equations(streams: list[Stream], dx_m: float, coupling: float | None, prior_t: Prior,
                      prior_r: Prior) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per wavenumber of the evenly mirrored grid (2n points): κ (2n,) rad/m, the normal matrix
    (2n, 2, 2) with the prior's inverse PSDs on its diagonal, the right-hand side (2n, 2) and the
    prior PSDs (2n, 2) of (T, R). See :func:`solve` for the model and the weights."""
    n = streams[0].data.size
    kappa = 2.0 * np.pi * np.fft.fftfreq(2 * n, dx_m)
    nb = kappa.size
    normal = np.zeros((nb, 2, 2), dtype=complex)
    rhs = np.zeros((nb, 2), dtype=complex)
    for s in streams:
        v = s.velocity_m_s
        f_hz = np.abs(v * kappa) / (2.0 * np.pi)
        h = butterworth2_magnitude(f_hz, s.bandwidth_hz) * lowpass_power(
            f_hz, s.lowpass_hz, s.lowpass_order)
        f_max = min(s.f_max_hz, 0.85 * s.lowpass_hz)
        w = np.where(f_hz <= f_max, s.count / (abs(v) * s.noise_density ** 2), 0.0)
        row = np.zeros((nb, 2), dtype=complex)
        if s.kind == "acc":
            spec = np.fft.fft(_extend(s.data, odd=False))
            row[:, 0] = -(v * kappa) ** 2 * h
            if coupling is not None:
                row[:, 1] = coupling * G * h
        elif s.kind == "gyro":
            spec = np.fft.fft(_extend(s.data, odd=True))
            row[:, 1] = 1j * kappa * v * h
        else:
            raise ValueError(f"Stream.kind is {s.kind!r}; expected 'acc' or 'gyro'")
        normal += w[:, None, None] * np.conj(row)[:, :, None] * row[:, None, :]
        rhs += (w * spec)[:, None] * np.conj(row)
    k = kappa / (2.0 * np.pi)
    prior = np.stack([prior_t.psd(k), prior_r.psd(k)], axis=1)
    normal[:, 0, 0] += 1.0 / prior[:, 0]
    normal[:, 1, 1] += 1.0 / prior[:, 1]
    return kappa, normal, rhs, prior


def solve(streams: list[Stream], dx_m: float, *, coupling: float | None,
          prior_t: Prior, prior_r: Prior) -> tuple[np.ndarray, np.ndarray]:
    """Maximum a-posteriori (Wiener) estimate per wavenumber of a translation T and an angle R.

    Per κ: minimise Σ_s w_s |D_s − G_s·u|² + |T|²/S_T + |R|²/S_R over u = (T, R), with data
    weights w_s = count/(|v|·n²) (the inverse position-domain noise PSD of the averaged record)
    and the prior PSDs S of ``prior_t``/``prior_r``; both sides are per unit of the same DFT
    normalisation, so the weighting is absolute (Wiener filter; with a weak prior this is the
    weighted least squares). Wavenumbers the data do not determine (a
    single speed cannot split g·R from v²κ²·T at long wavelengths) fall back to the prior, zero.

    coupling: c in f = v²T'' + c·g·R (+1 for E_YX/E_AX, −1 for E_XX/E_BX); None for an
    uncoupled DOF: then "acc" streams determine T alone and "gyro" streams R alone.
    Returns T (n,) m and R (n,) rad (κ = 0, the mean, set to zero).
    """
    n = streams[0].data.size
    kappa, normal, rhs, _ = _normal_equations(streams, dx_m, coupling, prior_t, prior_r)
    ok = np.ones(kappa.size, dtype=bool)
    ok[0] = False  # κ = 0: constants are unobservable
    sol = np.zeros((kappa.size, 2), dtype=complex)
    sol[ok] = np.linalg.solve(normal[ok], rhs[ok][:, :, None])[:, :, 0]
    t = np.real(np.fft.ifft(sol[:, 0]))[:n]
    r = np.real(np.fft.ifft(sol[:, 1]))[:n]
    return t, r


def posterior_psd(streams: list[Stream], dx_m: float, *, coupling: float | None,
                  prior_t: Prior, prior_r: Prior) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The error spectrum of :func:`solve`: per wavenumber the posterior covariance of (T, R) is
    P = N⁻¹, N the normal matrix with the prior's inverse PSDs on its diagonal (the linear-Gaussian
    model; e.g. Kay, *Fundamentals of Statistical Signal Processing: Estimation Theory*, 1993,
    ch. 12). Its diagonal is a one-sided PSD in the prior's units: Σ P(k)·Δk over a band of
    spatial frequencies is the expected squared error of that band (noise where the data determine
    the value, the prior's variance where they do not).

    Returns k (m,) spatial frequencies > 0 in 1/m, ascending with uniform step Δk = k[0] (the
    non-negative half of the mirrored grid's DFT without 0), and the posterior PSDs (m,) of T
    (m²·m) and of R (rad²·m).
    """
    kappa, normal, _, _ = _normal_equations(streams, dx_m, coupling, prior_t, prior_r)
    k = kappa / (2.0 * np.pi)
    pos = np.flatnonzero(k > 0)
    pos = pos[np.argsort(k[pos])]
    cov = np.linalg.inv(normal[pos])
    return k[pos], np.real(cov[:, 0, 0]), np.real(cov[:, 1, 1])


def resolved_band(k_per_m: np.ndarray, psd: np.ndarray, precision: float) -> tuple[float, float] | None:
    """The widest band of wavelengths whose expected RMS error stays within ``precision``.

    Starting at the spatial frequency of the lowest error PSD (:func:`posterior_psd`), the band
    grows one frequency at a time towards the neighbour with the lower PSD while Σ PSD·Δk stays at
    most ``precision``². Returns (shortest, longest wavelength), m, or None when even the best
    frequency alone exceeds it.
    """
    k = np.asarray(k_per_m, dtype=float)
    p = np.asarray(psd, dtype=float)
    dk = float(k[0])
    budget = precision ** 2
    lo = hi = int(np.argmin(p))
    if p[lo] * dk > budget:
        return None
    # The greedy growth, in one pass: it takes the frontier values of the two sides (towards lower
    # and towards higher k) smallest head first, so each side's values go in blocks that start at
    # a new running maximum of that side, and the blocks go in the order of those maxima (the
    # lower side first on a tie, as the greedy step takes it). A stable sort of the running maxima
    # gives that order; the band stops at the first value that is not finite or that would bring
    # Σ PSD·Δk (summed in the same order) above the budget.
    lower, upper = p[lo - 1::-1] if lo > 0 else p[:0], p[hi + 1:]
    keys = np.concatenate((np.maximum.accumulate(lower), np.maximum.accumulate(upper)))
    order = np.argsort(keys, kind="stable")
    values = np.concatenate((lower, upper))[order]
    total = np.cumsum(np.concatenate(([p[lo] * dk], values * dk)))[1:]
    over = np.flatnonzero(~np.isfinite(values) | (total > budget))
    taken = order[:over[0] if over.size else order.size]
    n_lower = int(np.count_nonzero(taken < lower.size))
    lo, hi = lo - n_lower, hi + (taken.size - n_lower)
    return 1.0 / float(k[hi]), 1.0 / float(k[lo])


def band_limit(e: np.ndarray, dx_m: float, band_m: tuple[float, float]) -> np.ndarray:
    """``e`` (..., n) on a grid of step ``dx_m`` keeping only the wavelengths inside ``band_m``
    (shortest, longest; m): an ideal band-pass of the evenly mirrored record (length 2n, as
    :func:`solve` extends accelerometer data), its mean removed."""
    e = np.asarray(e, dtype=float)
    n = e.shape[-1]
    ext = np.concatenate([e, e[..., ::-1]], axis=-1)
    k = np.abs(np.fft.fftfreq(2 * n, dx_m))
    lo, hi = band_m
    keep = (k >= 1.0 / hi * (1 - 1e-9)) & (k <= 1.0 / lo * (1 + 1e-9)) & (k > 0)
    return np.real(np.fft.ifft(np.fft.fft(ext, axis=-1) * keep, axis=-1))[..., :n]


def remove_unobservable(e: np.ndarray, x_m: np.ndarray) -> np.ndarray:
    """Remove the unobservable terms from (6, n) error motions: a least-squares quadratic in x
    from the translations (rows 0–2), the mean from the angles (rows 3–5)."""
    out = np.array(e, dtype=float, copy=True)
    u = (x_m - x_m.mean()) / max(float(np.ptp(x_m)), 1e-12)
    basis = np.vstack([np.ones_like(u), u, u * u]).T
    coef, *_ = np.linalg.lstsq(basis, out[:3].T, rcond=None)
    out[:3] -= (basis @ coef).T
    out[3:] -= out[3:].mean(axis=1, keepdims=True)
    return out


def pool_long_wavelengths(own: np.ndarray, pooled: np.ndarray, dx_m: float,
                          wavelength_m: float) -> np.ndarray:
    """``pooled`` at wavelengths above ``wavelength_m``, ``own`` below, crossing over smoothly
    (raised cosine in log-wavenumber over one octave, from ``wavelength_m`` down to half of it).

    Used to share the long wavelengths between the forward and the reverse estimates: a backlash
    shift s changes a wavelength λ by the phase 2π·s/λ (20 µm at 50 mm: 0.0025 rad), so pooling
    there loses no shift information and halves the noise variance. Arrays (..., n) on a grid of
    step ``dx_m``, mirrored evenly for the filtering.
    """
    d = np.asarray(own, dtype=float) - np.asarray(pooled, dtype=float)
    n = d.shape[-1]
    ext = np.concatenate([d, d[..., ::-1]], axis=-1)
    k = np.abs(np.fft.fftfreq(2 * n, dx_m))
    k0 = 1.0 / wavelength_m
    u = np.clip(np.log2(np.maximum(k, 1e-30) / k0), 0.0, 1.0)
    highpass = 0.5 - 0.5 * np.cos(np.pi * u)  # 0 at k ≤ 1/λ, 1 at k ≥ 2/λ
    hp = np.real(np.fft.ifft(np.fft.fft(ext, axis=-1) * highpass, axis=-1))[..., :n]
    return np.asarray(pooled, dtype=float) + hp

