"""Sweeps: one base scenario, fixed overrides and axes over any scenario keys; every point and
seed simulated, analysed and scored (:func:`twin.harness.run_point`), on all local cores or on a
``dask.distributed`` cluster, with one table of results.

A sweep file (TOML; paths relative to the file)::

    name = "backlash-recovery"            # optional; default: the file's stem
    description = "..."                    # optional
    scenario = "../backlash-steps.toml"    # the base scenario
    seeds = [1, 2]                         # values of the scenario key `seed` (default: its own)

    [set]                                  # fixed overrides, dotted keys as `twin simulate --set`
    "phase2.runs_per_session" = 4          # (or nested: phase2.runs_per_session = 4)
    "degradation.table_backlash_um" = [0.0, 0.0, 10.0]

    [[grid]]                               # grid axes: explicit values ...
    key = "degradation.table_backlash_um[2]"   # `[i]` sets one element of a list
    values = [2.0, 5.0, 10.0]
    [[grid]]                               # ... or start/stop/num, linear or log spaced
    key = ["geometry.straightness_rms_um", "geometry.lateral_straightness_rms_um"]  # tied keys
    start = 0.25
    stop = 1.0
    num = 3
    scale = "log"

    [random]                               # seeded random sampling (combined with the grid)
    n = 8                                  # points drawn
    seed = 7                               # the sweep's own seed
    [[random.axis]]
    key = "sensors.imu_acc_noise_ug_per_rthz"
    low = 2.0
    high = 50.0
    scale = "log"                          # log-uniform; "linear" = uniform

    [reference]                            # Phase I sweeps: the reference data set, simulated
    scenario = "../paper-reference.toml"   # once into OUT/reference before the points
    [reference.set]
    "phase1.captures_per_sample" = 2

The points are the Cartesian product of the grid axes (in file order, the last axis varying
fastest), times the random draws if there are both; every point runs once per seed. Every
point's scenario is validated (:func:`twin.scenario.from_dict`) before anything runs, so a bad
value stops the sweep with the scenario's own message and exit code 2.

Output directory::

    OUT/sweep.json              the expanded sweep (a restart must match it)
    OUT/reference/              the reference data set (if any)
    OUT/points/pNNNN_sSEED/     one campaign directory per point and seed (measurements.h5,
                                truth.h5, phase1/, backlash/, score.json) and result.json,
                                written by the client once the point's task returned
    OUT/sweep-log.jsonl         append-only: per invocation a start line, a line per point
                                computed, an end line with the counts
    OUT/results.parquet, .csv   one row per point and seed (sorted by point, then seed): swept
                                values (columns named by the scenario key), seed, every score
                                (:func:`analysis.scoring.flat`)
    OUT/roc.csv                 detection rate against false-alarm rate over threshold factors,
                                per Phase I method, aggregated over all points and seeds
    OUT/plots/*.png             scores against the swept values; the ROC curves

Executors: by default a ``concurrent.futures.ProcessPoolExecutor`` of ``os.cpu_count()``
processes (started with ``spawn``; no cluster to start); ``workers=N`` a
``dask.distributed.LocalCluster(n_workers=N, threads_per_worker=1, processes=True)``;
``scheduler=ADDRESS`` an existing cluster, whose workers must see OUT at the same path (a shared
file system), since each task writes its campaign directory there. Each task runs with one BLAS
thread (``threadpoolctl``), so results are bit-identical whichever executor runs them. A worker
lost mid-task is replaced by Dask, which reruns the task; the campaign resumes from its finished
parts. An interrupted sweep rerun with the same command computes only the points without a
``result.json``. The reference data set is simulated by the client on its own cores (all of
them, or N with ``workers=N``) before any point is submitted; it is bit-identical on any number
of processes.
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import os
import re
import time
import tomllib
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
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

from twin.scenario import ScenarioError, from_dict, read_toml

__all__ = [
    "LOG_NAME",
    "MANIFEST_NAME",
    "Plan",
    "SweepError",
    "SweepFile",
    "Task",
    "load_sweep",
    "plan_sweep",
    "results_table",
    "run_sweep",
    "run_task",
]

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


class SweepFile(_Model):
    name: str | None = None
    description: str = ""
    scenario: str
    seeds: list[int] | None = None
    set: dict[str, Any] = Field(default_factory=dict)
    grid: list[GridAxis] = Field(default_factory=list)
    random: RandomSampling | None = None
    reference: ReferenceConfig | None = None

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


_ALLOWED = {
    (): SweepFile, ("grid",): GridAxis, ("random",): RandomSampling, ("random", "axis"): RandomAxis,
    ("reference",): ReferenceConfig,
}
_SECTION_NAMES = {(): "at the top level", ("grid",): "in [[grid]]", ("random",): "in [random]",
                  ("random", "axis"): "in [[random.axis]]", ("reference",): "in [reference]"}
_SPACED = "`values = [numbers...]`, or `start`, `stop` (numbers) and `num` (an integer >= 1)"


def _path(loc: tuple) -> str:
    out = ""
    for p in loc:
        if isinstance(p, int):
            out += f"[{p}]"
        else:
            out += ("." if out else "") + str(p)
    return out or "(top level)"


def _raw_at(data: Any, loc: tuple) -> Any:
    for p in loc:
        try:
            data = data[p]
        except (KeyError, IndexError, TypeError):
            return None
    return data


def _axis_label(data: dict, loc: tuple) -> str:
    """`[[grid]] #2 (key `x`)` for a location inside an axis entry, else ''."""
    if len(loc) >= 2 and loc[0] == "grid" and isinstance(loc[1], int):
        key = _raw_at(data, loc[:2] + ("key",))
        return f"axis `{key}` (grid[{loc[1]}])" if key is not None else f"axis grid[{loc[1]}]"
    if len(loc) >= 3 and loc[:2] == ("random", "axis") and isinstance(loc[2], int):
        key = _raw_at(data, loc[:3] + ("key",))
        return (f"axis `{key}` (random.axis[{loc[2]}])" if key is not None
                else f"axis random.axis[{loc[2]}]")
    return ""


def _explain(err: dict, data: dict, source: str) -> str:
    loc = tuple(err.get("loc", ()))
    loc = tuple(p for p in loc if p not in ("str", "list[str]"))  # pydantic's union-member labels
    key, kind, ctx = _path(loc), err.get("type", ""), err.get("ctx") or {}
    value = _raw_at(data, loc) if loc else None
    if value is None:
        value = err.get("input")
    axis = _axis_label(data, loc)
    where = f" of {axis}" if axis else ""
    if kind == "extra_forbidden":
        section = tuple(p for p in loc[:-1] if not isinstance(p, int))
        model = _ALLOWED.get(section)
        allowed = ", ".join(model.model_fields) if model else "(none)"
        return (f"{source}: unknown key `{key}` (value {value!r}); allowed keys "
                f"{_SECTION_NAMES.get(section, 'here')}: {allowed}.")
    msg = str(ctx.get("error", err.get("msg", "")))
    if loc and loc[-1] == "key" and kind in ("string_type", "list_type"):
        return (f"{source}: key `{key}` = {value!r} is not valid; allowed: a scenario key as a "
                "string, or a list of keys that take the same value.")
    if "__not_a_number__" in msg:
        return (f"{source}: key `{key}`{where} = {value!r} is not a number; allowed: an integer "
                "or a finite float (sweep axes take numbers only).")
    if "__empty__" in msg:
        raw = _raw_at(data, loc)
        if loc[:1] != ("grid",):
            return (f"{source}: key `{key}` = {value!r} is empty; allowed: at least one "
                    "[[random.axis]] with key, low, high.")
        if isinstance(raw, dict) and "values" in raw:
            return (f"{source}: {axis} is empty (`values` = {raw['values']!r}); allowed: "
                    "`values = [numbers...]` with at least one number, or `start`, `stop` and "
                    "`num` >= 1.")
        return (f"{source}: {axis} is empty (`num` = {raw.get('num') if isinstance(raw, dict) else None!r}); "
                "allowed: `num` >= 1 points from `start` to `stop`.")
    if "__both__" in msg:
        return (f"{source}: {axis} gives both `values` and start/stop/num; allowed: one of "
                f"{_SPACED}.")
    if "__incomplete__" in msg:
        return f"{source}: {axis} has no `values` and not all of start/stop/num; allowed: {_SPACED}."
    if "__log__" in msg:
        return (f"{source}: {axis} is log-spaced but its bounds ({value!r}) include values <= 0; "
                "allowed: bounds > 0 with scale = \"log\", or scale = \"linear\".")
    if "__bounds__" in msg:
        return f"{source}: {axis} has low >= high ({value!r}); allowed: low < high."
    if "__empty_seeds__" in msg:
        return f"{source}: key `seeds` = [] is empty; allowed: a non-empty list of integers."
    if "__seeds__" in msg:
        return (f"{source}: key `seeds` = {value!r}; allowed: distinct integers 0 <= seed <= "
                f"{2**32 - 1}.")
    if kind == "missing":
        section = tuple(p for p in loc[:-1] if not isinstance(p, int))
        return f"{source}: key `{key}` is required but missing {_SECTION_NAMES.get(section, '')}."
    bounds = [f"{sym} {ctx[n]}" for n, sym in (("gt", ">"), ("ge", ">="), ("lt", "<"), ("le", "<="))
              if n in ctx]
    if bounds:
        return f"{source}: key `{key}`{where} = {value!r} is out of range; allowed: {' and '.join(bounds)}."
    return f"{source}: key `{key}`{where} = {value!r} is not valid: {err.get('msg')}."


def load_sweep(path: str | Path) -> SweepFile:
    """Read and validate a sweep file; raises :class:`SweepError` naming every problem."""
    path = Path(path)
    data = read_toml(path, "sweep file", SweepError)
    try:
        return SweepFile.model_validate(data)
    except ValidationError as exc:
        seen, lines = set(), []
        for e in exc.errors():
            line = _explain(e, data, str(path))
            if line not in seen:
                seen.add(line)
                lines.append(line)
        raise SweepError(" ".join(lines)) from None


# ---------------------------------------------------------------------------------------------
# Keys: dotted names, with `[i]` for one element of a list

_PART = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$")


def _parse_key(key: str, source: str) -> list[tuple[str, int | None]]:
    parts = []
    for p in key.split("."):
        m = _PART.match(p)
        if not m:
            raise SweepError(f"{source}: key `{key}` is not a scenario key; allowed: dotted names "
                             "as in `twin simulate --set`, e.g. `sensors.imu_acc_noise_ug_per_rthz`, "
                             "with `[i]` for one element of a list, e.g. "
                             "`degradation.table_backlash_um[2]`.")
        parts.append((m.group(1), None if m.group(2) is None else int(m.group(2))))
    return parts


def set_key(data: dict, key: str, value: Any, source: str) -> None:
    """Set ``key`` (dotted, ``name[i]`` for a list element) in the scenario dict ``data``.

    Missing sections are created (the scenario's validation then names an unknown key)."""
    parts = _parse_key(key, source)
    node: Any = data
    for i, (name, idx) in enumerate(parts):
        last = i == len(parts) - 1
        if not isinstance(node, dict):
            done = ".".join(k for k, _ in parts[:i])
            raise SweepError(f"{source}: key `{key}`: `{done}` is a value, not a section.")
        if idx is None:
            if last:
                node[name] = value
            else:
                node = node.setdefault(name, {})
            continue
        lst = node.get(name)
        if not isinstance(lst, list):
            raise SweepError(f"{source}: key `{key}`: `{name}` is "
                             f"{'missing' if lst is None else repr(lst)}, not a list; allowed: "
                             "`[i]` only on list-valued keys.")
        if idx >= len(lst):
            raise SweepError(f"{source}: key `{key}`: index {idx} is beyond the list `{name}` = "
                             f"{lst!r} (length {len(lst)}); allowed: 0 <= i < {len(lst)}.")
        if last:
            lst[idx] = value
        else:
            node = lst[idx]


def _flatten(d: dict, prefix: str = "") -> list[tuple[str, Any]]:
    """Nested ``[set]`` tables to dotted keys (``{"a": {"b": 1}}`` -> ``[("a.b", 1)]``)."""
    out = []
    for k, v in d.items():
        if isinstance(v, dict):
            out += _flatten(v, f"{prefix}{k}.")
        else:
            out.append((f"{prefix}{k}", v))
    return out


def _scenario_dict(path: Path, sets: dict, source: str, what: str) -> dict:
    """The full, validated scenario dict of ``path`` with the ``[set]`` overrides applied."""
    try:
        data = tomllib.loads(path.read_text())
    except OSError as exc:
        raise SweepError(f"{source}: key `{what}` = {str(path)!r}: cannot read the scenario "
                         f"({exc.strerror}); allowed: a scenario TOML file, relative to the sweep "
                         "file.") from None
    except tomllib.TOMLDecodeError as exc:
        raise SweepError(f"{source}: key `{what}` = {str(path)!r} is not valid TOML: {exc}.") from None
    set_what = "set" if what == "scenario" else "reference.set"
    for k, v in _flatten(sets):
        set_key(data, k, v, f"{source}: [{set_what}]")
    try:
        s = from_dict(data, source=f"{source}: [{set_what}] on {os.path.normpath(path)}" if sets
                      else os.path.normpath(path))
    except ScenarioError as exc:
        raise SweepError(str(exc)) from None
    return s.model_dump(mode="json")


# ---------------------------------------------------------------------------------------------
# The plan


@dataclass(frozen=True)
class Task:
    """One point and seed. ``values``: swept column -> value; ``scenario``: the full scenario dict."""

    point: int
    seed: int
    values: dict[str, Any]
    scenario: dict

    @property
    def id(self) -> str:
        return f"p{self.point:04d}_s{self.seed}"


@dataclass
class Plan:
    path: Path
    sweep: SweepFile
    name: str
    columns: list[str]                       # swept columns, in axis order
    primary: list[str]                       # the first key of each axis (tied keys share values)
    tied: dict[str, list[str]]               # primary key -> every key of its axis
    log_columns: set[str]                    # columns spaced or drawn logarithmically
    n_points: int
    seeds: list[int]
    base: dict
    reference: dict | None
    tasks: list[Task] = field(default_factory=list)

    def manifest(self) -> dict:
        return {"format": FORMAT, "version": 1, "sweep_file": str(self.path),
                "definition": self.sweep.model_dump(mode="json", exclude={"name", "description",
                                                                          "scenario", "reference"})
                | {"reference_set": None if self.sweep.reference is None else self.sweep.reference.set},
                "base_scenario": self.base, "reference_scenario": self.reference,
                "columns": self.columns, "n_points": self.n_points, "seeds": self.seeds}


def plan_sweep(path: str | Path) -> Plan:
    """Load, expand and validate a sweep: every point's scenario goes through
    :func:`twin.scenario.from_dict`. Raises :class:`SweepError`."""
    path = Path(path)
    sw = load_sweep(path)
    src = str(path)
    base = _scenario_dict(path.parent / sw.scenario, sw.set, src, "scenario")
    reference = None
    if sw.reference is not None:
        reference = _scenario_dict(path.parent / sw.reference.scenario, sw.reference.set, src,
                                   "reference.scenario")
    columns: list[str] = []
    primary: list[str] = []
    tied: dict[str, list[str]] = {}
    log_columns: set[str] = set()
    grid_values = []
    entries = [(f"grid[{i}]", a, a.points()) for i, a in enumerate(sw.grid)]
    for i, a in enumerate(sw.random.axis if sw.random else []):
        entries.append((f"random.axis[{i}]", a, None))
    for where, a, values in entries:
        primary.append(_keys(a.key)[0])
        tied[primary[-1]] = _keys(a.key)
        for k in _keys(a.key):
            _parse_key(k, f"{src}: {where}")
            if k == "seed":
                raise SweepError(f"{src}: {where}: key `seed` cannot be an axis; allowed: the "
                                 "top-level `seeds = [...]` list (every point runs once per seed).")
            if k in columns:
                raise SweepError(f"{src}: {where}: key `{k}` is swept by two axes; allowed: each "
                                 "scenario key on one axis (tie keys with `key = [a, b]`).")
            columns.append(k)
            if a.scale == "log":
                log_columns.add(k)
        if values is not None:
            grid_values.append(values)
    grid = list(itertools.product(*grid_values)) if grid_values else [()]
    rand = sw.random.points() if sw.random else [[]]
    all_keys = [_keys(a.key) for _, a, _ in entries]
    seeds = sw.seeds if sw.seeds is not None else [int(base["seed"])]
    plan = Plan(path=path, sweep=sw, name=sw.name or path.stem, columns=columns, primary=primary,
                tied=tied,
                log_columns=log_columns, n_points=len(grid) * len(rand), seeds=list(seeds),
                base=base, reference=reference)
    point = 0
    for g in grid:
        for r in rand:
            vals = list(g) + list(r)
            values: dict[str, Any] = {}
            data = copy.deepcopy(base)
            desc = []
            for keys, v in zip(all_keys, vals, strict=True):
                for k in keys:
                    values[k] = v
                    set_key(data, k, v, f"{src}: point {point}")
                desc.append(f"{keys[0] if len(keys) == 1 else '+'.join(keys)} = {v!r}")
            for seed in plan.seeds:
                d = copy.deepcopy(data)
                d["seed"] = seed
                label = (f"{src}: point {point} ({', '.join(desc + [f'seed = {seed}'])}) on "
                         f"{os.path.normpath(path.parent / sw.scenario)}")
                try:
                    s = from_dict(d, source=label)
                except ScenarioError as exc:
                    raise SweepError(str(exc)) from None
                plan.tasks.append(Task(point, seed, dict(values), s.model_dump(mode="json")))
            point += 1
    return plan


# ---------------------------------------------------------------------------------------------
# Work done on a worker


def run_task(scenario: dict, point_dir: str, reference_dir: str | None) -> dict:
    """Simulate, analyse and score one point in this process with one BLAS thread.

    Returns ``{"score": score.json object or None, "simulated_units", "reused_units",
    "skipped", "seconds", "host", "pid"}``."""
    import socket

    from threadpoolctl import threadpool_limits

    from twin.harness import run_point

    t0 = time.perf_counter()
    s = from_dict(scenario)
    with threadpool_limits(1):
        r = run_point(s, point_dir, reference_dir)
    r["seconds"] = time.perf_counter() - t0
    r["host"], r["pid"] = socket.gethostname(), os.getpid()
    return r


# ---------------------------------------------------------------------------------------------
# Executors


class _Executor:
    """submit(fn, *args, key) -> future; completed(futures) yields them as they finish."""

    description = ""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:  # pragma: no cover - overridden
        pass


class _LocalPool(_Executor):
    def __init__(self, workers: int):
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        self.workers = workers
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"))
        self.description = f"{workers} local processes"

    def submit(self, fn, *args, key: str):
        return self.pool.submit(fn, *args)

    def completed(self, futures) -> Iterator:
        from concurrent.futures import as_completed

        yield from as_completed(futures)

    def close(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


class _Dask(_Executor):
    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        import logging

        from distributed import Client, LocalCluster

        self.cluster = None
        if scheduler is None:
            self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                        dashboard_address=None, silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
            self.description = f"dask LocalCluster of {workers} worker processes"
        else:
            try:
                self.client = Client(scheduler, timeout="30s")
            except (OSError, TimeoutError) as exc:
                raise SweepError(f"--scheduler {scheduler}: cannot connect to a dask scheduler there "
                                 f"({exc}); expected the address of a running scheduler, e.g. "
                                 "tcp://10.0.0.5:8786") from None
            n = len(self.client.scheduler_info().get("workers", {}))
            self.description = f"dask cluster at {scheduler} ({n} workers now)"
        self.token = uuid.uuid4().hex[:8]

    def submit(self, fn, *args, key: str):
        return self.client.submit(fn, *args, key=f"sweep-{key}-{self.token}", pure=False)

    def completed(self, futures) -> Iterator:
        from distributed import as_completed

        yield from as_completed(futures)

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_executor(workers: int | None = None, scheduler: str | None = None) -> _Executor:
    if scheduler is not None:
        return _Dask(scheduler=scheduler)
    if workers is not None:
        return _Dask(workers=workers)
    return _LocalPool(os.cpu_count() or 1)


# ---------------------------------------------------------------------------------------------
# Output directory: manifest, records, log


def _diff(a: Any, b: Any, prefix: str = "") -> list[tuple[str, Any, Any]]:
    """(dotted key, a, b) where ``a`` and ``b`` differ; lists of equal length item by item."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b), key=str):
            out += _diff(a.get(k), b.get(k), f"{prefix}.{k}" if prefix else str(k))
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b) and a != b and \
            any(isinstance(x, (dict, list)) for x in a):
        out = []
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            out += _diff(x, y, f"{prefix}[{i}]")
        return out
    return [] if a == b else [(prefix, a, b)]


def _claim(out: Path, plan: Plan) -> None:
    """Write OUT/sweep.json, or check that OUT holds this very sweep (else SweepError)."""
    path = out / MANIFEST_NAME
    mine = json.loads(json.dumps(plan.manifest()))
    if path.exists():
        theirs = json.loads(path.read_text())
        diffs = [d for d in _diff(theirs, mine) if d[0] != "sweep_file"]
        if diffs:
            shown = "; ".join(f"`{k}`: {a!r} there, {b!r} in {plan.path}" for k, a, b in diffs[:6])
            more = f" (and {len(diffs) - 6} more)" if len(diffs) > 6 else ""
            raise SweepError(
                f"{out} holds the results of another sweep ({theirs.get('sweep_file')}); "
                f"differences: {shown}{more}. Its finished points cannot be reused: choose a new "
                "output directory (-o), or delete this one.")
        return
    out.mkdir(parents=True, exist_ok=True)
    _write_json(path, mine)


def _write_json(path: Path, doc: Any) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(doc, indent=1, allow_nan=False))
    os.replace(tmp, path)


def _append_log(out: Path, rec: dict) -> None:
    """Append one JSON line (after a newline if a killed writer left a partial line)."""
    path = out / LOG_NAME
    with open(path, "a+b") as f:
        f.seek(0, os.SEEK_END)
        if f.tell():
            f.seek(-1, os.SEEK_END)
            if f.read(1) != b"\n":
                f.write(b"\n")
        f.write((json.dumps(rec, allow_nan=False) + "\n").encode())
        f.flush()
        os.fsync(f.fileno())


def read_log(out: str | Path) -> list[dict]:
    """The log's records (a partial line left by a killed writer is skipped)."""
    path = Path(out) / LOG_NAME
    recs = []
    if path.exists():
        for line in path.read_text().splitlines():
            try:
                recs.append(json.loads(line))
            except json.JSONDecodeError:
                continue
    return recs


def point_dir(out: Path, task: Task) -> Path:
    return out / "points" / task.id


def read_result(out: Path, task: Task) -> dict | None:
    path = point_dir(out, task) / RESULT_NAME
    if not path.is_file():
        return None
    try:
        rec = json.loads(path.read_text())
    except json.JSONDecodeError:
        return None
    return rec if rec.get("error") is None else None


# ---------------------------------------------------------------------------------------------
# Running


@dataclass
class Callbacks:
    """Progress hooks: reference(done, total, unit); point(done, total, task, record)."""

    executor: Callable[[str], None] = lambda description: None
    reference: Callable[[int, int, str], None] = lambda done, total, name: None
    start: Callable[[int, int], None] = lambda todo, total: None
    point: Callable[[int, int, Task, dict], None] = lambda done, total, task, rec: None


def run_sweep(plan: Plan, out: str | Path, *, workers: int | None = None,
              scheduler: str | None = None, callbacks: Callbacks | None = None) -> dict:
    """Run every task of ``plan`` not yet recorded in ``out``; write the table and the plots.

    Returns the end record of the log: ``{"computed", "reused", "failed", "simulated_units",
    "reused_units", "reference_simulated_units", "seconds", ...}``. Raises :class:`SweepError`
    if ``out`` holds another sweep."""
    out = Path(out).resolve()  # the workers (possibly elsewhere, --scheduler) get absolute paths
    cb = callbacks or Callbacks()
    _claim(out, plan)
    t0 = time.perf_counter()
    invocation = uuid.uuid4().hex[:12]
    done_tasks = [t for t in plan.tasks if read_result(out, t) is not None]
    todo = [t for t in plan.tasks if read_result(out, t) is None]
    executor_name = ("dask:" + scheduler if scheduler else f"dask-local:{workers}" if workers
                     else f"processes:{os.cpu_count() or 1}")
    _append_log(out, {"event": "start", "invocation": invocation, "time": time.time(),
                      "executor": executor_name, "tasks": len(plan.tasks), "todo": len(todo),
                      "reused": len(done_tasks)})
    ref_dir = None
    ref_units = 0
    if plan.reference is not None:
        ref_dir = out / "reference"
        from twin.campaign import CampaignDirectoryError, simulate_campaign

        try:
            summary = simulate_campaign(from_dict(plan.reference), ref_dir,
                                        workers=workers or os.cpu_count() or 1,
                                        on_progress=cb.reference)
        except CampaignDirectoryError as exc:
            raise SweepError(str(exc)) from None
        ref_units = summary["simulated"]
    cb.start(len(todo), len(plan.tasks))
    computed = failed = sim_units = reused_units = 0
    n_done = len(done_tasks)
    if todo:
        with make_executor(workers, scheduler) as ex:
            cb.executor(ex.description)
            futures = {}
            for t in todo:
                futures[ex.submit(run_task, t.scenario, str(point_dir(out, t)),
                                  None if ref_dir is None else str(ref_dir), key=t.id)] = t
            for fut in ex.completed(list(futures)):
                t = futures[fut]
                try:
                    r = fut.result()
                    rec = {"point": t.point, "seed": t.seed, "values": t.values,
                           "score": r["score"], "skipped": r["skipped"], "error": None}
                    computed += 1
                    sim_units += r["simulated_units"]
                    reused_units += r["reused_units"]
                    n_done += 1
                except Exception as exc:  # a point that fails is recorded, retried on a rerun
                    r = {"simulated_units": 0, "reused_units": 0, "seconds": None, "host": None,
                         "pid": None}
                    rec = {"point": t.point, "seed": t.seed, "values": t.values, "score": None,
                           "skipped": {}, "error": f"{type(exc).__name__}: {exc}"}
                    failed += 1
                point_dir(out, t).mkdir(parents=True, exist_ok=True)
                _write_json(point_dir(out, t) / RESULT_NAME, rec)
                _append_log(out, {"event": "point", "invocation": invocation, "id": t.id,
                                  "error": rec["error"], "simulated_units": r["simulated_units"],
                                  "reused_units": r["reused_units"], "seconds": r["seconds"],
                                  "host": r["host"], "pid": r["pid"]})
                cb.point(n_done, len(plan.tasks), t, rec)
    table = results_table(plan, out)
    write_table(table, out)
    from twin.sweep_plots import write_plots

    figures = write_plots(plan, out, table)
    end = {"event": "end", "invocation": invocation, "time": time.time(),
           "executor": executor_name, "tasks": len(plan.tasks), "computed": computed,
           "reused": len(done_tasks), "failed": failed, "simulated_units": sim_units,
           "reused_units": reused_units, "reference_simulated_units": ref_units,
           "seconds": time.perf_counter() - t0, "figures": [str(f) for f in figures]}
    _append_log(out, end)
    return end


# ---------------------------------------------------------------------------------------------
# The table


def records(plan: Plan, out: str | Path) -> list[tuple[Task, dict]]:
    """(task, result.json record) of every recorded task, in table order."""
    out = Path(out)
    recs = []
    for t in sorted(plan.tasks, key=lambda t: (t.point, t.seed)):
        path = point_dir(out, t) / RESULT_NAME
        if path.is_file():
            recs.append((t, json.loads(path.read_text())))
    return recs


def results_table(plan: Plan, out: str | Path):
    """One row per recorded point and seed (sorted by point, then seed): ``point``, ``seed``,
    the swept values (one column per scenario key), ``directory`` (relative to OUT) and every
    scalar score of :func:`analysis.scoring.flat`; an ``error`` column only if a point failed."""
    import pandas as pd

    from analysis.scoring import flat

    rows, score_cols, any_error = [], [], False
    for t, rec in records(plan, out):
        row: dict[str, Any] = {"point": t.point, "seed": t.seed}
        row.update({c: t.values[c] for c in plan.columns})
        row["directory"] = f"points/{t.id}"
        scores = flat(rec["score"]) if rec.get("score") else {}
        for k in scores:
            if k not in score_cols:
                score_cols.append(k)
        row.update(scores)
        row["error"] = rec.get("error")
        any_error |= rec.get("error") is not None
        rows.append(row)
    cols = ["point", "seed", *plan.columns, "directory", *score_cols] + (["error"] if any_error else [])
    df = pd.DataFrame(rows, columns=cols)
    for c in score_cols:  # None -> missing: counts as nullable integers, the rest as floats
        ints = df[c].map(lambda v: v is None or (isinstance(v, int) and not isinstance(v, bool)))
        df[c] = df[c].astype("Int64") if ints.all() else pd.to_numeric(df[c]).astype(float)
    for c in plan.columns:
        if df[c].map(lambda v: isinstance(v, float)).any():
            df[c] = df[c].astype(float)
    return df


def write_table(df, out: str | Path) -> tuple[Path, Path]:
    out = Path(out)
    pq, csv = out / "results.parquet", out / "results.csv"
    df.to_parquet(out / "results.parquet.tmp", index=False)
    os.replace(out / "results.parquet.tmp", pq)
    df.to_csv(out / "results.csv.tmp", index=False)
    os.replace(out / "results.csv.tmp", csv)
    return pq, csv


# Scores shown in the summary table and plotted, in this order, if present.
KEY_SCORES = ("phase2.rms_error_um", "phase2.bias_um", "phase2.prognosis.error_hours")
PHASE1_KEY = ("delay_hours", "false_alarm_rate")


def phase1_methods(df) -> list[str]:
    seen = []
    for c in df.columns:
        if c.startswith("phase1.") and c.endswith(".delay_hours"):
            seen.append(c.split(".")[1])
    return seen


def summary(plan: Plan, df, methods: tuple[str, ...] = ("pca_t2",)) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the summary table: per point, the swept values, the number of seeds,
    and mean ± std over seeds of the key scores (Phase I: delay, false-alarm rate and the
    fraction of seeds detected after the onset, for ``methods``)."""
    score_cols = [c for c in KEY_SCORES if c in df.columns]
    p1 = [m for m in methods if m in phase1_methods(df)]
    header = [c.split(".")[-1] if len(c) > 24 else c for c in plan.primary] + ["seeds"]
    header += [c.removeprefix("phase2.") for c in score_cols]
    for m in p1:
        header += [f"{m} delay h", f"{m} FA rate", f"{m} detected"]
    rows = []

    def ms(x) -> str:
        x = np.asarray(x, float)
        x = x[np.isfinite(x)]
        if not len(x):
            return "-"
        return f"{x.mean():.3g}" + (f"±{x.std(ddof=1):.2g}" if len(x) > 1 else "")

    for _point, g in df.groupby("point", sort=True):
        row = [f"{g[c].iloc[0]:.4g}" for c in plan.primary] + [str(len(g))]
        row += [ms(g[c]) for c in score_cols]
        for m in p1:
            delay = g[f"phase1.{m}.delay_hours"]
            row += [ms(delay), ms(g[f"phase1.{m}.false_alarm_rate"]),
                    f"{int((delay > 0).sum())}/{len(g)}"]
        rows.append(row)
    return header, rows


def method_summary(df) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the Phase I methods over all rows (at each method's own limit):
    detected after the onset, mean false-alarm rate, median delay of the detections (h)."""
    header = ["method", "detected after onset", "mean false-alarm rate", "median delay h"]
    rows = []
    for m in phase1_methods(df):
        delay = df[f"phase1.{m}.delay_hours"]
        det = delay > 0
        fa = df[f"phase1.{m}.false_alarm_rate"].astype(float)
        rows.append([m, f"{int(det.sum())}/{len(df)}",
                     "-" if fa.isna().all() else f"{fa.mean():.3f}",
                     "-" if not det.any() else f"{delay[det].median():g}"])
    return header, rows
