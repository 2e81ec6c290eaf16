"""Degradation laws and gap-diagnosis candidates from outside the package (issue 17, item 1).

A developer's logistic degradation law and an effect "the carriage is heavier than the twin's"
(a twin parameter set wrong), in a module written into a temporary directory outside the
repository, reached by ``module:Class`` on ``PYTHONPATH`` and by entry points of the groups
``ballscrew_twin.degradation_laws`` and ``ballscrew_twin.gap_candidates`` (declared by a
``*.dist-info`` directory on ``PYTHONPATH``, which ``importlib.metadata`` finds as it finds an
installed package). The law drives a simulated campaign whose truth must follow it; the effect
must be what the gap diagnosis ranks first for a recording of a heavier carriage. Bad names and
keys raise the exact errors.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO, run_twin, simulate_shared

from analysis.base import registry
from analysis.dataset import open_truth

MODULE = "mylaws_plugin_kinds"
SOURCE = '''
"""A developer's degradation law and gap-diagnosis candidate."""
import numpy as np

from twin.harness.diagnosis.candidates.base import Effect, Param


class Sigmoid:
    """Logistic loss of preload and growth of backlash around ``midpoint_hours``."""

    label = "logistic wear"

    def __init__(self, midpoint_hours=300.0, width_hours=50.0, final_preload_fraction=0.2,
                 final_backlash_um=10.0):
        if not midpoint_hours >= 0:
            raise ValueError(f"midpoint_hours = {midpoint_hours!r}: allowed >= 0")
        self.midpoint_hours = midpoint_hours
        self.width_hours = width_hours
        self.final_preload_fraction = final_preload_fraction
        self.final_backlash_um = final_backlash_um

    def _s(self, hours):
        return 1.0 / (1.0 + np.exp(-(np.asarray(hours, float) - self.midpoint_hours) / self.width_hours))

    def preload_fraction(self, hours):
        return 1.0 - (1.0 - self.final_preload_fraction) * self._s(hours)

    def backlash(self, hours):
        return self.final_backlash_um * 1e-6 * self._s(hours)

    def injected_onset_hours(self):
        return self.midpoint_hours - 3.0 * self.width_hours


class NotALaw:
    def __init__(self):
        pass


HEAVY = Effect(name="carriage_mass", title="a carriage heavier than the twin's",
               params=(Param("extra_kg", keys=("axis.carriage_mass_kg",), mode="add", low=20.0,
                             high=80.0, grid=(0.0, 40.0, 80.0), label="extra carriage mass", unit="kg"),),
               source="a twin parameter set wrong")

SLOW_ACCEL = Effect(name="slow_accel", title="a Phase I acceleration far below the twin's",
                   params=(Param("drop_mm_s2", keys=("phase1.accel_mm_s2",), mode="add", low=-3950.0,
                                 high=-1000.0, grid=(-3950.0, -1000.0, 0.0), label="acceleration drop",
                                 unit="mm/s^2"),),
                   source="a candidate whose strong end leaves the capture without a constant speed")

FAKE_COGGING = Effect(name="cogging", title="another cogging", params=HEAVY.params, source="-")
'''

ENTRY_POINTS = f"""
[ballscrew_twin.degradation_laws]
sigmoid = {MODULE}:Sigmoid

[ballscrew_twin.gap_candidates]
carriage_mass = {MODULE}:HEAVY
"""

LAW = {"midpoint_hours": 250.0, "width_hours": 40.0, "final_preload_fraction": 0.3,
       "final_backlash_um": 12.0}


def expected_law(hours) -> tuple[np.ndarray, np.ndarray]:
    """(preload fraction, backlash µm) of the logistic law with LAW, written out here."""
    s = 1.0 / (1.0 + np.exp(-(np.asarray(hours, float) - 250.0) / 40.0))
    return 1.0 - 0.7 * s, 12.0 * s


def _write(root) -> tuple[str, str]:
    """The module in ``root/src`` and its entry points in ``root/ep`` (outside the repository)."""
    src, ep = root / "src", root / "ep"
    src.mkdir()
    (src / f"{MODULE}.py").write_text(SOURCE)
    info = ep / "mylaws_plugin_kinds-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: mylaws-plugin-kinds\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)
    assert REPO not in root.parents
    return str(src), str(ep)


def twin(*args, pythonpath: str = "", check: bool = True):
    path = os.pathsep.join(p for p in (str(REPO), pythonpath) if p)
    r = run_twin(*args, check=False, env=dict(os.environ, PYTHONPATH=path, COLUMNS="400"), timeout=600)
    if check:
        assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return r


def flat(text: str) -> str:
    return " ".join(text.split())


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    src, ep = _write(tmp_path)
    monkeypatch.syspath_prepend(src)
    return src, ep


def _sets(values: dict) -> list[str]:
    return [f"degradation.{k}={v}" for k, v in values.items()]


# ---------------------------------------------------------------------------------------------
# Degradation laws


def test_law_by_module_class_drives_the_campaign_state(plugin):
    from twin.sim.campaign import condition_at, degradation_at, onset_hours
    from twin.sim.scenario import from_dict, load

    s = load(REPO / "scenarios/quick.toml", [f'degradation.law="{MODULE}:Sigmoid"', *_sets(LAW)])
    hours = np.array([0.0, 150.0, 250.0, 400.0, 600.0])
    pf, bl = degradation_at(s, hours)
    want_pf, want_bl = expected_law(hours)
    np.testing.assert_allclose(pf, want_pf, rtol=1e-12)
    np.testing.assert_allclose(bl, want_bl, rtol=1e-12)
    assert onset_hours(s) == 250.0 - 3 * 40.0
    c = condition_at(s, 400.0)
    assert c.mech.backlash == pytest.approx(want_bl[3] * 1e-6, rel=1e-12)  # metres inside
    assert c.mech.preload == pytest.approx(want_pf[3] * s.axis.preload_N, rel=1e-12)
    # The law's keys survive the JSON a worker process receives.
    again = from_dict(json.loads(s.to_json()))
    assert again.degradation.model_extra == LAW
    assert type(again.degradation.make_law()).__name__ == "Sigmoid"


def test_bad_laws_and_keys_raise_the_exact_error(plugin):
    from twin.sim.laws import names
    from twin.sim.scenario import ScenarioError, load

    quick = REPO / "scenarios/quick.toml"
    assert {"wear", "table"} <= set(names())  # the built-ins register themselves

    def error(*overrides: str) -> str:
        with pytest.raises(ScenarioError) as exc:
            load(quick, list(overrides))
        return str(exc.value)

    assert error('degradation.law="logistic"') == (
        f"{quick}: key `degradation.law`: degradation law 'logistic' is unknown; expected one of "
        f"{', '.join(names())} or module:Class.")
    assert error('degradation.law="nomodule_here:Law"') == (
        f"{quick}: key `degradation.law`: degradation law 'nomodule_here:Law': cannot import it "
        "(No module named 'nomodule_here'); expected module:Class importable from sys.path.")
    fields = ("law, onset_hours, interference_um, wear_rate_um_per_kh, scatter_um, backlash_gain, "
              "truck_wear_coupling, table_hours, table_preload_fraction, table_backlash_um, "
              "thermal_rise_K, thermal_time_constant_hours, thermal_expansion_per_K, "
              "drag_temperature_coefficient_per_K")
    assert error(f'degradation.law="{MODULE}:Sigmoid"', "degradation.midpoint_hour=300.0") == (
        f"{quick}: key `degradation.midpoint_hour` = 300.0: unknown key; allowed keys in "
        f"[degradation]: {fields}, and for the degradation law '{MODULE}:Sigmoid': midpoint_hours, "
        "width_hours, final_preload_fraction, final_backlash_um.")
    # The same key without the law that takes it.
    assert error("degradation.midpoint_hours=300.0").startswith(
        f"{quick}: key `degradation.midpoint_hours` = 300.0: unknown key; allowed keys in "
        f"[degradation]: {fields}, and for the degradation law 'wear': residual_preload_fraction.")
    # The law's own check names the key.
    assert error(f'degradation.law="{MODULE}:Sigmoid"', "degradation.midpoint_hours=-5.0") == (
        f"{quick}: key `degradation.midpoint_hours` = -5.0: allowed >= 0.")
    assert error(f'degradation.law="{MODULE}:NotALaw"') == (
        f"{quick}: key `degradation.law` = '{MODULE}:NotALaw' is a NotALaw without "
        "preload_fraction, backlash, injected_onset_hours; expected a degradation law with "
        "preload_fraction, backlash, injected_onset_hours (twin.sim.laws).")


def test_law_by_entry_point_through_twin_simulate(plugin, tmp_path):
    """``twin simulate`` with the law named by its entry point: the injected truth (timeline,
    sessions, onset) follows the law; a wrong name exits 2 naming it."""
    src, ep = plugin
    out = tmp_path / "camp"
    sets = ['degradation.law="sigmoid"', *_sets(LAW), "campaign.phase1=false",
            "phase2.session_hours=[100.0, 250.0, 400.0]", "phase2.runs_per_session=1",
            "phase2.end_mm=150.0", "phase2.dwell_s=0.5", "campaign.total_hours=400.0"]
    twin("simulate", REPO / "scenarios/quick.toml", "-o", out, *[a for kv in sets for a in ("--set", kv)],
         pythonpath=os.pathsep.join((src, ep)))
    with open_truth(out / "truth.h5") as t:
        assert t.onset_hours == pytest.approx(250.0 - 3 * 40.0)
        tl = t.timeline()
        pf, bl = expected_law(tl["hours"])
        assert t.scenario()["degradation"]["law"] == "sigmoid"
        preload_n = t.scenario()["axis"]["preload_N"]
        np.testing.assert_allclose(tl["preload_N"], pf * preload_n, rtol=1e-9)
        np.testing.assert_allclose(tl["backlash_um"], bl, rtol=1e-9)
        sess = {t.session(s)[2]["hours"]: t.session(s)[2]["backlash_um"] for s in t.sessions()}
    assert sorted(sess) == [100.0, 250.0, 400.0]
    np.testing.assert_allclose([sess[h] for h in sorted(sess)], expected_law(sorted(sess))[1], rtol=1e-9)
    assert sess[400.0] > 10.0 > 1.0 > sess[100.0]  # the law, not the default wear (0 µm here)

    r = twin("simulate", "quick", "-o", tmp_path / "bad", "--set", 'degradation.law="sigmoidal"',
             pythonpath=os.pathsep.join((src, ep)), check=False)
    assert r.returncode == 2
    assert "key `degradation.law`: degradation law 'sigmoidal' is unknown; expected one of wear, " \
           "table, sigmoid or module:Class." in flat(r.stderr)


def test_entry_points_are_listed_with_the_built_ins(plugin):
    src, ep = plugin
    code = ("from twin.sim.laws import names; from twin.harness.diagnosis.candidates import candidates; "
            "print(list(names())); print(list(candidates()))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                       env=dict(os.environ, PYTHONPATH=os.pathsep.join((str(REPO), src, ep))))
    laws_line, cands_line = r.stdout.strip().splitlines()
    from twin.harness.diagnosis.candidates import LIBRARY
    from twin.sim.laws import names
    assert eval(laws_line) == [*names(), "sigmoid"]
    assert eval(cands_line) == [*LIBRARY, "carriage_mass"]


# ---------------------------------------------------------------------------------------------
# Gap-diagnosis candidates

# A small Phase I-only campaign of the benchmark's scenario (3 samples of two 1-s captures).
DIAG = ["campaign.phase2=false", "phase1.capture_s=1.0"]


def test_candidate_by_module_name_and_bad_names(plugin, tmp_path):
    from twin.harness.diagnosis.candidates import candidate
    from twin.harness.diagnosis.library import KINDS, candidate_names, library_json, resolve_library, with_effects

    ALL_KINDS = tuple(KINDS)  # the error names every candidate --candidate accepts (twin parameters too)
    from twin.sim.scenario import load

    effects, artefacts = resolve_library([f"{MODULE}:HEAVY", "cogging", "gain:acc1"])
    assert list(effects) == ["carriage_mass", "cogging"] and artefacts == ["gain:acc1"]
    assert library_json(["carriage_mass"], effects)["carriage_mass"]["params"]["extra_kg"]["unit"] == "kg"
    s = with_effects(load(REPO / "scenarios/quick.toml"), {f"{MODULE}:HEAVY": {"extra_kg": 40.0}})
    assert s.axis.carriage_mass_kg == 120.0 + 40.0

    with pytest.raises(ValueError) as exc:
        resolve_library(["carriage_mas"])
    assert str(exc.value) == (f"unknown candidate 'carriage_mas'; the candidates are "
                              f"{', '.join(candidate_names(ALL_KINDS))}, or module:NAME of an Effect")
    with pytest.raises(ValueError) as exc:
        resolve_library(["gain:acc9"])
    assert str(exc.value).startswith("unknown candidate 'gain:acc9'; the candidates are ")
    with pytest.raises(registry.RegistryError) as exc:
        candidate(f"{MODULE}:Sigmoid")
    assert str(exc.value) == (f"gap-diagnosis candidate '{MODULE}:Sigmoid' is a Sigmoid; expected a "
                              "twin.harness.diagnosis.candidates.base.Effect (or a class or function returning one)")
    with pytest.raises(registry.RegistryError) as exc:
        candidate(f"{MODULE}:FAKE_COGGING")
    assert str(exc.value) == (f"gap-diagnosis candidate '{MODULE}:FAKE_COGGING' is named 'cogging', "
                              "the name of the registered candidate of built-in; expected another name")

    real = tmp_path / "real"
    real.mkdir()
    (real / "measurements.h5").write_bytes(b"")  # never read: the candidate is checked first
    r = twin("diagnose", real, "--scenario", REPO / "scenarios/diagnose-bench.toml", "--candidate",
             "carriage_mas", "-o", tmp_path / "d", pythonpath=plugin[0], check=False)
    assert r.returncode == 2
    assert (f"unknown candidate 'carriage_mas'; the candidates are "
            f"{', '.join(candidate_names(ALL_KINDS))}, or module:NAME of an Effect") in flat(r.stderr)


def heavier_carriage(tmp_path_factory, out):
    """diagnose-bench (Phase I only, 1-s captures) with a carriage of 180 kg, seed 3: the
    recording of the two tests below, simulated once per test run."""
    sets = [a for kv in DIAG for a in ("--set", kv)]
    return simulate_shared(tmp_path_factory, REPO / "scenarios/diagnose-bench.toml", out, *sets,
                           "--set", "axis.carriage_mass_kg=180", "--set", "seed=3")


def test_external_candidate_is_ranked_by_the_diagnosis(plugin, tmp_path, tmp_path_factory):
    """A recording of a carriage 60 kg heavier than the scenario's: the diagnosis, given the
    external candidate by its entry point's name (then by module:NAME, from the same cache) and
    cogging, ranks it first, adds it with about 60 kg and shrinks the held-out gap."""
    src, ep = plugin
    path = os.pathsep.join((src, ep))
    bench = REPO / "scenarios/diagnose-bench.toml"
    sets = [a for kv in DIAG for a in ("--set", kv)]
    heavier_carriage(tmp_path_factory, tmp_path / "real")
    results = {}
    for spec in ("carriage_mass", f"{MODULE}:HEAVY"):
        out = tmp_path / f"diag-{len(results)}"
        r = twin("diagnose", tmp_path / "real", "--scenario", bench, *sets, "--candidate", spec,
                 "--candidate", "cogging", "--seeds", "3", "--response-seeds", "1", "-o", out,
                 "--cache", tmp_path / "cache", pythonpath=path)
        assert "carriage_mass" in flat(r.stdout)
        results[spec] = json.loads((out / "diagnosis.json").read_text())
    for res in results.values():
        assert [c["effect"] for c in res["ranking"]] == ["carriage_mass", "cogging"]
        assert res["library"]["carriage_mass"]["title"] == "a carriage heavier than the twin's"
        added = res["added"][0]
        assert added["effect"] == "carriage_mass"
        assert added["params"]["extra_kg"] == pytest.approx(60.0, abs=10.0)
        assert res["heldout_shrink"] > 0.9
    assert math.isclose(results["carriage_mass"]["heldout_gap_after"],
                        results[f"{MODULE}:HEAVY"]["heldout_gap_after"], rel_tol=1e-9)



def test_a_candidate_the_statistics_cannot_be_computed_for_is_left_out(plugin, tmp_path, tmp_path_factory):
    """A candidate whose simulation at the strong end of its grid has no constant-speed Phase I
    segment (the 220-mm stroke at 400 mm/s with 137 mm/s² never cruises): the diagnosis leaves
    it out with the reason (JSON, terminal, page) and ranks the others; it does not stop."""
    src, _ = plugin
    bench = REPO / "scenarios/diagnose-bench.toml"
    sets = [a for kv in DIAG for a in ("--set", kv)]
    heavier_carriage(tmp_path_factory, tmp_path / "real")
    out = tmp_path / "diag"
    r = twin("diagnose", tmp_path / "real", "--scenario", bench, *sets, "--candidate", f"{MODULE}:HEAVY",
             "--candidate", f"{MODULE}:SLOW_ACCEL", "--seeds", "3", "--response-seeds", "1", "-o", out,
             pythonpath=src)
    res = json.loads((out / "diagnosis.json").read_text())
    why = res["candidates_left_out"]["slow_accel"]
    assert "FeatureError" in why and "no constant-speed segment of at least 0.2 s" in why
    assert [c["effect"] for c in res["ranking"]] == ["carriage_mass"]
    assert res["added"][0]["effect"] == "carriage_mass"
    assert "left out: candidate slow_accel" in flat(r.stdout)
    assert "no constant-speed segment" in (out / "report" / "index.html").read_text()


def test_a_simulation_that_runs_away_is_cached_as_such_and_the_batch_goes_on(tmp_path, monkeypatch):
    """A candidate's value (or a drawn calibrated one) can make the axis unstable: its carriage
    leaves the rails' modelled length and the batched simulation raises RailRangeError. The
    other scenarios of the batch are simulated alone and get their statistics; the runaway is
    cached as unfeaturisable with the reason (the calibrate benchmark's case 9 failed its whole
    diagnosis on one)."""
    from twin.harness.diagnosis import cache
    from twin.sim.campaign import runner
    from twin.sim.geometry import RailRangeError
    from twin.sim.scenario import load

    real = runner.simulate_campaigns_batched
    good, bad = load("quick"), load("quick").model_copy(update={"seed": 99})

    def batched(scenarios, outs):
        if any(s.seed == 99 for s in scenarios):
            raise RailRangeError("rail coordinate outside the stored profiles [-0.15, 0.465] m: [-120, 89]")
        return real(scenarios, outs)

    monkeypatch.setattr(runner, "simulate_campaigns_batched", batched)
    paths = cache.evaluate([good.to_json(), bad.to_json()], str(tmp_path))
    assert os.path.exists(paths[0]) and cache.unfeaturisable(paths[0]) is None
    assert not os.path.exists(paths[1])
    assert cache.unfeaturisable(paths[1]).startswith(
        "its simulation ran away (diverged, or the carriage left the rails'")
