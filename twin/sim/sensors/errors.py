"""The deterministic errors of a triaxial sensor: bias, scale-factor error and misalignment
(:class:`ErrorModel`), applied to the true signal before the sensor's response. Pure numpy."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _as_tuple_vector(value, name: str) -> tuple[float, float, float]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be 3 finite numbers, got {value!r}")
    return tuple(float(v) for v in arr)


def _as_tuple_matrix(value, name: str) -> tuple[tuple[float, ...], ...]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3, 3) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite 3x3 matrix, got {value!r}")
    return tuple(tuple(float(v) for v in row) for row in arr)


@dataclass(frozen=True)
class ErrorModel:
    """Deterministic errors of a triaxial sensor: bias, scale-factor error, misalignment.

    ``s_meas = (I + diag(scale_error) + offdiag(misalignment)) @ s + bias``, applied per sample.

    Attributes:
        bias: (3,) offset per axis, in the unit of the signal (m/s² or rad/s).
        scale_error: (3,) fractional scale-factor error per axis (0.01 = reads 1 % high).
        misalignment: (3, 3) small-angle cross-axis matrix, dimensionless (rad for small angles).
            Element ``[i, j]`` is the sensitivity of output axis ``i`` to input axis ``j``; the
            diagonal is ignored (scale errors live in ``scale_error``).

    All zero by default (the error terms the twin models: "bias, scale, misalignment and cross-axis
    sensitivity as parameters (zero by default)"). Stored as tuples so the model is immutable and
    hashable; pass any array-like.
    """

    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scale_error: tuple[float, float, float] = (0.0, 0.0, 0.0)
    misalignment: tuple[tuple[float, ...], ...] = ((0.0,) * 3,) * 3

    def __post_init__(self) -> None:
        object.__setattr__(self, "bias", _as_tuple_vector(self.bias, "bias"))
        object.__setattr__(self, "scale_error", _as_tuple_vector(self.scale_error, "scale_error"))
        matrix = _as_tuple_matrix(self.misalignment, "misalignment")
        object.__setattr__(self, "misalignment", matrix)

    @property
    def matrix(self) -> np.ndarray:
        """(3, 3) gain matrix ``I + diag(scale_error) + offdiag(misalignment)``, dimensionless."""
        cross = np.array(self.misalignment)
        np.fill_diagonal(cross, 0.0)
        return np.eye(3) + np.diag(self.scale_error) + cross

    def apply(self, values: np.ndarray) -> np.ndarray:
        """Apply the errors to a triaxial signal.

        Args:
            values: (n, 3) true signal in the sensor frame (any unit; bias is in the same unit).

        Returns:
            (n, 3) signal as the erroneous sensor reports it.
        """
        values = np.asarray(values, dtype=float)
        if values.ndim != 2 or values.shape[1] != 3:
            raise ValueError(f"signal must have shape (n, 3), got {values.shape}")
        return values @ self.matrix.T + np.asarray(self.bias)
