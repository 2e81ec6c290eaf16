"""Verbs of the analysis: ``detect`` and ``monitor`` (Phase I), ``backlash`` (Phase II) and
``gate`` (the recovery gate for a method developer's CI)."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from twin.cli.common import (
    EXIT_INTERRUPTED,
    Force,
    Scheduler,
    Workers,
    _fail,
    _one_executor,
    _parse_params,
    _require,
    _writable_dir,
    app,
    console,
    gate_recording,
    record_check,
)


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
    cache: Path | None = typer.Option(None, "--cache", envvar="TWIN_BACKLASH_CACHE",
                                      help="keep the sessions' error motions in this folder: a rerun on "
                                           "the same recording with the same --position-reference and "
                                           "--strict (other estimators or parameters, say) computes none "
                                           "again"),
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

    from analysis.base import registry
    from analysis.base.executors import ExecutorError, mapper
    from analysis.dataset import DatasetError
    from analysis.phase2.workflow import estimator_dir, run

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
                 map_sessions=mapper(workers, scheduler=scheduler, prefix="session"), cache=cache)
    except (DatasetError, FileNotFoundError, OSError, ExecutorError) as exc:
        _fail(str(exc))
    except ValueError as exc:  # traces that cannot be correlated
        _fail(f"{directory}: {exc}")
    record_check(out / "backlash.json", checked)
    result, records, prog, figures = br.result, br.doc["sessions"], br.prognosis, br.figures
    if cache is not None:
        console.print(f"error motions: {result.from_cache} of {len(records) + len(result.skipped_sessions)} "
                      f"sessions from the cache {cache}", markup=False, highlight=False)
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
    except KeyboardInterrupt:  # a cache's build keeps what it finished (twin.harness.gate.cache)
        console.print("stopped; a build of the cache goes on from where it stopped when you run: "
                      f"twin {shlex.join(a for a in sys.argv[1:] if a != '--rebuild')}",
                      markup=False, highlight=False)
        raise typer.Exit(EXIT_INTERRUPTED) from None
    raise typer.Exit(code)


