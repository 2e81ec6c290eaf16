"""The verb: ``twin calibrate``'s three layers on a recording, written as a scenario whose every
value says where it came from, and its JSON record.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from analysis.base.executors import default_processes
from analysis.base.files import write_json, write_text
from twin.harness.calibration.misfit import fit_misfit, misfit_sentence
from twin.harness.calibration.physical import fit_physical
from twin.harness.calibration.sensors import (
    corrected_sensor_values,
    datasheet_keys,
    floors_beyond_span,
    sensor_values,
)
from twin.harness.calibration.uncertainty import joint_covariance
from twin.harness.calibration.values import (
    CALIBRATE_VERSION,
    NOT_INFORMED,
    SENSOR_CHANNELS,
    CalibrationError,
    _progress,
    flagged_keys,
)
from twin.sim.config import set_dotted
from twin.sim.scenario import Scenario, ScenarioError, from_dict, load

# ---------------------------------------------------------------------------------------------
# The verb


def calibrate(recording: str | Path, out_toml: str | Path, *, budget_minutes: float | None = None,
              workers: int | None = None, scheduler: str | None = None, cache: str | Path | None = None,
              name: str | None = None, progress: Callable[[str], None] = _progress,
              check: dict | None = None, twin_with: Callable[[Scenario], Scenario] | None = None) -> dict:
    """Calibrate the twin to ``recording`` (a campaign directory) and write the scenario to
    ``out_toml`` with the provenance of every value, and ``<out_toml>.calibration.json`` (what
    was measured, fitted and left, the fit's residuals and time). ``check``: the record of ``twin
    check`` on the recording (the CLI refuses errors unless forced): a value whose channel it flags
    keeps the twin's default (:func:`flagged_keys`). ``twin_with``: applied to the twin layer (c)
    fits (an effect the twin carries while it fits, not written: the diagnosis's refit,
    :mod:`twin.harness.diagnosis.refit`). Returns that JSON's content."""
    from twin.sim.scenario_init import scenario_text

    t0 = time.perf_counter()
    recording = Path(recording)
    out_toml = Path(out_toml)
    budget_s = None if budget_minutes is None else float(budget_minutes) * 60.0
    if budget_s is not None and not budget_s > 0:
        raise CalibrationError(f"--budget-minutes {budget_minutes}: expected a positive number of minutes")
    workers = workers or default_processes()
    cache = Path(cache) if cache else out_toml.parent / ".calibrate-cache"
    progress("layer a: the routine and the layout from the recording's moves")
    text_a, notes = scenario_text(recording, name)
    base = _load_text(text_a)
    progress("layer b: the sensor chain from the rests")
    measured, sens_notes = sensor_values(recording, base)
    # a floor far above its instrument's kind is left for the diagnosis to name (with the keys
    # read on the same spectra), as a channel `twin check` flags is: the written scenario keeps
    # the scenario's value, but layer (c)'s twin reads the channel at the recording's floor, so
    # that the physical fit does not bend its parameters to make up for the excess noise
    beyond = floors_beyond_span(measured, base, datasheet_keys(recording))
    for key, why in beyond.items():
        progress(f"layer b: {key} kept at the scenario's value in the written scenario: {why}")
    data = base.model_dump(mode="json")
    for key, v in measured.items():
        set_dotted(data, key, float(f"{v.value:.6g}"), source="calibrate")
    base_b = from_dict(data)
    fit = fit_physical(twin_with(base_b) if twin_with else base_b, recording, cache / "fit", budget_s, workers,
                       scheduler, progress,
                       spent_s=time.perf_counter() - t0, sensors=measured, check=check)
    if fit.first_sensors:
        # the second step: the calibrated twin, set to the first step's floors, measured again
        sens = corrected_sensor_values(measured, fit.first_sensors, fit.instruments)
    else:  # no fit ran (no Phase I): the raw measurements with their own errors
        sens = corrected_sensor_values(measured, {}, {})
    values = sens + fit.values
    defaults = {k: why for k, why in NOT_INFORMED.items()}
    defaults.update(fit.skipped)
    flagged = {**beyond, **flagged_keys(check, SENSOR_CHANNELS)}  # layer (c)'s are in fit.skipped
    values = [v for v in values if v.key not in flagged]
    defaults.update(flagged)
    covariance = joint_covariance(fit.covariance, [v for v in sens if v.key not in flagged], set(flagged))
    misfit = fit_misfit(fit.residual, fit.statistics, len(fit.values), fit.chi2)
    if misfit:
        progress(f"layer c: {misfit_sentence(misfit)}")
    record = {"version": CALIBRATE_VERSION, "recording": str(recording.resolve()), "check": check,
              "covariance": covariance, "misfit": misfit,
              "values": [v.to_json() for v in values],
              "defaults": [{"key": k, "why": w} for k, w in defaults.items()],
              "notes": notes + sens_notes + ([fit.stopped] if fit.stopped else [])
              + ([misfit_sentence(misfit)] if misfit else []), "simulations": fit.simulations,
              "fit_seconds": fit.seconds, "chi2": fit.chi2, "residual_se": fit.residual,
              "residual_statistics": fit.statistics,
              "estimated_s": fit.estimated_s,
              "budget_s": budget_s, "stopped": fit.stopped}
    text, _ = scenario_text(recording, name, calibrated={v.key: (v.value, v.source, v.comment()) for v in values},
                            defaults=defaults, calibration=record)
    _load_text(text)
    write_text(out_toml, text)
    record["seconds"] = time.perf_counter() - t0
    write_json(out_toml.with_suffix(".calibration.json"), record, nan_as_null=True)
    progress(f"wrote {out_toml} ({len(values)} values measured or fitted, {len(defaults)} left at the "
             f"twin's default) in {record['seconds']:.1f} s")
    return record


def _load_text(text: str) -> Scenario:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "scenario.toml"
        p.write_text(text, encoding="utf-8")
        try:
            return load(p)
        except ScenarioError as exc:
            raise CalibrationError(f"the calibrated scenario does not load: {exc}") from None
