"""What every verb of the command line shares: the Typer app, the console, the errors of the
user's input (exit 2 with one message naming the file, key and value), the optional extras, the
gate on a recording `twin check` rejects, and the options several verbs take."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console

from twin.sim.scenario import SHIPPED

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
    from analysis.base.files import read_json, write_json

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
