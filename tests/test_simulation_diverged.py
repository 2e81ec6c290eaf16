"""A simulation that diverges is an error that names it, never a recording: MuJoCo resets a
diverged state and ``mujoco.rollout`` goes on from there, so the rows after it held no motion and
were written as if they did (a 3 kg carriage on the default trucks: ω·dt far above 2 at the
0.2 ms step)."""

import json
import math
import os
import subprocess

import numpy as np
import pytest
from conftest import REPO, TWIN

from twin.sim.scenario import load

SMALL = {"campaign.phase2": False, "campaign.warmup_hours": 0.0, "campaign.total_hours": 1.0,
         "phase1.sample_hours": [0.5], "phase1.captures_per_sample": 1, "phase1.capture_s": 2.0}
LIGHT = 3.0  # kg: the carriage the default trucks shake apart at the default time step


def _small(name: str, seed: int, mass_kg: float | None = None):
    from twin.sim.config import set_dotted
    from twin.sim.scenario import from_dict

    data = load("quick").model_dump(mode="json")
    for k, v in SMALL.items():
        set_dotted(data, k, v)
    if mass_kg is not None:
        set_dotted(data, "axis.carriage_mass_kg", mass_kg)
    data["name"], data["seed"] = name, seed
    return from_dict(data)


@pytest.fixture(autouse=True)
def _in_tmp(tmp_path, monkeypatch):
    """MuJoCo writes its warnings to MUJOCO_LOG.TXT in the working directory: here, not the repository."""
    monkeypatch.chdir(tmp_path)


def test_twin_simulate_refuses_a_scenario_that_diverges_naming_the_unit_and_writing_nothing(tmp_path):
    out = tmp_path / "run"
    sets = [x for k, v in SMALL.items() for x in ("--set", f"{k}={json.dumps(v)}")]
    proc = subprocess.run([*TWIN, "simulate", "quick", "-o", str(out), "--workers", "1", *sets,
                           "--set", f"axis.carriage_mass_kg={LIGHT}"], cwd=tmp_path, capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=str(REPO)))
    text = " ".join((proc.stdout + proc.stderr).split())
    assert proc.returncode == 2, text
    assert ("error: quick: phase1 unit c000000 of 'quick' (seed 1): the simulation diverged 1.8 ms into the "
            "standstill before the command (MuJoCo found a NaN, Inf or huge acceleration and reset the state): "
            "the axis is unstable at the time step of 0.2 ms") in text
    assert "change the scenario (the carriage's mass" in text
    assert not (out / "measurements.h5").exists()


def test_a_batch_of_campaigns_names_the_one_that_diverged(tmp_path):
    """Batched rollouts (the diagnosis's grids, the calibration's fit): the error says which
    campaign of the batch diverged (its position, its name and seed) and is a RailRangeError, the
    runaway the grids already cache as such."""
    from twin.sim.campaign import simulate_campaigns_batched
    from twin.sim.geometry import RailRangeError
    from twin.sim.simulate import SimulationDiverged

    good, bad = _small("steady", 1), _small("light", 2, LIGHT)
    with pytest.raises(SimulationDiverged, match=r"^phase1 unit c000000 of 'light' \(seed 2\): the simulation "
                                                 r"diverged 1\.8 ms into the standstill") as info:
        simulate_campaigns_batched([good, bad], [tmp_path / "a", tmp_path / "b"])
    assert info.value.items == [1] and info.value.t_s == pytest.approx(1.8e-3)
    assert isinstance(info.value, RailRangeError)


def test_a_calibration_point_that_diverges_has_no_statistics_and_its_batch_goes_on(tmp_path):
    """Layer (c)'s twin evaluations: a point that diverges (a step of the fit into an unstable
    axis) gets NaN statistics, cached with the reason, and the other points of its batch are
    simulated alone and get theirs (the fit's residual at a NaN is its largest)."""
    from twin.harness.calibration.twin_statistics import evaluate
    from twin.harness.calibration.values import STAT_NAMES

    good, bad = _small("steady", 1), _small("light", 2, LIGHT)
    rows = evaluate([good.to_json(), bad.to_json()], str(tmp_path / "cache"), None)
    inertia = STAT_NAMES.index("inertia")
    assert math.isfinite(rows[0][0][inertia]) and rows[0][0][inertia] > 0
    assert np.all(np.isnan(rows[1][0])) and np.all(np.isnan(rows[1][1]))
    cached = [json.loads(p.read_text()) for p in (tmp_path / "cache").glob("*.json")]
    errors = [c["error"] for c in cached if "error" in c]
    assert len(cached) == 2 and len(errors) == 1 and "'light' (seed 2): the simulation diverged" in errors[0]
    assert np.all(np.isnan(evaluate([bad.to_json()], str(tmp_path / "cache"), None)[0][0]))  # from the cache
