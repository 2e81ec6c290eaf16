"""Where the points run: the work of one task, a local process pool or a Dask cluster."""

from __future__ import annotations

import os
import time
import uuid
from collections.abc import Iterator

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
# Executors


class _Executor:
    """submit(fn, *args, key) -> future; completed(futures) yields them as they finish."""

    description = ""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:  # pragma: no cover - overridden
        pass


class _LocalPool(_Executor):
    def __init__(self, workers: int):
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        self.workers = workers
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"))
        self.description = f"{workers} local processes"

    def submit(self, fn, *args, key: str):
        return self.pool.submit(fn, *args)

    def completed(self, futures) -> Iterator:
        from concurrent.futures import as_completed

        yield from as_completed(futures)

    def close(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


class _Dask(_Executor):
    def __init__(self, workers: int | None = None, scheduler: str | None = None):
        import logging

        from distributed import Client, LocalCluster

        self.cluster = None
        if scheduler is None:
            self.cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                        dashboard_address=None, silence_logs=logging.ERROR)
            self.client = Client(self.cluster)
            self.description = f"dask LocalCluster of {workers} worker processes"
        else:
            try:
                self.client = Client(scheduler, timeout="30s")
            except (OSError, TimeoutError) as exc:
                raise SweepError(f"--scheduler {scheduler}: cannot connect to a dask scheduler there "
                                 f"({exc}); expected the address of a running scheduler, e.g. "
                                 "tcp://10.0.0.5:8786") from None
            n = len(self.client.scheduler_info().get("workers", {}))
            self.description = f"dask cluster at {scheduler} ({n} workers now)"
        self.token = uuid.uuid4().hex[:8]

    def submit(self, fn, *args, key: str):
        return self.client.submit(fn, *args, key=f"sweep-{key}-{self.token}", pure=False)

    def completed(self, futures) -> Iterator:
        from distributed import as_completed

        yield from as_completed(futures)

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_executor(workers: int | None = None, scheduler: str | None = None) -> _Executor:
    if scheduler is not None:
        return _Dask(scheduler=scheduler)
    if workers is not None:
        return _Dask(workers=workers)
    return _LocalPool(os.cpu_count() or 1)
