"""Layer (c)'s misfit: the chi-squared test of the fit's residuals, what the calibration writes
of it, and `twin diagnose` keeping the calibrated values fixed when the fit did not hold."""

from __future__ import annotations

import tomllib
import types

import numpy as np
import pytest

from twin.harness.calibration.misfit import MISFIT_P, fit_misfit, misfit_sentence

NAMES = ["inertia", "cruise_drag", "ripple", "accel", "dwell", "lateral_mode", "loop_response", "loop_ringing"]


def _residuals(jac: np.ndarray, errors: np.ndarray) -> np.ndarray:
    """The least-squares residuals (n, m) of the errors ``errors`` (n, m) fitted by ``jac`` (m, p)."""
    return errors - errors @ np.linalg.pinv(jac).T @ jac.T


def _called(residuals: np.ndarray, n_fitted: int, chi2: np.ndarray | None = None) -> np.ndarray:
    """Whether each row of ``residuals`` (n, m), of χ² ``chi2`` (n,) (default Σ r²), is a misfit:
    the test's limit applied to every row at once, checked against :func:`fit_misfit` on the
    first 50."""
    chi2 = np.sum(residuals ** 2, axis=1) if chi2 is None else np.asarray(chi2)
    limit = _limit(max(residuals.shape[1] - n_fitted, 1))
    for r, c in zip(residuals[:50], chi2[:50], strict=True):
        assert (fit_misfit(r.tolist(), NAMES, n_fitted, float(c)) is not None) == bool(c > limit)
    return chi2 > limit


def _limit(dof: int) -> float:
    from scipy import stats

    return float(stats.chi2.isf(MISFIT_P, dof))


def test_a_fit_the_twin_can_produce_is_called_a_misfit_at_the_tests_rate():
    """20 000 linear fits of 6 parameters to 8 statistics with standard normal errors (the twin
    can produce the recording): the residuals at each least-squares solution are called a misfit
    in 0.1 % of them (MISFIT_P; binomial standard deviation 0.022 %): the test counts the
    m − p = 2 degrees of freedom the fit leaves, not the 8 statistics (with 8 it would call
    none)."""
    rng = np.random.default_rng(7)
    jac = rng.normal(size=(8, 6))
    rate = float(np.mean(_called(_residuals(jac, rng.standard_normal((20_000, 8))), 6)))
    assert 0.0005 < rate < 0.002
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
    assert said.startswith("the twin could not match the recording: χ² 1.19e+03 over 2 degree(s) of freedom (the "
                           "parameters kept at their start counted over their span), above the limit 13.8 at p = "
                           "0.001; unmatched: the IMU's ringing at the starts and stops (+32.8 standard errors), the "
                           "torque's inertia in the ramps (-10.1 standard errors), the velocity loop's response "
                           "(-3.5 standard errors)")
    one = [0.0] * 7 + [6.0]
    assert fit_misfit(one, NAMES, 6)["statistics"] == [{"statistic": "loop_ringing", "residual_se": 6.0}]
    assert fit_misfit([0.0] * 7 + [2.0], NAMES, 6) is None
    # as many statistics as parameters: one degree of freedom (3.29² = 10.8 is the limit)
    assert fit_misfit([3.0, 0.0], NAMES[:2], 2) is None
    assert fit_misfit([3.5, 0.0], NAMES[:2], 2) is not None
    assert fit_misfit([], [], 0) is None


def test_a_parameter_kept_at_its_default_is_counted_over_its_span_not_called_a_misfit():
    """20 000 linear fits of 5 parameters to 8 statistics whose errors hold, beside their own
    standard normal ones, a kept parameter's draw over its span (log standard deviation 0.76,
    the rails' friction's factor 3.5 at 90 %) through a column moving the statistics by 2 to 6
    standard errors per unit of log: Σ r² calls over 30 % of them a misfit, the χ² with the kept
    span counted (:func:`profiled_chi2`) 0.1 %. A residual the kept parameter cannot make (the
    direction no column has) is still one."""
    from twin.harness.calibration.misfit import profiled_chi2

    rng = np.random.default_rng(11)
    jac = rng.normal(size=(8, 5))
    kept = rng.uniform(2.0, 6.0, size=(8, 1)) * rng.choice([-1.0, 1.0], size=(8, 1))
    var = np.array([0.76 ** 2])
    errors = rng.standard_normal((20_000, 8)) + np.outer(rng.normal(0.0, 0.76, 20_000), kept[:, 0])
    r = _residuals(jac, errors)
    assert float(np.mean(_called(r, 5))) > 0.3
    profiled = [profiled_chi2(x, jac, kept, var) for x in r[:50]]
    # the same χ² for every row at once: whitened by C = I + A·P·Aᵀ, projected off the fitted columns
    low = np.linalg.cholesky(np.eye(8) + var[0] * kept @ kept.T)
    rw, jw = np.linalg.solve(low, r.T).T, np.linalg.solve(low, jac)
    chi2 = np.sum(_residuals(jw, rw) ** 2, axis=1)
    assert chi2[:50] == pytest.approx(profiled, rel=1e-9)
    assert 0.0005 < float(np.mean(_called(r, 5, chi2))) < 0.002
    # a residual of 20 standard errors orthogonal to every column: a misfit whatever the span
    q = np.linalg.qr(np.column_stack([jac, kept]), mode="complete")[0][:, -1]
    assert fit_misfit((20 * q).tolist(), NAMES, 5, profiled_chi2(20 * q, jac, kept, var))["chi2"] == pytest.approx(
        400.0, rel=1e-9)
    assert profiled_chi2(np.zeros(0), np.zeros((0, 0)), np.zeros((0, 0)), np.zeros(0)) == 0.0


def test_residuals_and_statistics_of_different_lengths_are_refused():
    with pytest.raises(ValueError, match=r"^3 residuals for 2 statistics: expected one residual each$"):
        fit_misfit([0.0, 1.0, 2.0], NAMES[:2], 1)


def test_a_misfit_is_written_in_the_toml_and_said_by_the_diagnosis():
    """The calibration record of a misfit written as the scenario's ``[calibration]`` table and read
    back: its ``misfit`` (χ², degrees of freedom, limit, the unmatched statistics) survives;
    `twin diagnose`'s entry carries it and says it (on the page too), and its twin seeds still
    draw the calibrated values (keeping them fixed turned a null whose misfit came from a value
    kept at its default into a false gap, and named no effect where an effect was behind it)."""
    from analysis.diagnosis.gap_report import calibration_phrase
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
    assert [(m["statistic"], m["residual_se"]) for m in table["misfit"]["statistics"]] == [
        ("loop_ringing", 32.78), ("inertia", -10.09), ("loop_response", -3.52)]
    entry = calibration_entry(types.SimpleNamespace(calibration=table, name="axis-7"), None, None)
    assert [v["key"] for v in entry["values"]] == ["axis.carriage_mass_kg"]
    assert entry["drawn"] == ["axis.carriage_mass_kg"] and entry["misfit"] == table["misfit"]
    said = calibration_phrase({"calibration": entry})
    assert "The calibration's fit: the twin could not match the recording: χ² 1.19e+03" in said
    assert said.endswith("a gap behind the misfit may be taken in part by the calibrated values, or hidden in "
                         "their spread.")
    without = {k: v for k, v in table.items() if k != "misfit"}
    plain = calibration_entry(types.SimpleNamespace(calibration=without, name="axis-7"), None, None)
    assert plain["misfit"] is None and "could not match" not in plain["candidates"]
