"""The blind benchmark of the sim-to-real gap diagnosis (issue 6, issue 15) and `twin diagnose`
against every candidate on its cache: marker ``validate`` (`make validate`, run by hand: CI's
`make validate-ci` leaves this file out), the twin's seeds and the candidates' grids being most
of a quarter of an hour on a fast 2-core machine.

One session fixture runs ``twin diagnose-benchmark`` (86 cases on scenarios/diagnose-bench.toml,
diagnosed against the candidates of the three kinds, ``--resim-seeds 0``). With the environment
variable ``TWIN_DIAGNOSE_BENCH_CACHE`` (set by `make validate`: the cache of
``benchmarks/bench_diagnosis.py``, which ran the same benchmark just before) it starts from that
cache; the ``twin diagnose`` tests share it and only simulate their own recordings.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import DIAGNOSE_BENCH as BENCH_SCENARIO
from conftest import record_diagnose_bench as _record
from conftest import run_twin

# Where each effect acts, from its physics (not from the diagnosis): (domain, channel prefix,
# family) patterns any of which the top region of a case may match; None = any value.
#  - thermal growth: the nut's drag torque changes with temperature -> Phase I torque level and
#    torque in every operating phase; the lead growth moves where E_XX features are seen.
#  - ball recirculation: impacts on the nut at the ball-pass harmonics -> nut accelerometers
#    (bands, phases, features of the vibration), torque/IMU in bands.
#  - origin variability: the E_XX profile shifts between sessions; dwell positions move (IMU
#    dwell levels: gravity through the tilt at another place).
#  - servo dynamics: the loops set how the screw, and through the nut the carriage, follows the
#    command in the accelerations: speed and torque (Phase I), the carriage's acceleration and
#    pitch rate in the transients and reversals (IMU, Phase II), vibration at the loop's modes.
#  - cogging: lines at N_c·f_rot in torque, speed, nut acc (Phase I) and in the IMU (Phase II).
#  - Stribeck friction: torque and vibration at reversals/transients.
#  - IMU misalignment/scale: the IMU accelerometer's dwell means and its amplitude in motion.
#  - base resonance: carriage vibration (nut acc, IMU) in bands and transients/reversals.
ACTS_ON = {
    "thermal_growth": [("phase1", "torque", None), ("phase1", "features", "feature"),
                       ("phase2", "E_XX", None)],
    "ball_recirculation": [("phase1", "acc", None), ("phase1", "features", "feature"),
                           ("phase1", "torque", "band"), ("phase2", "acc", "band"),
                           ("phase2", "gyro", "band")],
    "origin_variability": [("phase2", "E_", "lag"), ("phase2", "E_", "position"),
                           ("phase2", "acc", "level"), ("phase2", "gyro", "level")],
    "servo_dynamics": [("phase1", "speed", None), ("phase1", "torque", None),
                       ("phase1", "acc", None), ("phase1", "features", "feature"),
                       ("phase2", "acc", "phase"), ("phase2", "gyro", "phase")],
    "cogging": [("phase1", None, "band"), ("phase1", None, "phase"), ("phase1", "features", "feature"),
                ("phase2", None, "band"), ("phase2", None, "phase")],
    "stribeck_friction": [("phase1", "torque", None), ("phase1", "acc", None),
                          ("phase1", "speed", None), ("phase1", "features", "feature"),
                          ("phase2", "acc", "phase"), ("phase2", "gyro", "phase")],
    "imu_misalignment": [("phase2", "acc", None), ("phase2", "gyro", None),
                         ("phase2", "E_", None)],
    "base_resonance": [("phase1", "acc", None), ("phase1", "features", "feature"),
                       ("phase1", "torque", None), ("phase1", "speed", None),
                       ("phase2", "acc", None), ("phase2", "gyro", None), ("phase2", "E_", None)],
}


def _acts_on(effect: str, region: list[str]) -> bool:
    domain, channel, family, _ = region
    return any(d == domain and (c is None or channel.startswith(c)) and (f is None or f == family)
               for d, c, f in ACTS_ON[effect])


# From an empty cache the benchmark fixture simulates the twin's seeds, the candidates' grids and
# the 86 cases' recordings: 877 s on one process (the suite's TWIN_WORKERS=1) on the idle 2-core
# machine beside the rest of the suite, so the module allows 45 min (3× that: a busy machine slows
# it, it does not fail it). On bench_diagnose.py's cache (`make validate`) it only diagnoses.
pytestmark = [pytest.mark.validate, pytest.mark.timeout(2700)]


@pytest.fixture(scope="session")
def benchmark(tmp_path_factory):
    out = tmp_path_factory.mktemp("diagnose-benchmark")
    shared = os.environ.get("TWIN_DIAGNOSE_BENCH_CACHE")
    if shared and Path(shared).is_dir():
        (out / "cache").symlink_to(Path(shared).resolve(), target_is_directory=True)
    # Without the re-simulated shrink (--resim-seeds 0: it would cost 38 cases × the seeds more
    # campaigns); test_benchmark_resimulated_shrink (slow) re-runs it on this cache with it.
    proc = run_twin("diagnose-benchmark", "-o", str(out), "--resim-seeds", "0")
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out, json.loads((out / "benchmark.json").read_text()), proc


def test_benchmark_single_effects_named_first_and_gap_shrinks(benchmark):
    """Check 1: every effect at two magnitudes; the injected effect first in >= 80 % of the
    cases, median held-out shrink >= 60 %."""
    _, res, _ = benchmark
    singles = [c for c in res["cases"] if c["kind"] == "single"]
    assert len(singles) == 16
    assert {(c["injected"][0], c["magnitude"]) for c in singles} == {
        (e, m) for e in ACTS_ON for m in ("low", "high")}
    assert res["top1_accuracy"] >= 0.8, [(c["id"], c["injected"], c["added"]) for c in singles]
    assert res["median_heldout_shrink"] >= 0.6


def test_benchmark_null_cases_say_no_gap(benchmark):
    """Check 2: the nominal twin with another seed: "no significant gap" in >= 9 of 10."""
    _, res, _ = benchmark
    nulls = [c for c in res["cases"] if c["kind"] == "null"]
    assert len(nulls) == 10
    assert sum(c["verdict"] == "no significant gap" for c in nulls) >= 9


def test_benchmark_open_set_reports_unexplained(benchmark):
    """Check 3: the injected effect removed from the library: the verdict is "unexplained gap
    remains" (no wrong effect presented as the explanation) in >= 4 of 5."""
    _, res, _ = benchmark
    cases = [c for c in res["cases"] if c["kind"] == "open_set"]
    assert len(cases) == 5
    for c in cases:  # the removed effect can never be named
        assert c["injected"][0] not in c["ranking"] and c["injected"][0] not in c["added"]
    assert sum(c["verdict"] == "unexplained gap remains" for c in cases) >= 4
    assert res["open_set_correct_fraction"] >= 0.8
    assert res["open_set_no_wrong_effect_fraction"] <= res["open_set_correct_fraction"]


def test_benchmark_localisation_matches_physics(benchmark):
    """Check 4: the top region of every single-effect case is one its effect acts on."""
    _, res, _ = benchmark
    for c in res["cases"]:
        if c["kind"] == "single" and c["top_region"] is not None:
            assert _acts_on(c["injected"][0], c["top_region"]), (c["id"], c["injected"], c["top_region"])
    assert sum(c["top_region"] is not None for c in res["cases"] if c["kind"] == "single") >= 14


def test_benchmark_two_effects_in_top_three(benchmark):
    """Check 5: two effects at once, both among the first three in >= 3 of 5."""
    _, res, _ = benchmark
    pairs = [c for c in res["cases"] if c["kind"] == "pair"]
    assert len(pairs) == 5
    assert sum(c["correct"] for c in pairs) >= 3


def test_benchmark_files_and_table(benchmark):
    out, res, proc = benchmark
    for key in ("top1_accuracy", "median_heldout_shrink", "null_correct_fraction",
                "open_set_correct_fraction"):
        assert 0.0 <= res[key] <= 1.0
    lines = (out / "benchmark_cases.csv").read_text().splitlines()
    assert len(lines) == 1 + res["n_cases"] == 87
    # what is seen, apart from what is named when it is seen
    for kind, case_kind in (("physical effect", "single"), ("signal artefact", "artefact"),
                            ("parameter", "parameter")):
        cases = [c for c in res["cases"] if c["kind"] == case_kind]
        seen = [c for c in cases if c["verdict"] != "no significant gap"]
        assert res["per_kind_detected"][kind] == pytest.approx(len(seen) / len(cases))
        when = res["per_kind_top1_when_detected"][kind]
        assert when["n"] == len(seen) and when["top1"] == pytest.approx(np.mean([c["correct"] for c in seen]))
    assert "top-1 accuracy" in proc.stderr and "blind benchmark" in proc.stdout


def test_benchmark_signal_artefacts_named_first(benchmark):
    """Each of the 7 signal artefacts at two magnitudes on a twin recording (post-processed): the
    injected artefact, on its target, is the first added candidate in at least 13 of 14 cases
    (issue 15's 90 %; 13 measured, docs/gap-diagnosis.md); the physical single cases keep their
    top-1."""
    _, res, _ = benchmark
    arts = [c for c in res["cases"] if c["kind"] == "artefact"]
    assert len(arts) == 14
    assert {c["injected"][0].split(":")[0] for c in arts} == {
        "gain", "noise", "mains_line", "order_line", "bias_drift", "time_offset", "clipping"}
    assert sum(c["correct"] for c in arts) >= 13, [(c["id"], c["injected"], c["added"]) for c in arts]
    assert res["per_kind_top1"]["signal artefact"] == pytest.approx(np.mean([c["correct"] for c in arts]))
    assert res["per_kind_top1"]["physical effect"] == res["top1_accuracy"] >= 0.8


def test_benchmark_mis_set_parameters_named_first(benchmark):
    """Issue 15, item 4, the twin parameters: each of the 15 mis-set twice (30 cases), beyond the
    least deviation the diagnosis sees on its side: every one seen, and the mis-set parameter
    named first in at least 90 % (28 of 30 measured, docs/gap-diagnosis.md: the nut taken for
    the support bearings, springs in series, said "not told apart"; the position loop × 0.67
    seen in one statistic, nothing added); a noisier torque signal counts when named as noise
    on the torque (the same recording) and is listed as such; the constant and the viscous drag
    are told apart (the torque's drags over the ramps); no physical effect is taken for a
    parameter; a named parameter's factor within 10 % of the truth (median per parameter, the
    torque ripple aside: 17 %)."""
    _, res, _ = benchmark
    pars = [c for c in res["cases"] if c["kind"] == "parameter"]
    assert len(pars) == 30 and "parameter" in res["kinds"]
    misses = [(c["id"], c["values"], c["verdict"], c["added"]) for c in pars if not c["correct"]]
    assert res["per_kind_top1"]["parameter"] == pytest.approx(np.mean([c["correct"] for c in pars]))
    assert res["per_kind_top1"]["parameter"] >= 0.9, misses
    assert res["per_kind_detected"]["parameter"] >= 0.9, misses
    for name in ("axis.no_load_torque_Nm", "axis.drag_viscous_Nm_s_per_rad"):
        assert res["per_parameter_top1"][name] == 1.0, misses
    torque_noise = [c["id"] for c in pars if c["injected"] == ["sensors.torque_noise_Nm"]]
    assert res["per_parameter_top1"]["sensors.torque_noise_Nm"] == 1.0, misses  # both, by either name
    for s in res["same_recording"]:
        assert (s["injected"], s["named"]) in {("sensors.torque_noise_Nm", "noise:torque"),
                                               ("noise:torque", "sensors.torque_noise_Nm")}, s
    named_noise = {c["id"] for c in pars if c["id"] in torque_noise and c["added"][0] == "noise:torque"}
    assert named_noise == {s["id"] for s in res["same_recording"] if s["id"] in torque_noise}
    singles = [c for c in res["cases"] if c["kind"] == "single"]
    assert not [c["id"] for c in singles if c["added_kinds"][:1] == ["parameter"]]
    errs = {k: v for k, v in res["fitted_relative_error"].items() if k.startswith(("axis.", "sensors."))}
    assert len(errs) >= 12 and all(v <= 0.1 for k, v in errs.items() if not k.startswith("axis.torque_ripple")), errs


def test_benchmark_out_of_everything_and_false_attributions(benchmark):
    """Issue 15, item 4: the cases nothing in the library explains (5 physical effects withheld,
    6 recording edits no candidate models: impulses, lost samples, a low-pass, each twice) are
    "unexplained" in at least 90 % (11 of 11 measured, docs/gap-diagnosis.md); the
    false-attribution rate (a candidate not injected added with half the gap or more) is the
    mean of the cases' flags and at most 5 % (1 of 86 measured, the nut's stiffness named as the
    support bearings'; the candidates that approximate a withheld effect are refused for what
    they leave where they act), none among the nulls, single effects, withheld effects and
    edits; every added candidate explains its footprint."""
    _, res, _ = benchmark
    edits = [c for c in res["cases"] if c["kind"] == "edit"]
    assert len(edits) == 6 and sorted({c["injected"][0].split(":")[0] for c in edits}) == [
        "dropouts", "lowpass", "spikes"]
    for c in edits:  # an edit is never a candidate
        assert c["injected"][0] not in c["ranking"] and c["injected"][0] not in c["added"]
    ooe = [c for c in res["cases"] if c["kind"] in ("open_set", "edit")]
    assert res["out_of_everything_unexplained_fraction"] == pytest.approx(np.mean([c["correct"] for c in ooe]))
    assert res["out_of_everything_unexplained_fraction"] >= 0.9, [(c["id"], c["verdict"]) for c in ooe]
    assert res["false_attribution_rate"] == pytest.approx(np.mean([c["false_attribution"] for c in res["cases"]]))
    wrong = [(c["id"], c["added"]) for c in res["cases"] if c["false_attribution"]]
    assert res["false_attribution_rate"] <= 0.05, wrong
    for kind in ("null", "single", "open_set", "edit"):
        assert res["per_case_kind_false_attribution"][kind] == 0.0, kind
    for c in res["cases"]:
        assert all(left <= 0.1 for left in c["footprint_gap_left"].values()), (c["id"], c["footprint_gap_left"])
        assert not set(c["refused"]) & set(c["added"])
    assert sum(bool(c["refused"]) for c in ooe) >= 3  # the rule at work where nothing explains the gap


def test_diagnose_cli_names_cogging_and_writes_report(benchmark, tmp_path):
    out_b, _, _ = benchmark
    real = _record(tmp_path, "real", "effects.cogging_Nm=0.1", "effects.cogging_per_rev=18")
    out = tmp_path / "diag"
    proc = run_twin("diagnose", str(real), "--scenario", str(BENCH_SCENARIO), "-o", str(out),
                    "--cache", str(out_b / "cache"), "--resim-seeds", "2")
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads((out / "diagnosis.json").read_text())
    assert res["verdict"] in ("explained", "unexplained gap remains")
    assert res["added"][0]["effect"] == "cogging"
    # The re-simulated shrink (2 of the 8 twin seeds here), side by side with the interpolated one.
    rs = res["resimulation"]
    assert rs["done"] and rs["seeds"] == 2 and rs["twin_seeds"] == res["twin_seeds"][:2]
    assert res["response_seeds"] == 3
    assert res["heldout_shrink_resimulated"] == rs["heldout_shrink"] >= 0.8
    assert abs(rs["heldout_shrink"] - res["heldout_shrink"]) <= 0.05
    assert res["verdict"] == rs["verdict"]
    said = " ".join(proc.stdout.split())
    assert re.search(r"interpolated \(shrink \d+ %\); re-simulated with 2 twin seeds -> [\d.]+ \(shrink \d+ %\)", said)
    assert "The verdict follows the re-simulated shrink" in (out / "report" / "index.html").read_text()
    fitted = res["added"][0]["params"]
    assert fitted["per_rev"] == 18.0
    lo, hi = res["added"][0]["interval"]["torque_Nm"]
    assert lo <= 0.1 <= hi or abs(fitted["torque_Nm"] - 0.1) < 0.03
    assert res["heldout_shrink"] >= 0.6
    assert "effect 1: cogging" in proc.stdout
    for png in ("gap_phase1_channel_band.png", "gap_phase2_position_error_motion.png",
                "gap_operating_phase.png", "gap_hours_and_ranking.png"):
        assert (out / "report" / png).stat().st_size > 5000
    assert "Gap diagnosis" in (out / "report" / "index.html").read_text()


def _diagnose_against_every_candidate(benchmark, tmp_path, *sets) -> dict:
    """`twin diagnose` of a twin recording (seed 777, ``sets`` as `--set`) against the candidates
    of the three kinds on the benchmark's cache, re-simulated with 2 twin seeds: diagnosis.json."""
    out_b, _, _ = benchmark
    real = _record(tmp_path, "real", *sets)
    out = tmp_path / "diag"
    proc = run_twin("diagnose", str(real), "--scenario", str(BENCH_SCENARIO), "-o", str(out),
                    "--kinds", "physical,parameter,artefact", "--cache", str(out_b / "cache"),
                    "--resim-seeds", "2")
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads((out / "diagnosis.json").read_text())


def test_diagnose_names_a_heavier_carriage_and_resimulates_it(benchmark, tmp_path):
    """Issue 15, items 1(b) and 2: the twin with the carriage 35 % heavier (162 kg, nominal
    120 kg), diagnosed against every candidate of the three kinds on the benchmark's cache: the
    carriage mass is the first added candidate and the first ranked, kind "parameter", fitted
    within 8 % of the truth, said with fitted and nominal masses in kg; re-simulated with 2
    twin seeds, at least 80 % of the held-out gap removed, within 5 points of the interpolated
    shrink, and the verdict follows it."""
    from analysis.diagnosis import wording as w

    res = _diagnose_against_every_candidate(benchmark, tmp_path, "axis.carriage_mass_kg=162")
    first = res["added"][0]
    print(json.dumps({k: first[k] for k in ("effect", "params", "interval", "heldout_reduction")}),
          [(r["effect"], round(r["net_reduction"], 3)) for r in res["ranking"][:5]], res["verdict"],
          res["heldout_shrink"], res["heldout_shrink_resimulated"])
    assert first["effect"] == res["ranking"][0]["effect"] == "axis.carriage_mass_kg"
    assert first["kind"] == "parameter"
    mass = 120.0 * first["params"]["factor"]
    assert mass == pytest.approx(162.0, rel=0.08)
    said = w.owner_phrase(res, first)
    m = re.fullmatch(r"carriage mass ([\d.]+) kg, not 120 kg"
                     r"(?: \(interval ([\d.]+)–([\d.]+) kg\))? \[parameter\]", said)
    assert m and float(m.group(1)) == pytest.approx(mass, rel=0.01), said
    rs = res["resimulation"]
    assert rs["done"] and rs["seeds"] == 2
    assert res["heldout_shrink_resimulated"] == rs["heldout_shrink"] >= 0.8
    assert abs(rs["heldout_shrink"] - res["heldout_shrink"]) <= 0.05
    assert res["verdict"] == rs["verdict"]


def test_the_nominal_twin_is_not_resimulated(benchmark, tmp_path):
    """The twin itself with another seed, diagnosed against every candidate with
    `--resim-seeds 2`: no significant gap, nothing added, nothing re-simulated, and
    diagnosis.json says why."""
    res = _diagnose_against_every_candidate(benchmark, tmp_path)
    assert res["verdict"] == "no significant gap" and res["added"] == []
    assert res["resimulation"] == {"done": False, "reason": "no significant gap: nothing to explain"}
    assert res["heldout_shrink_resimulated"] is None


@pytest.mark.slow
def test_benchmark_resimulated_shrink(benchmark, tmp_path):
    """Issue 15, item 2: the default benchmark again on the fixture's cache, every case with
    candidates added re-simulated with 2 twin seeds (38 cases, 76 campaigns: about 4.5 min on two
    loaded cores): the re-simulated shrink beside the interpolated one per case and per kind; the
    single effects' re-simulated median at least 90 % and within 2 points of the interpolated one
    (measured 99.5 % and 99.7 %); the nulls are not re-simulated."""
    out_b, before, _ = benchmark
    out = tmp_path / "b"
    out.mkdir()
    (out / "cache").symlink_to(out_b / "cache")
    proc = run_twin("diagnose-benchmark", "-o", str(out), "--workers", "2", "--resim-seeds", "2")
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads((out / "benchmark.json").read_text())
    assert res["resim_seeds"] == 2 and res["n_resimulated"] >= 30
    kind = "physical effect"
    med, med_rs = res["per_kind_median_heldout_shrink"][kind], res["per_kind_median_heldout_shrink_resimulated"][kind]
    print(res["per_kind_median_heldout_shrink"], res["per_kind_median_heldout_shrink_resimulated"],
          res["per_kind_median_shrink_difference"], res["verdict_changed_by_resimulation"], res["wall_time_s"])
    assert med_rs >= 0.9 and abs(med_rs - med) <= 0.02
    assert res["per_kind_median_heldout_shrink_resimulated"]["signal artefact"] >= 0.9
    for c in res["cases"]:
        assert (c["heldout_shrink_resimulated"] is None) == (not c["added"]), c["id"]
    assert "re-simulated with 2 twin seeds" in " ".join(proc.stderr.split())


@pytest.mark.slow
def test_larger_benchmark_three_cases_per_cell(tmp_path):
    """The benchmark with 3 cases per effect and magnitude (48 single cases), 20 null cases,
    8 open-set and 10 pair cases, on another case plan: the same thresholds as checks 1-3, 5."""
    proc = run_twin("diagnose-benchmark", "-o", str(tmp_path), "--per-cell", "3", "--nulls", "20",
                    "--open-set", "8", "--pairs", "10", "--rng-seed", "7")
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads((tmp_path / "benchmark.json").read_text())
    assert res["top1_accuracy"] >= 0.8
    assert res["median_heldout_shrink"] >= 0.6
    assert res["null_correct_fraction"] >= 0.9
    assert res["open_set_correct_fraction"] >= 0.8
    assert res["pair_both_top3_fraction"] >= 0.6


def test_diagnose_names_a_mains_line_on_the_accelerometers(benchmark, tmp_path):
    """A twin recording plus a 50 Hz line of 0.03 m/s² on acc1 and acc2 (measurements.h5
    post-processed): the diagnosis adds that signal artefact first, ranks it above every physical
    effect, fits 50 Hz and the amplitude within 10 %, and says it in the owner's words."""
    from analysis.diagnosis.artefacts import apply

    out_b, _, _ = benchmark
    twin_rec = _record(tmp_path, "twin")
    real = tmp_path / "real"
    apply(twin_rec / "measurements.h5", real / "measurements.h5",
          {"mains_line:acc": {"amplitude": 0.03, "frequency_hz": 50.0}}, seed=777)
    out = tmp_path / "diag"
    proc = run_twin("diagnose", str(real), "--scenario", str(BENCH_SCENARIO), "-o", str(out),
                    "--cache", str(out_b / "cache"), "--workers", "1", "--resim-seeds", "1")
    assert proc.returncode == 0, proc.stderr[-3000:]
    res = json.loads((out / "diagnosis.json").read_text())
    first = res["added"][0]
    assert first["effect"] == "mains_line:acc" and first["kind"] == "signal artefact"
    assert first["params"]["frequency_hz"] == 50.0
    assert first["params"]["amplitude"] == pytest.approx(0.03, rel=0.1)
    kinds = [r["kind"] for r in res["ranking"]]
    assert kinds.index("physical effect") > [r["effect"] for r in res["ranking"]].index("mains_line:acc")
    assert res["library"]["mains_line:acc"]["kind"] == "signal artefact"
    assert res["heldout_shrink"] >= 0.9
    # Re-simulated on the first seed's campaign (kept for the artefact grid), post-processed.
    assert res["resimulation"]["seeds"] == 1 and res["heldout_shrink_resimulated"] >= 0.9
    said = " ".join(proc.stdout.split())
    assert "artefact 1: mains_line:acc (signal artefact;" in said
    assert re.search(r"a 50 Hz line of 0\.0[23]\d* m/s² on acc1 and acc2 at every speed: electrical pickup", said)
    page = (out / "report" / "index.html").read_text()
    assert "at every speed: electrical pickup" in page and "signal artefact" in page


def test_benchmark_confusion_lists_every_miss(benchmark):
    """Issue 15, item 6: the confusion table of benchmark.json (and benchmark_confusion.csv)
    holds every single and artefact case whose first added candidate is not the injected one,
    once, with what was named instead."""
    out, res, _ = benchmark
    misses = {c["id"]: c for c in res["cases"] if c["kind"] in ("single", "parameter", "artefact") and not c["correct"]}
    listed = [i for g in res["confusion"] for i in g["cases"]]
    assert sorted(listed) == sorted(misses)
    for g in res["confusion"]:
        assert g["count"] == len(g["cases"]) and g["named"] != g["injected"]
        for i in g["cases"]:
            assert misses[i]["injected"][0] == g["injected"]
            assert (misses[i]["added"][:1] or [None])[0] == g["named"]
    rows = (out / "benchmark_confusion.csv").read_text().splitlines()
    assert rows[0] == "kind,injected,named first,verdict when none,count,cases"
    assert len(rows) == 1 + len(res["confusion"])


def test_benchmark_reports_interval_coverage(benchmark):
    """Issue 15, item 5: on the default benchmark the stated 90 % interval of each fitted
    continuous parameter holds the injected value in at least 85 % of the cases, per kind
    (measured 95 % of 20 physical-effect and 91 % of 11 artefact parameters; docs/gap-diagnosis.md,
    "Intervals"), and it is not so wide as to say nothing: the median half-width is under 20 % of
    the value."""
    _, res, _ = benchmark
    cov = res["interval_coverage"]
    print("interval coverage", cov["per_kind"], cov["n"], cov["median_relative_half_width"], cov["missed"])
    assert cov["n"]["physical effect"] >= 16 and cov["n"]["signal artefact"] >= 8
    assert set(cov["per_kind"]) == {"physical effect", "signal artefact", "parameter"}
    assert cov["per_kind"]["physical effect"] >= 0.85 and cov["per_kind"]["signal artefact"] >= 0.85
    assert all(w < 0.2 for w in cov["median_relative_half_width"].values() if w is not None)

