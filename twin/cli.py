"""The ``twin`` command line, the face of the tool: ``simulate`` and ``export-model`` (the
simulator), ``detect`` and ``backlash`` (the analysis), ``score``, ``report``, ``demo``, ``sweep``,
``view``, ``diagnose``, ``diagnose-benchmark`` and ``gate`` (the harness). Each verb parses its options,
calls one function of the package below it and prints a summary; errors of the user's input exit
with code 2 and one message naming the file, key and value."""

from __future__ import annotations

import importlib.util
import math
import shlex
import sys
import time
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from twin.scenario import SHIPPED, ScenarioError, load

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="MuJoCo digital twin of a ball-screw linear axis.")
console = Console(stderr=True)
SCENARIOS = SHIPPED
#: The optional parts of the tool (pyproject extras): extra -> (modules, what they are).
EXTRAS = {"sim": (("mujoco",), "MuJoCo (the simulator)"), "view": (("rerun",), "Rerun (the viewer)"),
          "cluster": (("distributed",), "Dask (the cluster)")}
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command stopped by Ctrl-C


def _fail(message: str, code: int = 2) -> None:
    console.print("error:", style="bold red", end=" ")
    console.print(message, markup=False, highlight=False, soft_wrap=True)
    raise typer.Exit(code)


def _installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def _require(verb: str, *extras: str) -> None:
    """Exit 2 naming the extra to install when an optional dependency of ``verb`` is missing;
    the imports of those modules stay inside the verbs, so the others work without them."""
    for extra in extras:
        modules, what = EXTRAS[extra]
        missing = [m for m in modules if not _installed(m)]
        if missing:
            _fail(f"twin {verb} needs {what}: {', '.join(missing)} is not installed; install the extra "
                  f"with: pip install 'ballscrew-twin[{extra}]' (or [all] for every extra)")


def _writable_dir(out: Path, what: str = "output directory") -> None:
    """Exit 2 when ``out`` cannot be a directory: it, or a folder above it, is an existing file."""
    for p in (out, *out.parents):
        if p.exists():
            if not p.is_dir():
                _fail(f"{out}: cannot write the {what} there: {p} is a file, not a directory")
            return


def gate_recording(directory: Path, force: bool, verb: str) -> dict:
    """``twin check`` before an analysis: exit 2 listing the errors unless ``force``; print the
    warnings (and forced errors); a directory without ``measurements.h5`` exits 2 first.
    Returns the record the analysis writes into its JSON
    (:func:`analysis.ingest.check.check_record`)."""
    from analysis.dataset import DatasetError
    from analysis.ingest.check import RecordingRefused, check_record, require_clean_recording

    if not (directory / "measurements.h5").is_file():
        _fail(f"{directory}: no measurements.h5; expected a recording in the dataset format "
              "(docs/dataset-format.md)")
    try:
        findings = require_clean_recording(directory, force, f"twin {verb}")
    except RecordingRefused as exc:
        _fail(str(exc))
    except (DatasetError, FileNotFoundError, OSError) as exc:
        _fail(str(exc))
    for f in findings:
        console.print(f"{'warning' if f.level == 'warning' else 'error (forced)'}: twin check: {f.where}: {f.what}",
                      style="yellow", markup=False, highlight=False, soft_wrap=True)
    return check_record(findings, force)


def record_check(json_path: Path, record: dict) -> None:
    """Add the ``check`` record to an analysis's JSON output (``detection.json``, ...)."""
    from analysis.files import read_json, write_json

    if json_path.is_file():
        doc = read_json(json_path, "the analysis's results")
        doc["check"] = record
        write_json(json_path, doc)


Force = Annotated[bool, typer.Option("--force", help=(
    "analyse a recording that twin check finds errors in (default: exit 2 listing them); the "
    "errors are written into the JSON"))]


# Options several verbs take, defined once (typer reads the option from the ``Annotated`` type).
ScenarioOverrides = Annotated[list[str], typer.Option(
    "--set", help="scenario override KEY=VALUE (TOML value), repeatable")]
Workers = Annotated[int | None, typer.Option("--workers", min=1, help=(
    "local processes (default: the environment variable TWIN_WORKERS, else all cores)"))]
ResponseSeeds = Annotated[int, typer.Option("--response-seeds", min=1, help=(
    "twin seeds each candidate's response is simulated with: the first seed's is fitted, all of "
    "them give the stated 90 % interval (1: the cheapest; the interval then lacks the bootstrap "
    "over the responses' seeds); at most --seeds"))]
Scheduler = Annotated[str | None, typer.Option(
    "--scheduler", help="address of a running dask.distributed scheduler to run on instead of local "
                        "processes; its workers must see the files at the same paths")]
TwinSeeds = Annotated[int, typer.Option("--seeds", min=3, help="twin seeds for the seed-to-seed spread")]


def _one_executor(scheduler: str | None, workers: int | None, what: str) -> None:
    """Exit 2 when both --scheduler and --workers are given; ``what``: the work they would run
    ("units", "sessions", ...)."""
    if scheduler is not None and workers is not None:
        _fail(f"--scheduler and --workers exclude each other: --scheduler sends the {what} to an "
              "existing dask cluster, --workers N runs them in N local processes")


def _version(value: bool) -> None:
    if value:
        from importlib.metadata import PackageNotFoundError, version

        try:
            v = version("ballscrew-twin")
        except PackageNotFoundError:
            v = "unknown (not installed as a package)"
        typer.echo(f"ballscrew-twin {v}")
        raise typer.Exit()


@app.callback()
def _main(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="print the version and exit")) -> None:
    """MuJoCo digital twin of a ball-screw linear axis."""


def _run_simulation(scenario: Path, out: Path, overrides: list[str], workers: int | None,
                    scheduler: str | None = None) -> dict:
    from twin.campaign import CampaignDirectoryError, CampaignInterrupted, plan, simulate_campaign
    from twin.executors import ExecutorError

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
        from twin.live import simulate_live

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


def _parse_params(items: list[str]) -> dict:
    """--set-param KEY=VALUE items as a dict; VALUE is a TOML value, else taken as a string."""
    import tomllib

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip().isidentifier():
            _fail(f"--set-param {item!r}: expected KEY=VALUE with KEY a parameter name")
        try:
            out[key.strip()] = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            out[key.strip()] = value
        if isinstance(out[key.strip()], list):
            out[key.strip()] = tuple(out[key.strip()])
    return out


def _score_tables(doc: dict) -> list[Table]:
    """The summary tables of a score.json object (shared by ``twin score`` and ``twin demo``)."""
    from analysis.registry import label

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
            t.add_row(f"{r.get('label') or name} [{name}]", str(r["n_sessions"]),
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
    from twin.campaign import make_world
    from twin.model import build_mjcf
    from twin.scenario import Scenario, to_axis

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


# --- Phase I detection ----------------------------------------------------------------------------
@app.command()
def detect(
    directory: Path = typer.Argument(..., help="campaign directory (measurements.h5; truth.h5 for scoring)"),
    reference: Path | None = typer.Option(None, "--reference", help="reference data set directory (Fisher selection)"),
    out: Path | None = typer.Option(None, "-o", "--out", help="output directory (default: DIRECTORY/phase1)"),
    save_model: Path | None = typer.Option(None, "--save-model", help="also write the fitted Phase I model there"),
    model: Path | None = typer.Option(None, "--model", help="score with this model (from --save-model) "
                                      "instead of fitting; no --reference then"),
    method: list[str] = typer.Option([], "--method", help="detector(s) to run: a registered name or "
                                     "module:Class, repeatable (default: every registered detector)"),
    consecutive: int = typer.Option(1, "--consecutive", min=1, help="alarms in a row that make a detection"),
    force: Force = False,
) -> None:
    """Phase I incipient-fault detection (paper section IV): writes OUT/detection.json and OUT/detection.png."""
    from analysis.phase1.detect import run

    out = out or directory / "phase1"
    if (reference is None) == (model is None) or (model is not None and save_model is not None):
        _fail("give either --reference REF (fit; --save-model M to keep the fit) or --model M "
              "(score with a saved model)")
    for d, what in ((directory, "recording"), (reference, "reference data set")):
        if d is not None and not (d / "measurements.h5").is_file():
            _fail(f"{d}: no measurements.h5; expected the {what} in the dataset format "
                  "(docs/dataset-format.md)")
    _writable_dir(out)
    checked = gate_recording(directory, force, "detect")
    existed = out.is_dir() and any(out.iterdir())
    try:
        details = run(directory, reference, out, method or None, consecutive, model=model,
                      save_model=save_model)
    except (ValueError, FileNotFoundError) as exc:  # DatasetError, ExtractionError, DetectError
        kept = not existed and out.is_dir() and any(out.iterdir())
        _fail(f"{exc}" + (f" (what was computed before the error is in {out})" if kept else ""))
    onset = details["onset_hours"]
    table = Table(title=f"Phase I detection, {details['n_samples']} samples, baseline "
                        f"{details['n_baseline']}, injected onset "
                        f"{'none' if onset is None else f'{onset:g} h'}")
    for col in ("method", "limit", "detect h", "delay h", "delay n", "FA/healthy", "FA base"):
        table.add_column(col)
    for r in details["methods"].values():
        def fmt(v, f="{:g}"):
            return "-" if v is None else f.format(v)
        table.add_row(r["label"], f"{r['threshold']:.4g}", fmt(r["detection_hours"]),
                      fmt(r["delay_hours"]), fmt(r["delay_samples"]),
                      f"{r['false_alarms']} / {r['healthy_test_samples']}", str(r["baseline_alarms"]))
    Console(width=max(100, Console().width)).print(table)
    record_check(out / "detection.json", checked)
    console.print(f"selected features: {', '.join(details['selected_features'])}")
    console.print(f"wrote {out / 'detection.json'} and {out / 'detection.png'}"
                  + (f"; the model: {save_model}" if save_model else ""))
# --- end of Phase I detection ---------------------------------------------------------------------


@app.command()
def monitor(
    source: Path = typer.Argument(..., help="growing campaign folder (SOURCE/live/ from twin simulate --live)"),
    model: Path = typer.Option(..., "--model", help="Phase I model from twin detect --save-model"),
    out: Path = typer.Option(..., "-o", "--out", help="state directory: the event log events.jsonl"),
    poll: float = typer.Option(0.2, "--poll", min=0.01, help="seconds between looks at SOURCE"),
    exit_at_end: bool = typer.Option(False, "--exit-at-end", help="stop once the source says it is "
                                     "finished and everything is processed"),
    serve: bool = typer.Option(False, "--serve", help="stream scores, limits, alarms and backlash to a "
                               "web viewer (Rerun) served here"),
    connect: str | None = typer.Option(None, "--connect", help="stream to a running Rerun viewer at "
                                       "this gRPC address (rerun+http://HOST:9876/proxy)"),
    rrd: Path | None = typer.Option(None, "--rrd", help="stream into this .rrd file instead"),
    web_port: int = typer.Option(9090, "--web-port", help="with --serve: port of the web viewer"),
    grpc_port: int = typer.Option(9876, "--grpc-port", help="with --serve: port of the data server"),
) -> None:
    """Watch SOURCE: score every new Phase I sample with the model, alarm, ask for Phase II and
    estimate the change of backlash of the sessions that follow; events go to OUT/events.jsonl
    (docs/monitoring.md). Killed, it resumes from OUT with no event lost or repeated."""
    from analysis.phase1.model_file import ModelFileError
    from twin.harness.monitor import Monitor, MonitorError

    _writable_dir(out, "state directory")
    if not source.is_dir() and not source.absolute().parent.is_dir():  # SOURCE itself may come later
        _fail(f"{source}: no such directory, nor its parent; expected the campaign folder to watch "
              "(SOURCE/live/, written by twin simulate --live or a DAQ following docs/monitoring.md)")
    if sum((serve, connect is not None, rrd is not None)) > 1:
        _fail("--serve, --connect and --rrd exclude each other: give one")
    try:
        mon = Monitor(source, model, out, say=lambda s: console.print(s, markup=False, highlight=False))
        console.print(f"monitoring {mon.live} with {model}; events -> {mon.log}", highlight=False)
        if serve or connect or rrd:
            _require("monitor --serve/--connect/--rrd", "view")
            from twin.harness.view.monitor_view import MonitorView

            view = MonitorView(mon.model.labels, mon.model.thresholds(), serve=serve, connect=connect,
                               save=rrd, web_port=web_port, grpc_port=grpc_port)
            mon.on_event = view.on_event
            if view.url:
                console.print(f"web viewer: {view.url}")
        n = mon.run(poll, exit_at_end)
    except (ModelFileError, MonitorError) as exc:
        _fail(str(exc))
    except KeyboardInterrupt:
        console.print(f"stopped; resume with: twin {shlex.join(sys.argv[1:])}")
        raise typer.Exit(EXIT_INTERRUPTED) from None
    console.print(f"source finished: {n} events in {mon.log}")


# --- Phase II backlash ----------------------------------------------------------------------------
@app.command()
def backlash(
    directory: Path = typer.Argument(..., help="campaign directory (measurements.h5; truth.h5 only for the plot)"),
    out: Path | None = typer.Option(None, "-o", "--out", help="output directory (default: DIRECTORY/backlash)"),
    strict: bool = typer.Option(False, "--strict", help="exit 2 on a bad run instead of skipping it"),
    plots: bool = typer.Option(True, "--plots/--no-plots", help="write the PNG figures"),
    process_noise: str = typer.Option("auto", "--process-noise",
                                      help="Kalman process noise q in m²/h³, 'ml' (maximum likelihood), or "
                                           "'auto': 1e-23 unless a likelihood-ratio test on the sessions "
                                           "rejects it for the maximum-likelihood q"),
    baseline_sessions: int = typer.Option(1, "--baseline-sessions", min=1,
                                          help="leading sessions known to share the initial backlash; "
                                               "the estimates are re-zeroed on their mean (1 = the paper's "
                                               "single reference)"),
    position_reference: str = typer.Option("auto", "--position-reference",
                                           help="position axis of the traces: 'auto' (command if the runs "
                                                "record position_cmd, else imu), 'command' (the controller's "
                                                "position_cmd) or 'imu' (strokes from the accelerometer and "
                                                "the run's routine metadata; Eq. 5)"),
    estimator: str | None = typer.Option(None, "--estimator",
                                         help="backlash estimator: a registered name or module:Class "
                                              "(default: the paper's, 'shift'); other than the default "
                                              "it writes to OUT/NAME/"),
    set_param: list[str] = typer.Option([], "--set-param",
                                        help="estimator parameter KEY=VALUE (TOML value), repeatable"),
    workers: Workers = None,
    scheduler: Scheduler = None,
    force: Force = False,
) -> None:
    """Phase II backlash (paper section V): change of backlash per session by signal shifts and by
    perceived pitch, Kalman trend and remaining hours to 10 µm. Writes OUT/backlash.json and PNGs.
    A bad run (missing, cut short, non-finite channel) is skipped with a warning recorded in the
    JSON, or with --strict ends the command with exit code 2 naming session, run and channel.
    The sessions' error motions are computed in parallel (local processes, or a Dask cluster with
    --scheduler); the results are those of one process."""
    import math

    from analysis import registry
    from analysis.dataset import DatasetError
    from analysis.phase2.workflow import estimator_dir, run
    from twin.executors import ExecutorError, mapper

    if scheduler is not None:
        _require("backlash --scheduler", "cluster")
    _one_executor(scheduler, workers, "sessions")

    try:
        entry = (registry.get("backlash_estimators", estimator) if estimator
                 else registry.default("backlash_estimators"))
    except registry.RegistryError as exc:
        _fail(f"--estimator: {exc}")
    params = _parse_params(set_param)
    out = estimator_dir(out or directory / "backlash", entry.name)
    _writable_dir(out)
    try:
        q = process_noise if process_noise in ("ml", "auto") else float(process_noise)
        if q not in ("ml", "auto") and not (math.isfinite(q) and q >= 0):
            raise ValueError(process_noise)
    except ValueError:
        _fail(f"--process-noise {process_noise!r}: expected a number >= 0 in m²/h³ (e.g. 1e-23), 'ml' or 'auto'")
    if position_reference not in ("auto", "command", "imu"):
        _fail(f"--position-reference {position_reference!r}: expected 'auto', 'command' or 'imu'")
    checked = gate_recording(directory, force, "backlash")
    try:
        br = run(directory, out, strict=strict, plots=plots, process_noise=q,
                 baseline_sessions=baseline_sessions, position_reference=position_reference,
                 estimator=estimator, params=params,
                 map_sessions=mapper(workers, scheduler=scheduler, prefix="session"))
    except (DatasetError, FileNotFoundError, OSError, ExecutorError) as exc:
        _fail(str(exc))
    except ValueError as exc:  # traces that cannot be correlated
        _fail(f"{directory}: {exc}")
    record_check(out / "backlash.json", checked)
    result, records, prog, figures = br.result, br.doc["sessions"], br.prognosis, br.figures
    ses = result.sessions
    for session, run_name, why in result.skipped_runs:
        console.print(f"warning: skipped session {session} run {run_name}: {why}", style="yellow",
                      markup=False, highlight=False)
    for session, why in result.skipped_sessions:
        console.print(f"warning: skipped session {session}: {why}", style="yellow", markup=False,
                      highlight=False)
    if not ses:
        _fail(f"{directory / 'measurements.h5'}: no Phase II session could be used (see the warnings); "
              f"wrote {out / 'backlash.json'}")

    def fmt(v, f="{:.2f}"):
        return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f.format(v)

    ref = (f"session {ses[0].session}" if result.baseline_sessions == 1 else
           f"the mean of sessions {ses[0].session}-{ses[result.baseline_sessions - 1].session}")
    table = Table(title=f"Phase II backlash change vs {ref} ({len(ses)} sessions), estimator "
                        f"{br.doc['estimator']['name']} ({br.doc['estimator']['label']})")
    for col in ("session", "hours", "Δb shifts µm", "Δb pitch µm", "smoothed µm", "dial Δ µm",
                "pitch mm", "γ max"):
        table.add_column(col)
    for rec in records:
        g = [v for v in rec["gamma"].values() if v is not None]
        withheld = (rec.get("pitch_note") or "").startswith("withheld")
        table.add_row(rec["session"], f"{rec['hours']:g}", fmt(rec["delta_backlash_um_shift"]),
                      "withheld" if withheld else fmt(rec["delta_backlash_um_pitch"]), fmt(rec.get("smoothed_um")),
                      fmt(rec.get("dial_delta_um")), fmt(rec["observed_pitch_mm"], "{:.6f}"),
                      fmt(max(g) if g else None, "{:.3f}"))
    Console(width=max(100, Console().width)).print(table)
    notes = {}
    for rec in records:
        if rec.get("pitch_note"):
            notes.setdefault(rec["pitch_note"].split(":")[0], []).append(rec)
    for kind, recs in notes.items():
        if kind == "withheld":
            for rec in recs:
                console.print(f"note: Δb pitch (Eq. 9) of {rec['session']} {rec['pitch_note']}", markup=False,
                              highlight=False, soft_wrap=True)
        else:
            console.print(f"note: Δb pitch (Eq. 9) of {', '.join(r['session'] for r in recs)}: "
                          f"{recs[0]['pitch_note']}", markup=False, highlight=False, soft_wrap=True)
    if prog is not None:
        p = prog.to_json()
        console.print(f"prognosis: {fmt(p['level_um'])} µm at {p['at_hours']:g} h, rate "
                      f"{fmt(p['rate_um_per_kh'])} µm/kh; {p['limit_um']:g} µm reached at "
                      f"{fmt(p['crossing_hours'], '{:.0f}')} h (95 % band "
                      f"{fmt(p['band_hours'][0], '{:.0f}')}–{fmt(p['band_hours'][1], '{:.0f}')} h)",
                      markup=False, highlight=False)
    console.print(f"wrote {out / 'backlash.json'}" + (f" and {len(figures)} figures" if figures else ""))
# --- end of Phase II backlash ---------------------------------------------------------------------


# --- the recovery gate for a method developer's CI ----------------------------------------------
@app.command()
def gate(
    estimator: list[str] = typer.Option([], "--estimator", help="backlash estimator to check: a registered "
                                        "name, module:Class or 'all', repeatable"),
    detector: list[str] = typer.Option([], "--detector", help="Phase I detector to check: a registered "
                                       "name, module:Class or 'all', repeatable"),
    suite: str = typer.Option("standard", "--suite", help="the suite of checks"),
    junit: Path | None = typer.Option(None, "--junit", help="write the verdicts as JUnit XML to this file"),
    cache: Path | None = typer.Option(None, "--cache", help="cache root (default "
                                      "$XDG_CACHE_HOME/ballscrew-twin/gate)"),
    check: list[str] = typer.Option([], "--check", help="run only this check, repeatable"),
    rebuild: bool = typer.Option(False, "--rebuild", help="rebuild the cache even if it verifies"),
) -> None:
    """Recovery checks of a backlash estimator or a Phase I detector on cached campaigns with
    injected backlash and preload loss: figure, tolerance and verdict per check; exit 0 only if
    every check passes (1 otherwise). Without --estimator and --detector: the paper's methods."""
    from twin.harness.gate import GateError, command

    try:
        code = command(estimator, detector, suite, junit, cache, check, rebuild)
    except GateError as exc:
        _fail(str(exc))
    raise typer.Exit(code)


# --- bringing a real axis's recordings in: import, check ------------------------------------------
@app.command("import")
def import_(
    spec: Path = typer.Argument(..., help="import spec (TOML; docs/import.md)"),
    out: Path | None = typer.Option(None, "-o", "--out", help="campaign directory (default: the spec's output)"),
    watch: bool = typer.Option(False, "--watch", help="watch the spec's folder as it grows and import each "
                               "complete capture and session as a live unit for twin monitor (OUT/live/)"),
    poll: float = typer.Option(1.0, "--poll", min=0.01, help="with --watch: seconds between looks at the folder"),
    settle: float = typer.Option(2.0, "--settle", min=0.0, help="with --watch: seconds a file's size and "
                                 "modification time must stay unchanged before it is read"),
    once: bool = typer.Option(False, "--once", help="with --watch: import what is there, once every file has "
                              "settled, then stop"),
    until_idle: float | None = typer.Option(None, "--until-idle", min=0.0, help="with --watch: stop after this "
                                            "many seconds with no file arriving or changing"),
) -> None:
    """Convert a laboratory's files (CSV, MATLAB .mat, NI TDMS, ASAM MDF) into a campaign's
    measurements.h5 as the import spec maps them: channels, units (g, mV, rpm, deg/s, mm, ...),
    rates, hours and the axis description. Resumes: files converted before are not read again.
    With --watch, a DAQ's export folder is imported while it grows (docs/import.md)."""
    from analysis.dataset import DatasetError
    from analysis.ingest import ImportSpecError, run_import

    if out is not None:
        _writable_dir(out, "campaign directory")
    if (once or until_idle is not None) and not watch:
        _fail("--once and --until-idle go with --watch")
    if once and until_idle is not None:
        _fail("--once and --until-idle exclude each other: give one")
    if watch:
        _import_watch(spec, out, poll, settle, once, until_idle)
        return

    t0 = time.perf_counter()
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=False) as progress:
        task = progress.add_task("importing", total=None)

        def on_progress(done: int, total: int, name: str, reused: bool) -> None:
            progress.update(task, completed=done, total=total,
                            description=f"{'kept' if reused else 'read'} {name}")

        try:
            s = run_import(spec, output=out, progress=on_progress)
        except (ImportSpecError, DatasetError) as exc:
            progress.stop()
            _fail(str(exc))
    _print_mapping(s.mapping or [])
    for w in s.warnings or []:
        console.print(f"warning: {w}", style="yellow", markup=False, highlight=False, soft_wrap=True)
    hours = "-" if s.hours is None else f"{s.hours[0]:g}–{s.hours[1]:g} h"
    console.print(f"imported {s.captures} Phase I captures, {s.sessions} Phase II sessions ({s.runs} runs), "
                  f"{hours}: {s.converted} files read, {s.reused} kept from before, "
                  f"{time.perf_counter() - t0:.1f} s", markup=False, highlight=False)
    console.print(f"wrote {s.output / 'measurements.h5'} and {s.output / 'import.json'}; next: "
                  f"twin check {s.output}", markup=False, highlight=False)


def _import_watch(spec: Path, out: Path | None, poll: float, settle: float, once: bool,
                  until_idle: float | None) -> None:
    """``twin import SPEC --watch``: analysis.ingest.watch, stopped cleanly by Ctrl-C or SIGTERM."""
    import signal

    from analysis.dataset import DatasetError
    from analysis.ingest import ImportSpecError
    from analysis.ingest.watch import ImportWatcher

    def say(text: str) -> None:
        console.print(text, markup=False, highlight=False, soft_wrap=True,
                      style="yellow" if text.startswith(("refused", "warning")) else None)

    try:
        w = ImportWatcher(spec, out, settle_s=settle, say=say)
    except (ImportSpecError, DatasetError) as exc:
        _fail(str(exc))
    signals = []

    def stop(signum, frame) -> None:
        signals.append(signum)
        w.stop = True

    old = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    console.print(f"watching {w.spec_dir} ({', '.join(p.files for p in w.phases.values())}) -> {w.live}; "
                  f"a file is read once unchanged for {settle:g} s; log: {w.log}", markup=False, highlight=False)
    try:
        r = w.run(poll, once=once, until_idle_s=until_idle)
    except (ImportSpecError, DatasetError) as exc:
        _fail(str(exc))
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
    console.print(f"{w.live}: {r.units} units from {r.files} files ({w.n_published_now} units new); "
                  f"{r.refused} files refused (reasons in {w.log})", markup=False, highlight=False)
    if r.summary is not None:
        console.print(f"wrote {r.summary.output / 'measurements.h5'}, {r.summary.output / 'import.json'} and "
                      f"{w.live / 'end.json'}", markup=False, highlight=False)
        for warning in r.summary.warnings or []:
            console.print(f"warning: {warning}", style="yellow", markup=False, highlight=False, soft_wrap=True)
    if r.ended == "stopped":
        console.print(f"stopped; resume with: twin {shlex.join(sys.argv[1:])}", markup=False, highlight=False)
        if signal.SIGINT in signals:
            raise typer.Exit(EXIT_INTERRUPTED)


#: Rows of the file -> capture / session, run -> hours table `twin import` prints (all are in import.json).
MAPPING_ROWS = 200


def _print_mapping(mapping: list[dict]) -> None:
    """The file -> capture or session/run (the lab's session name) -> hours table of an import."""
    if not mapping:
        return
    table = Table(title=f"what came from where ({len(mapping)} files; import.json lists them all)")
    for col in ("file", "phase", "stored as", "lab's session", "hours", "hours from"):
        table.add_column(col)
    for r in mapping[:MAPPING_ROWS]:
        stored = r.get("capture") or f"{r['session']}/{r['run']}"
        hours = f"{r['hours']:g}" if r.get("file_hours", r["hours"]) == r["hours"] else \
            f"{r['hours']:g} (file {r['file_hours']:g})"
        table.add_row(Path(r["file"]).name, r["phase"], stored, str(r.get("session_name") or "-"), hours,
                      str(r.get("hours_from") or "-"))
    Console(width=max(120, Console().width), stderr=True).print(table)
    if len(mapping) > MAPPING_ROWS:
        console.print(f"... and {len(mapping) - MAPPING_ROWS} more files (import.json lists them all)")


@app.command()
def check(
    directory: Path = typer.Argument(..., help="campaign directory or measurements.h5"),
    as_json: bool = typer.Option(False, "--json", help="print the report as JSON on stdout"),
) -> None:
    """What a recording holds (captures, sessions, runs, rates, durations, hours) and what is wrong
    or suspicious in it (NaN, flat lines, clipping, dropouts, hours going back, differing rates, an
    IMU that does not see gravity). Exit 1 if there is an error, 0 otherwise."""
    import json as _json

    from analysis.dataset import DatasetError
    from analysis.ingest.check import check_recording

    try:
        rep = check_recording(directory)
    except (DatasetError, FileNotFoundError, OSError) as exc:
        _fail(str(exc))
    if as_json:
        print(_json.dumps(rep.to_json(), indent=2))
    else:
        s = rep.summary
        table = Table(title=f"{rep.file}")
        table.add_column("what")
        table.add_column("value")
        p1, p2 = s["phase1"], s["phase2"]

        def span(v, unit):
            return "-" if not v else (f"{v[0]:g} {unit}" if v[0] == v[1] else f"{v[0]:g}–{v[1]:g} {unit}")

        table.add_row("Phase I", f"{p1['captures']} captures in {p1['samples']} samples, "
                                 f"{', '.join(f'{f:g}' for f in p1['fs_hz']) or '-'} Hz, {span(p1['capture_s'], 's')}")
        rates = "; ".join(f"{k} {', '.join(f'{f:.6g}' for f in v)} Hz" for k, v in p2["fs_hz"].items() if v)
        table.add_row("Phase II", f"{p2['sessions']} sessions, {p2['runs']} runs, {span(p2['run_s'], 's')}; {rates}")
        table.add_row("hours", span(s["hours"], "h"))
        table.add_row("dial readings", str(s["dial_readings"]))
        ax = s.get("axis") or {}
        table.add_row("axis", ", ".join(f"{k} {ax[k]}" for k in ("name", "lead_mm", "travel_mm") if k in ax) or "-")
        Console(width=max(100, Console().width)).print(table)
        if rep.findings:
            ft = Table(title=f"{len(rep.errors)} errors, {len(rep.findings) - len(rep.errors)} warnings")
            for col in ("level", "where", "what"):
                ft.add_column(col)
            for f in rep.findings[:200]:
                ft.add_row(f.level, f.where, f.what, style="red" if f.level == "error" else "yellow")
            Console(width=max(100, Console().width)).print(ft)
            if len(rep.findings) > 200:
                console.print(f"... and {len(rep.findings) - 200} more (--json lists all)")
        else:
            console.print("no errors, no warnings")
    if rep.errors:
        raise typer.Exit(1)
scenario_app = typer.Typer(no_args_is_help=True, help="Scenarios: write one that describes a recording.")
app.add_typer(scenario_app, name="scenario")


@scenario_app.command("init")
def scenario_init(
    directory: Path = typer.Argument(..., help="campaign directory or measurements.h5 of the recording"),
    out: Path = typer.Option(..., "-o", "--out", help="scenario file to write (TOML)"),
    name: str | None = typer.Option(None, "--name", help="scenario name (default: the directory's name)"),
) -> None:
    """A scenario whose layout matches the recording (samples, captures, sessions, runs, hours, rates)
    and whose routine is measured from it (stroke, speeds, acceleration, dwell), the axis values from
    its /@axis and a comment on every value that is a twin default. Then:
    twin diagnose DIRECTORY --scenario OUT."""
    from analysis.dataset import DatasetError
    from twin.scenario_init import write_scenario

    if out.exists() and out.is_dir():
        _fail(f"-o {out}: is a directory; expected a scenario file path (e.g. {out / 'axis.toml'})")
    try:
        notes = write_scenario(directory, out, name)
    except (DatasetError, FileNotFoundError, OSError) as exc:
        _fail(str(exc))
    except ScenarioError as exc:
        _fail(f"the scenario measured from {directory} cannot be written: {exc}")
    for n in notes:
        console.print(f"note: {n}", style="yellow", markup=False, highlight=False)
    console.print(f"wrote {out}: the layout and routine only (the drive's parameters and the sensor chain "
                  f"are the twin's defaults); to fit them: twin calibrate {directory} -o {out}; then: "
                  f"twin diagnose {directory} --scenario {out}", markup=False, highlight=False)
# --- end of import, check, scenario init ----------------------------------------------------------

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
) -> None:
    """The round trip of `twin calibrate`, blind: foreign axes drawn from a seed, simulated, written
    out as a lab's files (CSV, TDMS, MAT, MDF in turn), imported, calibrated (and diagnosed),
    scored against the draws. Writes OUT/calibrate-benchmark.json; stopped and run again, it goes
    on from the cases already done."""
    _require("calibrate-benchmark", "sim")
    from twin.executors import default_processes
    from twin.harness.calibrate_benchmark import run_benchmark

    _writable_dir(out)
    doc = run_benchmark(out, cases=cases, seed=seed, workers=workers or default_processes(), diagnose=diagnose,
                        seeds=seeds, resume=not fresh,
                        progress=lambda t: console.print(t, markup=False, highlight=False))
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
    sensor chain (measured at rest), the drive's mass, drags, torque ripple and the Phase I
    acceleration (fitted jointly through the twin, each with its 90 % interval). Every value of
    the written scenario says where it came from; what the recording cannot inform keeps the
    twin's default and says why. Then: twin diagnose DIRECTORY --scenario OUT."""
    _require("calibrate", "sim", *(["cluster"] if scheduler is not None else []))
    _one_executor(scheduler, workers, "simulations")
    if budget_minutes is not None and not (math.isfinite(budget_minutes) and budget_minutes > 0):
        _fail(f"--budget-minutes {budget_minutes:g}: expected a positive number of minutes")
    from analysis.dataset import DatasetError
    from twin.harness.calibrate import CalibrationError
    from twin.harness.calibrate import calibrate as run_calibration

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
    from analysis import registry
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


# --- twin diagnose --------------------------------------------------------------------------------
def _progress_callback(progress: Progress, tasks: dict):
    def on_progress(what: str, done: int, total: int) -> None:
        if what not in tasks:
            tasks[what] = progress.add_task(what, total=total)
        progress.update(tasks[what], completed=done)
    return on_progress


def _print_diagnosis(res: dict) -> None:
    from analysis.diagnosis.wording import added_phrase, refused_phrase, subset_phrase

    out = Console(width=max(110, Console().width))
    if res.get("subset"):
        out.print(subset_phrase(res), markup=False, highlight=False)
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
    from twin.harness.gap_runner import check_kinds, check_response_seeds, resolve_library, run_diagnosis

    try:
        s = load(scenario, overrides)
    except ScenarioError as exc:
        _fail(str(exc))
    try:  # an option out of range is refused before the recording is read
        check_response_seeds(response_seeds, seeds)
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
                                budget_minutes=budget_minutes, response_seeds=response_seeds)
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
    from twin.harness.gap_benchmark import plan_cases, run_benchmark
    from twin.harness.gap_runner import check_response_seeds

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


def main() -> None:
    from twin.executors import ExecutorError, default_processes, keep_freed_memory

    keep_freed_memory()
    try:
        default_processes()  # a bad TWIN_WORKERS is refused before any work
    except ExecutorError as exc:
        console.print(f"[bold red]error:[/] {exc}")
        sys.exit(2)
    try:
        app()
    except ScenarioError as exc:  # pragma: no cover - defensive
        console.print(f"[bold red]error:[/] {exc}")
        sys.exit(2)


if __name__ == "__main__":
    main()
