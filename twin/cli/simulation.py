"""Verbs of the simulator and its harness: ``simulate``, ``score``, ``demo``, ``export-model``,
``sweep``, ``view`` and ``report``."""

from __future__ import annotations

import shlex
import sys
import time
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from twin.cli.common import (
    EXIT_INTERRUPTED,
    SCENARIOS,
    ScenarioOverrides,
    Scheduler,
    Workers,
    _fail,
    _one_executor,
    _require,
    _writable_dir,
    app,
    console,
)
from twin.sim.scenario import ScenarioError, load


def _run_simulation(scenario: Path, out: Path, overrides: list[str], workers: int | None,
                    scheduler: str | None = None) -> dict:
    from analysis.base.executors import ExecutorError
    from twin.sim.campaign import CampaignDirectoryError, CampaignInterrupted, plan, simulate_campaign
    from twin.sim.simulate import SimulationDiverged

    try:
        s = load(scenario, overrides)
    except ScenarioError as exc:
        _fail(str(exc))
    _writable_dir(out, "campaign directory")
    units = plan(s)
    n1 = sum(u.kind == "phase1" for u in units)
    n2 = sum(u.kind == "phase2" for u in units)
    console.print(f"scenario [bold]{s.name}[/]: {n1} Phase I captures, {n2} Phase II sessions "
                  f"x {s.runs_per_session} runs, {s.campaign.total_hours:g} h -> {out}")
    t0 = time.perf_counter()
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=False) as progress:
        task = progress.add_task("simulating", total=len(units))

        def on_progress(done: int, total: int, name: str) -> None:
            progress.update(task, completed=done, description=f"simulating {name}")

        try:
            summary = simulate_campaign(s, out, workers=workers, on_progress=on_progress,
                                        scheduler=scheduler)
        except (CampaignDirectoryError, ExecutorError) as exc:
            progress.stop()
            _fail(str(exc))
        except SimulationDiverged as exc:
            progress.stop()
            _fail(f"{scenario}: {exc}; change the scenario (the carriage's mass, the stiffnesses, the loops' "
                  "bandwidths, or phase1.timestep_s and phase2.timestep_s) and run again")
        except CampaignInterrupted as exc:
            progress.stop()
            _fail(f"interrupted: {exc.done} of {exc.total} units finished and kept in {out / '.parts'}, "
                  f"the other {exc.cancelled} cancelled; resume with: twin {shlex.join(sys.argv[1:])}",
                  code=EXIT_INTERRUPTED)
    summary["seconds"] = time.perf_counter() - t0
    summary["scenario"] = s
    return summary


@app.command()
def simulate(
    scenario: Path = typer.Argument(..., help="scenario TOML file, or a shipped scenario's name (quick)"),
    out: Path = typer.Option(..., "-o", "--out", help="campaign directory to write"),
    set_: ScenarioOverrides = (),
    workers: Workers = None,
    scheduler: Scheduler = None,
    live: bool = typer.Option(False, "--live", help="publish the units into OUT/live/ in time order, "
                              "as complete files, at their scaled times (the source of twin monitor)"),
    speedup: float = typer.Option(3600.0, "--speedup", min=1e-6, help="with --live: operating hours "
                                  "run this many times faster than real time (3600: an hour a second)"),
) -> None:
    """Simulate a campaign: writes OUT/measurements.h5 and OUT/truth.h5 (resumes if killed).
    SCENARIO is a TOML file or the name of a shipped scenario (quick, demo, paper-rtf, ...)."""
    _require("simulate", "sim", *(["cluster"] if scheduler is not None else []))
    _one_executor(scheduler, workers, "units")
    if live:
        from twin.sim.live import simulate_live

        try:
            s = load(scenario, set_)
        except ScenarioError as exc:
            _fail(str(exc))
        _writable_dir(out, "campaign directory")
        summary = simulate_live(s, out, speedup, on_unit=lambda i, n, m: console.print(
            f"published {i}/{n}: {m['kind']} {m['name']} at {m['hours']:g} h", highlight=False))
        console.print(f"{summary['published']} units published in {out / 'live'} "
                      f"({summary['seconds']:.1f} s); wrote {out / 'measurements.h5'} and {out / 'truth.h5'}")
        return
    summary = _run_simulation(scenario, out, set_, workers, scheduler)
    console.print(f"{summary['simulated']} units simulated ({summary['executor']}), "
                  f"{summary['skipped']} reused, {summary['seconds']:.1f} s; wrote {out / 'measurements.h5'} and "
                  f"{out / 'truth.h5'}")


REFERENCE_SMALL = ["phase1.captures_per_sample=2", "phase1.capture_s=4.0",
                   "phase1.sample_interval_hours=20"]


def _score_tables(doc: dict) -> list[Table]:
    """The summary tables of a score.json object (shared by ``twin score`` and ``twin demo``)."""
    from analysis.base.registry import label

    def fmt(v, f="{:g}"):
        return "-" if v is None else f.format(v)

    tables = []
    p1 = doc.get("phase1")
    if p1:
        onset = p1["onset_hours"]
        t = Table(title=f"Phase I: detection hour per method ({p1['n_samples']} samples, baseline "
                        f"{p1['n_baseline']}, injected onset {fmt(onset)} h)")
        for col in ("method", "detection h", "delay h", "delay samples", "false alarms / healthy"):
            t.add_column(col)
        for name, r in p1["methods"].items():
            t.add_row(r.get("label") or label("detectors", name), fmt(r["detection_hours"]), fmt(r["delay_hours"]),
                      fmt(r["delay_samples"]), f"{r['false_alarms']} / {r['healthy_test_samples']}")
        tables.append(t)
    p2 = doc.get("phase2")
    ests = doc.get("phase2_estimators") or {}
    if len(ests) > 1:
        t = Table(title="Phase II: every backlash estimator found, side by side (µm against the "
                        "injected change; h for the 10 µm crossing)")
        for col in ("estimator", "sessions", "RMS error µm", "largest µm", "bias µm",
                    "vs lost motion µm", "prognosis error h"):
            t.add_column(col)
        for name, r in ests.items():
            t.add_row(escape(f"{r.get('label') or name} [{name}]"), str(r["n_sessions"]),  # [name]: not markup
                      fmt(r["rms_error_um"], "{:.2f}"), fmt(r["max_abs_error_um"], "{:.2f}"),
                      fmt(r["bias_um"], "{:+.2f}"), fmt(r.get("rms_error_vs_lost_motion_um"), "{:.2f}"),
                      fmt((r.get("prognosis") or {}).get("error_hours"), "{:+.0f}"))
        tables.append(t)
    if p2:
        t = Table(title=f"Phase II ({p2.get('label') or p2.get('estimator') or 'shift'}): change of "
                        f"backlash against the injected one (RMS error "
                        f"{fmt(p2['rms_error_um'], '{:.2f}')} µm, largest "
                        f"{fmt(p2['max_abs_error_um'], '{:.2f}')} µm)")
        for col in ("session", "hours", "injected Δ µm", "estimated Δ µm", "error µm",
                    "lost-motion Δ µm", "error vs it µm", "dial Δ µm"):
            t.add_column(col)
        for r in p2["sessions"]:
            t.add_row(r["session"], fmt(r["hours"]), f"{r['injected_delta_um']:.2f}",
                      fmt(r["estimated_delta_um"], "{:.2f}"), fmt(r["error_um"], "{:+.2f}"),
                      fmt(r.get("injected_lost_motion_delta_um"), "{:.2f}"),
                      fmt(r.get("error_vs_lost_motion_um"), "{:+.2f}"),
                      fmt(r["dial_delta_um"], "{:.1f}"))
        tables.append(t)
        pr = p2["prognosis"]
        t = Table(title=f"Phase II: hour at which the change of backlash reaches {pr['limit_um']:g} µm")
        for col in ("predicted h", "injected h", "error h"):
            t.add_column(col)
        t.add_row(fmt(pr["predicted_crossing_hours"], "{:.0f}"), fmt(pr["true_crossing_hours"], "{:.0f}"),
                  fmt(pr["error_hours"], "{:+.0f}"))
        tables.append(t)
    return tables


def _print_score(doc: dict) -> None:
    out = Console(width=max(100, Console().width))
    for t in _score_tables(doc):
        out.print(t)


@app.command()
def score(
    directory: Path = typer.Argument(..., help="campaign directory with truth.h5 and the analyses' outputs"),
) -> None:
    """Score both phases against DIRECTORY/truth.h5: prints the tables and writes DIRECTORY/score.json.

    Reads DIRECTORY/phase1/detection.json (twin detect), DIRECTORY/backlash/backlash.json
    (twin backlash) and DIRECTORY/backlash/*/backlash.json (twin backlash --estimator NAME);
    either phase may be missing, not both. Every estimator found is scored side by side."""
    from analysis.dataset import DatasetError
    from analysis.scoring import ScoreError, write_score
    from analysis.scoring import score as score_dir

    try:
        doc = score_dir(directory)
    except (ScoreError, DatasetError) as exc:
        _fail(str(exc))
    _print_score(doc)
    console.print(f"wrote {write_score(directory, doc)}")


@app.command()
def demo(
    out: Path = typer.Option(Path("runs/demo"), "-o", "--out", help="where to write the demo"),
    set_: ScenarioOverrides = (),
    workers: Workers = None,
) -> None:
    """The whole chain on a small campaign (scenarios/demo.toml): simulate the Phase I reference
    data set and the campaign, run Phase I (Fisher selection, six detectors) and Phase II
    (backlash, trend), score both against the truth, write the report and a Rerun recording,
    and print the summary."""
    _require("demo", "sim", "view")
    from analysis.report import write_report
    from twin.harness.chain import analyse
    from twin.harness.view import write_recording

    t0 = time.perf_counter()
    _run_simulation(SCENARIOS / "paper-reference.toml", out / "reference", REFERENCE_SMALL, workers)
    _run_simulation(SCENARIOS / "demo.toml", out, set_, workers)
    with console.status("analysing") as status:
        def on_step(what: str) -> None:
            status.update(what)
            console.print(f"{what} ...")

        try:
            a = analyse(out, out / "reference", on_step=on_step)
        except (ValueError, FileNotFoundError) as exc:
            _fail(f"{exc} (anything computed before the error is in {out})")
        on_step("report")
        report = write_report(out)
        on_step("Rerun recording")
        recording = write_recording(out, out / "view.rrd").path
    for phase, why in a.skipped.items():
        console.print(f"note: {phase} skipped: {why}", style="yellow")
    if a.score is not None:
        _print_score(a.score)
    console.print(f"demo done in {time.perf_counter() - t0:.0f} s")
    for line in (f"  scores:    {out / 'score.json'}  (the same tables: twin score {out})",
                 f"  report:    {report}",
                 f"  recording: {recording}  (open with: rerun {recording}, or twin view {out} --serve)"):
        console.print(line, soft_wrap=True, markup=False, highlight=False)


@app.command("export-model")
def export_model(
    scenario: Path | None = typer.Argument(None, help="scenario TOML (default: the paper's axis)"),
    out: Path = typer.Option(Path("models/linear_axis.xml"), "-o", "--out"),
    timestep: float | None = typer.Option(None, help="time step, s (default: the Phase I step)"),
) -> None:
    """Write the MJCF of the axis in its new, healthy state: a complete model that holds still,
    e.g. to open in MuJoCo's viewer (`python -m mujoco.viewer --mjcf models/linear_axis.xml`)."""
    _require("export-model", "sim")
    from twin.sim.campaign import make_world
    from twin.sim.model import build_mjcf
    from twin.sim.scenario import Scenario, to_axis

    try:
        s = load(scenario) if scenario else Scenario()
    except ScenarioError as exc:
        _fail(str(exc))
    _writable_dir(out.parent)
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        text = build_mjcf(to_axis(s), timestep or s.phase1.timestep_s, make_world(s).base_mode)
    except ValueError as exc:  # a base too light for the time step
        _fail(str(exc))
    out.write_text(text)
    console.print(f"wrote {out}")



# --- twin sweep -----------------------------------------------------------------------------------
@app.command()
def sweep(
    sweep_file: Path = typer.Argument(..., help="sweep TOML file (see docs/usage.md and scenarios/sweeps/)"),
    out: Path | None = typer.Option(None, "-o", "--out", help="output directory (default: runs/sweeps/<file stem>)"),
    scheduler: Scheduler = None,
    workers: Workers = None,
    methods: str | None = typer.Option(None, "--methods",
                                       help="Phase I methods of the per-point summary, comma-separated, "
                                            "or 'all' (default: the sweep's [analysis] methods, else "
                                            "the default detector)"),
) -> None:
    """Run a sweep: every point and seed simulated, analysed and scored; writes OUT/results.parquet,
    OUT/results.csv and plots. Default executor: all local cores (processes). Resumes if interrupted."""
    _require("sweep", "sim", *(["cluster"] if scheduler is not None or workers is not None else []))
    from twin.harness.sweep import Callbacks, SweepError, method_summary, plan_sweep, run_sweep, summary

    if scheduler is not None and workers is not None:
        _fail("--scheduler and --workers exclude each other: --scheduler runs on an existing "
              "dask cluster, --workers N starts a local one")
    try:
        plan = plan_sweep(sweep_file)
    except SweepError as exc:
        _fail(str(exc))
    out = out or Path("runs/sweeps") / sweep_file.stem
    _writable_dir(out)
    n_tasks = len(plan.tasks)
    console.print(f"sweep [bold]{plan.name}[/]: {plan.n_points} points x {len(plan.seeds)} seeds = "
                  f"{n_tasks} campaigns of scenario {plan.base['name']} "
                  f"({', '.join(plan.columns) or 'no axes'}) -> {out}")
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=False) as progress:
        tasks: dict = {}

        def on_reference(done: int, total: int, name: str) -> None:
            if "ref" not in tasks:
                tasks["ref"] = progress.add_task("reference data set", total=total)
            progress.update(tasks["ref"], completed=done, description=f"reference data set {name}")

        def on_start(todo: int, total: int) -> None:
            tasks["pts"] = progress.add_task("points", total=total, completed=total - todo)

        def on_executor(description: str) -> None:
            progress.console.print(f"executor: {description}")

        def on_point(done: int, total: int, task, rec: dict) -> None:
            if rec["error"] is not None:
                progress.console.print(f"warning: point {task.id} failed: {rec['error']}",
                                       style="yellow", markup=False, highlight=False)
            progress.update(tasks["pts"], completed=done, description=f"points (last {task.id})")

        try:
            end = run_sweep(plan, out, workers=workers, scheduler=scheduler,
                            callbacks=Callbacks(executor=on_executor, reference=on_reference,
                                                start=on_start, point=on_point))
        except SweepError as exc:
            progress.stop()
            _fail(str(exc))
    import pandas as pd

    df = pd.read_parquet(out / "results.parquet")
    from analysis.base import registry
    from twin.harness.sweep.results import phase1_methods

    if methods == "all":
        shown = phase1_methods(df)
    elif methods:
        shown = [m.strip() for m in methods.split(",") if m.strip()]
    else:
        shown = [registry.get("detectors", m).name for m in plan.methods or []] or None
    try:
        header, rows = summary(plan, df, shown)
    except ValueError as exc:
        _fail(str(exc))
    table = Table(title=f"sweep {plan.name}: mean ± sd over seeds ({len(df)} rows)")
    for col in header:
        table.add_column(col)
    for row in rows:
        table.add_row(*row)
    out_console = Console(width=max(130, Console().width))
    out_console.print(table)
    header, rows = method_summary(df)
    if rows:
        table = Table(title=f"Phase I methods over all {len(df)} rows, at their own limits "
                            f"(curves over the limit: {out / 'roc.csv'})")
        for col in header:
            table.add_column(col)
        for row in rows:
            table.add_row(*row)
        out_console.print(table)
    console.print(f"{end['computed']} points computed, {end['reused']} reused, {end['failed']} failed; "
                  f"{end['simulated_units']} units simulated, {end['reused_units']} reused; "
                  f"{end['seconds']:.1f} s; wrote {out / 'results.parquet'}, {out / 'results.csv'} "
                  f"and {len(end['figures'])} figures")
    if end["failed"]:
        _fail(f"{end['failed']} point(s) failed (see the warnings and {out / 'sweep-log.jsonl'}); "
              "rerun the same command to retry them", code=1)
# --- end of twin sweep ----------------------------------------------------------------------------



# --- twin view ------------------------------------------------------------------------------------
@app.command()
def view(
    directory: Path = typer.Argument(..., help="campaign directory (measurements.h5; truth.h5, phase1/, "
                                               "backlash/ when present)"),
    save: Path | None = typer.Option(None, "--save", help="write the recording here "
                                                            "(default: DIRECTORY/view.rrd)"),
    serve: bool = typer.Option(False, "--serve", help="serve a web viewer instead and block until Ctrl-C"),
    session: str | None = typer.Option(None, "--session", help="Phase II session shown in 3D "
                                                                  "(default: the last)"),
    run_: str | None = typer.Option(None, "--run", help="run of that session (default: its first)"),
    capture: list[str] = typer.Option([], "--capture", help="Phase I capture(s) to show, repeatable "
                                                           "(default: the first and the last)"),
    exaggeration: float = typer.Option(2000.0, "--exaggeration",
                                       help="factor on the error motions in the 3D view"),
    web_port: int = typer.Option(9090, "--web-port", help="with --serve: port of the web viewer"),
    grpc_port: int = typer.Option(9876, "--grpc-port", help="with --serve: port of the data server"),
) -> None:
    """A Rerun recording of a campaign: the axis in 3D through one Phase II run with exaggerated
    error motions, the Phase I and Phase II sensor streams, the Phase I scores (T²) with their
    limits and the onset, backlash estimates against the truth and the dial indicator over
    operating hours, the scenario as properties. Parts whose inputs are missing are left out
    with a note (e.g. no truth.h5 on a real machine)."""
    _require("view", "view")
    from analysis.dataset import DatasetError
    from twin.harness.view import ViewError, serve_recording, write_recording

    if save is not None and serve:
        _fail("--save and --serve: give one of them (--save FILE.rrd writes a file, --serve serves a "
              "web viewer)")
    options = {"session": session, "run": run_, "captures": capture or None, "exaggeration": exaggeration}
    try:
        if serve:
            summary, url, rec = serve_recording(directory, web_port=web_port, grpc_port=grpc_port, **options)
        else:
            summary = write_recording(directory, save, **options)
    except (ViewError, DatasetError, FileNotFoundError) as exc:
        _fail(str(exc))
    except OSError as exc:  # e.g. a port in use, an unwritable --save
        _fail(f"{exc}")
    for note in summary.notes:
        console.print(f"note: {note}", style="yellow", markup=False, highlight=False, soft_wrap=True)
    what = (f"session {summary.session} run {summary.run} ({summary.hours:g} h), {summary.n_poses} poses, "
            f"error motions x{summary.exaggeration:g} from {summary.error_motion_source}"
            if summary.session else "no Phase II run")
    console.print(f"{what}; Phase I captures {', '.join(summary.captures) or '-'}; "
                  f"{len(summary.methods)} detector(s); {summary.backlash_sessions} backlash session(s)",
                  markup=False, highlight=False, soft_wrap=True)
    if not serve:
        console.print(f"wrote {summary.path} ({summary.size_bytes / 1e6:.1f} MB) in {summary.seconds:.1f} s; "
                      f"open it with: rerun {summary.path}", markup=False, highlight=False, soft_wrap=True)
        return
    console.print(f"serving the web viewer at {url} (Ctrl-C to stop)", markup=False, highlight=False, soft_wrap=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        rec.disconnect()
        console.print("stopped")
# --- end of twin view -----------------------------------------------------------------------------


# --- twin report ----------------------------------------------------------------------------------
@app.command()
def report(
    directory: Path = typer.Argument(
        ..., help="analysed campaign directory (truth.h5, phase1/, backlash/, score.json)"),
    out: Path | None = typer.Option(None, "-o", "--out", help="report folder (default: DIRECTORY/report)"),
) -> None:
    """HTML report: the scenario, the scores of both phases, and the paper's Table III and Figs. 6,
    10-13 side by side with ours. Writes OUT/index.html and the PNGs it shows into OUT/figures;
    computes DIRECTORY/score.json first if it is missing and truth.h5 is there."""
    from analysis.report import INPUT_ERRORS, render

    _writable_dir(out or directory / "report", "report folder")
    try:
        rep = render(directory, out)
    except INPUT_ERRORS as exc:
        _fail(str(exc))
    except OSError as exc:
        _fail(f"{out or directory / 'report'}: cannot write the report ({exc})")
    for note in rep.notes:
        console.print(note, markup=False, highlight=False)
    console.print(f"wrote {rep.index} with {len(rep.figures)} figures", markup=False, highlight=False)
# --- end of twin report ---------------------------------------------------------------------------

