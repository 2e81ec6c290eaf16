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


# --- Phase II backlash (issue 4) -------------------------------------------------------------
@app.command()
def backlash(
    directory: Path = typer.Argument(..., help="campaign directory (measurements.h5; truth.h5 only for the plot)"),
    out: Optional[Path] = typer.Option(None, "-o", "--out", help="output directory (default: DIRECTORY/backlash)"),
    strict: bool = typer.Option(False, "--strict", help="exit 2 on a bad run instead of skipping it"),
    plots: bool = typer.Option(True, "--plots/--no-plots", help="write the PNG figures"),
    process_noise: str = typer.Option("1e-23", "--process-noise",
                                      help="Kalman process noise q in m²/h³, or 'ml' (maximum likelihood)"),
    baseline_sessions: int = typer.Option(1, "--baseline-sessions", min=1,
                                          help="leading sessions known to share the initial backlash; "
                                               "the estimates are re-zeroed on their mean (1 = the paper's "
                                               "single reference)"),
) -> None:
    """Phase II backlash (paper section V): change of backlash per session by signal shifts and by
    perceived pitch, Kalman trend and remaining hours to 10 µm. Writes OUT/backlash.json and PNGs.
    A bad run (missing, cut short, non-finite channel) is skipped with a warning recorded in the
    JSON, or with --strict ends the command with exit code 2 naming session, run and channel."""
    import json
    import math

    import numpy as np

    from analysis.dataset import DatasetError, open_measurements, open_truth
    from analysis.phase2.backlash import campaign_backlash
    from analysis.phase2.prognosis import BacklashTrend, prognosis

    out = out or directory / "backlash"
    try:
        q = process_noise if process_noise == "ml" else float(process_noise)
        if q != "ml" and not (math.isfinite(q) and q >= 0):
            raise ValueError(process_noise)
    except ValueError:
        _fail(f"--process-noise {process_noise!r}: expected a number >= 0 in m²/h³ (e.g. 1e-23) or 'ml'")
    try:
        with open_measurements(directory / "measurements.h5") as m:
            result = campaign_backlash(m, on_bad_run="raise" if strict else "skip",
                                       baseline_sessions=baseline_sessions)
            dial = m.dial_indicator()
    except (DatasetError, FileNotFoundError, OSError) as exc:
        _fail(str(exc))
    except ValueError as exc:  # traces that cannot be correlated
        _fail(f"{directory}: {exc}")
    for session, run, why in result.skipped_runs:
        console.print(f"warning: skipped session {session} run {run}: {why}", style="yellow",
                      markup=False, highlight=False)
    for session, why in result.skipped_sessions:
        console.print(f"warning: skipped session {session}: {why}", style="yellow", markup=False,
                      highlight=False)
    ses = result.sessions
    hours = [s.hours for s in ses]
    shift = [s.delta_backlash_shift_m for s in ses]
    trend = None
    if len(ses) >= 2 and np.isfinite(shift).any():
        trend = BacklashTrend(process_noise=q).fit(hours, shift)
    prog = prognosis(trend) if trend is not None else None
    dial_delta = None
    if dial is not None and len(dial[0]):
        dial_delta = (dial[0], dial[1] - dial[1][0])
    records = []
    for i, s in enumerate(ses):
        rec = s.to_json()
        if trend is not None:
            rec["smoothed_um"] = float(trend.smoothed[i] * 1e6)
            rec["smoothed_std_um"] = float(trend.smoothed_std[i] * 1e6)
        if dial_delta is not None:
            k = int(np.argmin(np.abs(dial_delta[0] - s.hours)))
            if abs(dial_delta[0][k] - s.hours) < 1e-6:
                rec["dial_indicator_um"] = float(dial[1][k])
                rec["dial_delta_um"] = float(dial_delta[1][k])
        records.append(rec)
    est = result.estimator
    doc = {
        "sessions": records,
        "prognosis": prog.to_json() if prog is not None else None,
        "reference_session": ses[0].session,
        "position_reference": "commanded position (position_cmd, screw-locked); rail-fixed "
                              "features shift by +Δbacklash forward minus reverse",
        "sign": "positive = more backlash than in the reference session",
        "skipped_runs": [{"session": a, "run": b, "reason": c} for a, b, c in result.skipped_runs],
        "skipped_sessions": [{"session": a, "reason": b} for a, b in result.skipped_sessions],
        "parameters": {"cutoff_wavelength_mm": est.cutoff_wavelength_m * 1e3,
                       "baseline_sessions": result.baseline_sessions,
                       "baseline_offset_um": {"shift": result.baseline_offset_m[0] * 1e6,
                                              "pitch": result.baseline_offset_m[1] * 1e6},
                       "kalman_process_noise_m2_per_h3": None if trend is None else trend.process_noise,
                       "window_definition": est.window_definition, "threshold": est.threshold,
                       "sigma": est.sigma, "dofs": list(est.dofs), "stationary": est.stationary,
                       "travel_mm": est.travel_m * 1e3, "lead_mm": est.lead_m * 1e3,
                       "reference_pitch_mm": None if not math.isfinite(est.reference_pitch_m_)
                       else est.reference_pitch_m_ * 1e3},
    }
    out.mkdir(parents=True, exist_ok=True)
    (out / "backlash.json").write_text(json.dumps(doc, indent=1, allow_nan=False))
    figures = []
    if plots:
        from analysis.phase2.report import write_figures

        injected = None
        if (directory / "truth.h5").exists():
            with open_truth(directory / "truth.h5") as t:
                names = [s.session for s in ses]
                b = [t.session(n)[2]["backlash_um"] for n in names]
                injected = (hours, [v - b[0] for v in b])
        figures = write_figures(result, out, trend=trend, dial=dial_delta, injected=injected)

    def fmt(v, f="{:.2f}"):
        return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f.format(v)

    ref = (f"session {ses[0].session}" if result.baseline_sessions == 1 else
           f"the mean of sessions {ses[0].session}-{ses[result.baseline_sessions - 1].session}")
    table = Table(title=f"Phase II backlash change vs {ref} ({len(ses)} sessions)")
    for col in ("session", "hours", "Δb shifts µm", "Δb pitch µm", "smoothed µm", "dial Δ µm",
                "pitch mm", "γ max"):
        table.add_column(col)
    for rec in records:
        g = [v for v in rec["gamma"].values() if v is not None]
        table.add_row(rec["session"], f"{rec['hours']:g}", fmt(rec["delta_backlash_um_shift"]),
                      fmt(rec["delta_backlash_um_pitch"]), fmt(rec.get("smoothed_um")),
                      fmt(rec.get("dial_delta_um")), fmt(rec["observed_pitch_mm"], "{:.6f}"),
                      fmt(max(g) if g else None, "{:.3f}"))
    Console(width=max(100, Console().width)).print(table)
    if prog is not None:
        p = prog.to_json()
        console.print(f"prognosis: {fmt(p['level_um'])} µm at {p['at_hours']:g} h, rate "
                      f"{fmt(p['rate_um_per_kh'])} µm/kh; {p['limit_um']:g} µm reached at "
                      f"{fmt(p['crossing_hours'], '{:.0f}')} h (95 % band "
                      f"{fmt(p['band_hours'][0], '{:.0f}')}–{fmt(p['band_hours'][1], '{:.0f}')} h)",
                      markup=False, highlight=False)
    console.print(f"wrote {out / 'backlash.json'}" + (f" and {len(figures)} figures" if figures else ""))
# --- end of Phase II backlash ----------------------------------------------------------------


def main() -> None:
    try:
        app()
    except ScenarioError as exc:  # pragma: no cover - defensive
        console.print(f"[bold red]error:[/] {exc}")
        sys.exit(2)


if __name__ == "__main__":
    main()
