"""The sweep file: its pydantic schema and messages that name the file, key, value and what is allowed."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from twin.sim.config import explain_errors, value_at
from twin.sim.scenario import read_toml

LOG_NAME = "sweep-log.jsonl"
MANIFEST_NAME = "sweep.json"
RESULT_NAME = "result.json"
FORMAT = "ballscrew-twin/sweep"


class SweepError(ValueError):
    """A sweep that cannot run; the message names the file, the key, the value and what is allowed."""


# ---------------------------------------------------------------------------------------------
# The sweep file


def _number(v: Any) -> Any:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError("__not_a_number__")
    if isinstance(v, float) and not math.isfinite(v):
        raise ValueError("__not_a_number__")
    return v


Number = Annotated[Any, AfterValidator(_number)]
Keys = str | list[str]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid")


def _keys(k: Keys) -> list[str]:
    return [k] if isinstance(k, str) else list(k)


class GridAxis(_Model):
    """A grid axis: ``values``, or ``start``/``stop``/``num`` spaced linearly or logarithmically."""

    key: Keys
    values: list[Number] | None = None
    start: Number | None = None
    stop: Number | None = None
    num: int | None = Field(None, strict=True)
    scale: Literal["linear", "log"] = "linear"

    @model_validator(mode="after")
    def _one_way(self) -> GridAxis:
        spaced = (self.start, self.stop, self.num)
        if self.values is not None:
            if any(v is not None for v in spaced):
                raise ValueError("__both__")
            if not self.values:
                raise ValueError("__empty__")
            if self.scale == "log" and any(v <= 0 for v in self.values):
                raise ValueError("__log__")
            return self
        if any(v is None for v in spaced):
            raise ValueError("__incomplete__")
        if self.num < 1:
            raise ValueError("__empty__")
        if self.scale == "log" and (self.start <= 0 or self.stop <= 0):
            raise ValueError("__log__")
        return self

    def points(self) -> list[float | int]:
        if self.values is not None:
            return list(self.values)
        f = np.geomspace if self.scale == "log" else np.linspace
        return [_tidy(v) for v in f(float(self.start), float(self.stop), int(self.num))]


class RandomAxis(_Model):
    """A randomly sampled axis: uniform (``linear``) or log-uniform (``log``) in [low, high)."""

    key: Keys
    low: Number
    high: Number
    scale: Literal["linear", "log"] = "linear"

    @model_validator(mode="after")
    def _bounds(self) -> RandomAxis:
        if not self.low < self.high:
            raise ValueError("__bounds__")
        if self.scale == "log" and self.low <= 0:
            raise ValueError("__log__")
        return self


class RandomSampling(_Model):
    n: int = Field(strict=True, ge=1)
    seed: int = Field(strict=True, ge=0)
    axis: list[RandomAxis]

    @field_validator("axis")
    @classmethod
    def _some(cls, v: list[RandomAxis]) -> list[RandomAxis]:
        if not v:
            raise ValueError("__empty__")
        return v

    def points(self) -> list[list[float]]:
        """(n, axes) values drawn from the sweep's own seed, in one call (so adding points keeps
        no earlier draw, but the same file always gives the same draws)."""
        u = np.random.default_rng(self.seed).random((self.n, len(self.axis)))
        out = []
        for row in u:
            vals = []
            for a, x in zip(self.axis, row, strict=True):
                lo, hi = float(a.low), float(a.high)
                if a.scale == "log":
                    vals.append(_tidy(math.exp(math.log(lo) + x * (math.log(hi) - math.log(lo)))))
                else:
                    vals.append(_tidy(lo + x * (hi - lo)))
            out.append(vals)
        return out


class ReferenceConfig(_Model):
    scenario: str
    set: dict[str, Any] = Field(default_factory=dict)


class AnalysisConfig(_Model):
    """Which methods every point runs: registered names or ``module:Class`` (default: every
    registered detector; the default backlash estimator)."""

    methods: list[str] | None = None
    estimators: list[str] | None = None


class SweepFile(_Model):
    name: str | None = None
    description: str = ""
    scenario: str
    seeds: list[int] | None = None
    set: dict[str, Any] = Field(default_factory=dict)
    grid: list[GridAxis] = Field(default_factory=list)
    random: RandomSampling | None = None
    reference: ReferenceConfig | None = None
    analysis: AnalysisConfig | None = None

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, v: list[int] | None) -> list[int] | None:
        if v is None:
            return v
        if not v:
            raise ValueError("__empty_seeds__")
        if len(set(v)) != len(v) or any(not 0 <= s <= 2**32 - 1 for s in v):
            raise ValueError("__seeds__")
        return v


def _tidy(v: float) -> float:
    """12 significant digits: 0.30000000000000004 -> 0.3 (a column value that reads as written)."""
    return float(f"{float(v):.12g}")


_SPACED = "`values = [numbers...]`, or `start`, `stop` (numbers) and `num` (an integer >= 1)"


def _axis_label(data: dict, loc: tuple) -> str:
    """`axis `x` (grid[2])` for a location inside an axis entry, else ''."""
    if len(loc) >= 2 and loc[0] == "grid" and isinstance(loc[1], int):
        key = value_at(data, loc[:2] + ("key",))
        return f"axis `{key}` (grid[{loc[1]}])" if key is not None else f"axis grid[{loc[1]}]"
    if len(loc) >= 3 and loc[:2] == ("random", "axis") and isinstance(loc[2], int):
        key = value_at(data, loc[:3] + ("key",))
        return (f"axis `{key}` (random.axis[{loc[2]}])" if key is not None
                else f"axis random.axis[{loc[2]}]")
    return ""


def _sweep_messages(data: dict):
    """The messages only a sweep file has (its validators' markers, the axis named), as a hook of
    :func:`twin.sim.config.explain_errors`."""
    def special(kind: str, loc: tuple, key: str, value: Any, msg: str, ctx: dict) -> str | None:
        axis = _axis_label(data, loc)
        if loc and loc[-1] == "key" and kind in ("string_type", "list_type"):
            return (f"key `{key}` = {value!r} is not valid; allowed: a scenario key as a "
                    "string, or a list of keys that take the same value.")
        if "__not_a_number__" in msg:
            return (f"key `{key}` of {axis} = {value!r} is not a number; allowed: an integer "
                    "or a finite float (sweep axes take numbers only).")
        if "__empty__" in msg:
            raw = value_at(data, loc)
            if loc[:1] != ("grid",):
                return (f"key `{key}` = {value!r} is empty; allowed: at least one "
                        "[[random.axis]] with key, low, high.")
            if isinstance(raw, dict) and "values" in raw:
                return (f"{axis} is empty (`values` = {raw['values']!r}); allowed: "
                        "`values = [numbers...]` with at least one number, or `start`, `stop` and "
                        "`num` >= 1.")
            num = raw.get("num") if isinstance(raw, dict) else None
            return f"{axis} is empty (`num` = {num!r}); allowed: `num` >= 1 points from `start` to `stop`."
        if "__both__" in msg:
            return f"{axis} gives both `values` and start/stop/num; allowed: one of {_SPACED}."
        if "__incomplete__" in msg:
            return f"{axis} has no `values` and not all of start/stop/num; allowed: {_SPACED}."
        if "__log__" in msg:
            return (f"{axis} is log-spaced but its bounds ({value!r}) include values <= 0; "
                    "allowed: bounds > 0 with scale = \"log\", or scale = \"linear\".")
        if "__bounds__" in msg:
            return f"{axis} has low >= high ({value!r}); allowed: low < high."
        if "__empty_seeds__" in msg:
            return "key `seeds` = [] is empty; allowed: a non-empty list of integers."
        if "__seeds__" in msg:
            return f"key `seeds` = {value!r}; allowed: distinct integers 0 <= seed <= {2**32 - 1}."
        bounds = [f"{sym} {ctx[n]}" for n, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
                  if n in ctx]
        if bounds and axis:
            return f"key `{key}` of {axis} = {value!r} is out of range; allowed: value {' and '.join(bounds)}."
        return None

    return special


def load_sweep(path: str | Path) -> SweepFile:
    """Read and validate a sweep file; raises :class:`SweepError` naming every problem."""
    path = Path(path)
    data = read_toml(path, "sweep file", SweepError)
    try:
        return SweepFile.model_validate(data)
    except ValidationError as exc:
        raise SweepError(explain_errors(exc, data, str(path), SweepFile, _sweep_messages(data))) from None
