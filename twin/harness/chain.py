"""The whole chain on one campaign directory: simulate -> Phase I -> Phase II -> score.

Used by ``twin demo`` and by every point of ``twin sweep``, so both write the same files:

    DIR/measurements.h5, DIR/truth.h5        the simulated campaign (resumable)
    DIR/phase1/detection.json, ...           Phase I (if the campaign has Phase I samples and a
                                             reference data set is given)
    DIR/backlash/backlash.json, ...          Phase II (if the campaign has >= 2 sessions): the
                                             default estimator; DIR/backlash/<name>/ the others
    DIR/score.json                           both phases against truth.h5
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from analysis.dataset import open_measurements
from analysis.scoring import score, write_score
from twin.sim.campaign import simulate_campaign
from twin.sim.scenario import Scenario

__all__ = ["Analysed", "analyse", "run_point"]


@dataclass
class Analysed:
    """What :func:`analyse` ran. ``phase1``: the details of ``twin detect`` (or None, with the
    reason in ``skipped``); ``phase2``: the ``backlash.json`` object (or None); ``score``: the
    score.json object (None without truth.h5)."""

    phase1: dict | None = None
    phase2: dict | None = None
    score: dict | None = None
    skipped: dict[str, str] = field(default_factory=dict)


def analyse(directory: str | Path, reference: str | Path | None, *, plots: bool = True,
            process_noise: float | str = "ml", baseline_sessions: int = 1,
            on_step: Callable[[str], None] | None = None, methods: list[str] | None = None,
            estimators: list[str] | None = None) -> Analysed:
    """Run the analyses the campaign in ``directory`` supports, then score it if it has truth.

    Phase I needs more than the baseline samples (:data:`analysis.phase1.pipeline.N_BASELINE`)
    and a reference data set directory;
    Phase II needs two sessions. ``process_noise`` of the backlash trend defaults to maximum
    likelihood, since campaigns run at different time scales (the CLI default 1e-23 m²/h³ is
    tuned to the paper's 8000 h). ``methods``: detectors to run (registered names or
    ``module:Class``; default every registered one); ``estimators``: backlash estimators (default
    the registered default), each written to :func:`analysis.phase2.workflow.estimator_dir`.
    """
    from analysis.base import registry
    from analysis.phase1 import detect
    from analysis.phase2 import workflow

    directory = Path(directory)
    step = on_step or (lambda _: None)
    with open_measurements(directory / "measurements.h5") as m:
        n1, n2 = len(m.phase1_captures()), len(m.phase2_sessions())
    out = Analysed()
    if reference is None:
        out.skipped["phase1"] = "no reference data set"
    elif n1 == 0:
        out.skipped["phase1"] = "no Phase I captures"
    else:
        step("Phase I detection")
        out.phase1 = detect.run(directory, Path(reference), directory / "phase1", methods)
    if n2 < 2:
        out.skipped["phase2"] = f"{n2} Phase II session(s); 2 needed"
    else:
        for spec in estimators or [registry.default("backlash_estimators").name]:
            name = registry.get("backlash_estimators", spec).name
            step(f"Phase II backlash ({name})")
            doc = workflow.run(directory, workflow.estimator_dir(directory / "backlash", name),
                               plots=plots, process_noise=process_noise,
                               baseline_sessions=baseline_sessions, estimator=spec).doc
            out.phase2 = out.phase2 or doc
    if (directory / "truth.h5").is_file() and (out.phase1 or out.phase2):
        step("scoring")
        out.score = score(directory)
        write_score(directory, out.score)
    return out


def run_point(s: Scenario, directory: str | Path, reference: str | Path | None, *,
              plots: bool = False, process_noise: float | str = "ml",
              methods: list[str] | None = None, estimators: list[str] | None = None) -> dict:
    """Simulate ``s`` into ``directory`` in this process, analyse and score it.

    Returns ``{"simulated_units": n, "reused_units": m, "score": score.json object or None,
    "skipped": {phase: reason}}``; a campaign killed halfway resumes from its finished parts.
    """
    summary = simulate_campaign(s, directory, workers=1)
    a = analyse(directory, reference, plots=plots, process_noise=process_noise, methods=methods,
                estimators=estimators)
    return {"simulated_units": summary["simulated"], "reused_units": summary["skipped"],
            "score": a.score, "skipped": a.skipped}
