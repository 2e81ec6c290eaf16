"""Containers for error motions against position, shared by the error-motion and backlash code.

Position reference: the *commanded* position of the controller (``position_cmd``), which is
proportional to the screw angle. Rows of every (6, n) array follow :data:`DOFS`: E_XX, E_YX, E_ZX
in m, E_AX, E_BX, E_CX in rad (ISO 230-1 names; carriage travels along +X, Z up).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from analysis.dataset.schema import DOF_UNITS, DOFS

__all__ = ["DOFS", "DOF_UNITS", "DirectionalTraces", "SessionErrorMotions"]


@dataclass(frozen=True)
class DirectionalTraces:
    """Error motions of one direction pair on a common position grid.

    x_m: (n,) commanded position, m, ascending with uniform step ``dx_m``.
    forward, reverse: (6, n) error motions while moving towards +X and towards −X, rows DOFS.
    band_m: (6, 2) per DOF the wavelengths (shortest, longest; m) the recording resolves: the
        widest band whose expected RMS error is within the stated precision
        (:func:`analysis.phase2.fusion.resolved_band`); NaN where none; None when not known.
    """

    x_m: np.ndarray
    forward: np.ndarray
    reverse: np.ndarray
    band_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = len(self.x_m)
        for name in ("forward", "reverse"):
            a = getattr(self, name)
            if a.shape != (6, n):
                raise ValueError(f"DirectionalTraces.{name} has shape {a.shape}; expected (6, {n})")

    @property
    def dx_m(self) -> float:
        """Grid step, m."""
        return float(self.x_m[1] - self.x_m[0])


@dataclass(frozen=True)
class SessionErrorMotions:
    """The error motions of one Phase II session, averaged over its usable runs.

    combined: all speeds combined where each is best (the full error motions).
    slow: the slow-speed component ``slow()`` of the paper, the high-spatial-frequency content
        that the backlash methods correlate.
    skipped: (run, reason) for each run left out.
    position_reference: the position axis of the traces: "command" (the controller's
        ``position_cmd``) or "imu" (the IMU-based position).
    """

    session: str
    hours: float
    runs: tuple[str, ...]
    combined: DirectionalTraces
    slow: DirectionalTraces
    skipped: tuple[tuple[str, str], ...] = field(default_factory=tuple)
    position_reference: str = "command"


def band_mm(band_m: np.ndarray | None) -> dict[str, list[float] | None] | None:
    """A (6, 2) resolved band in m (:attr:`DirectionalTraces.band_m`) as JSON: ``{dof: [shortest,
    longest] wavelength in mm, or None where no band is resolved}``; None when ``band_m`` is None."""
    if band_m is None:
        return None
    return {d: None if not np.isfinite(band_m[i]).all() else [float(band_m[i, 0] * 1e3), float(band_m[i, 1] * 1e3)]
            for i, d in enumerate(DOFS)}
