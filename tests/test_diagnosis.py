"""Sim-to-real gap diagnosis (issue 6): the blind benchmark's checks, the localisation against a
physics table, the CLI, and the refusal of recordings laid out differently from the scenario.

One session fixture runs ``twin diagnose-benchmark`` (86 cases on scenarios/diagnose-bench.toml,
diagnosed against the candidates of the three kinds); its simulation cache is shared with the
``twin diagnose`` tests, which then only simulate their own recordings.
"""

from __future__ import annotations

import json
import re
import shutil

import h5py
import numpy as np
import pytest
from conftest import REPO, run_twin

from analysis.diagnosis import gap
from analysis.diagnosis.signature import Region, Signature

BENCH_SCENARIO = REPO / "scenarios" / "diagnose-bench.toml"

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


# The benchmark fixture simulates the twin's seeds, the candidates' grids and the 86 cases'
# recordings; the first test that needs it carries that setup: 972 s in `make test` on the 2-core
# machine with other work beside it (`--durations`), so the module allows 45 min (3× that setup:
# a busy machine slows it, it does not fail it).
pytestmark = pytest.mark.timeout(2700)


@pytest.fixture(scope="session")
def benchmark(tmp_path_factory):
    out = tmp_path_factory.mktemp("diagnose-benchmark")
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


# ---------------------------------------------------------------------------------------------
# twin diagnose on one recording


def _record(tmp_path, name, *sets):
    d = tmp_path / name
    proc = run_twin("simulate", str(BENCH_SCENARIO), "-o", str(d), "--workers", "1",
                    "--set", "seed=777", *[x for s in sets for x in ("--set", s)])
    assert proc.returncode == 0, proc.stderr
    # The diagnosis must not need the truth.
    (d / "truth.h5").unlink()
    return d


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


def test_diagnose_refuses_missing_channel_and_other_rate(benchmark, tmp_path):
    """Check 6: refused (exit 2) with a message naming the channel or the rate."""
    out_b, _, _ = benchmark
    real = _record(tmp_path, "real")
    broken = tmp_path / "missing"
    shutil.copytree(real, broken)
    with h5py.File(broken / "measurements.h5", "a") as f:
        name = sorted(f["phase1"])[1]
        del f[f"phase1/{name}/acc2"]
    proc = run_twin("diagnose", str(broken), "--scenario", str(BENCH_SCENARIO), "-o",  # --force: past
                    str(tmp_path / "d1"), "--cache", str(out_b / "cache"), "--force", check=False)  # twin check
    assert proc.returncode == 2
    assert f"/phase1/{name}/acc2 is missing" in proc.stderr
    assert "does not match the scenario" in proc.stderr

    other = _record(tmp_path, "rate", "sensors.imu_acc_fs_hz=1000")
    proc = run_twin("diagnose", str(other), "--scenario", str(BENCH_SCENARIO), "-o",
                    str(tmp_path / "d2"), "--cache", str(out_b / "cache"), check=False)
    assert proc.returncode == 2
    assert ("/phase2/s0000/r0000/imu_acc is sampled at 1000 Hz (and 5 more run(s)); the scenario "
            "has 1613 Hz (sensors.imu_acc_fs_hz)") in " ".join(proc.stderr.split())

    proc = run_twin("diagnose", str(tmp_path / "nowhere"), "--scenario", str(BENCH_SCENARIO),
                    check=False)
    assert proc.returncode == 2 and "no measurements.h5" in proc.stderr


# ---------------------------------------------------------------------------------------------
# The statistics of the gap test


def test_holm_rejects_in_step_down_order():
    p = np.array([0.001, 0.04, 0.012, np.nan, 0.5])
    # m = 4 tested: 0.001 <= 0.05/4, 0.012 <= 0.05/3, 0.04 > 0.05/2 stops.
    assert gap.holm(p, 0.05).tolist() == [True, False, True, False, False]


def test_spread_pools_by_region_and_calibrates_null_t():
    """A draw from the same distribution as the seeds: |t| beyond the 1 % two-sided quantile
    in about 1 % of the statistics (pooled over the hours of a region)."""
    rng = np.random.default_rng(5)
    regions = [Region("phase1", f"c{i % 50}", "band", "b", float(i // 50)) for i in range(1000)]
    scale = np.repeat(rng.uniform(0.5, 2.0, 50)[None, :], 20, axis=0).ravel()
    seeds = [Signature(rng.normal(0, 1, 1000) * scale, regions) for _ in range(8)]
    sp = gap.spread(seeds)
    # independent from hour to hour: the pooled variance has nearly its 20·(K − 1) degrees of freedom
    assert np.all((sp.dof > 0.8 * 20 * 7) & (sp.dof <= 20 * 7)), (sp.dof.min(), sp.dof.max())
    rates = []
    for _ in range(20):
        z = gap.zscores(Signature(rng.normal(0, 1, 1000) * scale, regions), sp)
        rates.append(np.mean(gap.pvalues(z, sp) < 0.01))
    assert 0.005 < np.mean(rates) < 0.016


def test_spread_counts_a_seed_shared_over_the_hours_once():
    """What a seed draws once (its rails, its screw's error phases) moves a region's statistic
    alike at every hour: the variance pooled over 10 hours of K = 3 seeds then has about K − 1
    degrees of freedom, not 10·(K − 1). A recording that is one more seed gets |t| beyond the
    1 % two-sided quantile in about 1 % of the statistics (with 10·(K − 1) = 20 degrees of
    freedom it was about 10 %, the false gap of the nominal foreign recording: docs/import.md)."""
    rng = np.random.default_rng(14)
    n_reg, hours, k = 100, 10, 3
    regions = [Region("phase1", f"c{i // hours}", "feature", "kurt", float(i % hours))
               for i in range(n_reg * hours)]

    def draw() -> Signature:  # a machine per seed, the same at every hour, plus a little noise
        machine = np.repeat(rng.normal(0, 1, n_reg), hours)
        return Signature(machine + rng.normal(0, 0.05, n_reg * hours), regions)

    rates, dofs = [], []
    for _ in range(40):
        sp = gap.spread([draw() for _ in range(k)])
        dofs.append(sp.dof)
        rates.append(np.mean(gap.pvalues(gap.zscores(draw(), sp), sp) < 0.01))
    dofs = np.concatenate(dofs)
    print(f"dof median {np.median(dofs):.2f} (K - 1 = {k - 1}); null rate at 1 %: {np.mean(rates):.4f}")
    assert np.median(dofs) < 1.2 * (k - 1)
    assert 0.004 < np.mean(rates) < 0.02


def test_pooled_dof_between_seed_count_and_pooled_count():
    rng = np.random.default_rng(3)
    assert gap.pooled_dof(rng.normal(size=(5, 1))) == 4.0  # one statistic: K − 1
    shared = np.repeat(rng.normal(size=(5, 1)), 6, axis=1)  # every statistic moved alike
    assert gap.pooled_dof(shared + 1e-9 * rng.normal(size=(5, 6))) == pytest.approx(4.0, rel=1e-3)
    assert gap.pooled_dof(np.ones((5, 6))) == 24.0  # constant: nothing pooled, the sd floor applies


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


def test_confusion_groups_misses_by_what_was_named():
    from twin.harness.diagnosis.benchmark import confusion

    def row(i, kind, injected, added, verdict="explained", correct=False):
        return {"id": i, "kind": kind, "injected": [injected], "added": added, "verdict": verdict,
                "correct": correct}

    rows = [row("a", "parameter", "axis.nut_stiffness_N_per_um", ["axis.bearing_stiffness_N_per_um"]),
            row("b", "parameter", "axis.nut_stiffness_N_per_um", ["axis.bearing_stiffness_N_per_um", "cogging"]),
            row("c", "parameter", "axis.rail_friction_N", [], "no significant gap"),
            row("d", "single", "cogging", ["cogging"], correct=True),
            row("e", "null", "-", [], "explained"),
            row("f", "artefact", "gain:acc1", [], "unexplained gap remains")]
    assert confusion(rows) == [
        {"kind": "parameter", "injected": "axis.nut_stiffness_N_per_um", "named": "axis.bearing_stiffness_N_per_um",
         "verdict": None, "count": 2, "cases": ["a", "b"]},
        {"kind": "artefact", "injected": "gain:acc1", "named": None, "verdict": "unexplained gap remains",
         "count": 1, "cases": ["f"]},
        {"kind": "parameter", "injected": "axis.rail_friction_N", "named": None, "verdict": "no significant gap",
         "count": 1, "cases": ["c"]}]


def test_interval_coverage_counts_the_injected_value_inside_the_stated_interval():
    """Issue 15, item 5: the coverage of the stated intervals, per kind, over the continuous
    parameters of the injected candidate where it was added first (the discrete cogging order
    and wrong or missed cases do not count)."""
    from twin.harness.diagnosis.benchmark import interval_coverage

    def row(i, kind, name, values, intervals, correct=True):
        return {"id": i, "kind": kind, "injected": [name], "correct": correct,
                "values": {name: values}, "intervals": {name: intervals} if correct else {}}

    rows = [row("a", "single", "cogging", {"torque_Nm": 0.07, "per_rev": 12.0},
                {"torque_Nm": [0.06, 0.08], "per_rev": [18.0, 18.0]}),
            row("b", "single", "thermal_growth", {"rise_K": 5.4}, {"rise_K": [5.31, 5.35]}),
            row("c", "single", "thermal_growth", {"rise_K": 9.0}, {}, correct=False),
            row("d", "artefact", "gain:acc1", {"error_pct": 10.0}, {"error_pct": [9.5, 10.0]}),
            row("e", "null", "-", {}, {})]
    cov = interval_coverage(rows)
    assert cov["per_kind"] == {"physical effect": 0.5, "signal artefact": 1.0, "parameter": None}
    assert cov["n"] == {"physical effect": 2, "signal artefact": 1, "parameter": 0}
    assert cov["per_parameter"] == {"cogging.torque_Nm": 1.0, "gain:acc1.error_pct": 1.0, "thermal_growth.rise_K": 0.0}
    assert cov["missed"] == [["b", "thermal_growth.rise_K", 5.4, [5.31, 5.35]]]
    # half-widths: cogging 0.01 / 0.07, thermal 0.02 / 5.4 (median of the two), gain 0.25 / 10
    assert cov["median_relative_half_width"] == pytest.approx(
        {"physical effect": (0.01 / 0.07 + 0.02 / 5.4) / 2, "signal artefact": 0.025, "parameter": None})


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


def test_region_bootstrap_interval_covers_what_the_regions_disagree_on():
    """Issue 15, item 5: where regions prefer different values (a response whose shape is not
    the recording's), the block bootstrap's 90 % interval spans them while the Δχ² profile is
    narrow; it is deterministic, and a candidate the regions agree on keeps a narrow interval."""
    from analysis.diagnosis import attribution as at

    grid = (0.0, 1.0, 2.0, 3.0, 4.0)
    n_regions, per = 40, 100
    regions = [Region("phase1", f"ch{r}", "band", "x", float(h)) for r in range(n_regions) for h in range(per)]
    slope = np.ones(n_regions * per)
    delta = np.stack([v * slope for v in grid])  # (5, n): the response grows by 1 sd per unit
    cand = at.CandidateResponse("c", [at.ParamAxis("p", grid)], {"cal": delta, "heldout": delta})
    sd = np.ones(n_regions * per)
    prefer = np.repeat(np.linspace(1.5, 2.5, n_regions), per)  # each region's own best value
    boot = at.bootstrap_interval(cand, prefer, sd, regions)["p"]
    fit = at.fit_candidate(cand, prefer, prefer, {"cal": sd, "heldout": sd}, np.ones_like(sd, bool), 0.01)
    lo, hi = fit.interval["p"]
    print("profile", (lo, hi), "bootstrap", boot)
    assert hi - lo < 0.05 and abs(fit.params["p"] - 2.0) < 0.02
    assert boot[0] < 1.95 and boot[1] > 2.05 and boot[1] - boot[0] < 0.3
    assert at.bootstrap_interval(cand, prefer, sd, regions)["p"] == boot
    agree = at.bootstrap_interval(cand, np.full_like(prefer, 2.0), sd, regions)["p"]
    assert agree[1] - agree[0] < 0.02


def test_a_response_averaged_over_seeds_is_not_penalised_within_its_own_spread():
    """A candidate that removes the gap of the significant statistics S and overshoots a region
    outside S: with a one-seed response that region counts as made worse (the penalty exceeds
    the gain, the candidate is not significant); with a response averaged over seeds whose
    seed-to-seed spread covers the overshoot (an order line added coherently to each seed's own
    vibration), it does not, and the same fit is added."""
    from analysis.diagnosis import attribution as at

    regions = [Region("phase1", "s", "band", "x", float(h)) for h in range(2)] + \
              [Region("phase1", "o", "band", "y", float(h)) for h in range(10)]
    sd = np.ones(12)
    z = np.r_[np.full(2, 6.0), np.full(10, 3.0)]  # S: region "s"; "o" shows it too
    delta = np.r_[np.full(2, 6.0), np.full(10, 9.0)][None, :]  # one grid point: overshoots "o" by 6 sd
    select = np.arange(12) < 2
    one_seed = at.CandidateResponse("c", [at.ParamAxis("p", (1.0,))], {"cal": delta, "heldout": delta})
    f1 = at.fit_candidate(one_seed, z, z, {"cal": sd, "heldout": sd}, select, 0.01, regions=regions)
    assert f1.gain == pytest.approx(72.0) and f1.heldout_after == pytest.approx(0.0)
    assert [w["channel"] for w in f1.worse] == ["o"] and f1.penalty == pytest.approx(270.0)
    assert not f1.significant(0.1)
    spread = np.r_[np.zeros(2), np.full(10, 8.0)][None, :]
    averaged = at.CandidateResponse("c", [at.ParamAxis("p", (1.0,))], {"cal": delta, "heldout": delta},
                                    spread={"cal": spread, "heldout": spread})
    f2 = at.fit_candidate(averaged, z, z, {"cal": sd, "heldout": sd}, select, 0.01, regions=regions)
    assert f2.params == f1.params and f2.gain == f1.gain
    assert f2.worse == [] and f2.penalty == 0.0 and f2.significant(0.1)
