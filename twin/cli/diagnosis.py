"""Verbs of the sim-to-real gap: ``calibrate`` and ``calibrate-benchmark`` (the twin fitted to
a recording), ``diagnose`` and ``diagnose-benchmark``."""

from __future__ import annotations

import math
import time
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from twin.cli.common import (
    SCENARIOS,
    Force,
    ResponseSeeds,
    ScenarioOverrides,
    Scheduler,
    TwinSeeds,
    Workers,
    _fail,
    _one_executor,
    _require,
    _writable_dir,
    app,
    console,
    gate_recording,
    record_check,
)
from twin.sim.scenario import ScenarioError, load


@app.command("calibrate-benchmark")
def calibrate_benchmark(
    out: Path = typer.Option(..., "-o", "--out", help="output directory"),
    cases: int = typer.Option(24, "--cases", min=1, help="foreign axes drawn"),
    seed: int = typer.Option(2026, "--seed", min=0, help="seed of the draws"),
    diagnose: bool = typer.Option(False, "--diagnose/--no-diagnose", help=(
        "also diagnose each recording against its calibrated twin (the right verdict: no significant gap)")),
    seeds: TwinSeeds = 6,
    workers: Workers = None,
    fresh: bool = typer.Option(False, "--fresh", help=(
        "run every case again (default: a case already in OUT with the same draw, options and "
        "versions is kept)")),
    first: int = typer.Option(0, "--first", min=0, help=(
        "run only the cases from this index on (those before it are taken from OUT when kept): "
        "a benchmark split between processes or machines")),
    kept: Path | None = typer.Option(None, "--kept", help=(
        "a directory of recorded case entries (case-NNN.json, e.g. benchmarks/results/calibrate-benchmark): "
        "a case recorded there with the same draw, options and versions is taken, not run")),
) -> None:
    """The round trip of `twin calibrate`, blind: foreign axes drawn from a seed, simulated, written
    out as a lab's files (CSV, TDMS, MAT, MDF in turn), imported, calibrated (and diagnosed),
    scored against the draws. Writes OUT/calibrate-benchmark.json; stopped and run again, it goes
    on from the cases already done."""
    _require("calibrate-benchmark", "sim")
    from analysis.base.executors import default_processes
    from twin.harness.calibration.benchmark import run_benchmark

    _writable_dir(out)
    if first >= cases:
        _fail(f"--first {first}: expected an index below --cases {cases} (the cases are 0 to {cases - 1})")
    if kept is not None and not kept.is_dir():
        _fail(f"--kept {kept}: not a directory; expected one holding recorded case entries (case-NNN.json)")
    doc = run_benchmark(out, cases=cases, seed=seed, workers=workers or default_processes(), diagnose=diagnose,
                        seeds=seeds, resume=not fresh, first=first, kept_dir=kept,
                        progress=lambda t: console.print(t, markup=False, highlight=False, soft_wrap=True))
    sm = doc["summary"]
    table = Table(title=f"calibrate-benchmark: {sm['cases']} foreign axes (seed {seed})", title_justify="left")
    table.add_column("figure")
    table.add_column("value", justify="right")
    table.add_row("routine values within 0.1 % (or a sample)", f"{100 * sm['routine_within']:.0f} %")
    table.add_row("(case, parameter) pairs inside the 90 % interval",
                  f"{100 * sm['parameters_inside']:.0f} % of {sm['parameter_pairs']}")
    for k, v in sm["per_parameter_inside"].items():
        table.add_row(f"  {k}", f"{100 * v:.0f} %")
    n = sm.get("per_kind_cases", {})
    for key, words, kind in (("null_no_gap", "nulls: no significant gap", "null"),
                             ("effect_named_first", "one effect: named first", "effect"),
                             ("artefact_named_first", "one artefact: named first", "artefact"),
                             ("several_all_named", "several: effect and artefact named", "several"),
                             ("several_nothing_else", "several: nothing else named", "several")):
        if sm.get(key) is not None:
            table.add_row(f"diagnosis, {words}", f"{100 * sm[key]:.0f} % of {n.get(kind, 0)}")
    if sm.get("median_shrink_resimulated_named") is not None:
        table.add_row("diagnosis, re-simulated shrink (named, median)",
                      f"{100 * sm['median_shrink_resimulated_named']:.0f} %")
    if sm.get("diagnosis_failed"):
        table.add_row("diagnosis failed (cases)", ", ".join(map(str, sm["diagnosis_failed"])))
    table.add_row("formats", ", ".join(sm["formats_used"]))
    if sm["calibrate_s_median"] is not None:
        table.add_row("calibration, median", f"{sm['calibrate_s_median']:.0f} s")
    Console(width=max(100, Console().width)).print(table)
    console.print(f"wrote {out / 'calibrate-benchmark.json'} ({doc['seconds'] / 60:.1f} min)")



@app.command()
def calibrate(
    directory: Path = typer.Argument(..., help="campaign directory of the recording (imported or simulated)"),
    out: Path = typer.Option(..., "-o", "--out", help="scenario file to write (TOML)"),
    name: str | None = typer.Option(None, "--name", help="scenario name (default: the directory's name)"),
    budget_minutes: float | None = typer.Option(None, "--budget-minutes", help=(
        "the longest the calibration may take: it refuses after timing its first simulations, "
        "with its estimate and the smallest budget that would do")),
    workers: Workers = None,
    scheduler: Scheduler = None,
    cache: Path | None = typer.Option(None, "--cache", help="simulation cache (default: beside OUT)"),
    force: Force = False,
) -> None:
    """The twin fitted to a recording, in three layers: the routine and layout (measured), the
    sensor chain (measured at rest), the drive's mass, drags and torque ripple, the trucks'
    stiffnesses, the velocity loop and the Phase I acceleration (fitted jointly through the twin,
    each with its 90 % interval). With --budget-minutes the fit stops at the budget. Every value of
    the written scenario says where it came from; what the recording cannot inform keeps the
    twin's default and says why. Then: twin diagnose DIRECTORY --scenario OUT."""
    _require("calibrate", "sim", *(["cluster"] if scheduler is not None else []))
    _one_executor(scheduler, workers, "simulations")
    if budget_minutes is not None and not (math.isfinite(budget_minutes) and budget_minutes > 0):
        _fail(f"--budget-minutes {budget_minutes:g}: expected a positive number of minutes")
    from analysis.dataset import DatasetError
    from twin.harness.calibration import CalibrationError
    from twin.harness.calibration import calibrate as run_calibration

    if out.exists() and out.is_dir():
        _fail(f"-o {out}: is a directory; expected a scenario file path (e.g. {out / 'axis.toml'})")
    checked = gate_recording(directory, force, "calibrate")
    try:
        rec = run_calibration(directory, out, budget_minutes=budget_minutes, workers=workers,
                              scheduler=scheduler, cache=cache, name=name, check=checked)
    except (CalibrationError, DatasetError, FileNotFoundError, OSError) as exc:
        _fail(str(exc))
    except ScenarioError as exc:
        _fail(f"the scenario measured from {directory} cannot be written: {exc}")
    table = Table(title="calibrated values", title_justify="left")
    for col in ("key", "value", "90 % interval", "source"):
        table.add_column(col)
    for v in rec["values"]:
        iv = f"{v['low']:.4g} to {v['high']:.4g}" if v["low"] is not None else ""
        table.add_row(v["key"], f"{v['value']:.6g}", iv, v["source"])
    Console(width=max(120, Console().width)).print(table)
    for d in rec["defaults"]:
        console.print(f"twin default: {d['key']} ({d['why']})", markup=False, highlight=False)
    for n in rec["notes"]:
        console.print(f"note: {n}", style="yellow", markup=False, highlight=False)
    console.print(f"wrote {out} and {out.with_suffix('.calibration.json')} in {rec['seconds']:.0f} s; "
                  f"next: twin diagnose {directory} --scenario {out}", markup=False, highlight=False)




# --- twin diagnose --------------------------------------------------------------------------------
def _progress_callback(progress: Progress, tasks: dict):
    def on_progress(what: str, done: int, total: int) -> None:
        if what not in tasks:
            tasks[what] = progress.add_task(what, total=total)
        progress.update(tasks[what], completed=done)
    return on_progress


def _print_diagnosis(res: dict) -> None:
    from analysis.diagnosis.wording import added_phrase, check_phrase, refused_phrase, subset_phrase

    out = Console(width=max(110, Console().width))
    if res.get("subset"):
        out.print(subset_phrase(res), markup=False, highlight=False)
    if res.get("found_by_check"):
        out.print(f"found by twin check: {check_phrase(res)}", markup=False, highlight=False)
    out.print(f"[bold]{res['verdict']}[/]: {res['n_significant_calibration']} of "
              f"{res['n_statistics']} statistics beyond the twin's seed-to-seed spread on the "
              f"calibration part (Holm, α = {res['alpha']:g}); held-out gap "
              f"{res['heldout_gap_before']:.1f} (critical {res['heldout_gap_critical']:.1f})")
    sig = [r for r in res["regions"] if r["significant"]][:4]
    if sig:
        out.print("where: " + "; ".join(
            f"{r['domain']} {r['channel']} {r['family']} {r['bin']} (mean t² {r['calibration_gap']:.0f})"
            for r in sig))
    hours = sorted(res.get("hours", []), key=lambda h: -h["heldout_gap_before"])
    if hours and res["verdict"] != "no significant gap":
        out.print("when: " + ", ".join(f"{h['hours']:g} h (mean t² {h['heldout_gap_before']:.0f})"
                                       for h in hours[:3]) + " (held-out, worst first)")
    for i, a in enumerate(res["added"]):
        pars = ", ".join(f"{k} = {v:.3g} [{a['interval'][k][0]:.3g}, {a['interval'][k][1]:.3g}]"
                         + (f" at the {a['at_grid_edge'][k]} edge of its grid"
                            if a.get("at_grid_edge", {}).get(k) else "")
                         for k, v in a["params"].items())
        kind = res.get("library", {}).get(a["effect"], {}).get("kind", "physical effect")
        word = {"physical effect": "effect", "parameter": "parameter"}.get(kind, "artefact")
        out.print(f"{word} {i + 1}: "
                  f"[bold]{a['effect']}[/] ({kind}; {pars}): held-out gap "
                  f"{a['heldout_gap_before']:.1f} -> {a['heldout_gap_after']:.1f} "
                  f"(-{100 * a['heldout_reduction']:.0f} %, gain {a['gain']:.1f} > {a['gain_threshold']:.1f})")
        out.print(f"  in words: {added_phrase(res, a)}", markup=False, highlight=False)
    for r in res.get("refused", []):
        out.print(f"refused: {refused_phrase(res, r)}", markup=False, highlight=False)
    for name, why in res.get("candidates_left_out", {}).items():
        out.print(f"left out: candidate {name}: {why}", markup=False, highlight=False)
    if res["ranking"] and not res["added"] and not res.get("refused"):
        best = res["ranking"][0]
        out.print(f"no candidate (physical effect, twin parameter or signal artefact) reduces the held-out gap "
                  f"significantly (best: {best['effect']}, {best.get('kind', 'physical effect')}, "
                  f"-{100 * best['heldout_reduction']:.0f} %)")
    if res["verdict"] != "no significant gap":
        rs = res.get("resimulation") or {}
        residual = rs["residual"] if rs.get("done") else res["residual"]
        resim = (f"re-simulated with {rs['seeds']} twin seeds -> {rs['heldout_gap_after']:.1f} "
                 f"(shrink {100 * rs['heldout_shrink']:.0f} %)" if rs.get("done")
                 else f"no re-simulation: {rs.get('reason') or 'nothing was added'}")
        out.print(f"held-out gap {res['heldout_gap_before']:.1f} -> {res['heldout_gap_after']:.1f} "
                  f"interpolated (shrink {100 * res['heldout_shrink']:.0f} %); {resim}"
                  + ("; still beyond the spread: " + "; ".join(
                      f"{r['domain']} {r['channel']} {r['family']} {r['bin']}"
                      for r in residual.get("top_regions", [])[:3])
                     if residual.get("significant") else ""))
    if res.get("refit"):
        from analysis.diagnosis.gap_report import refit_phrase

        out.print(refit_phrase(res).strip(), markup=False, highlight=False)
    if res.get("worse_regions"):
        out.print("made worse by the added effects (held-out): " + "; ".join(
            f"{r['domain']} {r['channel']} {r['family']} {r['bin']} (mean t² "
            f"{r['heldout_gap_before']:.1f} -> {r['heldout_gap_after']:.1f})"
            for r in res["worse_regions"][:3]))


@app.command()
def diagnose(
    real_dir: Path = typer.Argument(..., help="directory with the recording's measurements.h5 (no truth needed)"),
    scenario: Path = typer.Option(..., "--scenario", help="the scenario meant to describe the recorded axis"),
    out: Path | None = typer.Option(None, "-o", "--out", help="output directory (default REAL_DIR/diagnosis)"),
    overrides: ScenarioOverrides = (),
    seeds: TwinSeeds = 8,
    alpha: float = typer.Option(0.01, "--alpha", min=1e-9, max=0.5, help="family-wise error rate"),
    workers: Workers = None,
    cache: Path | None = typer.Option(None, "--cache", help="simulation cache (default OUT/cache)"),
    candidates: list[str] = typer.Option(
        [], "--candidate", help="a candidate the diagnosis may add (repeatable; default: every "
                                "candidate of --kinds): a name (an effect, a twin parameter, a "
                                "signal artefact) or module:NAME of an Effect"),
    kinds: str | None = typer.Option(None, "--kinds", help=(
        "kinds of candidate, comma-separated: physical (the registered effects), parameter (twin "
        "parameters set wrong: 60 more simulations per response seed, docs/gap-diagnosis.md), artefact (signal "
        "artefacts); default physical,artefact; --candidate wins")),
    scheduler: Scheduler = None,
    resim_seeds: int | None = typer.Option(None, "--resim-seeds", min=0, help=(
        "twin seeds the twin is re-simulated with, the added candidates at their fitted values, "
        "for the re-simulated shrink the verdict follows (default: all --seeds; 0: none, the "
        "verdict then follows the interpolated shrink)")),
    response_seeds: ResponseSeeds = 3,
    budget_minutes: float | None = typer.Option(None, "--budget-minutes", help=(
        "diagnose a subset of the recording that fits this time (samples and sessions spread "
        "over its hours, the first captures and runs of each; the costs measured on this "
        "machine at the start): for a campaign-sized recording. Default: the whole recording")),
    refit_effects: int = typer.Option(1, "--refit-effects", min=0, help=(
        "against a calibrated scenario, when the gap stays unexplained: the leading physical effects "
        "the calibration is fitted again with (each in the twin: a calibration and a one-candidate "
        "diagnosis per size of its grid; 0: none; not with --budget-minutes)")),
    force: Force = False,
) -> None:
    """Where the twin and the recording differ, which candidate explains it (a physical effect
    of the library, a twin parameter set wrong, a signal artefact), and how far the gap shrinks
    once it is added (held-out data). Writes OUT/diagnosis.json and OUT/report/ (gap maps
    before and after)."""
    _require("diagnose", "sim", *(["cluster"] if scheduler is not None else []))
    _one_executor(scheduler, workers, "simulations")
    if budget_minutes is not None and not (math.isfinite(budget_minutes) and budget_minutes > 0):
        _fail(f"--budget-minutes {budget_minutes:g}: expected a positive number of minutes (the time "
              "the diagnosis may take)")
    from analysis.dataset import DatasetError
    from twin.harness.calibration.uncertainty import check_drawable
    from twin.harness.diagnosis.ensemble import check_response_seeds
    from twin.harness.diagnosis.library import check_kinds, resolve_library
    from twin.harness.diagnosis.runner import run_diagnosis

    try:
        s = load(scenario, overrides)
    except ScenarioError as exc:
        _fail(str(exc))
    try:  # an option out of range, or a calibration drawn too wide, is refused before the recording is read
        check_response_seeds(response_seeds, seeds)
        check_drawable(s.calibration, f"--scenario {scenario}")
    except ValueError as exc:
        _fail(str(exc))
    try:
        kind_list = check_kinds(None if kinds is None else [k.strip() for k in kinds.split(",") if k.strip()])
    except ValueError as exc:
        _fail(f"--kinds {kinds}: {exc}")
    try:  # an unknown candidate is refused before the recording is read
        resolve_library(list(candidates) or None, kind_list)
    except ValueError as exc:
        _fail(str(exc))
    out = out or real_dir / "diagnosis"
    _writable_dir(out)
    checked = gate_recording(real_dir, force, "diagnose")
    console.print(f"diagnosing {real_dir} against scenario [bold]{s.name}[/] "
                  f"({seeds} twin seeds) -> {out}")
    t0 = time.perf_counter()
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=False) as progress:
        cb = _progress_callback(progress, {})
        try:
            res = run_diagnosis(real_dir, s, out, seeds=seeds, workers=workers, alpha=alpha,
                                cache=cache, library=list(candidates) or None,
                                on_progress=lambda d, n: cb("simulations", d, n), kinds=kind_list,
                                scheduler=scheduler, resim_seeds=resim_seeds,
                                on_resim_progress=lambda d, n: cb("re-simulation with the added candidates", d, n),
                                budget_minutes=budget_minutes, response_seeds=response_seeds, check=checked,
                                refit_effects=refit_effects, progress=lambda t: progress.console.print(
                                    t, markup=False, highlight=False))
        except (DatasetError, ValueError) as exc:
            progress.stop()
            _fail(str(exc))
    record_check(out / "diagnosis.json", checked)
    _print_diagnosis(res)
    console.print(f"{time.perf_counter() - t0:.1f} s; wrote {out / 'diagnosis.json'} and "
                  f"{out / 'report' / 'index.html'}")


@app.command("diagnose-benchmark")
def diagnose_benchmark(
    out: Path = typer.Option(Path("runs/diagnose-benchmark"), "-o", "--out"),
    scenario: Path = typer.Option(SCENARIOS / "diagnose-bench.toml", "--scenario",
                                  help="nominal scenario of the benchmark"),
    per_cell: int = typer.Option(1, "--per-cell", min=1, help="cases per effect and magnitude"),
    nulls: int = typer.Option(10, "--nulls", min=0),
    open_set: int = typer.Option(5, "--open-set", min=0),
    pairs: int = typer.Option(5, "--pairs", min=0),
    artefacts: int = typer.Option(1, "--artefacts", min=0,
                                  help="cases per signal artefact and magnitude (0: none)"),
    parameters: int = typer.Option(1, "--parameters", min=0, help=(
        "cases per twin parameter and magnitude (0: none, and the diagnosis leaves the twin "
        "parameters out of its candidates)")),
    edits: int = typer.Option(2, "--edits", min=0, help=(
        "cases per recording edit no candidate models (impulses, lost samples, a low-pass; 0: "
        "none)")),
    rng_seed: int = typer.Option(2026, "--rng-seed", help="seed of the case plan"),
    seeds: TwinSeeds = 8,
    workers: Workers = None,
    resim_seeds: int = typer.Option(2, "--resim-seeds", min=0, help=(
        "twin seeds each case with candidates added is re-simulated with, for the re-simulated "
        "shrink and the verdict (0: none; fewer than --seeds: that many campaigns per case)")),
    response_seeds: ResponseSeeds = 3,
) -> None:
    """The blind benchmark: recordings with withheld effects (or none), diagnosed against the
    nominal scenario and scored; writes OUT/benchmark.json and OUT/benchmark_cases.csv."""
    _require("diagnose-benchmark", "sim")
    from twin.harness.diagnosis.benchmark import plan_cases, run_benchmark
    from twin.harness.diagnosis.ensemble import check_response_seeds

    try:
        check_response_seeds(response_seeds, seeds)
    except ValueError as exc:
        _fail(str(exc))

    try:
        s = load(scenario)
    except ScenarioError as exc:
        _fail(str(exc))
    cases = plan_cases(rng_seed, per_cell, nulls, open_set, pairs, artefacts_per_cell=artefacts,
                       parameters_per_cell=parameters, edits_per_cell=edits)
    console.print(f"benchmark of the gap diagnosis: {len(cases)} cases on scenario "
                  f"[bold]{s.name}[/] -> {out}")
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=False) as progress:
        res = run_benchmark(out, s, cases, seeds=seeds, workers=workers,
                            on_progress=_progress_callback(progress, {}), resim_seeds=resim_seeds,
                            response_seeds=response_seeds)
    fmt = lambda v: "-" if v is None else f"{100 * v:.0f} %"  # noqa: E731
    table = Table(title=f"blind benchmark ({res['n_cases']} cases, {res['wall_time_s']['total']:.0f} s)")
    for col in ("case", "injected", "magnitude", "verdict", "first ranked", "added", "held-out shrink",
                "re-simulated", "correct"):
        table.add_column(col)
    for r in res["cases"]:
        table.add_row(r["id"], "+".join(r["injected"]) or "-", r["magnitude"] or "-", r["verdict"],
                      r["ranking"][0] if r["ranking"] else "-", "+".join(r["added"]) or "-",
                      f"{100 * r['heldout_shrink']:.0f} %",
                      fmt(r["heldout_shrink_resimulated"]),
                      "yes" if r["correct"] else "NO")
    Console(width=max(130, Console().width)).print(table)
    resim = (f"re-simulated with {res['resim_seeds']} twin seeds {fmt(res['median_heldout_shrink_resimulated'])}"
             if res["resim_seeds"] else "not re-simulated")
    console.print(f"top-1 accuracy {fmt(res['top1_accuracy'])}, median held-out shrink "
                  f"{fmt(res['median_heldout_shrink'])} ({resim}), null cases correct "
                  f"{fmt(res['null_correct_fraction'])}, open-set unexplained "
                  f"{fmt(res['open_set_correct_fraction'])} (and no wrong effect removing half "
                  f"the gap: {fmt(res['open_set_no_wrong_effect_fraction'])}), out of everything "
                  f"(physics withheld, recording edits) unexplained "
                  f"{fmt(res['out_of_everything_unexplained_fraction'])}, false attributions "
                  f"{fmt(res['false_attribution_rate'])}, pairs both in top 3 "
                  f"{fmt(res['pair_both_top3_fraction'])}; top-1 per kind: "
                  + ", ".join(f"{k} {fmt(v)}" for k, v in res["per_kind_top1"].items() if v is not None)
                  + f"; wrote {out / 'benchmark.json'}")
# --- end of twin diagnose -------------------------------------------------------------------------


