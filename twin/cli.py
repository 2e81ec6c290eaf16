"""The ``twin`` command line: simulate campaigns (and, as later issues land, analyse them)."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from twin.scenario import ScenarioError, load

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="MuJoCo digital twin of a ball-screw linear axis.")
console = Console(stderr=True)
SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"


def _fail(message: str, code: int = 2) -> None:
    console.print("error:", style="bold red", end=" ")
    console.print(message, markup=False, highlight=False, soft_wrap=True)
    raise typer.Exit(code)


def _run_simulation(scenario: Path, out: Path, overrides: list[str], workers: Optional[int]) -> dict:
    from twin.campaign import CampaignDirectoryError, plan, simulate_campaign

    try:
        s = load(scenario, overrides)
    except ScenarioError as exc:
        _fail(str(exc))
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
            summary = simulate_campaign(s, out, workers=workers, on_progress=on_progress)
        except CampaignDirectoryError as exc:
            progress.stop()
            _fail(str(exc))
    summary["seconds"] = time.perf_counter() - t0
    summary["scenario"] = s
    return summary


@app.command()
def simulate(
    scenario: Path = typer.Argument(..., help="scenario TOML file"),
    out: Path = typer.Option(..., "-o", "--out", help="campaign directory to write"),
    set_: list[str] = typer.Option([], "--set", help="override KEY=VALUE (TOML value), repeatable"),
    workers: Optional[int] = typer.Option(None, "--workers", help="processes (default: all cores)"),
) -> None:
    """Simulate a campaign: writes OUT/measurements.h5 and OUT/truth.h5 (resumes if killed)."""
    summary = _run_simulation(scenario, out, set_, workers)
    console.print(f"{summary['simulated']} units simulated, {summary['skipped']} reused, "
                  f"{summary['seconds']:.1f} s; wrote {out / 'measurements.h5'} and "
                  f"{out / 'truth.h5'}")


@app.command()
def demo(
    out: Path = typer.Option(Path("runs/demo"), "-o", "--out", help="where to write the demo"),
    set_: list[str] = typer.Option([], "--set", help="override KEY=VALUE on the quick scenario"),
    workers: Optional[int] = typer.Option(None, "--workers"),
) -> None:
    """Simulate the quick campaign and print what was simulated."""
    from analysis.dataset import open_measurements, open_truth

    summary = _run_simulation(SCENARIOS / "quick.toml", out, set_, workers)
    with open_measurements(out / "measurements.h5") as m, open_truth(out / "truth.h5") as t:
        tl = t.timeline()
        table = Table(title=f"quick campaign in {out}")
        for col in ("what", "count", "values"):
            table.add_column(col)
        caps = m.phase1_captures()
        sessions = m.phase2_sessions()
        table.add_row("Phase I captures", str(len(caps)),
                      f"{m.phase1(caps[0]).hours:.0f} .. {m.phase1(caps[-1]).hours:.0f}" if caps else "-")
        table.add_row("Phase II sessions", str(len(sessions)),
                      ", ".join(f"{m.session_hours(x):.0f}" for x in sessions))
        dial = m.dial_indicator()
        if dial is not None:
            table.add_row("dial-indicator backlash (µm)", str(len(dial[0])),
                          ", ".join(f"{b:.1f}" for b in dial[1]))
        table.add_row("injected backlash at sessions (µm)", "",
                      ", ".join(f"{t.session(x)[2]['backlash_um']:.1f}" for x in t.sessions()))
        table.add_row("injected preload at end (N)", "", f"{tl['preload_N'][-1]:.0f}")
        Console().print(table)
    console.print(f"done in {summary['seconds']:.1f} s")


@app.command("export-model")
def export_model(
    scenario: Optional[Path] = typer.Argument(None, help="scenario TOML (default: the paper's axis)"),
    out: Path = typer.Option(Path("models/linear_axis.xml"), "-o", "--out"),
    timestep: Optional[float] = typer.Option(None, help="time step, s (default: the Phase I step)"),
) -> None:
    """Write the MJCF of the axis in its new, healthy state: a complete model that holds still,
    e.g. to open in MuJoCo's viewer (`python -m mujoco.viewer --mjcf models/linear_axis.xml`)."""
    from twin.model import build_mjcf
    from twin.scenario import Scenario, to_axis

    try:
        s = load(scenario) if scenario else Scenario()
    except ScenarioError as exc:
        _fail(str(exc))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(build_mjcf(to_axis(s), timestep or s.phase1.timestep_s))
    console.print(f"wrote {out}")


# --- Phase I detection (issue 3) -------------------------------------------------------------
@app.command()
def detect(
    directory: Path = typer.Argument(..., help="campaign directory (measurements.h5; truth.h5 for scoring)"),
    reference: Path = typer.Option(..., "--reference", help="reference data set directory (Fisher selection)"),
    out: Optional[Path] = typer.Option(None, "-o", "--out", help="output directory (default: DIRECTORY/phase1)"),
    method: list[str] = typer.Option([], "--method", help="method(s) to run (default: all six)"),
    consecutive: int = typer.Option(1, "--consecutive", min=1, help="alarms in a row that make a detection"),
) -> None:
    """Phase I incipient-fault detection (paper section IV): writes OUT/detection.json and OUT/detection.png."""
    from analysis.phase1.detect import run
    from analysis.phase1.pipeline import METHODS, PAPER_NAMES

    out = out or directory / "phase1"
    try:
        details = run(directory, reference, out, method or METHODS, consecutive)
    except (ValueError, FileNotFoundError) as exc:  # DatasetError, ExtractionError, DetectError
        _fail(f"{exc} (anything computed before the error is in {out})")
    onset = details["onset_hours"]
    table = Table(title=f"Phase I detection, {details['n_samples']} samples, baseline "
                        f"{details['n_baseline']}, injected onset "
                        f"{'none' if onset is None else f'{onset:g} h'}")
    for col in ("method", "limit", "detect h", "delay h", "delay n", "FA/healthy", "FA base"):
        table.add_column(col)
    for name, r in details["methods"].items():
        def fmt(v, f="{:g}"):
            return "-" if v is None else f.format(v)
        table.add_row(PAPER_NAMES[name], f"{r['threshold']:.4g}", fmt(r["detection_hours"]),
                      fmt(r["delay_hours"]), fmt(r["delay_samples"]),
                      f"{r['false_alarms']} / {r['healthy_test_samples']}", str(r["baseline_alarms"]))
    Console(width=max(100, Console().width)).print(table)
    console.print(f"selected features: {', '.join(details['selected_features'])}")
    console.print(f"wrote {out / 'detection.json'} and {out / 'detection.png'}")
# --- end of Phase I detection ---------------------------------------------------------------


def main() -> None:
    try:
        app()
    except ScenarioError as exc:  # pragma: no cover - defensive
        console.print(f"[bold red]error:[/] {exc}")
        sys.exit(2)


if __name__ == "__main__":
    main()
