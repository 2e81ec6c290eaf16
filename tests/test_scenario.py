"""Bad scenarios exit with code 2 and one paragraph naming the key, the value and what is
allowed, without a traceback (check 12 of the twin issue)."""

import pytest
from conftest import REPO, run_twin

from twin.sim.scenario import ScenarioError, load

QUICK = REPO / "scenarios/quick.toml"

CASES = [
    (["--set", "axis.prelaod_N=1000"], ["axis.prelaod_N", "1000", "allowed keys in [axis]", "preload_N"]),
    (["--set", "phase2.runs_per_session=\"many\""], ["phase2.runs_per_session", "'many'", "integer"]),
    (["--set", "degradation.law=\"table\"", "--set", "degradation.table_hours=[0.0]",
      "--set", "degradation.table_preload_fraction=[1.0]", "--set", "degradation.table_backlash_um=[-3.0]"],
     ["degradation", "table_backlash_um", "-3.0", "negative backlash", ">= 0"]),
    (["--set", "axis.preload_N=5000"], ["`axis.preload_N` = 5000", "beyond the rated range", "2100"]),
    (["--set", "phase1.end_mm=500"], ["`phase1.end_mm` = 500", "beyond the travel", "450"]),
    (["--set", "phase1.fs_hz=0"], ["phase1.fs_hz", "= 0", ">= 2000"]),
    (["--set", "sensors.imu_acc_bias_ug=[1.0, 2.0]"], ["sensors.imu_acc_bias_ug", "[1.0, 2.0]", "at least 3"]),
    (["--set", "phase2.session_hours=[-5.0]"], ["`phase2.session_hours` = [-5.0]", "hours >= 0"]),
    (["--set", "phase1.sample_hours=[3.0, -1.0]"], ["`phase1.sample_hours` = [3.0, -1.0]", "hours >= 0"]),
    (["--set", "degradation.law=\"table\"", "--set", "degradation.table_hours=[10.0, 0.0]",
      "--set", "degradation.table_preload_fraction=[1.0, 1.0]", "--set", "degradation.table_backlash_um=[0.0, 1.0]"],
     ["`degradation.table_hours` = [10.0, 0.0]", "strictly increasing"]),
    (["--set", "campaign.warmup_hours=700"],
     ["`campaign.warmup_hours` = 700", "total_hours = 600", "warmup_hours <= total_hours"]),
    (["--set", "seed=4294967296"], ["seed", "4294967296", "<= 4294967295"]),
    (["--set", "sensors.imu_acc_fs_hz=0"], ["sensors.imu_acc_fs_hz", "0", "> 0"]),
    (["--set", "axis.friction_timeconst_ms=0.1"],
     ["axis.friction_timeconst_ms", "0.1", "shorter than two simulation steps", ">= 0.4 ms"]),
    (["--set", "axis.friction_impedance=1.0"], ["axis.friction_impedance", "1", "0.9999"]),
    (["--set", "phase2.start_flank=\"middle\""], ["phase2.start_flank", "middle", "'first'", "'last'"]),
    (["--set", "phase2.rail_passes=0"], ["phase2.rail_passes", "0", ">= 1"]),
]


@pytest.mark.parametrize("args,needles", CASES)
def test_bad_scenario_exits_2_with_message(tmp_path, args, needles):
    res = run_twin("simulate", QUICK, "-o", tmp_path / "x", *args, check=False)
    text = " ".join(res.stderr.split())
    print(text)
    assert res.returncode == 2
    assert "Traceback" not in res.stderr
    for needle in needles:
        assert needle in text, needle
    assert not (tmp_path / "x" / "measurements.h5").exists()


def test_unreadable_and_invalid_toml(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("seed = [1,\n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load(bad)
    with pytest.raises(ScenarioError, match="cannot read the scenario file"):
        load(tmp_path / "missing.toml")


def test_shipped_scenarios_load():
    for name in ("quick", "paper-rtf", "paper-reference"):
        s = load(REPO / f"scenarios/{name}.toml")
        assert s.name == name


def test_reduced_scale_is_one_override():
    from twin.sim.campaign import plan

    full = load(REPO / "scenarios/paper-rtf.toml")
    reduced = load(REPO / "scenarios/paper-rtf.toml", ["campaign.scale=0.1"])
    assert (full.captures_per_sample, full.runs_per_session) == (10, 90)
    assert (reduced.captures_per_sample, reduced.runs_per_session) == (1, 9)
    n_full = sum(u.kind == "phase1" for u in plan(full))
    n_reduced = sum(u.kind == "phase1" for u in plan(reduced))
    assert n_full == 10 * n_reduced
    # the same timeline: the same sessions and samples
    assert [u.hours for u in plan(full) if u.kind == "phase2"] == \
        [u.hours for u in plan(reduced) if u.kind == "phase2"]


def test_friction_constraint_keys():
    """axis.friction_timeconst_ms / friction_impedance set MuJoCo's friction constraint of the
    nut drag and the rails; unset, the MJCF carries no such attribute (MuJoCo's defaults)."""
    from twin.sim.model import build_mjcf, build_model
    from twin.sim.scenario import to_axis

    plain = load(QUICK)
    assert "solreffriction" not in build_mjcf(to_axis(plain), 2e-4)
    s = load(QUICK, ["axis.friction_timeconst_ms=0.4", "axis.friction_impedance=0.999"])
    m = build_model(to_axis(s), 2e-4)
    for joint in ("screw", "carriage_x"):
        dof = m.joint(joint).dofadr[0]
        assert list(m.dof_solref[dof]) == pytest.approx([4e-4, 1.0])
        assert list(m.dof_solimp[dof][:2]) == pytest.approx([0.999, 0.999])


def test_dial_tests_every_n_sessions_and_none():
    """`dial_indicator.every_n_sessions`: a dial test after sessions 0, n, 2n, ...; 0: none (the
    calibration's twin, which reads no dial)."""
    from twin.sim.campaign.planning import plan

    def dials(n: int) -> list[int]:
        s = load(REPO / "scenarios/backlash-steps.toml", [f"dial_indicator.every_n_sessions={n}"])
        return [u.index for u in plan(s) if u.kind == "dial"]

    assert dials(1) == [0, 1, 2, 3, 4, 5]
    assert dials(4) == [0, 4]
    assert dials(0) == []
