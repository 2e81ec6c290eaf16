"""Verbs that bring a real axis's recordings in: ``import`` (batch or ``--watch``), ``check``
and ``scenario init``."""

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
    _fail,
    _writable_dir,
    app,
    console,
)
from twin.sim.scenario import ScenarioError


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
        table = Table(title=escape(rep.file))
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
                # escaped: a key names an axis as imu_acc[x], which Rich would take for markup
                ft.add_row(f.level, escape(f.where), escape(f.what), style="red" if f.level == "error" else "yellow")
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
    from twin.sim.scenario_init import write_scenario

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

