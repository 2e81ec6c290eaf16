"""Where the points run: the work of one task, a local process pool or a Dask cluster."""

from __future__ import annotations

import os
import time

from twin.executors import Executor, ExecutorError, default_processes
from twin.executors import make_executor as shared_executor
from twin.harness.sweep.schema import SweepError
from twin.scenario import from_dict

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
# Executors: the shared ones of twin.executors


def make_executor(workers: int | None = None, scheduler: str | None = None) -> Executor:
    """Default: all local cores (processes); ``workers=N``: a Dask LocalCluster of N worker
    processes; ``scheduler``: an existing Dask cluster (:func:`twin.executors.make_executor`).

    Raises:
        SweepError: no scheduler answers at ``scheduler``.
    """
    try:
        return shared_executor(default_processes(), dask_workers=workers, scheduler=scheduler,
                               prefix="sweep")
    except ExecutorError as exc:
        raise SweepError(str(exc)) from None
