"""A candidate's response: its parameters' grids (:class:`ParamAxis`), the change of every
statistic on them (:class:`CandidateResponse`), its interpolation between grid values and the
fine and zoomed grids its fit searches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import RegularGridInterpolator


@dataclass(frozen=True)
class ParamAxis:
    """One parameter of a candidate: name (with its unit, e.g. ``rise_K``), the grid values at
    which the response was simulated (ascending, including the value that turns it off where
    there is one), whether it is discrete (no interpolation between grid values), and whether
    the grid is closed: it lists every value the parameter can take (the mains frequency and
    its harmonics), so that a fit on its first or last value is not "at the edge"; log: its
    prior is log-uniform (:attr:`log_scaled`)."""

    name: str
    values: tuple[float, ...]
    discrete: bool = False
    closed: bool = False
    log: bool = False

    @property
    def log_scaled(self) -> bool:
        """A scale whose prior is log-uniform (a factor on a twin parameter) and whose grid is
        positive: its response is also interpolated in log p for the interval."""
        return self.log and not self.discrete and min(self.values) > 0


@dataclass
class CandidateResponse:
    """The simulated response of one candidate effect.

    name: candidate name; params: its axes; delta: {"cal": array, "heldout": array}, each of
    shape (*[len(a.values) for a in params], n) with the change of every statistic on the grid;
    kind: "physical effect" (simulated) or "signal artefact" (applied to a simulated recording);
    spread: for a response that is the mean of its change over the twin's seeds, the standard
    deviation of that change from seed to seed, same shapes as ``delta`` (None: one seed's
    response): how far one recording's change may stand from the mean. per_seed: the change
    on each twin seed it was computed with, {"cal", "heldout"}: (seeds, *grid, n) (None: one
    seed), for the interval (:func:`seed_interval`).
    """

    name: str
    params: list[ParamAxis]
    delta: dict[str, np.ndarray]
    kind: str = "physical effect"
    spread: dict[str, np.ndarray] | None = None
    per_seed: dict[str, np.ndarray] | None = None

    def __post_init__(self) -> None:
        shape = tuple(len(a.values) for a in self.params)
        for part, d in self.delta.items():
            if d.shape[:-1] != shape:
                raise ValueError(f"{self.name}: {part} response has shape {d.shape}; expected "
                                 f"{shape} + (n,) for the grids of {[a.name for a in self.params]}")
            if self.per_seed is not None and self.per_seed[part].shape[1:] != d.shape:
                raise ValueError(f"{self.name}: {part} per-seed responses have shape "
                                 f"{self.per_seed[part].shape}; expected (seeds,) + {d.shape}")


def grid_edge(axis: ParamAxis, value: float, interval: tuple[float, float]) -> str | None:
    """Whether a fit sits on the edge of the grid it was searched on: "low" | "high" when the
    value or its interval reaches the first | last grid value, "both" when the interval reaches
    both, None inside. A zero first value of a grid without negative values (a magnitude: a
    torque, a mass, a spread) is a physical floor, not an edge."""
    v = np.asarray(axis.values, float)
    lo_g, hi_g = float(v.min()), float(v.max())
    if hi_g == lo_g:
        return None
    tol = 1e-9 * (hi_g - lo_g)
    if axis.closed:
        spans = interval[0] <= lo_g + tol and interval[1] >= hi_g - tol
        return "both" if spans else None
    floor = lo_g == 0.0
    low = not floor and min(value, interval[0]) <= lo_g + tol
    high = max(value, interval[1]) >= hi_g - tol
    return "both" if low and high else "low" if low else "high" if high else None

def _fine_axes(params: list[ParamAxis], n_fine: int) -> list[np.ndarray]:
    out = []
    for a in params:
        v = np.asarray(a.values, float)
        if a.discrete or v.size == 1:
            out.append(v)
        else:
            # The grid values themselves plus an even subdivision between them.
            out.append(np.unique(np.concatenate([v, np.linspace(v[0], v[-1], n_fine)])))
    return out


def _interpolator(params: list[ParamAxis], delta: np.ndarray, method: str = "linear"):
    """The response ``delta`` (*grid, n) as a function of the parameters: points (m, k) ->
    (m, n). ``method``: "linear" (the fit's), or one of the interpolations the interval is
    checked with (:func:`interpolation_shift`): "pchip" (the shape-preserving cubic; an axis with
    fewer than four grid values is first given linearly interpolated midpoints), "log" (linear
    in log p on the :attr:`ParamAxis.log_scaled` axes, linear on the others). A single grid
    value gets a flat second one."""
    if not params:
        return lambda pts: np.broadcast_to(delta, (len(pts), delta.shape[-1]))
    axes = [np.asarray(a.values, float) for a in params]
    in_log = np.array([method == "log" and a.log_scaled for a in params])
    axes2, d = [], delta
    for i, ax in enumerate(axes):
        if ax.size == 1:
            # A single grid value cannot be interpolated over: repeat it as a flat axis.
            ax = np.array([ax[0], ax[0] + 1.0])
            d = np.concatenate([d, d], axis=i)
        while method == "pchip" and ax.size < 4:
            mid = 0.5 * (ax[1:] + ax[:-1])
            dm = 0.5 * (np.take(d, range(1, ax.size), axis=i) + np.take(d, range(ax.size - 1), axis=i))
            order = np.argsort(np.concatenate([ax, mid]), kind="stable")
            ax = np.concatenate([ax, mid])[order]
            d = np.take(np.concatenate([d, dm], axis=i), order, axis=i)
        axes2.append(np.log(ax) if in_log[i] else ax)
    f = RegularGridInterpolator(axes2, d, method="linear" if method == "log" else method)
    if not in_log.any():
        return f
    return lambda pts: f(np.where(in_log, np.log(np.where(in_log, pts, 1.0)), pts))


ZOOM_STEPS = 2.0  # half-width of the zoomed search, in steps of the fine grid
ZOOM_POINTS = 41  # points of each continuous parameter in the zoomed search


def _zoom_half_width(values: np.ndarray, n_fine: int) -> float:
    """Half the width of the zoomed search of a continuous parameter whose grid is ``values``:
    ZOOM_STEPS steps of the fine grid (its range in ``n_fine`` values)."""
    return ZOOM_STEPS * (values[-1] - values[0]) / max(n_fine - 1, 1)


def _zoom_axes(params: list[ParamAxis], fine: list[np.ndarray], p: np.ndarray, n_fine: int) -> list[np.ndarray]:
    """The zoomed search around the fine grid's best point ``p`` (k,): ZOOM_POINTS values of each
    continuous parameter within ± ZOOM_STEPS fine-grid steps of it (inside its grid), a discrete
    one (or a single-valued one) held at its value."""
    out = []
    for a, v, x in zip(params, fine, p, strict=True):
        if a.discrete or v.size == 1:
            out.append(np.array([x]))
            continue
        half = _zoom_half_width(v, n_fine)
        out.append(np.linspace(max(v[0], x - half), min(v[-1], x + half), ZOOM_POINTS))
    return out


def _points(axes: list[np.ndarray]) -> np.ndarray:
    """Every combination of the axes' values: (m, k)."""
    if not axes:
        return np.zeros((1, 0))
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(axes))


def search_step(axis: ParamAxis, n_fine: int = 61) -> float:
    """The step of the zoomed search of a continuous parameter (0 for a discrete one): the
    resolution of its fitted value."""
    v = np.asarray(axis.values, float)
    if axis.discrete or v.size == 1:
        return 0.0
    return 2.0 * _zoom_half_width(v, n_fine) / (ZOOM_POINTS - 1)


