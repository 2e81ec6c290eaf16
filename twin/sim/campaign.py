"""A run-to-failure campaign: the plan of captures and sessions over operating hours, the state of
the axis at each of them, and the resumable, parallel runner that writes the dataset.

Determinism: every random draw comes from ``numpy.random.SeedSequence([seed, kind, index...])``,
so a unit of work gives the same arrays whichever process, executor or order runs it.

Resuming: each finished unit is stored as its own part file (atomic rename, see
:class:`twin.sim.parts.PartStore`); a rerun skips the parts that exist and assembles
``measurements.h5`` and ``truth.h5`` from all parts at the end.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from analysis import dataset as ds
from analysis.base.files import write_json
from twin.sim import degradation as deg
from twin.sim import geometry as geo
from twin.sim.model import MechanicalState, stiffness_of
from twin.sim.parts import PartStore
from twin.sim.scenario import Scenario, from_dict, nominal_axis_description, to_axis
from twin.sim.sensors import instruments as ins
from twin.sim.sensors.instruments import MICRO_G
from twin.sim.simulate import (
    Condition,
    Simulator,
    World,
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

KIND_WORLD, KIND_PHASE1, KIND_PHASE2, KIND_DIAL, KIND_ORIGIN = range(5)
RAIL_MARGIN = 0.15  # m of rail modelled beyond each end of the travel


def rng_for(seed: int, kind: int, *index: int) -> np.random.Generator:
    """The generator of one unit of work: a pure function of the seed, the kind and the index."""
    return np.random.default_rng(np.random.SeedSequence([seed, kind, *index]))


# ---------------------------------------------------------------------------------------------
# The world and the state of the axis over hours


def make_world(s: Scenario) -> World:
    """Draw the campaign's fixed imperfections (rails, screw phases) from the scenario seed."""
    axis = to_axis(s)
    g, se = s.geometry, s.sensors
    # Separate streams for the rails, the screw and the motor, so that no other scenario key
    # changes what is drawn for one of them.
    rails_rng, screw_rng, motor_rng = (rng_for(s.seed, KIND_WORLD, i) for i in range(3))
    # The effects' draws come from streams of their own (3: cogging phase), never from the above.
    cogging_rng = rng_for(s.seed, KIND_WORLD, 3)
    fx = s.effects
    rail_spec = geo.RailSpec(
        straightness_rms_vertical_m=g.straightness_rms_um * 1e-6,
        straightness_rms_lateral_m=g.lateral_straightness_rms_um * 1e-6,
        spectrum_exponent=g.spectrum_exponent, bolt_pitch_m=g.bolt_pitch_mm * 1e-3,
        bolt_amplitude_vertical_m=g.bolt_amplitude_um * 1e-6,
        bolt_amplitude_lateral_m=0.6 * g.bolt_amplitude_um * 1e-6)
    # A fixed extent beyond the travel (more than the largest allowed origin offset plus half
    # the truck spacing), so that nuisance settings do not change the rails.
    margin = RAIL_MARGIN
    rails = geo.make_rail_profiles(rail_spec, length_m=axis.travel + 2 * margin, rng=rails_rng,
                                   u_start_m=-margin)
    carriage = geo.CarriageGeometry.from_carriage(axis.carriage)
    screw = geo.draw_screw_phases(geo.ScrewSpec(
        lead_m=axis.screw.lead, cumulative_lead_error_m_per_m=g.cumulative_lead_error_um_per_m * 1e-6,
        cyclic_lead_error_m=tuple(a * 1e-6 for a in g.cyclic_lead_error_um),
        cyclic_lead_phase_rad=tuple(0.0 for _ in g.cyclic_lead_error_um),
        runout_m=g.runout_um * 1e-6, pitch_diameter_m=axis.screw.pitch_diameter,
        ball_diameter_m=g.ball_diameter_mm * 1e-3, contact_angle_rad=math.radians(g.contact_angle_deg),
        ball_pass_amplitude_m=g.ball_pass_amplitude_um * 1e-6), screw_rng)
    mis = np.zeros((3, 3))
    m = [v * 1e-6 for v in se.imu_misalignment_urad]
    # Small rotation (roll, pitch, yaw) of the IMU case: skew-symmetric cross-axis matrix.
    mis[0, 1], mis[1, 0] = -m[2], m[2]
    mis[0, 2], mis[2, 0] = m[1], -m[1]
    mis[1, 2], mis[2, 1] = -m[0], m[0]
    imu_acc = ins.AnalogAccelerometerSpec(
        fs_hz=se.imu_acc_fs_hz, bandwidth_hz=se.imu_acc_bandwidth_hz,
        noise_density=se.imu_acc_noise_ug_per_rthz * MICRO_G,
        error=ins.ErrorModel(bias=tuple(b * MICRO_G for b in se.imu_acc_bias_ug),
                             scale_error=tuple(se.imu_acc_scale_error),
                             misalignment=tuple(map(tuple, mis))))
    imu_gyro = ins.DigitalGyroSpec(
        fs_hz=se.imu_gyro_fs_hz, bandwidth_hz=se.imu_gyro_bandwidth_hz,
        noise_density=se.imu_gyro_noise_urad_s_per_rthz * 1e-6,
        error=ins.ErrorModel(bias=tuple(b * 1e-6 for b in se.imu_gyro_bias_urad_s),
                             misalignment=tuple(map(tuple, mis))))
    fs = s.phase1.fs_hz
    nut_acc = ins.NutAccelerometerSpec(fs_hz=fs, bandwidth_hz=0.4 * fs,
                                       noise_density=se.nut_acc_noise_ug_per_rthz * MICRO_G)
    return World(axis=axis, rails=rails, carriage=carriage, screw=screw,
                 ripple_torque=s.axis.torque_ripple_Nm, ripple_per_rev=s.axis.torque_ripple_per_rev,
                 ripple_phase=float(motor_rng.uniform(0, 2 * math.pi)),
                 thermal_expansion=s.degradation.thermal_expansion_per_K,
                 drag_temperature_coefficient=s.degradation.drag_temperature_coefficient_per_K,
                 imu_acc=imu_acc, imu_gyro=imu_gyro, nut_acc=nut_acc,
                 controller_fs=fs, encoder_counts_per_rev=se.encoder_counts_per_rev,
                 torque_noise=se.torque_noise_Nm, position_cmd_fs=se.position_cmd_fs_hz,
                 cogging_torque=fx.cogging_Nm, cogging_per_rev=fx.cogging_per_rev,
                 cogging_phase=float(cogging_rng.uniform(0, 2 * math.pi)),
                 recirculation_impulse=fx.recirculation_impulse_N,
                 recirculation_width=fx.recirculation_width,
                 stribeck_excess=fx.stribeck_excess_N,
                 stribeck_velocity=fx.stribeck_velocity_mm_s * 1e-3,
                 base_modal_mass=fx.base_modal_mass_kg, base_frequency=fx.base_frequency_hz,
                 base_damping_ratio=fx.base_damping_ratio)


def degradation_law(s: Scenario):
    """The scenario's degradation law (:mod:`twin.sim.laws`: ``degradation.law`` looked up in the
    registry, made with its parameters from ``[degradation]``)."""
    return s.degradation.make_law()


def degradation_at(s: Scenario, hours) -> tuple[np.ndarray, np.ndarray]:
    """(preload fraction (n,), backlash µm (n,)) at operating ``hours`` (n,)."""
    h = np.atleast_1d(np.asarray(hours, dtype=float))
    law = degradation_law(s)
    return law.preload_fraction(h), law.backlash(h) * 1e6


def onset_hours(s: Scenario) -> float:
    """The injected onset of degradation, h (NaN if the scenario never degrades): the law's
    ``injected_onset_hours()`` (for the table law, the last healthy point before the first
    degraded one)."""
    return float(degradation_law(s).injected_onset_hours())


def resume_hours(s: Scenario) -> list[float]:
    return [p.hours for p in s.campaign.pauses]


def temperature_at(s: Scenario, hours) -> np.ndarray:
    """Screw temperature rise above ambient at operating ``hours``, K: it warms towards the
    steady rise after every (re)start, from what remains after the stop cooled it for its
    ``days`` with the same time constant (a first-order thermal model)."""
    d = s.degradation
    h = np.atleast_1d(np.asarray(hours, float))
    since = deg.hours_since_resume(h, resume_hours(s))
    rise = deg.temperature_rise_K(since, d.thermal_rise_K, d.thermal_time_constant_hours)
    # Heat left at the restart: the temperature when the axis stopped, cooled over the pause.
    pauses = sorted(s.campaign.pauses, key=lambda p: p.hours)
    left = np.zeros_like(h)
    for i, p in enumerate(pauses):
        run_before = p.hours - (pauses[i - 1].hours if i else 0.0)
        at_stop = float(deg.temperature_rise_K(run_before, d.thermal_rise_K,
                                               d.thermal_time_constant_hours))
        since_this = h - p.hours
        active = (since_this >= 0) & (since_this == since)
        left[active] = at_stop * math.exp(-24.0 * p.days / d.thermal_time_constant_hours)
    return rise + left * np.exp(-since / d.thermal_time_constant_hours)


def condition_at(s: Scenario, hours: float, origin_offset: float = 0.0) -> Condition:
    law = degradation_law(s)
    h = np.atleast_1d(np.asarray(hours, dtype=float))
    pf, backlash = law.preload_fraction(h), law.backlash(h)  # (1,) fraction, (1,) m
    coupling = s.degradation.truck_wear_coupling
    mech = MechanicalState(preload=float(pf[0]) * s.axis.preload_N, backlash=float(backlash[0]),
                           truck_preload_fraction=1.0 - coupling * (1.0 - float(pf[0])))
    return Condition(mech=mech, temperature_rise=float(temperature_at(s, hours)[0]),
                     origin_offset=origin_offset)


def origin_offset(s: Scenario, session: int) -> float:
    """Origin set against the wooden block before a Phase II session: uniform within ±max, m."""
    lim = s.phase2.origin_offset_max_mm * 1e-3
    return float(rng_for(s.seed, KIND_ORIGIN, session).uniform(-lim, lim)) if lim > 0 else 0.0


# ---------------------------------------------------------------------------------------------
# The plan


@dataclass(frozen=True)
class Unit:
    """One unit of work. kind: "phase1" | "phase2" | "dial"; name: part name; index: capture or
    session index; sample: Phase I sample index (−1 otherwise); hours: operating hours."""

    kind: str
    name: str
    index: int
    hours: float
    sample: int = -1


def session_hours(s: Scenario) -> list[float]:
    p2 = s.phase2
    if p2.session_hours:
        return sorted(float(h) for h in p2.session_hours)
    out, h = [], p2.session_interval_hours / 2.0
    while h <= s.campaign.total_hours:
        out.append(h)
        h += p2.session_interval_hours
    return out


def sample_hours(s: Scenario) -> list[float]:
    """Operating hours of each Phase I sample's first capture: ``phase1.sample_hours`` when
    given (sorted), else every ``sample_interval_hours`` from ``warmup_hours`` while the
    sample's last capture is within ``total_hours``."""
    p1 = s.phase1
    if p1.sample_hours:
        return sorted(float(h) for h in p1.sample_hours)
    out, h = [], s.campaign.warmup_hours
    step = p1.capture_interval_minutes / 60.0
    while h + (s.captures_per_sample - 1) * step <= s.campaign.total_hours:
        out.append(h)
        h += p1.sample_interval_hours
    return out


def plan(s: Scenario) -> list[Unit]:
    """Every unit of the campaign, in time order within each kind."""
    units: list[Unit] = []
    if s.campaign.phase1:
        step = s.phase1.capture_interval_minutes / 60.0
        idx = 0
        for sample, h in enumerate(sample_hours(s)):
            for j in range(s.captures_per_sample):
                units.append(Unit("phase1", f"c{idx:06d}", idx, h + j * step, sample))
                idx += 1
    if s.campaign.phase2:
        for i, h in enumerate(session_hours(s)):
            units.append(Unit("phase2", f"s{i:04d}", i, h))
            if i % s.dial_indicator.every_n_sessions == 0:
                units.append(Unit("dial", f"d{i:04d}", i, h))
    return units


# ---------------------------------------------------------------------------------------------
# Work done in a worker process

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
    store = PartStore(out_dir)
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
    return unit.name


def run_unit_batch(scenario_jsons: list[str], unit: Unit, out_dirs: list[str]) -> str:
    """Simulate one unit of several campaigns of the same plan (scenarios differing in their
    seed, effects, sensors...) with batched rollouts: the captures or sessions whose models share
    a structure and whose commands are equal go into one ``mujoco.rollout`` call
    (:func:`twin.sim.simulate.run_many`); each campaign's part is what :func:`run_unit` stores.
    Dial-indicator units run one by one."""
    import json

    if unit.kind not in ("phase1", "phase2"):
        for j, d in zip(scenario_jsons, out_dirs, strict=True):
            run_unit(j, unit, d)
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
        trajs = run_many([(items[i][1], items[i][2]) for i in g], items[g[0]][3], passes,
                         contact_guess=unit.kind == "phase2" and passes == 1)
        for i, traj in zip(g, trajs, strict=True):
            s, sim, cond, _, rng, store = items[i]
            if unit.kind == "phase1":
                _store_phase1(store, unit, phase1_measure(sim, s.phase1, traj, rng))
            else:
                _store_phase2(s, sim, store, unit, cond, traj)
    return unit.name


# ---------------------------------------------------------------------------------------------
# The runner


def _timeline(s: Scenario, units: list[Unit]) -> dict[str, np.ndarray]:
    """Truth timeline: the injected state every 12 h and at every unit's hours."""
    grid = np.arange(0.0, s.campaign.total_hours + 1e-9, 12.0)
    hours = np.unique(np.concatenate([grid, [u.hours for u in units]]))
    axis = to_axis(s)
    conds = [condition_at(s, h) for h in hours]
    return {"hours": hours,
            "preload_N": np.array([c.mech.preload for c in conds]),
            "backlash_um": np.array([c.mech.backlash * 1e6 for c in conds]),
            "axial_stiffness_N_per_m": np.array([stiffness_of(axis, c.mech)["axial"] for c in conds]),
            "drag_torque_Nm": np.array([axis.screw.drag_torque(c.mech.preload) for c in conds]),
            "temperature_rise_K": np.array([c.temperature_rise for c in conds])}


def phase2_item(s: Scenario, name: str, attrs: dict, data: dict, dattrs: dict) -> tuple:
    """A stored Phase II part as the ``(session_name, session_attrs, runs)`` item of
    :func:`analysis.dataset.assemble_measurements` (the runs with the routine's attributes)."""
    runs = sorted({k.split("/")[0] for k in data if k.startswith("r")})
    return (name, {"hours": attrs["hours"]},
            [(r, {"speeds_mm_s": list(s.phase2.speeds_mm_s), "accel_mm_s2": s.phase2.accel_mm_s2,
                  "start_mm": s.phase2.start_mm, "end_mm": s.phase2.end_mm,
                  "dwell_s": s.phase2.dwell_s},
              {k.split("/")[1]: data[k] for k in data if k.startswith(r + "/")},
              {k.split("/")[1]: dattrs.get(k, {}) for k in data if k.startswith(r + "/")})
             for r in runs])


#: The order in which :func:`assemble` reads the parts, and so the order in which
#: :func:`simulate_campaign` computes them (the assembly follows the simulation).
ASSEMBLY_ORDER = ("dial", "phase1", "phase2")


def assemble(s: Scenario, out_dir: Path, units: list[Unit],
             wait: Callable[[Unit], None] | None = None) -> None:
    """Write measurements.h5 and truth.h5 from the stored parts, reading them kind by kind in
    :data:`ASSEMBLY_ORDER` and by name within a kind. ``wait(unit)``, if given, is called before
    each part is read and returns once that part is stored (or raises to abandon the assembly:
    nothing is written then), so the assembly can run while the units are still computed."""
    store = PartStore(out_dir)
    by_kind = {k: [u for u in units if u.kind == k] for k in ASSEMBLY_ORDER}

    def read(u: Unit, prefix: str = ""):
        if wait is not None:
            wait(u)
        return store.read(u.kind, u.name, prefix)

    def phase1_items():
        for u in by_kind["phase1"]:
            attrs, data, _ = read(u)
            yield u.name, attrs, data

    def phase2_items():
        for u in by_kind["phase2"]:
            yield phase2_item(s, u.name, *read(u))

    dial_h, dial_b = [], []
    for u in by_kind["dial"]:
        attrs, _, _ = read(u)
        dial_h.append(attrs["hours"])
        dial_b.append(attrs["backlash_um"])
    ds.assemble_measurements(out_dir / "measurements.h5", nominal_axis_description(s),
                             phase1_items(), phase2_items(),
                             (np.asarray(dial_h), np.asarray(dial_b)) if dial_h else None)

    def sessions():
        for u in by_kind["phase2"]:
            attrs, data, _ = store.read("phase2", u.name, "truth/")
            strokes = {k[len("truth/stroke_"):]: v for k, v in data.items() if k.startswith("truth/stroke_")}
            yield u.name, attrs, data["truth/x_m"], data["truth/E"], strokes

    ds.assemble_truth(out_dir / "truth.h5", s.to_json(), onset_hours(s), _timeline(s, units),
                      sessions(), effects={})


class CampaignDirectoryError(ValueError):
    """The output directory holds the parts of a different scenario."""


class CampaignInterrupted(KeyboardInterrupt):
    """Ctrl-C during :func:`simulate_campaign`: the queued units were cancelled and the running
    ones stopped; ``done`` of ``total`` units are stored as parts (a rerun resumes from them),
    ``cancelled`` were not started or were stopped unfinished."""

    def __init__(self, done: int, total: int, cancelled: int):
        super().__init__(f"interrupted: {done} of {total} units finished")
        self.done, self.total, self.cancelled = done, total, cancelled


def _stored(store: PartStore, units: list[Unit]) -> int:
    """How many of ``units`` are stored as parts (part files appear complete, by atomic rename)."""
    names = {kind: set(store.names(kind)) for kind in {u.kind for u in units}}
    return sum(u.name in names[u.kind] for u in units)


def _claim(out: Path, s: Scenario) -> None:
    """Record the scenario in ``out/.parts/scenario.json``; refuse to mix with another one.

    Resuming reuses stored parts, which is only right for the very same scenario (all keys,
    overrides and seed)."""
    import json

    manifest = out / ".parts" / "scenario.json"
    mine = json.loads(s.to_json())
    if manifest.exists():
        theirs = json.loads(manifest.read_text())
        if theirs != mine:
            diff = sorted(_diff_keys(theirs, mine))
            raise CampaignDirectoryError(
                f"{out} holds a campaign of another scenario (differing keys: "
                f"{', '.join(diff[:8])}{' ...' if len(diff) > 8 else ''}); its finished parts "
                "cannot be reused. Choose a new output directory, or delete this one.")
        return
    write_json(manifest, mine, sort_keys=True)


def _diff_keys(a, b, prefix: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in set(a) | set(b):
            out += _diff_keys(a.get(k), b.get(k), f"{prefix}{k}.")
        return out
    return [] if a == b else [prefix.rstrip(".")]


def simulate_campaign(s: Scenario, out_dir: str | Path, workers: int | None = None,
                      on_progress: Callable[[int, int, str], None] | None = None,
                      scheduler: str | None = None) -> dict:
    """Simulate every unit of the campaign not yet stored, then assemble the two files.

    Args:
        s: the scenario. out_dir: campaign directory (created).
        workers: local processes (default: ``TWIN_WORKERS`` or all local cores,
            :func:`analysis.base.executors.default_processes`; 1 runs in this process).
        on_progress: called as (done, total, unit name) after each unit.
        scheduler: address of a running Dask scheduler to send the units to instead
            (:mod:`analysis.base.executors`); its workers must see ``out_dir`` at the same path.
    Returns:
        {"units": n, "simulated": n_new, "skipped": n_existing, "executor": where they ran}.

    Raises:
        analysis.base.executors.ExecutorError: no scheduler answers at ``scheduler``.
        CampaignInterrupted: on Ctrl-C (KeyboardInterrupt), after cancelling the queued units and
            stopping the running ones; the finished units stay stored.
    """
    from analysis.base.executors import make_executor

    out = Path(out_dir).resolve()  # the workers (possibly elsewhere) get absolute paths
    out.mkdir(parents=True, exist_ok=True)
    _claim(out, s)
    store = PartStore(out)
    store.remove_temporaries()
    units = plan(s)
    todo = [u for u in units if not store.has(u.kind, u.name)]
    done = len(units) - len(todo)
    if on_progress:
        on_progress(done, len(units), "")
    payload = s.to_json()
    # In the order the assembly reads them, which starts on the files as soon as the first parts
    # are stored (_Assembler); the tail this leaves unbalanced is at most one Phase II session.
    todo.sort(key=lambda u: ASSEMBLY_ORDER.index(u.kind))
    processes = 1 if len(todo) <= 1 and scheduler is None else workers
    assembler = _Assembler(s, out, units, stored={u.name for u in units} - {u.name for u in todo})
    with make_executor(processes, scheduler=scheduler, prefix="unit") as ex:
        try:
            futures = [ex.submit(run_unit, payload, u, str(out), key=u.name) for u in todo]
            if not ex.in_process:
                assembler.start()  # in this process's spare time while the workers simulate
            for fut in ex.completed(futures):
                name = fut.result()
                assembler.stored(name)
                done += 1
                if on_progress:
                    on_progress(done, len(units), name)
        except KeyboardInterrupt:
            assembler.abandon()
            ex.interrupt()
            kept = _stored(store, units)
            raise CampaignInterrupted(kept, len(units), len(units) - kept) from None
        except BaseException:
            assembler.abandon()
            raise
        where = ex.description
    assembler.finish()
    return {"units": len(units), "simulated": len(todo), "skipped": len(units) - len(todo),
            "executor": where}


class _Abandoned(Exception):
    """The simulation stopped: the assembly running beside it writes nothing."""


class _Assembler:
    """:func:`assemble` in a thread of the campaign's process, reading each part as soon as its
    unit is stored, so that writing the two files overlaps the simulation of the later units
    (the process otherwise only waits for its workers). ``finish`` runs it here if it was not
    started (one process simulating), or waits for it and re-raises what it raised."""

    def __init__(self, s: Scenario, out: Path, units: list[Unit], stored: set[str]):
        import threading

        self._args = (s, out, units)
        self._cond = threading.Condition()
        self._stored, self._abandoned = set(stored), False
        self._thread = threading.Thread(target=self._run, name="assemble", daemon=True)
        self._error: BaseException | None = None

    def _wait(self, unit: Unit) -> None:
        with self._cond:
            self._cond.wait_for(lambda: unit.name in self._stored or self._abandoned)
            if self._abandoned:
                raise _Abandoned

    def _run(self) -> None:
        try:
            assemble(*self._args, wait=self._wait)
        except BaseException as exc:  # noqa: BLE001 - handed to the caller by finish()
            self._error = exc

    def start(self) -> None:
        self._thread.start()

    def stored(self, name: str) -> None:
        with self._cond:
            self._stored.add(name)
            self._cond.notify_all()

    def abandon(self) -> None:
        with self._cond:
            self._abandoned = True
            self._cond.notify_all()
        if self._thread.is_alive():
            self._thread.join()

    def finish(self) -> None:
        if self._thread.ident is None:  # never started
            assemble(*self._args)
            return
        self._thread.join()
        if self._error is not None:
            raise self._error


def simulate_campaigns_batched(scenarios: list[Scenario], out_dirs: list[str | Path]) -> None:
    """Simulate several campaigns of the same plan in this process with batched rollouts
    (:func:`run_unit_batch`): the same files as :func:`simulate_campaign` of each, unit for unit
    (tests/test_campaign.py). Parts already stored are kept; a campaign whose plan differs from
    the first one's raises ValueError."""
    units = plan(scenarios[0])
    outs = [Path(d) for d in out_dirs]
    for s, out in zip(scenarios, outs, strict=True):
        if plan(s) != units:
            raise ValueError(f"simulate_campaigns_batched: scenario {s.name!r} (seed {s.seed}) has "
                             f"another plan than {scenarios[0].name!r}; batch only campaigns of "
                             "the same plan")
        out.mkdir(parents=True, exist_ok=True)
        _claim(out, s)
    payloads = [s.to_json() for s in scenarios]
    stores = [PartStore(out) for out in outs]
    for st in stores:
        st.remove_temporaries()
    for u in units:
        todo = [i for i, st in enumerate(stores) if not st.has(u.kind, u.name)]
        if todo:
            run_unit_batch([payloads[i] for i in todo], u, [str(outs[i]) for i in todo])
    for s, out in zip(scenarios, outs, strict=True):
        assemble(s, out, units)
