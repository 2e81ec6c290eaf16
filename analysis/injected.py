"""What was injected into a simulated campaign, read from its ``truth.h5``, in the form the
estimates are compared with (scorer, Fig. 13, the Rerun view)."""

from __future__ import annotations

import numpy as np

from analysis.dataset import Truth

__all__ = ["injected_backlash_um", "injected_change_um"]


def injected_backlash_um(truth: Truth, sessions: list[str]) -> np.ndarray:
    """The injected backlash (clearance, µm) of each Phase II session of truth.h5; raises
    DatasetError naming a session truth.h5 does not hold."""
    return np.array([float(truth.session(n)[2]["backlash_um"]) for n in sessions])


def injected_change_um(truth: Truth, sessions: list[str], baseline_sessions: int = 1) -> np.ndarray:
    """The injected change of backlash (µm) of each session against the mean of the first
    ``baseline_sessions``: what the Phase II estimates, re-zeroed the same way, are compared with."""
    b = injected_backlash_um(truth, sessions)
    return b - b[:baseline_sessions].mean()
