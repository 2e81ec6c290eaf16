"""Running a sweep: submit the points not yet done, record each result as it returns."""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from analysis.base.executors import ExecutorError, default_processes, make_executor
from analysis.base.files import write_json
from twin.harness.sweep.plan import Plan, Task
from twin.harness.sweep.plots import write_plots
from twin.harness.sweep.results import results_table, write_table
from twin.harness.sweep.runlog import _append_log, _claim, point_dir, read_result
from twin.harness.sweep.schema import RESULT_NAME, SweepError
from twin.sim.scenario import from_dict

# ---------------------------------------------------------------------------------------------
# Work done on a worker


def run_task(scenario: dict, point_dir: str, reference_dir: str | None,
             analysis: dict | None = None) -> dict:
    """Simulate, analyse and score one point in this process with one BLAS thread.
    ``analysis``: {"methods", "estimators"} of the sweep's ``[analysis]`` (None: the defaults).

    Returns ``{"score": score.json object or None, "simulated_units", "reused_units",
    "skipped", "seconds", "host", "pid"}``."""
    import socket

    from threadpoolctl import threadpool_limits

    from twin.harness.chain import run_point

    t0 = time.perf_counter()
    s = from_dict(scenario)
    with threadpool_limits(1):
        r = run_point(s, point_dir, reference_dir, **(analysis or {}))
    r["seconds"] = time.perf_counter() - t0
    r["host"], r["pid"] = socket.gethostname(), os.getpid()
    return r


# ---------------------------------------------------------------------------------------------
# Running


@dataclass
class Callbacks:
    """Progress hooks: reference(done, total, unit); point(done, total, task, record)."""

    executor: Callable[[str], None] = lambda description: None
    reference: Callable[[int, int, str], None] = lambda done, total, name: None
    start: Callable[[int, int], None] = lambda todo, total: None
    point: Callable[[int, int, Task, dict], None] = lambda done, total, task, rec: None


def run_sweep(plan: Plan, out: str | Path, *, workers: int | None = None,
              scheduler: str | None = None, callbacks: Callbacks | None = None) -> dict:
    """Run every task of ``plan`` not yet recorded in ``out``; write the table and the plots.

    Returns the end record of the log: ``{"computed", "reused", "failed", "simulated_units",
    "reused_units", "reference_simulated_units", "seconds", ...}``. Raises :class:`SweepError`
    if ``out`` holds another sweep."""
    out = Path(out).resolve()  # the workers (possibly elsewhere, --scheduler) get absolute paths
    cb = callbacks or Callbacks()
    _claim(out, plan)
    t0 = time.perf_counter()
    invocation = uuid.uuid4().hex[:12]
    done_tasks = [t for t in plan.tasks if read_result(out, t) is not None]
    todo = [t for t in plan.tasks if read_result(out, t) is None]
    executor_name = ("dask:" + scheduler if scheduler else f"dask-local:{workers}" if workers
                     else f"processes:{default_processes()}")
    _append_log(out, {"event": "start", "invocation": invocation, "time": time.time(),
                      "executor": executor_name, "tasks": len(plan.tasks), "todo": len(todo),
                      "reused": len(done_tasks)})
    ref_dir = None
    ref_units = 0
    if plan.reference is not None:
        ref_dir = out / "reference"
        from twin.sim.campaign import CampaignDirectoryError, simulate_campaign

        try:
            summary = simulate_campaign(from_dict(plan.reference), ref_dir,
                                        workers=workers or default_processes(),
                                        on_progress=cb.reference)
        except CampaignDirectoryError as exc:
            raise SweepError(str(exc)) from None
        ref_units = summary["simulated"]
    cb.start(len(todo), len(plan.tasks))
    computed = failed = sim_units = reused_units = 0
    n_done = len(done_tasks)
    if todo:
        try:  # default: all local cores; workers=N: a Dask LocalCluster of N; scheduler: a cluster
            executor = make_executor(default_processes(), dask_workers=workers, scheduler=scheduler, prefix="sweep")
        except ExecutorError as exc:
            raise SweepError(str(exc)) from None
        with executor as ex:
            cb.executor(ex.description)
            futures = {}
            for t in todo:
                futures[ex.submit(run_task, t.scenario, str(point_dir(out, t)),
                                  None if ref_dir is None else str(ref_dir), plan.analysis,
                                  key=t.id)] = t
            for fut in ex.completed(list(futures)):
                t = futures[fut]
                try:
                    r = fut.result()
                    rec = {"point": t.point, "seed": t.seed, "values": t.values,
                           "score": r["score"], "skipped": r["skipped"], "error": None}
                    computed += 1
                    sim_units += r["simulated_units"]
                    reused_units += r["reused_units"]
                    n_done += 1
                except Exception as exc:  # a point that fails is recorded, retried on a rerun
                    r = {"simulated_units": 0, "reused_units": 0, "seconds": None, "host": None,
                         "pid": None}
                    rec = {"point": t.point, "seed": t.seed, "values": t.values, "score": None,
                           "skipped": {}, "error": f"{type(exc).__name__}: {exc}"}
                    failed += 1
                point_dir(out, t).mkdir(parents=True, exist_ok=True)
                write_json(point_dir(out, t) / RESULT_NAME, rec)
                _append_log(out, {"event": "point", "invocation": invocation, "id": t.id,
                                  "error": rec["error"], "simulated_units": r["simulated_units"],
                                  "reused_units": r["reused_units"], "seconds": r["seconds"],
                                  "host": r["host"], "pid": r["pid"]})
                cb.point(n_done, len(plan.tasks), t, rec)
    table = results_table(plan, out)
    write_table(table, out)

    figures = write_plots(plan, out, table)
    end = {"event": "end", "invocation": invocation, "time": time.time(),
           "executor": executor_name, "tasks": len(plan.tasks), "computed": computed,
           "reused": len(done_tasks), "failed": failed, "simulated_units": sim_units,
           "reused_units": reused_units, "reference_simulated_units": ref_units,
           "seconds": time.perf_counter() - t0, "figures": [str(f) for f in figures]}
    _append_log(out, end)
    return end
