"""Layer (c)'s misfit: the chi-squared test of the fit's residuals, what the calibration writes
of it, and `twin diagnose` keeping the calibrated values fixed when the fit did not hold."""

from __future__ import annotations

import tomllib
import types

import numpy as np
import pytest

from twin.harness.calibration.misfit import MISFIT_P, fit_misfit, misfit_sentence

NAMES = ["inertia", "cruise_drag", "ripple", "accel", "dwell", "lateral_mode", "loop_response", "loop_ringing"]


def test_a_fit_the_twin_can_produce_is_called_a_misfit_at_the_tests_rate():
    """20 000 linear fits of 6 parameters to 8 statistics with standard normal errors (the twin
    can produce the recording): the residuals at each least-squares solution are called a misfit
    in 0.1 % of them (MISFIT_P; binomial standard deviation 0.022 %): the test counts the
    m − p = 2 degrees of freedom the fit leaves, not the 8 statistics (with 8 it would call
    none)."""
    rng = np.random.default_rng(7)
    jac = rng.normal(size=(8, 6))
    hits = 0
    for _ in range(20_000):
        e = rng.standard_normal(8)
        r = e - jac @ np.linalg.lstsq(jac, e, rcond=None)[0]
        hits += fit_misfit(r.tolist(), NAMES, 6) is not None
    assert 0.0003 < hits / 20_000 < 0.002
    assert MISFIT_P == 0.001


def test_a_twin_that_cannot_ring_as_the_recording_does_is_a_misfit_naming_what_it_left():
    """The residuals of a fit that could not match the IMU's ringing (a base resonance the twin
    lacks drives it: −10.1, +0.7, −0.1, −0.05, +0.1, +0.1, −3.5, +32.8 standard errors, 6
    parameters): a misfit (χ² 1 189 against 13.8 with 2 degrees of freedom), naming the
    statistics beyond the two-sided 0.1 % limit (3.29) largest first; one statistic 6 standard
    errors off (36 > 13.8) is one too, and 2 is not."""
    r = [-10.09, 0.68, -0.10, -0.05, 0.09, 0.13, -3.52, 32.78]
    m = fit_misfit(r, NAMES, 6)
    assert m["dof"] == 2 and m["critical"] == pytest.approx(13.8155, abs=1e-3)
    assert m["chi2"] == pytest.approx(float(np.dot(r, r)))
    assert [(s["statistic"], s["residual_se"]) for s in m["statistics"]] == [
        ("loop_ringing", 32.78), ("inertia", -10.09), ("loop_response", -3.52)]
    said = misfit_sentence(m)
    assert said.startswith("the twin could not match the recording: squared residuals 1.19e+03 over 2 degree(s) "
                           "of freedom, above the chi-squared limit 13.8 at p = 0.001; unmatched: the IMU's "
                           "ringing at the starts and stops (+32.8 standard errors), the torque's inertia in the "
                           "ramps (-10.1 standard errors), the velocity loop's response (-3.5 standard errors)")
    one = [0.0] * 7 + [6.0]
    assert fit_misfit(one, NAMES, 6)["statistics"] == [{"statistic": "loop_ringing", "residual_se": 6.0}]
    assert fit_misfit([0.0] * 7 + [2.0], NAMES, 6) is None
    # as many statistics as parameters: one degree of freedom (3.29² = 10.8 is the limit)
    assert fit_misfit([3.0, 0.0], NAMES[:2], 2) is None
    assert fit_misfit([3.5, 0.0], NAMES[:2], 2) is not None
    assert fit_misfit([], [], 0) is None


def test_residuals_and_statistics_of_different_lengths_are_refused():
    with pytest.raises(ValueError, match=r"^3 residuals for 2 statistics: expected one residual each$"):
        fit_misfit([0.0, 1.0, 2.0], NAMES[:2], 1)


def test_a_misfit_is_written_in_the_toml_and_the_diagnosis_keeps_the_calibrated_values_fixed():
    """The calibration record of a misfit written as the scenario's ``[calibration]`` table and read
    back: its ``misfit`` (χ², degrees of freedom, limit, the unmatched statistics) survives;
    `twin diagnose`'s entry says it (on the page too) and draws nothing, and the twin seeds keep
    the calibrated values, where the same record without the misfit draws them."""
    from analysis.diagnosis.gap_report import calibration_phrase
    from twin.harness.calibration.uncertainty import draw_calibrated
    from twin.harness.diagnosis.runner import calibration_entry
    from twin.sim.scenario_init import _calibration_table

    misfit = fit_misfit([-10.09, 0.68, -0.10, -0.05, 0.09, 0.13, -3.52, 32.78], NAMES, 6)
    record = {"version": 26, "recording": "/data/axis-7", "misfit": misfit,
              "values": [{"key": "axis.carriage_mass_kg", "value": 105.4, "source": "fitted", "low": 55.2,
                          "high": 201.2}],
              "defaults": [{"key": "axis.truck_stiffness_vertical_N_per_um", "why": "not informed"}],
              "covariance": {"keys": ["axis.carriage_mass_kg"], "log": [[0.1165]]}}
    table = tomllib.loads(_calibration_table(record))["calibration"]
    assert table["misfit"]["dof"] == 2 and table["misfit"]["critical"] == pytest.approx(13.8155, abs=1e-3)
    assert [s["statistic"] for s in table["misfit"]["statistics"]] == ["loop_ringing", "inertia", "loop_response"]
    entry = calibration_entry(types.SimpleNamespace(calibration=table, name="axis-7"), None, None)
    assert [v["key"] for v in entry["values"]] == ["axis.carriage_mass_kg"]
    assert entry["drawn"] == [] and entry["misfit"] == table["misfit"]
    assert "The calibration's fit: the twin could not match the recording" in entry["candidates"]
    assert "keeps the calibrated values fixed" in calibration_phrase({"calibration": entry})
    data = {"axis": {"carriage_mass_kg": 105.4}}
    assert draw_calibrated(data, table, 3) == {"axis": {"carriage_mass_kg": 105.4}}
    without = {k: v for k, v in table.items() if k != "misfit"}
    assert calibration_entry(types.SimpleNamespace(calibration=without, name="axis-7"), None, None)["drawn"] == [
        "axis.carriage_mass_kg"]
