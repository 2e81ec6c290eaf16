"""The round trip of ``twin calibrate``, blind: foreign axes drawn from a seed, simulated, written
out as a laboratory's files, imported with a spec, calibrated and (optionally) diagnosed, then
scored against what was drawn.

Each case is an axis that is neither the paper's nor the twin's default: lead, stroke, moving
mass, routines, sensor rates, noise floors, frictions and ripple drawn within their priors
(:func:`draw_case`), several off the twin's defaults at once. Its campaign is a nominal machine
(no preload loss, no backlash growth) of the layout of ``scenarios/foreign-16mm.toml``, written
out in a rotation of the formats the importer reads (:data:`FORMATS`: each used), imported
(``twin import``) and calibrated (:func:`twin.harness.calibration.calibrate`). Scored:

- the routine: every measured routine value within 0.1 % of the drawn one (or the channel's
  resolution: one sample of the rate for a dwell);
- the physical parameters and the sensor chain: the drawn value inside the stated 90 % interval,
  over the (case, parameter) pairs the recording informs;
- with ``diagnose``: the calibrated twin against the recording, scored by the case's kind
  (:data:`CASE_KINDS`, in turn, so a benchmark stopped early has every kind):

  - ``null``: the foreign axis alone (its parameters off the twin's defaults are what
    ``calibrate`` must absorb): the right verdict is "no significant gap";
  - ``effect``: one physical effect of the library (:func:`twin.harness.diagnosis.candidates.candidates`) added to
    the machine, drawn in the upper half of its prior range: it must be named first (the
    first added candidate, or one that makes the same recording:
    :func:`twin.harness.diagnosis.benchmark.same_answer`), and the held-out gap must shrink on the
    twin re-simulated with it;
  - ``artefact``: one signal artefact (:data:`analysis.diagnosis.artefacts.ARTEFACTS`, upper half)
    applied to the recording before it is written out as the lab's files: named first;
  - ``several``: the axis's own mis-set parameters, an effect and an artefact at once: both named
    (among the added candidates), and nothing named that is not there.

  The effects and artefacts are drawn from a stream of their own (``[seed, 1]``): the axes are
  those of a benchmark without them.

Writes ``OUT/calibrate-benchmark.json`` (per case and the summary) and prints a table.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from analysis.base.files import write_json
from twin.harness.calibration.benchmark_summary import CASE_KINDS, ROUTINE_KEYS, summarise
from twin.harness.diagnosis.cache import DEFAULT_RESPONSE_SEEDS
from twin.sim.scenario import Scenario, from_dict, load

#: (Phase I format, Phase II format) of the cases in turn: every reader is used.
FORMATS = (("tdms", "csv"), ("mat", "mat"), ("mdf", "mdf"), ("csv", "tdms"))
BENCH_VERSION = 3  # 3: a time offset's recording mirrored at its edge (apply(edge="mirror")), not held
#: Twin seeds the diagnosis re-simulates with its added candidates (the re-simulated shrink).
RESIM_SEEDS = 2
#: Twin seeds each candidate's response is computed with, in the diagnosis and its oracle: those of
#: ``twin diagnose`` as the owner runs it (its default), whose spread the diagnosis allows for
#: (:func:`analysis.diagnosis.fit.error_scale`); with one seed it allows none, and a right
#: candidate whose response varies from seed to seed (a mains line's phase, drawn per capture)
#: loses to one that matches only its mean or is refused.
RESPONSE_SEEDS = DEFAULT_RESPONSE_SEEDS


#: Least Phase I cruise a drawn axis gets, s (the features' 0.2-s spectra plus the trims).
MIN_CRUISE_S = 0.3


def _base() -> dict:
    return load("foreign-16mm").model_dump(mode="json")


def draw_case(rng: np.random.Generator, i: int) -> Scenario:
    """A foreign axis within the priors: lead 4–20 mm, stroke 150–800 mm, moving mass 30–400 kg
    (log-uniform), Phase I speed up to 2400 rpm of the motor and its acceleration (its stroke 0.3–0.6 s
    of cruise: a 2-s capture holds whole moves and rests, and the features their 0.2-s spectra), two Phase II
    speeds (the slower no longer than 8 s a move), Phase I DAQ rate 5.12–25.6 kHz, IMU rate
    1–2 kHz, noise floors ×0.5–2 of the twin's, rail friction 5–40 N, viscous drag
    1–5 × 10⁻⁴ N·m·s/rad, torque ripple 0.005–0.03 N·m, the trucks' vertical and lateral
    stiffness × 0.6–1.6 of the twin's 300 and 200 N/µm (the guide blocks' preload classes), the
    velocity loop's bandwidth × 0.5–1.6 of its 60 Hz (a drive's tuning; all log-uniform)."""
    d = _base()
    lead = float(rng.choice([4.0, 5.0, 8.0, 10.0, 12.0, 16.0, 20.0]))
    stroke = float(rng.uniform(150.0, 800.0))
    travel = round(stroke + 60.0, 1)
    loguni = lambda lo, hi: float(np.exp(rng.uniform(math.log(lo), math.log(hi))))  # noqa: E731
    ax = d["axis"]
    # the shaft as the owner describes it and `scenario init` writes it (the travel plus the nut
    # and bearings when the twin's 500 mm is too short): the axis description, not fitted
    shaft = ax["shaft_length_mm"] if ax["shaft_length_mm"] >= travel + 50.0 else round(travel + 80.0, 1)
    ax.update(travel_mm=travel, lead_mm=lead, shaft_length_mm=shaft, carriage_mass_kg=round(loguni(30.0, 400.0), 2),
              rail_friction_N=round(float(rng.uniform(5.0, 40.0)), 3),
              drag_viscous_Nm_s_per_rad=float(f"{loguni(1e-4, 5e-4):.4g}"),
              torque_ripple_Nm=float(f"{loguni(0.005, 0.03):.4g}"),
              truck_stiffness_vertical_N_per_um=round(300.0 * loguni(0.6, 1.6), 1),
              truck_stiffness_lateral_N_per_um=round(200.0 * loguni(0.6, 1.6), 1),
              velocity_bandwidth_hz=round(60.0 * loguni(0.5, 1.6), 1))
    vmax1 = min(500.0, 2400.0 / 60.0 * lead)  # motor at most 2400 rpm
    speed1 = round(float(rng.uniform(0.4, 1.0)) * vmax1, 2)
    # a 2-s capture holds whole moves and rests, as a lab sets its captures: no cruise longer
    # than 0.6 s (a slow axis's Phase I stroke is shorter; a capture of a 3.6-s move holds no
    # rest, and its routine cannot be measured)
    p1_stroke = round(min(0.6 * stroke, 300.0, 0.6 * speed1), 2)
    start1 = round(30.0 + 0.5 * (stroke - p1_stroke), 2)
    d["phase1"].update(fs_hz=float(rng.choice([5120.0, 10000.0, 12800.0, 25600.0])),
                       speed_mm_s=speed1, accel_mm_s2=round(float(rng.uniform(1500.0, 6000.0)), 2),
                       start_mm=start1, end_mm=round(start1 + p1_stroke, 2),
                       dwell_s=round(float(rng.uniform(0.2, 0.4)), 3), capture_s=2.0)
    # at least MIN_CRUISE_S of cruise (the Phase I features' 0.2-s spectra after the segments'
    # trims): on a short stroke the speed is lowered until the stroke holds it
    a1 = d["phase1"]["accel_mm_s2"]
    if speed1 * MIN_CRUISE_S + speed1 ** 2 / a1 > p1_stroke:
        d["phase1"]["speed_mm_s"] = round(0.5 * a1 * (math.sqrt(MIN_CRUISE_S ** 2 + 4.0 * p1_stroke / a1)
                                                      - MIN_CRUISE_S), 2)
    vmax2 = min(300.0, 2400.0 / 60.0 * lead)
    # the slow speed: no move longer than 8 s (the cost of a case), the fast one above it
    s_lo = round(max(float(rng.uniform(0.15, 0.4)) * vmax2, stroke / 8.0), 2)
    s_hi = round(max(float(rng.uniform(0.6, 1.0)) * vmax2, 1.5 * s_lo), 2)
    d["phase2"].update(speeds_mm_s=[s_lo, s_hi], accel_mm_s2=round(float(rng.uniform(5000.0, 20000.0)), 1),
                       start_mm=30.0, end_mm=round(30.0 + stroke, 2),
                       dwell_s=round(float(rng.uniform(0.5, 1.0)), 3))
    fs_imu = float(rng.choice([1000.0, 1600.0, 2000.0]))
    se = d["sensors"]
    se.update(imu_acc_fs_hz=fs_imu, imu_gyro_fs_hz=fs_imu, position_cmd_fs_hz=fs_imu,
              imu_acc_noise_ug_per_rthz=round(7.0 * loguni(0.5, 2.0), 3),
              imu_gyro_noise_urad_s_per_rthz=round(35.0 * loguni(0.5, 2.0), 3),
              nut_acc_noise_ug_per_rthz=round(20.0 * loguni(0.5, 2.0), 3),
              torque_noise_Nm=float(f"{0.005 * loguni(0.5, 2.0):.4g}"))
    d["phase2"]["session_hours"] = [50.0, 250.0]  # two sessions: a calibration and a held-out part each
    d["phase1"]["sample_interval_hours"] = 200.0
    d["name"], d["seed"] = f"foreign-{i:03d}", int(rng.integers(0, 2**31))
    d["description"] = f"calibrate-benchmark case {i}"
    return from_dict(d)


def draw_additions(rng: np.random.Generator, kind: str) -> tuple[dict, dict]:
    """What is added on top of a foreign axis of ``kind`` (:data:`CASE_KINDS`): ({effect:
    {param: value}}, {artefact: {param: value}}), each drawn in the upper half of its prior
    range; an artefact's kind (gain, noise, line, drift, offset, clipping) first, then its
    target. The effects that act only through a draw per Phase II session (``random``: the
    origin's spread between sessions) are not drawn: a case's recording has two sessions, one
    shift between them, from which no diagnosis can tell a spread; the diagnosis benchmark, with
    three sessions, scores them."""
    from analysis.diagnosis.artefacts import ARTEFACTS
    from twin.harness.diagnosis.candidates import candidates

    effects, artefacts = {}, {}
    if kind in ("effect", "several"):
        lib = candidates()
        name = str(rng.choice(sorted(n for n, e in lib.items() if not e.random)))
        effects[name] = lib[name].draw(rng, "high")
    if kind in ("artefact", "several"):
        by_kind: dict[str, list[str]] = {}
        for n, a in ARTEFACTS.items():
            by_kind.setdefault(a.artefact, []).append(n)
        names = by_kind[str(rng.choice(sorted(by_kind)))]
        name = str(rng.choice(names))
        artefacts[name] = ARTEFACTS[name].draw(rng, "high")
    return effects, artefacts


def absorbed_effects(effects: dict, parameters: dict, verdict: str | None = None) -> list[str]:
    """The ``effects`` that `twin calibrate` absorbed: an effect every scenario key of which
    (``servo_dynamics``: both loops' bandwidths) the calibration fitted, each holding the
    machine's value (the drawn one changed by the effect: :func:`score_case`) inside its 90 %
    interval. Such an effect is a change of calibrated parameters: the calibrated twin carries
    it, its TOML says by how much, and the diagnosis, which looks for what the calibration left,
    has nothing to name. Also absorbed, in part: at least one key fitted inside its interval and
    the others keys the calibration never fits (not in ``parameters``, and in
    :data:`twin.harness.calibration.values.NOT_INFORMED`: the position loop), with the diagnosis
    against the calibrated twin finding no significant gap (``verdict``): what the calibration
    cannot carry, the recording does not show.
    ``parameters``: a case entry's, {key: {"source", "inside", ...}}."""
    from analysis.diagnosis.attribution import NO_GAP
    from twin.harness.calibration.values import NOT_INFORMED
    from twin.harness.diagnosis.candidates import candidates

    lib, out = candidates(), []
    for name in effects:
        keys = [k for prm in getattr(lib.get(name), "params", ()) for k in prm.keys]
        held = [k for k in keys if parameters.get(k, {}).get("source") == "fitted" and parameters[k]["inside"]]
        part = verdict == NO_GAP and bool(held) and all(
            k in held or (k not in parameters and k in NOT_INFORMED) for k in keys)
        if keys and (len(held) == len(keys) or part):
            out.append(name)
    return out


def score_diagnosis(kind: str, effects: dict, artefacts: dict, res: dict, parameters: dict | None = None) -> dict:
    """The diagnosis ``res`` of a case of ``kind`` against what was added (``effects``,
    ``artefacts``: those that change the recording), the case's calibrated ``parameters`` (a case
    entry's): its verdict and figures (``refitted_with``: the effect the calibration was fitted
    again with when that diagnosis is the answer, :mod:`twin.harness.diagnosis.refit`), judged by
    :func:`judge_diagnosis`."""
    from analysis.diagnosis.flagged import named
    from analysis.diagnosis.gap_report import refit_explaining

    added = named(res)  # what twin check found first, then the attribution's
    row = {"verdict": res["verdict"], "heldout_gap": res["heldout_gap_before"],
           "critical": res["heldout_gap_critical"],
           "significant": int(sum(r["significant"] for r in res.get("regions", []))),
           "added": [a["effect"] for a in added], "fitted": {a["effect"]: a["params"] for a in added},
           "heldout_shrink": res.get("heldout_shrink"),
           "heldout_shrink_resimulated": res.get("heldout_shrink_resimulated"),
           "refitted_with": refit_explaining(res)}
    return {**row, **judge_diagnosis(kind, effects, artefacts, row, parameters or {})}


def judge_diagnosis(kind: str, effects: dict, artefacts: dict, row: dict, parameters: dict) -> dict:
    """{"absorbed", "correct", "nothing_else"} of a diagnosis's ``row`` (:func:`score_diagnosis`:
    what it named, in order, with the fitted values): ``correct`` by the kind's rule
    (:data:`CASE_KINDS`; an effect ``absorbed`` by the calibration, :func:`absorbed_effects`,
    counts as found) and ``nothing_else`` (every added candidate is something that was added, or
    makes the same recording). A kept case is judged again from its row by the current rule."""
    from analysis.diagnosis.attribution import NO_GAP
    from twin.harness.diagnosis.benchmark import same_answer

    values = {**effects, **artefacts}
    added = [{"effect": n, "params": row["fitted"].get(n, {})} for n in row["added"]]
    absorbed = absorbed_effects(effects, parameters, row["verdict"])

    def names(name: str, v: dict, a: dict) -> bool:
        return same_answer(name, v, a["effect"], a["params"])

    if kind == "null" or not values:  # nothing added, or an artefact that changed no sample
        correct = row["verdict"] == NO_GAP and not added
    elif kind in ("effect", "artefact"):
        name, v = next(iter(values.items()))
        correct = name in absorbed or (bool(added) and names(name, v, added[0]))
    else:
        correct = all(n in absorbed or any(names(n, v, a) for a in added) for n, v in values.items())
    return {"absorbed": absorbed, "correct": correct,
            "nothing_else": all(any(names(n, v, a) for n, v in values.items()) for a in added)}


def judged_again(entry: dict) -> dict:
    """A case's ``entry`` (kept from an earlier run) with its diagnosis judged by the current
    rule (:func:`judge_diagnosis`) from the diagnosis it recorded."""
    if "diagnosis" in entry:
        active = {n: v for n, v in entry["artefacts"].items() if n not in entry.get("inactive_artefacts", [])}
        entry["diagnosis"].update(judge_diagnosis(entry["kind"], entry["effects"], active, entry["diagnosis"],
                                                  entry["parameters"]))
    return entry


def _get(data: dict, key: str):
    a, b = key.split(".")
    return data[a][b]


def score_case(truth: Scenario, calibrated: Scenario, record: dict) -> dict:
    """The routine's relative errors (and whether each is within tolerance) and, for every value
    the calibration measured or fitted, whether the machine's value is inside its 90 % interval.
    ``truth``: the axis as drawn with the case's effects applied (an effect that changes a
    scenario key, as ``servo_dynamics`` the loops' bandwidths, makes the machine's value the
    changed one: the value a calibrated twin should carry)."""
    t, c = truth.model_dump(mode="json"), calibrated.model_dump(mode="json")
    routine = {}
    for key in ROUTINE_KEYS:
        tv, cv = _get(t, key), _get(c, key)
        tv_l, cv_l = (tv, cv) if isinstance(tv, list) else ([tv], [cv])
        if len(tv_l) != len(cv_l):
            routine[key] = {"truth": tv, "calibrated": cv, "error": None, "within": False}
            continue
        err = max(abs(a - b) / abs(b) for a, b in zip(cv_l, tv_l, strict=True))
        tol = 1e-3
        if key.endswith("dwell_s"):  # one sample of the channel the rests are measured on
            fs = t["phase1"]["fs_hz"] if key.startswith("phase1") else t["sensors"]["position_cmd_fs_hz"]
            tol = max(tol, 1.0 / fs / tv_l[0])
        routine[key] = {"truth": tv, "calibrated": cv, "error": err, "within": bool(err <= tol)}
    params = {}
    for v in record["values"]:
        if v["low"] is None:
            continue
        tv = float(_get(t, v["key"]))
        params[v["key"]] = {"truth": tv, "value": v["value"], "low": v["low"], "high": v["high"],
                            "source": v["source"], "inside": bool(v["low"] <= tv <= v["high"])}
    return {"routine": routine, "parameters": params}


def run_case(i: int, s: Scenario, out: Path, workers: int, diagnose: bool, seeds: int,
             progress: Callable[[str], None], kind: str = "null", effects: dict | None = None,
             artefacts: dict | None = None, key: str | None = None) -> dict:
    """One case end to end in ``out/case-NNN``: the axis ``s`` with ``effects`` added to the
    machine and ``artefacts`` to its recording; returns its entry of the JSON. With ``key`` (the
    case's :func:`case_key`), a finished calibration is marked with its :func:`calibration_key`
    in ``case-NNN/calibrated.json``: a run stopped during the diagnosis, or one whose diagnosis
    options, statistics or rules changed, goes on from the calibration with the same key instead of
    calibrating again (the diagnosis's own cache, in the case's directory too, keeps the twin
    simulations it had finished)."""
    from analysis.diagnosis.artefacts import apply, changes
    from analysis.ingest import run_import
    from analysis.ingest.check import check_record, require_clean_recording
    from twin.harness.calibration import calibrate
    from twin.harness.diagnosis.library import with_effects
    from twin.harness.lab_export import export
    from twin.sim.campaign import simulate_campaign

    effects, artefacts = dict(effects or {}), dict(artefacts or {})
    machine = with_effects(s, effects)  # the axis as built: simulated, and what the calibration is scored against

    d = out / f"case-{i:03d}"
    f1, f2 = FORMATS[i % len(FORMATS)]
    added = ", ".join([*effects, *artefacts]) or "nothing added"
    step = lambda t: progress(f"case {i} ({kind}): {t}")  # noqa: E731 - a line per step, for a log
    marker = d / "calibrated.json"
    cal_key = calibration_key(s, kind, effects, artefacts) if key is not None else None
    earlier = json.loads(marker.read_text()) if key is not None and marker.exists() else {}
    if key is not None and earlier.get("key") == cal_key:
        rec = json.loads((d / "axis.calibration.json").read_text())
        t_sim, inactive = earlier["simulate_export_import_s"], earlier.get("inactive_artefacts", [])
        step(f"calibrated by an earlier run ({marker}, the same key): taken, not calibrated again")
    else:
        shutil.rmtree(d, ignore_errors=True)
        d.mkdir(parents=True)
        step(f"simulating the axis (lead {s.axis.lead_mm:g} mm, {s.axis.carriage_mass_kg:g} kg; {added})")
        t0 = time.perf_counter()
        simulate_campaign(machine, d / "twin", workers=1)
        inactive = []
        if artefacts:
            h5 = d / "twin" / "measurements.h5"
            # a clock offset's first (last) samples show the motion before (after) the window,
            # not a held value (which twin check calls a dropout)
            done = apply(h5, h5.with_name("measurements.artefacts.h5"), artefacts, s.seed, edge="mirror")
            # one that changes no sample (a converter range above every peak) is not in the recording
            inactive = [n for n in artefacts if not changes(h5, done, n)]
            done.replace(h5)
            if inactive:
                step(f"{', '.join(inactive)} changes no sample of this recording: not scored as added")
        spec = export(d / "twin", d / "lab", phase1_format=f1, phase2_format=f2)
        run_import(spec, output=d / "campaign")
        t_sim = time.perf_counter() - t0
        step(f"written out as {f1}/{f2} and imported ({t_sim:.0f} s); calibrating")
        # as the owner's `twin calibrate` does: what `twin check` flags is not fitted (errors forced)
        check = check_record(require_clean_recording(d / "campaign", True, "twin calibrate"), True)
        rec = calibrate(d / "campaign", d / "axis.toml", workers=workers,
                        progress=lambda t: step(f"calibrate: {t}"), check=check)
        if key is not None:
            write_json(marker, {"key": cal_key, "simulate_export_import_s": t_sim, "inactive_artefacts": inactive})
    cal = load(d / "axis.toml")
    active = {n: v for n, v in artefacts.items() if n not in inactive}
    entry = {"case": i, "kind": kind, "effects": effects, "artefacts": artefacts, "inactive_artefacts": inactive,
             "formats": [f1, f2], "scenario": json.loads(s.to_json()),
             "simulate_export_import_s": t_sim, "calibrate_s": rec["seconds"],
             "calibrate_estimated_s": rec.get("estimated_s"), **score_case(machine, cal, rec)}
    if diagnose:
        from twin.harness.diagnosis.runner import run_diagnosis

        step(f"calibrated ({rec['seconds']:.0f} s); diagnosing against the calibrated twin ({seeds} twin seeds)")
        t1 = time.perf_counter()
        try:
            res = run_diagnosis(d / "campaign", cal, d / "diagnosis", seeds=seeds, workers=workers,
                                plots=False, response_seeds=RESPONSE_SEEDS, resim_seeds=RESIM_SEEDS)
        except Exception as exc:  # noqa: BLE001 - one case's failure is a figure, not the end
            entry["diagnosis_error"] = f"{type(exc).__name__}: {exc}"
        else:
            entry["diagnosis"] = {**score_diagnosis(kind, effects, active, res, entry["parameters"]),
                                  "seconds": time.perf_counter() - t1}
    r_ok = sum(v["within"] for v in entry["routine"].values())
    p_ok = sum(v["inside"] for v in entry["parameters"].values())
    dg = entry.get("diagnosis")
    if "diagnosis_error" in entry:
        progress(f"case {i}: the diagnosis failed: {entry['diagnosis_error']}")
    progress(f"case {i} ({kind}: {added}): lead {s.axis.lead_mm:g} mm, {s.axis.carriage_mass_kg:g} kg, "
             f"{f1}/{f2}: routine "
             f"{r_ok}/{len(entry['routine'])} within tolerance, parameters {p_ok}/{len(entry['parameters'])} "
             f"inside their interval" + (f", diagnosis: {dg['verdict']}, named {', '.join(dg['added']) or 'nothing'} "
                f"({'right' if dg['correct'] else 'wrong'})" if dg else ""))
    return entry


def run_oracle(entry: dict, s: Scenario, out: Path, workers: int, seeds: int,
               progress: Callable[[str], None]) -> dict:
    """The oracle of a case with something added: the same recording diagnosed against the axis
    as drawn (``s``: every parameter true, nothing calibrated) with only the added candidates in
    the library. It says what any diagnosis can see in this recording: an effect the perfect twin
    finds no significant gap for (a 4-mm lead's profile hides an origin shift that is a multiple
    of the lead; a short capture hides a small time offset) is invisible here, whatever the
    calibration. Returns ``{"verdict", "named", "detected", "names_all", "seconds"}``."""
    from analysis.diagnosis.attribution import NO_GAP
    from analysis.diagnosis.flagged import named as named_by
    from twin.harness.diagnosis.runner import run_diagnosis

    d = out / f"case-{entry['case']:03d}"
    added = [*entry["effects"], *(a for a in entry["artefacts"] if a not in entry.get("inactive_artefacts", []))]
    progress(f"case {entry['case']}: the oracle: diagnosing against the axis as drawn ({', '.join(added)} only)")
    t0 = time.perf_counter()
    res = run_diagnosis(d / "campaign", s, d / "oracle", seeds=seeds, workers=workers, plots=False,
                        response_seeds=RESPONSE_SEEDS, resim_seeds=0, library=added)
    named = [a["effect"] for a in named_by(res)]
    row = {"verdict": res["verdict"], "named": named, "detected": res["verdict"] != NO_GAP or bool(named),
           "names_all": all(n in named for n in added), "seconds": time.perf_counter() - t0}
    progress(f"case {entry['case']}: the oracle (the axis as drawn, the added candidates only): "
             f"{row['verdict']}, named {', '.join(named) or 'nothing'}")
    return row


def case_key(s: Scenario, kind: str, effects: dict, artefacts: dict, *, diagnose: bool, seeds: int) -> str:
    """What makes a case's result: its draw, the options and the versions of the benchmark, of
    ``twin check``, of the calibration and of the diagnosis's statistics, rules and refit (a case
    with the same key is not run again)."""
    from analysis.diagnosis.attribution import ATTRIBUTION_VERSION
    from analysis.diagnosis.signature import SIGNATURE_VERSION
    from analysis.ingest.check import CHECK_VERSION
    from twin.harness.calibration import CALIBRATE_VERSION
    from twin.harness.diagnosis.refit import REFIT_VERSION

    text = json.dumps([BENCH_VERSION, CALIBRATE_VERSION, CHECK_VERSION, SIGNATURE_VERSION, ATTRIBUTION_VERSION,
                       REFIT_VERSION, s.to_json(), kind, effects, artefacts, bool(diagnose), int(seeds), RESIM_SEEDS,
                       RESPONSE_SEEDS], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def calibration_key(s: Scenario, kind: str, effects: dict, artefacts: dict) -> str:
    """What makes a case's recording and calibration: its draw and the versions of the benchmark,
    of ``twin check`` (what it flags is not fitted) and of the calibration (not the diagnosis's
    options, statistics or rules, which :func:`case_key` adds)."""
    from analysis.ingest.check import CHECK_VERSION
    from twin.harness.calibration import CALIBRATE_VERSION

    text = json.dumps(["calibration", BENCH_VERSION, CALIBRATE_VERSION, CHECK_VERSION, s.to_json(), kind, effects,
                       artefacts], sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


def draws(cases: int, seed: int) -> tuple[list[Scenario], list[tuple[dict, dict]]]:
    """The ``cases`` foreign axes drawn from ``seed`` (:func:`draw_case`) and what is added to
    each (:func:`draw_additions`, from the stream ``[seed, 1]``)."""
    rng = np.random.default_rng(seed)
    scenarios = [draw_case(rng, i) for i in range(cases)]
    add_rng = np.random.default_rng([seed, 1])
    return scenarios, [draw_additions(add_rng, CASE_KINDS[i % len(CASE_KINDS)]) for i in range(cases)]


def run_benchmark(out: str | Path, *, cases: int = 24, seed: int = 2026, workers: int = 2,
                  diagnose: bool = False, seeds: int = 4, resume: bool = True, first: int = 0,
                  kept_dir: str | Path | None = None,
                  progress: Callable[[str], None] = lambda t: print(t, flush=True)) -> dict:
    """Draw ``cases`` foreign axes from ``seed``, take each through the round trip
    (:func:`run_case`), write ``OUT/calibrate-benchmark.json`` and return it. With ``resume``, a
    case whose ``OUT/case-NNN/entry.json`` has the same :func:`case_key` is taken from it (a
    long benchmark can be stopped and run again; the code's other changes are not in the key:
    ``resume=False`` after them). Cases before ``first`` are not run, only taken when kept (one
    benchmark split between processes or machines: each runs its own range into its own
    directory; the entries copied into one directory and run again give the whole summary). A
    case not kept in ``OUT`` is taken from ``kept_dir/case-NNN.json`` when that entry has the same
    key (the entries a benchmark recorded: ``benchmarks/calibrate_benchmark.py``)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    scenarios, additions = draws(cases, seed)
    t0 = time.perf_counter()
    done: list[dict] = []
    doc = {"version": BENCH_VERSION, "seed": seed, "workers": workers, "diagnose": diagnose, "cases_drawn": cases,
           "seconds": 0.0, "summary": summarise(done), "cases": done}
    for i, s in enumerate(scenarios):
        kind = CASE_KINDS[i % len(CASE_KINDS)]
        key = case_key(s, kind, *additions[i], diagnose=diagnose, seeds=seeds)
        kept = out / f"case-{i:03d}" / "entry.json"
        entry, source = (json.loads(kept.read_text()), kept) if resume and kept.exists() else ({}, None)
        recorded = Path(kept_dir) / f"case-{i:03d}.json" if kept_dir is not None else None
        if entry.get("key") != key and recorded is not None and recorded.exists():
            entry, source = json.loads(recorded.read_text()), recorded
            if entry.get("key") == key:  # into OUT too: OUT alone then holds the whole benchmark
                kept.parent.mkdir(parents=True, exist_ok=True)
                write_json(kept, entry, nan_as_null=True)
        if entry.get("key") == key:
            progress(f"case {i} ({kind}): kept from {source} (the same draw, options and versions)")
            entry = judged_again(entry)
        elif i < first:
            continue
        else:
            entry = {**run_case(i, s, out, workers, diagnose, seeds, progress, kind, *additions[i], key=key),
                     "key": key}
            write_json(kept, entry, nan_as_null=True)
        if diagnose and kind != "null" and "oracle" not in entry:
            try:
                entry["oracle"] = run_oracle(entry, s, out, workers, seeds, progress)
            except Exception as exc:  # noqa: BLE001 - recorded, the benchmark goes on
                entry["oracle"] = {"error": f"{type(exc).__name__}: {exc}"}
            write_json(kept, entry, nan_as_null=True)
        done.append(entry)
        # written after every case: a long benchmark stopped early keeps what it measured
        doc = {"version": BENCH_VERSION, "seed": seed, "workers": workers, "diagnose": diagnose,
               "cases_drawn": cases, "seconds": time.perf_counter() - t0, "summary": summarise(done),
               "cases": done}
        write_json(out / "calibrate-benchmark.json", doc, nan_as_null=True)
    return doc


__all__ = ["absorbed_effects", "calibration_key", "case_key", "draw_additions", "draw_case", "draws",
           "judge_diagnosis", "judged_again", "run_benchmark", "run_oracle", "score_case", "score_diagnosis"]
