"""The preloaded nut's drag torque and stiffness as functions of its preload: the lead angle, the
catalogue's preload-torque relation, the Hertz contact stiffness, and springs in series.

Sources ([Archard], [Hertz], [Catalogue], [Paper], [XJTU]) and units: :mod:`twin.sim.degradation`.
"""

from __future__ import annotations

import numpy as np


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
