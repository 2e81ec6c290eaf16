"""The work done in a worker process: one unit of a campaign simulated and stored as a part
(:func:`run_unit`), or one unit of several campaigns of the same plan with batched rollouts
(:func:`run_unit_batch`); the compiled simulators a worker keeps between units.
"""

from __future__ import annotations

import numpy as np

from twin.sim.campaign.planning import Unit
from twin.sim.campaign.seeds import KIND_DIAL, KIND_PHASE1, KIND_PHASE2, rng_for
from twin.sim.campaign.state import condition_at, make_world, origin_offset
from twin.sim.parts import PartStore
from twin.sim.scenario import Scenario, from_dict
from twin.sim.simulate import (
    Condition,
    SimulationDiverged,
    Simulator,
    dial_indicator,
    phase1_capture,
    phase1_measure,
    phase1_profile,
    phase2_command,
    phase2_measure_runs,
    phase2_trajectory,
    run_many,
    stroke_travels,
    true_error_motions,
)

_SIMULATORS: dict[tuple[str, float], Simulator] = {}


def _simulator(s: Scenario, key: str, timestep: float) -> Simulator:
    sim = _SIMULATORS.get((key, timestep))
    if sim is None:
        if len(_SIMULATORS) > 16:
            _SIMULATORS.clear()
        sim = Simulator(make_world(s), timestep)
        _SIMULATORS[(key, timestep)] = sim
    return sim


def _store_phase1(store: PartStore, unit: Unit, sig: dict) -> None:
    store.write("phase1", unit.name,
                attrs={"hours": unit.hours, "sample": unit.sample, "fs_hz": sig["fs_hz"]},
                datasets={k: sig[k] for k in ("speed", "torque", "acc1", "acc2")})


def _store_phase2(s: Scenario, sim: Simulator, store: PartStore, unit: Unit, cond: Condition,
                  traj) -> None:
    datasets, dattrs = {}, {}
    rngs = [rng_for(s.seed, KIND_PHASE2, unit.index, r) for r in range(s.runs_per_session)]
    lead_s = s.sensors.position_cmd_lead_ms_per_kh * 1e-6 * unit.hours  # ms/kh · h -> s
    for r, m in enumerate(phase2_measure_runs(sim, traj, rngs, lead_s)):
        for key in ("imu_acc", "imu_gyro", "position_cmd"):
            datasets[f"r{r:04d}/{key}"] = m[key]
            dattrs[f"r{r:04d}/{key}"] = {"fs_hz": m[f"{key}_fs_hz"]}
    x, e = true_error_motions(sim.world, s.phase2, cond)
    datasets["truth/x_m"], datasets["truth/E"] = x, e
    for key, arr in stroke_travels(sim.world, traj).items():
        datasets[f"truth/stroke_{key}"] = arr
    store.write("phase2", unit.name,
                attrs={"hours": unit.hours, "backlash_um": cond.mech.backlash * 1e6,
                       "origin_offset_m": cond.origin_offset, "preload_N": cond.mech.preload,
                       "temperature_rise_K": cond.temperature_rise, "position_cmd_lead_s": lead_s},
                datasets=datasets, dataset_attrs=dattrs)


def run_unit(scenario_json: str, unit: Unit, out_dir: str) -> str:
    """Simulate one unit and store it as a part. Returns the unit's name."""
    import json

    s = from_dict(json.loads(scenario_json))
    try:
        _run_unit(s, scenario_json, unit, PartStore(out_dir))
    except SimulationDiverged as exc:
        raise SimulationDiverged(f"{_named(unit, [s])}: {exc}", [0], exc.t_s) from exc
    return unit.name


def _named(unit: Unit, scenarios: list[Scenario]) -> str:
    """The unit and its campaigns, for an error: 'phase1 unit c000003 of 'x' (seed 7)'."""
    return f"{unit.kind} unit {unit.name} of " + ", ".join(f"{s.name!r} (seed {s.seed})" for s in scenarios)


def _run_unit(s: Scenario, scenario_json: str, unit: Unit, store: PartStore) -> None:
    """:func:`run_unit`'s simulation of ``unit`` of ``s`` into ``store``."""
    if unit.kind == "phase1":
        sim = _simulator(s, scenario_json, s.phase1.timestep_s)
        cond = condition_at(s, unit.hours)
        _store_phase1(store, unit, phase1_capture(sim, s.phase1, cond,
                                                  rng_for(s.seed, KIND_PHASE1, unit.index)))
    elif unit.kind == "phase2":
        sim = _simulator(s, scenario_json, s.phase2.timestep_s)
        cond = condition_at(s, unit.hours, origin_offset(s, unit.index))
        _store_phase2(s, sim, store, unit, cond, phase2_trajectory(sim, s.phase2, cond))
    elif unit.kind == "dial":
        sim = _simulator(s, scenario_json, s.phase2.timestep_s)
        cond = condition_at(s, unit.hours)
        res = dial_indicator(sim, s.dial_indicator, cond, rng_for(s.seed, KIND_DIAL, unit.index))
        store.write("dial", unit.name,
                    attrs={"hours": unit.hours, "backlash_um": res.backlash_um,
                           "elastic_um": res.elastic_um, "true_backlash_um": cond.mech.backlash * 1e6},
                    datasets={"repeats_um": np.asarray(res.repeats_um)})
    else:
        raise ValueError(f"unknown unit kind {unit.kind!r}")


def run_unit_batch(scenario_jsons: list[str], unit: Unit, out_dirs: list[str]) -> str:
    """Simulate one unit of several campaigns of the same plan (scenarios differing in their
    seed, effects, sensors...) with batched rollouts: the captures or sessions whose models share
    a structure and whose commands are equal go into one ``mujoco.rollout`` call
    (:func:`twin.sim.simulate.run_many`); each campaign's part is what :func:`run_unit` stores.
    Dial-indicator units run one by one."""
    import json

    if unit.kind not in ("phase1", "phase2"):
        for k, (j, d) in enumerate(zip(scenario_jsons, out_dirs, strict=True)):
            try:
                run_unit(j, unit, d)
            except SimulationDiverged as exc:  # its item: this scenario's position
                raise SimulationDiverged(exc.args[0], [k], exc.t_s) from exc
        return unit.name
    ss = [from_dict(json.loads(j)) for j in scenario_jsons]
    items = []  # (scenario, simulator, condition, command, rng or None, store)
    for s, j, d in zip(ss, scenario_jsons, out_dirs, strict=True):
        store = PartStore(d)
        if unit.kind == "phase1":
            sim = _simulator(s, j, s.phase1.timestep_s)
            rng = rng_for(s.seed, KIND_PHASE1, unit.index)
            cmd = phase1_profile(s.phase1, sim.fs, rng)
            items.append((s, sim, condition_at(s, unit.hours), cmd, rng, store))
        else:
            sim = _simulator(s, j, s.phase2.timestep_s)
            cond = condition_at(s, unit.hours, origin_offset(s, unit.index))
            items.append((s, sim, cond, phase2_command(sim, s.phase2), None, store))
    groups: list[list[int]] = []
    for i, (_, sim, _, cmd, _, _) in enumerate(items):
        for g in groups:
            _, sim0, _, cmd0, _, _ = items[g[0]]
            if sim.structure() == sim0.structure() and cmd.x.shape == cmd0.x.shape \
                    and items[i][0].phase2.rail_passes == items[g[0]][0].phase2.rail_passes \
                    and np.array_equal(cmd.x, cmd0.x) and np.array_equal(cmd.v, cmd0.v) \
                    and cmd.rest_direction == cmd0.rest_direction:
                g.append(i)
                break
        else:
            groups.append([i])
    for g in groups:
        passes = 1 if unit.kind == "phase1" else items[g[0]][0].phase2.rail_passes
        try:
            trajs = run_many([(items[i][1], items[i][2]) for i in g], items[g[0]][3], passes,
                             contact_guess=unit.kind == "phase2" and passes == 1)
        except SimulationDiverged as exc:
            bad = [g[j] for j in exc.items]
            raise SimulationDiverged(f"{_named(unit, [ss[i] for i in bad])}: {exc}", bad, exc.t_s) from exc
        for i, traj in zip(g, trajs, strict=True):
            s, sim, cond, _, rng, store = items[i]
            if unit.kind == "phase1":
                _store_phase1(store, unit, phase1_measure(sim, s.phase1, traj, rng))
            else:
                _store_phase2(s, sim, store, unit, cond, traj)
    return unit.name
