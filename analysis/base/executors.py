"""Where independent pieces of work run: this process, local processes or a Dask cluster.

One executor choice serves ``twin sweep`` (campaigns), ``twin simulate`` (the units of a
campaign) and ``twin backlash`` (the sessions of a campaign):

- local processes (the default): a ``concurrent.futures.ProcessPoolExecutor`` started with
  ``spawn``;
- ``dask_workers=N``: a ``dask.distributed.LocalCluster`` of N single-threaded worker processes;
- ``scheduler=ADDRESS``: an existing Dask cluster; its workers need the same environment and must
  see the files the work reads and writes at the same paths (a shared file system).

Every piece of work handed to an executor is a pure function of its arguments (seeded draws, files
read), so the results do not depend on which executor runs it, nor on the order; :func:`map_ordered`
returns them in the order of the arguments.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Iterator, Sequence

__all__ = ["ExecutorError", "Executor", "default_processes", "make_executor", "map_ordered", "mapper", "run_tasks"]


class ExecutorError(ValueError):
    """The executor cannot be set up (e.g. no Dask scheduler at the given address)."""


#: The environment variable that sets how many local processes a command starts when it is not
#: told (``--workers``): e.g. 1 on a machine whose cores are busy with other work, or under a
#: test runner that already runs one test per core.
WORKERS_ENV = "TWIN_WORKERS"


def default_processes() -> int:
    """The local processes a command starts by default: ``TWIN_WORKERS`` when set, else every
    core (``os.cpu_count()``).

    Raises:
        ExecutorError: ``TWIN_WORKERS`` is not a whole number >= 1.
    """
    text = os.environ.get(WORKERS_ENV)
    if text is None or not text.strip():
        return os.cpu_count() or 1
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise ExecutorError(f"environment variable {WORKERS_ENV}={text!r}: expected a whole number of "
                            "local processes >= 1 (or unset: every core)")
    return n


class Executor:
    """submit(fn, *args, key) -> future; completed(futures) yields them as they finish;
    ``description`` says where the work runs (for logs); ``in_process`` whether it runs in this
    process (then this process has no spare time while it does)."""

    description = ""
    in_process = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def submit(self, fn, *args, key: str):  # pragma: no cover - overridden
        raise NotImplementedError

    def completed(self, futures) -> Iterator:  # pragma: no cover - overridden
        raise NotImplementedError

    def close(self) -> None:  # pragma: no cover - overridden
        pass

    def interrupt(self) -> None:
        """Ctrl-C: cancel the queued work and stop what runs now, as far as this executor can
        (the caller then closes it); pieces of work must be safe to stop (atomic writes)."""
        self.close()


def keep_freed_memory(mmap_threshold_bytes: int = 64 << 20, trim_threshold_bytes: int = 256 << 20) -> bool:
    """Let this process's C allocator keep freed memory for the next allocation instead of
    handing it back to the operating system at every ``free``.

    The sensor models and the Phase II gridding allocate and free arrays of a few megabytes
    thousands of times; glibc's defaults return the top of the heap to the system as soon as
    more than its trim threshold is free, so each new array faults its pages in again (about as
    much time as the arithmetic on it). ``mallopt(3)`` with ``M_MMAP_THRESHOLD`` (allocations
    above it get their own mapping, released at once) and ``M_TRIM_THRESHOLD`` (free memory
    kept at the top of the heap) sets both; the peak memory is unchanged. Returns whether it was
    applied: False off glibc (another C library or operating system), where nothing changes.
    """
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3  # <malloc.h>
    return bool(mallopt(m_mmap_threshold, mmap_threshold_bytes) == 1
                and mallopt(m_trim_threshold, trim_threshold_bytes) == 1)


def _init_worker() -> None:
    """Worker initializer: Ctrl-C is the parent's to handle (it stops the workers), so a worker
    neither dies with a traceback nor reports a half-done piece of work as an error; one BLAS and
    OpenMP thread per worker (the workers already fill the cores: a second thread per worker
    only competes with the other workers, about 20 % more CPU time for the same work); and the
    allocator keeps freed memory (:func:`keep_freed_memory`)."""
    import signal

    from threadpoolctl import threadpool_limits

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threadpool_limits(1)
    keep_freed_memory()


class _Deferred:
    """A call made in this process when its result is first asked for (so that progress is
    reported as each call finishes)."""

    def __init__(self, fn, args):
        self._fn, self._args, self._done, self._value = fn, args, False, None

    def result(self):
        if not self._done:
            self._value, self._done = self._fn(*self._args), True
        return self._value


class _Serial(Executor):
    description = "this process"
    in_process = True

    def submit(self, fn, *args, key: str):
        return _Deferred(fn, args)

    def completed(self, futures) -> Iterator:
        yield from futures

    def interrupt(self) -> None:
        pass  # the call in progress was interrupted in this process; the rest never start


class _LocalPool(Executor):
    def __init__(self, workers: int):
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        self.workers = workers
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                                        initializer=_init_worker)
        self.description = f"{workers} local processes"

    def submit(self, fn, *args, key: str):
        return self.pool.submit(fn, *args)

    def completed(self, futures) -> Iterator:
        from concurrent.futures import as_completed

        yield from as_completed(futures)

    def close(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)

    def interrupt(self) -> None:
        # ProcessPoolExecutor cannot stop running calls: its worker processes (in _processes,
        # which shutdown() forgets, so they are taken first) are killed.
        procs = list((getattr(self.pool, "_processes", None) or {}).values())
        manager = getattr(self.pool, "_executor_manager_thread", None)
        self.pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            proc.kill()
        for proc in procs:
            proc.join(timeout=1.0)
        # The pool's manager thread closes its wake-up pipe once it sees the workers gone; the
        # interpreter's exit writes to that pipe, and if the thread is still closing it the write
        # fails with "Bad file descriptor" and a traceback after the clean exit 130. So wait for it.
        if manager is not None:
            manager.join(timeout=1.0)


class _Dask(Executor):
    def __init__(self, workers: int | None = None, scheduler: str | None = None,
                 prefix: str = "task"):
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
                raise ExecutorError(f"--scheduler {scheduler}: cannot connect to a dask scheduler "
                                    f"there ({exc}); expected the address of a running scheduler, "
                                    "e.g. tcp://10.0.0.5:8786") from None
            n = len(self.client.scheduler_info().get("workers", {}))
            self.description = f"dask cluster at {scheduler} ({n} workers now)"
        self.prefix = prefix
        self.token = uuid.uuid4().hex[:8]
        self._submitted: list = []

    def submit(self, fn, *args, key: str):
        fut = self.client.submit(fn, *args, key=f"{self.prefix}-{key}-{self.token}", pure=False)
        self._submitted.append(fut)
        return fut

    def completed(self, futures) -> Iterator:
        from distributed import as_completed

        yield from as_completed(futures)

    def interrupt(self) -> None:
        self.client.cancel(self._submitted, force=True)

    def close(self) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()


def make_executor(processes: int | None = None, *, dask_workers: int | None = None,
                  scheduler: str | None = None, prefix: str = "task") -> Executor:
    """The executor for one command.

    Args:
        processes: local processes (default :func:`default_processes`); 1 runs in this process.
        dask_workers: start a Dask LocalCluster of this many worker processes instead.
        scheduler: connect to the Dask scheduler at this address instead (``tcp://host:8786``).
        prefix: first part of the Dask task keys (seen on the cluster's dashboard).

    Raises:
        ExecutorError: no scheduler answers at ``scheduler``.
    """
    if scheduler is not None:
        return _Dask(scheduler=scheduler, prefix=prefix)
    if dask_workers is not None:
        return _Dask(workers=dask_workers, prefix=prefix)
    n = processes or default_processes()
    return _Serial() if n == 1 else _LocalPool(n)


def parallel_slots(processes: int | None = None, scheduler: str | None = None) -> int:
    """How many tasks run at once: ``processes`` local processes (default
    :func:`default_processes`), or the threads of the workers the Dask cluster at ``scheduler``
    has now."""
    if scheduler is None:
        return processes or default_processes()
    with make_executor(scheduler=scheduler) as ex:
        return max(1, sum(ex.client.nthreads().values()))  # type: ignore[attr-defined]


def map_ordered(executor: Executor, fn: Callable, args: Sequence[tuple], keys: Sequence[str],
                on_done: Callable[[int, str], None] | None = None) -> list:
    """``[fn(*a) for a in args]`` on ``executor``, in the order of ``args``.

    ``keys`` names each call (Dask task keys, progress); ``on_done(i, key)`` is called as each
    call finishes (in completion order). The first call that raised re-raises here, after the
    executor has finished or cancelled the rest (when the caller closes it)."""
    futures = [executor.submit(fn, *a, key=k) for a, k in zip(args, keys, strict=True)]
    index = {id(f): i for i, f in enumerate(futures)}
    results: list = [None] * len(futures)
    for fut in executor.completed(futures):
        i = index[id(fut)]
        results[i] = fut.result()
        if on_done is not None:
            on_done(i, keys[i])
    return results


def mapper(processes: int | None = None, *, scheduler: str | None = None,
           prefix: str = "task") -> Callable[[Callable, Sequence[tuple]], Iterator]:
    """A ``map(fn, args)`` that yields ``fn(*a)`` for each of ``args`` in order, each as soon as
    it and those before it are done (the caller works on it while the executor computes the
    next), running the calls on an executor started for them and closed after: local processes
    (``processes``, default all cores, never more than there are calls; one runs them in this
    process, one after the other) or the Dask cluster at ``scheduler``. What ``twin backlash``
    passes to the analysis for its sessions. A call that raised re-raises where its result is
    due; the executor is then closed, which stops the rest.

    Raises (when iterated):
        ExecutorError: no scheduler answers at ``scheduler``.
    """
    def run(fn: Callable, args: Sequence[tuple]) -> Iterator:
        n = len(args)
        local = min(processes or default_processes(), max(n, 1))
        with make_executor(local, scheduler=scheduler, prefix=prefix) as ex:
            futures = [ex.submit(fn, *a, key=str(i)) for i, a in enumerate(args)]
            for fut in futures:
                yield fut.result()

    return run


def run_tasks(fn: Callable, args: list[tuple], workers: int, scheduler: str | None = None,
              on_done: Callable[[int], None] | None = None, prefix: str = "task") -> list:
    """``[fn(*a) for a in args]`` in order: on the Dask cluster at ``scheduler`` when given
    (its workers must see the files the tasks read and write at the same paths), else on
    ``workers`` local processes (never more than there are tasks), or in this process when there
    is one worker or one task. ``on_done(i)`` is called as task i finishes; ``prefix`` names the
    tasks on the cluster's dashboard. Each task must be a pure function of its arguments, so the
    results do not depend on where it ran."""
    if not args:
        return []
    local = 1 if workers <= 1 or len(args) <= 1 else min(workers, len(args))
    with make_executor(local, scheduler=scheduler, prefix=prefix) as ex:
        return map_ordered(ex, fn, args, [str(i) for i in range(len(args))],
                           None if on_done is None else (lambda i, _key: on_done(i)))
