"""The plan of a sweep: the base scenario with the ``[set]`` overrides, then every point and seed
expanded and validated before anything runs."""

from __future__ import annotations

import copy
import itertools
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twin.harness.sweep.schema import FORMAT, SweepError, SweepFile, _keys, load_sweep
from twin.sim.config import parse_key, set_dotted
from twin.sim.scenario import ScenarioError, from_dict

# ---------------------------------------------------------------------------------------------
# Scenario dicts


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
        set_dotted(data, k, v, source=f"{source}: [{set_what}]", error=SweepError)
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
    methods: list[str] | None = None          # [analysis] methods (None: every registered detector)
    estimators: list[str] | None = None       # [analysis] estimators (None: the default one)

    @property
    def analysis(self) -> dict:
        """What every point runs: {"methods": [...] or None, "estimators": [...] or None}."""
        return {"methods": self.methods, "estimators": self.estimators}

    def manifest(self) -> dict:
        return {"format": FORMAT, "version": 1, "sweep_file": str(self.path),
                "definition": self.sweep.model_dump(mode="json", exclude={"name", "description",
                                                                          "scenario", "reference",
                                                                          "analysis"})
                | {"reference_set": None if self.sweep.reference is None else self.sweep.reference.set}
                | ({"analysis": self.analysis} if self.sweep.analysis is not None else {}),
                "base_scenario": self.base, "reference_scenario": self.reference,
                "columns": self.columns, "n_points": self.n_points, "seeds": self.seeds}


def _analysis(sw, src: str) -> tuple[list[str] | None, list[str] | None]:
    """The ``[analysis]`` lists, each name checked against :mod:`analysis.base.registry`."""
    from analysis.base import registry

    if sw.analysis is None:
        return None, None
    out = []
    for key, kind in (("methods", "detectors"), ("estimators", "backlash_estimators")):
        specs = getattr(sw.analysis, key)
        if specs is not None:
            if not specs:
                raise SweepError(f"{src}: analysis.{key} is empty; expected at least one name "
                                 f"(or leave the key out for the default)")
            for spec in specs:
                try:
                    registry.get(kind, spec)
                except registry.RegistryError as exc:
                    raise SweepError(f"{src}: analysis.{key}: {exc}") from None
        out.append(None if specs is None else list(specs))
    return out[0], out[1]


def plan_sweep(path: str | Path) -> Plan:
    """Load, expand and validate a sweep: every point's scenario goes through
    :func:`twin.sim.scenario.from_dict`. Raises :class:`SweepError`."""
    path = Path(path)
    sw = load_sweep(path)
    src = str(path)
    base = _scenario_dict(path.parent / sw.scenario, sw.set, src, "scenario")
    reference = None
    if sw.reference is not None:
        reference = _scenario_dict(path.parent / sw.reference.scenario, sw.reference.set, src,
                                   "reference.scenario")
    methods, estimators = _analysis(sw, src)
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
            parse_key(k, f"{src}: {where}", SweepError)
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
                base=base, reference=reference, methods=methods, estimators=estimators)
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
                    set_dotted(data, k, v, source=f"{src}: point {point}", error=SweepError)
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
