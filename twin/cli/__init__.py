"""The ``twin`` command line, the face of the tool: ``simulate`` and ``export-model`` (the
simulator), ``detect``, ``monitor`` and ``backlash`` (the analysis), ``import``, ``check`` and
``scenario init`` (a lab's recordings), ``calibrate``, ``diagnose`` and their benchmarks (the
sim-to-real gap), ``score``, ``report``, ``demo``, ``sweep``, ``view`` and ``gate`` (the
harness). Each verb parses its options, calls one function of the package below it and prints a
summary; errors of the user's input exit with code 2 and one message naming the file, key and
value. The verbs live in modules by group; importing them registers them on :data:`app`."""

from __future__ import annotations

import importlib
import sys

from twin.cli.common import app, console, gate_recording
from twin.sim.scenario import ScenarioError

#: The verb groups in the order ``twin --help`` lists them (importing one registers its verbs).
GROUPS = ("simulation", "monitoring", "lab", "diagnosis")
for _group in GROUPS:
    importlib.import_module(f"twin.cli.{_group}")

__all__ = ["GROUPS", "app", "gate_recording", "main"]


def main() -> None:
    from threadpoolctl import threadpool_limits

    from analysis.base.executors import ExecutorError, default_processes, keep_freed_memory

    keep_freed_memory()
    # One BLAS and OpenMP thread, as in the worker processes: the commands' parallelism is their
    # worker processes (--workers); with one worker the work runs here, where OpenBLAS's extra
    # threads only spin between its many small products (docs/validation.md, "Simulation speed").
    threadpool_limits(1)
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
