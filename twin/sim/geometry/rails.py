"""The two guide rails' deviations as functions of the rail coordinate: their statistical
description (:class:`RailSpec`: waviness with a 1/k spectrum, bolt-pitch waviness, roughness,
correlated between the rails), the stored profiles (:class:`RailProfiles`, interpolated at any
rail coordinate) and how they are drawn (:func:`make_rail_profiles`) or set to a sinusoid
(:func:`sinusoidal_rail_profiles`). Frames and signs: :mod:`twin.sim.geometry`. SI units (m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.interpolate import CubicSpline

from twin.sim.geometry.frames import (
    DEFAULT_RAIL_LENGTH_M,
    TRAVEL_M,
    _as_1d,
)


class RailRangeError(ValueError):
    """A rail coordinate outside the stored profiles: the carriage left the rails' modelled
    length, which in a simulation means it ran away (an unstable set of parameters)."""


@dataclass(frozen=True)
class RailSpec:
    """Statistical description of the two rails' geometric deviations (SI units).

    Each rail profile (vertical and lateral, on each rail) is the sum of three parts:

    1. waviness ("straightness"): random-phase sum of sinusoids with PSD ∝ 1/k^p (k = 1/λ in
       1/m) for wavelengths from ``min_wavelength_m`` to ``max_wavelength_m`` (default: the rail
       length); p = 2 gives amplitudes ∝ 1/k, a "roughly 1/k" spectrum [M].
       Its rms over the generated rail is exactly ``straightness_rms_*_m``;
    2. bolt-pitch waviness: a sinusoid of period ``bolt_pitch_m`` and amplitude
       ``bolt_amplitude_*_m`` (about 60 mm, 0.2–1 µm [M]); the bolt positions of a
       rail are random (one phase per rail, shared by its vertical and lateral profiles);
    3. roughness: flat-PSD random-phase sum between ``min_wavelength_m`` and
       ``roughness_max_wavelength_m``, rms ``roughness_rms_m`` (both directions) [M].

    The waviness of rail 1 is correlated with that of rail 0 (coefficient ρ, a common part from
    the flatness/straightness of the machined base both rails are bolted to [M]):
    w_1 = ρ·w_0 + sqrt(1 − ρ²)·w_1', rescaled to the exact rms. ρ matters for roll (the
    rail-to-rail difference) and for the mean seen by the carriage.

    Attributes:
        straightness_rms_vertical_m: rms of the vertical waviness, m. Default 0.5 µm [M]: with
            the 1/k spectrum this gives a few µm p-v per rail over the 450 mm travel ("a few µm
            p-v over 0.5 m" [M]) and, with the default carriage, carriage angles p-v over the
            travel within [M]'s 5–20 µrad in roll but partly above it in pitch and yaw (per-seed
            figures: docs/validation.md): the two [M] figures are in mild tension, because a
            1/k spectrum puts most of the slope in the longest wavelengths.
        straightness_rms_lateral_m: rms of the lateral waviness, m. Default 0.5 µm [M].
        rail_correlation_vertical: ρ of the two rails' vertical waviness (default 0.8 [M]).
        rail_correlation_lateral: ρ of the two rails' lateral waviness (default 0.5 [M]: each
            rail is aligned to its own reference edge).
        spectrum_exponent: p in PSD ∝ 1/k^p (dimensionless), default 2.
        min_wavelength_m: shortest wavelength of waviness and roughness, m (default 0.5 mm, the
            paper's section V high-pass cutoff; 10 grid steps at the default grid).
        max_wavelength_m: longest waviness wavelength, m; None → the rail length.
        bolt_pitch_m: bolt spacing, m (default 0.060 [M]).
        bolt_amplitude_vertical_m: bolt-pitch amplitude in Z, m (default 0.5 µm, in the 0.2–1 µm
            range [M]).
        bolt_amplitude_lateral_m: bolt-pitch amplitude in Y, m (default 0.3 µm [M]).
        roughness_rms_m: rms of the short-wavelength roughness, m (default 0.02 µm [M]).
        roughness_max_wavelength_m: longest roughness wavelength, m (default 2 mm [M]).
        grid_step_m: spacing du of the stored profiles, m (default 0.05 mm).
    """

    straightness_rms_vertical_m: float = 0.5e-6
    straightness_rms_lateral_m: float = 0.5e-6
    rail_correlation_vertical: float = 0.8
    rail_correlation_lateral: float = 0.5
    spectrum_exponent: float = 2.0
    min_wavelength_m: float = 0.5e-3
    max_wavelength_m: float | None = None
    bolt_pitch_m: float = 0.060
    bolt_amplitude_vertical_m: float = 0.5e-6
    bolt_amplitude_lateral_m: float = 0.3e-6
    roughness_rms_m: float = 0.02e-6
    roughness_max_wavelength_m: float = 2.0e-3
    grid_step_m: float = 0.05e-3

    def __post_init__(self) -> None:
        if self.grid_step_m <= 0 or self.min_wavelength_m < 2 * self.grid_step_m:
            raise ValueError("min_wavelength_m must be at least two grid steps (Nyquist)")
        if self.bolt_pitch_m <= 0:
            raise ValueError("bolt_pitch_m must be positive")
        for rho in (self.rail_correlation_vertical, self.rail_correlation_lateral):
            if not -1.0 <= rho <= 1.0:
                raise ValueError("rail correlations must lie in [-1, 1]")

    def expected_rms_m(self, which: str) -> float:
        """Expected total rms of one rail profile, m: sqrt(s² + A_bolt²/2 + r²).

        ``which`` is "vertical" or "lateral". Exact for the waviness and roughness parts over the
        generated record; the bolt sinusoid's rms is A/√2 up to an end effect of order
        bolt_pitch / rail length."""
        if which == "vertical":
            s, b = self.straightness_rms_vertical_m, self.bolt_amplitude_vertical_m
        elif which == "lateral":
            s, b = self.straightness_rms_lateral_m, self.bolt_amplitude_lateral_m
        else:
            raise ValueError(f"which must be 'vertical' or 'lateral', got {which!r}")
        return math.sqrt(s**2 + b**2 / 2.0 + self.roughness_rms_m**2)


@dataclass(frozen=True, eq=False)
class RailProfiles:
    """Deviation profiles of the two rails on a uniform grid of rail coordinates.

    Attributes:
        u_m: (n,) rail coordinates of the samples, m, uniform step ``du``.
        vertical: (2, n) vertical (+Z) deviation of rail 0 (y = −w/2) and rail 1 (y = +w/2), m.
        lateral: (2, n) lateral (+Y) deviation of rail 0 and rail 1, m.
    """

    u_m: np.ndarray
    vertical: np.ndarray
    lateral: np.ndarray

    def __post_init__(self) -> None:
        u = np.array(self.u_m, dtype=float)  # private copies, then frozen read-only
        v = np.array(self.vertical, dtype=float)
        lat = np.array(self.lateral, dtype=float)
        if u.ndim != 1 or u.size < 2:
            raise ValueError("u_m must be 1-D with at least two samples")
        if v.shape != (2, u.size) or lat.shape != (2, u.size):
            raise ValueError(f"vertical/lateral must have shape (2, {u.size})")
        steps = np.diff(u)
        if np.any(steps <= 0) or np.ptp(steps) > 1e-6 * steps.mean():
            raise ValueError("u_m must be uniform and increasing")
        for name, arr in (("u_m", u), ("vertical", v), ("lateral", lat)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def du(self) -> float:
        """Grid step, m."""
        return float(self.u_m[1] - self.u_m[0])

    @property
    def u_range(self) -> tuple[float, float]:
        """(first, last) rail coordinate covered, m."""
        return float(self.u_m[0]), float(self.u_m[-1])

    @cached_property
    def _spline(self) -> CubicSpline:
        # Rows: vertical rail 0, rail 1, lateral rail 0, rail 1.
        return CubicSpline(self.u_m, np.vstack([self.vertical, self.lateral]), axis=1)

    def at(self, u, method: str = "linear") -> tuple[np.ndarray, np.ndarray]:
        """Profiles interpolated at rail coordinates u.

        Args:
            u: scalar or (m,) rail coordinates, m; must lie inside ``u_range``.
            method: "linear" (np.interp) or "cubic" (not-a-knot cubic spline).

        Returns:
            (vertical, lateral), each (2, m) in m: row 0 rail 0, row 1 rail 1.
        """
        uu = _as_1d(u)
        lo, hi = self.u_range
        tol = 1e-9 * max(1.0, abs(lo), abs(hi))
        if uu.size and (uu.min() < lo - tol or uu.max() > hi + tol):
            raise RailRangeError(
                f"rail coordinate outside the stored profiles [{lo:.6g}, {hi:.6g}] m: "
                f"[{uu.min():.6g}, {uu.max():.6g}]")
        if method == "linear":
            out = np.stack([np.interp(uu, self.u_m, row)
                            for row in (*self.vertical, *self.lateral)])
        elif method == "cubic":
            out = self._spline(uu)
        else:
            raise ValueError(f"method must be 'linear' or 'cubic', got {method!r}")
        return out[:2], out[2:]


def _uniform_grid(length_m: float, du: float, u_start_m: float | None) -> np.ndarray:
    """(n,) uniform grid, n = round(length/du) + 1, from u_start (None: travel centred), m."""
    if length_m <= 0:
        raise ValueError("length_m must be positive")
    start = -(length_m - TRAVEL_M) / 2.0 if u_start_m is None else float(u_start_m)
    n = int(round(length_m / du)) + 1
    return start + du * np.arange(n)


def _random_phase_profiles(n: int, du: float, k_min: float, k_max: float, exponent: float,
                           rms: float, rng: np.random.Generator, count: int) -> np.ndarray:
    """(count, n) random-phase profiles with one-sided PSD ∝ k^(−exponent) on k ∈ [k_min, k_max].

    Method [D]: harmonics k_j = j/(n·du) of the record; amplitude c_j ∝ k_j^(−exponent/2) (so
    c_j²/2, the power per bin, follows the PSD), uniform random phases φ_j from ``rng``;
    x(u_i) = Σ_j c_j cos(2π k_j u_i + φ_j), evaluated with an inverse real FFT. The harmonics are
    orthogonal over the record, so the rms is exactly sqrt(Σ c_j²/2), scaled to ``rms``.
    """
    out = np.zeros((count, n))
    if rms == 0.0:
        return out
    record = n * du
    j_lo = max(1, int(round(k_min * record)))
    j_hi = min((n - 1) // 2, int(math.floor(k_max * record + 1e-9)))
    if j_hi < j_lo:
        raise ValueError("empty wavelength band for this record length / grid step")
    j = np.arange(j_lo, j_hi + 1)
    c = (j / record) ** (-exponent / 2.0)
    c *= rms / math.sqrt(np.sum(c**2) / 2.0)
    phases = rng.uniform(0.0, 2.0 * math.pi, size=(count, j.size))
    spectrum = np.zeros((count, n // 2 + 1), dtype=complex)
    spectrum[:, j] = 0.5 * n * c * np.exp(1j * phases)
    out[:] = np.fft.irfft(spectrum, n=n, axis=1)
    return out


def _correlate_rails(pair: np.ndarray, rho: float) -> np.ndarray:
    """(2, n) → (2, n): rail 1 := ρ·rail 0 + sqrt(1 − ρ²)·rail 1, rescaled to rail 1's rms."""
    target = math.sqrt(np.mean(pair[1] ** 2))
    mixed = rho * pair[0] + math.sqrt(max(0.0, 1.0 - rho**2)) * pair[1]
    norm = math.sqrt(np.mean(mixed**2))
    return np.vstack([pair[0], mixed * (target / norm if norm > 0 else 0.0)])


def make_rail_profiles(spec: RailSpec, length_m: float = DEFAULT_RAIL_LENGTH_M,
                       rng: np.random.Generator | None = None, *,
                       u_start_m: float | None = None) -> RailProfiles:
    """Random rail profiles drawn from ``spec`` (see :class:`RailSpec` for the model).

    Args:
        spec: the rail description (SI).
        length_m: rail length covered by the profiles, m (default 0.70).
        rng: the caller's generator; all random draws come from it, in this order: waviness
            phases (vertical rail 0, rail 1, lateral rail 0, rail 1), bolt positions (rail 0,
            rail 1), roughness phases (same order as the waviness). Required.
        u_start_m: rail coordinate of the first sample, m; None → the travel [0, 0.45] m is
            centred on the rail (−0.125 m for the default length).

    Returns:
        RailProfiles on a grid of step ``spec.grid_step_m``. Deterministic for a given rng state.
    """
    if rng is None:
        raise ValueError("pass a numpy.random.Generator (all random draws come from the caller)")
    du = spec.grid_step_m
    u = _uniform_grid(length_m, du, u_start_m)
    n = u.size
    lam_max = spec.max_wavelength_m if spec.max_wavelength_m is not None else length_m
    k_lo, k_hi = 1.0 / lam_max, 1.0 / spec.min_wavelength_m

    wav_v = _correlate_rails(
        _random_phase_profiles(n, du, k_lo, k_hi, spec.spectrum_exponent,
                               spec.straightness_rms_vertical_m, rng, 2),
        spec.rail_correlation_vertical)
    wav_l = _correlate_rails(
        _random_phase_profiles(n, du, k_lo, k_hi, spec.spectrum_exponent,
                               spec.straightness_rms_lateral_m, rng, 2),
        spec.rail_correlation_lateral)
    # Bolt positions u_b (one per rail); the rail sinks at its bolts: −A·cos(2π(u − u_b)/P).
    bolt_at = rng.uniform(0.0, spec.bolt_pitch_m, size=(2, 1))
    bolt_shape = -np.cos(2.0 * math.pi * (u[None, :] - bolt_at) / spec.bolt_pitch_m)
    k_rough_lo = 1.0 / spec.roughness_max_wavelength_m
    rough = _random_phase_profiles(n, du, k_rough_lo, k_hi, 0.0, spec.roughness_rms_m, rng, 4)

    vertical = wav_v + spec.bolt_amplitude_vertical_m * bolt_shape + rough[:2]
    lateral = wav_l + spec.bolt_amplitude_lateral_m * bolt_shape + rough[2:]
    return RailProfiles(u_m=u, vertical=vertical, lateral=lateral)


def sinusoidal_rail_profiles(length_m: float, wavelength_m: float, amplitude_m: float,
                             which: str = "vertical", phase: float = 0.0, *,
                             grid_step_m: float = 0.05e-3,
                             u_start_m: float | None = None) -> RailProfiles:
    """The same sinusoid A·sin(2π u/λ + φ) on both rails (the other direction zero); for tests.

    Args:
        length_m: rail length, m. wavelength_m: λ, m. amplitude_m: A, m. phase: φ, rad.
        which: "vertical", "lateral" or "both".
        grid_step_m: du, m. u_start_m: first sample, m (None → travel centred, as
            :func:`make_rail_profiles`).
    """
    u = _uniform_grid(length_m, grid_step_m, u_start_m)
    wave = amplitude_m * np.sin(2.0 * math.pi * u / wavelength_m + phase)
    both = np.vstack([wave, wave])
    zero = np.zeros_like(both)
    if which == "vertical":
        return RailProfiles(u, both, zero)
    if which == "lateral":
        return RailProfiles(u, zero, both)
    if which == "both":
        return RailProfiles(u, both, both.copy())
    raise ValueError(f"which must be 'vertical', 'lateral' or 'both', got {which!r}")
