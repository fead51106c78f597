"""The task pool: ``fn(shared, item)`` for many items, in order, on one scheduler.

:func:`task_pool` opens a :class:`TaskPool` on this process (``inline``), local
worker processes (:mod:`shtools.tasks.workers`) or a Dask cluster
(:mod:`shtools.tasks.dask_cluster`); :meth:`TaskPool.map_ordered` yields the
results in submission order with a bounded window of tasks in flight (the
schedulers are described in :mod:`shtools.tasks`).
"""

from __future__ import annotations

import collections
import os
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from shtools.errors import InputError
from shtools.tasks.dask_cluster import (
    CONNECT_TIMEOUT,
    EMBEDDED_CLUSTER_CONFIG,
    _is_dask,
    _run_dask,
    _setup_dask,
    check_scheduler,
)
from shtools.tasks.workers import (
    MAX_LOCAL_WORKERS,
    _run_local,
    _terminate,
    _timed,
    _worker_init,
    blas_threads,
    can_start_workers,
    default_workers,
    start_worker,
    worker_context,
)

#: Rebuilds of a broken local process pool before the run is given up.
MAX_RESUBMITS = 3
#: Tasks in flight per worker (the result window is ``WINDOW_PER_WORKER * workers``):
#: two keep every worker busy while the caller consumes results in order.
WINDOW_PER_WORKER = 2


@dataclass
class WorkerStats:
    """Tasks run, and wall and CPU seconds spent in them, by one worker (``--json``).

    ``cpu_seconds`` is the CPU time of the thread running the tasks: against
    ``seconds`` it shows how much of a task's wall time other processes on a
    busy machine took.
    """

    tasks: int = 0
    seconds: float = 0.0
    cpu_seconds: float = 0.0


@dataclass
class TaskPool:
    """Runs ``fn(shared, item)`` for many items on one scheduler (see the module docstring).

    Create it with :func:`task_pool`.

    Attributes
    ----------
    scheduler : str
        ``"inline"``, ``"processes"`` or ``"dask"``.
    workers : int
        Workers the tasks are spread over (for a remote cluster: its worker
        count when the run started).
    address : str or None
        The Dask scheduler's address.
    stats : dict
        Worker name -> :class:`WorkerStats` of the runs so far.
    """

    scheduler: str
    workers: int
    address: str | None = None
    client: Any = None
    stats: dict = field(default_factory=dict)
    #: Seconds spent starting a cluster and connecting to it.
    startup_seconds: float = 0.0
    #: Seconds spent shipping shared state to the workers and running their
    #: one-time ``setup`` (:meth:`share`), before any task.
    setup_seconds: float = 0.0

    @contextmanager
    def share(self, shared: Any, setup: Callable[[Any], None] | None = None
              ) -> Iterator[Shared]:
        """Ship ``shared`` to the workers once, for any number of :meth:`map_ordered` calls.

        Parameters
        ----------
        shared : object
            State every task needs (a prepared scene, tables, options).
        setup : callable, optional
            ``setup(shared)``, the one-time work of a worker before its first
            task (building a runtime from the shared state, ...): run on every
            Dask worker here, before any task, and timed into
            :attr:`setup_seconds` (start-up, not task time); in each local
            worker when it starts; once in this process for ``inline``.
            Tasks must still work without it (a Dask worker that joins later
            or replaces a dead one runs its first task without the set-up), so
            ``setup`` is the same cached initialisation the task function does;
            a set-up that fails is left to the first task, which fails with
            the real error.

        Yields
        ------
        Shared
            Pass it as ``shared=`` to :meth:`map_ordered`.
        """
        start = time.perf_counter()
        if self.scheduler != "dask":
            if setup is not None and self.scheduler == "inline":
                setup(shared)
            self.setup_seconds += time.perf_counter() - start
            yield Shared(shared, None, setup)
            return
        from distributed import wait

        client = self.client
        ref = None if shared is None else client.scatter(shared, broadcast=True, hash=False)
        handle = None
        try:
            if setup is not None:
                # One set-up task per worker; loose restrictions so a worker
                # that dies meanwhile does not leave its set-up waiting forever.
                wait([client.submit(_setup_dask, setup, ref, workers=[w],
                                    allow_other_workers=True, pure=False)
                      for w in client.scheduler_info().get("workers", {})])
            self.setup_seconds += time.perf_counter() - start
            handle = Shared(shared, ref, setup)
            yield handle
        finally:
            if ref is not None:
                ref.release()
                if handle is not None and handle.ref is not ref:  # scattered again (_dask)
                    handle.ref.release()

    def map_ordered(self, fn: Callable[[Any, Any], Any], items: Iterable, *,
                    shared: Any = None, window: int | None = None,
                    setup: Callable[[Any], None] | None = None) -> Iterator[Any]:
        """Yield ``fn(shared, item)`` for each item, in the order of ``items``.

        Parameters
        ----------
        fn : callable
            A module-level function (picklable by reference) of ``(shared, item)``.
        items : iterable
            Task inputs (small, picklable).
        shared : object or Shared, optional
            State every task needs (a prepared scene, options; picklable):
            pickled once to each local worker, scattered once to Dask workers; a :class:`Shared`
            from :meth:`share` is reused as it is (no second shipping).
        window : int, optional
            Tasks in flight at most (default ``WINDOW_PER_WORKER * workers``).
        setup : callable, optional
            Per-worker one-time set-up of ``shared`` (see :meth:`share`).

        Yields
        ------
        object
            Each task's result, in submission order.
        """
        if not isinstance(shared, Shared):
            with self.share(shared, setup) as handle:
                yield from self.map_ordered(fn, items, shared=handle, window=window)
            return
        window = max(1, window or WINDOW_PER_WORKER * self.workers)
        if self.scheduler == "inline":
            yield from self._inline(fn, items, shared.value)
        elif self.scheduler == "processes":
            yield from self._processes(fn, items, shared.value, window, shared.setup)
        else:
            yield from self._dask(fn, items, shared, window)

    # ------------------------------------------------------------------ schedulers
    def _record(self, worker: str, seconds: float, cpu: float) -> None:
        s = self.stats.setdefault(worker, WorkerStats())
        s.tasks += 1
        s.seconds += seconds
        s.cpu_seconds += cpu

    def _inline(self, fn, items, shared):
        for item in items:
            result, worker, seconds, cpu = _timed(fn, shared, item, f"pid {os.getpid()}")
            self._record(worker, seconds, cpu)
            yield result

    def _processes(self, fn, items, shared, window, setup):
        from concurrent.futures import ProcessPoolExecutor
        from concurrent.futures.process import BrokenProcessPool

        context = worker_context()
        blas = blas_threads()
        items = iter(items)
        pending: collections.OrderedDict = collections.OrderedDict()  # index -> item
        futures: dict[int, Any] = {}  # index -> Future, None when the pool was broken
        resubmits = 0
        next_index = 0
        exhausted = False

        def new_pool():
            return ProcessPoolExecutor(self.workers, mp_context=context, initializer=_worker_init,
                                       initargs=(os.getpid(), shared, setup, blas))

        def submit(index):
            try:
                futures[index] = start_worker(pool.submit, _run_local, fn, pending[index])
            except BrokenProcessPool:  # a worker died since the last check
                futures[index] = None

        def succeeded(f) -> bool:
            return f is not None and f.done() and not f.cancelled() and f.exception() is None

        pool = new_pool()
        try:
            while True:
                while not exhausted and len(pending) < window:
                    try:
                        pending[next_index] = next(items)
                    except StopIteration:
                        exhausted = True
                        break
                    submit(next_index)
                    next_index += 1
                if not pending:
                    return
                first = next(iter(pending))
                try:
                    if futures[first] is None:
                        raise BrokenProcessPool("a worker died")
                    result, worker, seconds, cpu = futures[first].result()
                except BrokenProcessPool:
                    # A worker died (killed, out of memory): rebuild the pool and
                    # resubmit every unfinished task; finished ones are kept.
                    resubmits += 1
                    if resubmits > MAX_RESUBMITS:
                        raise RuntimeError(
                            f"worker processes died {resubmits} times; giving up") from None
                    _terminate(pool)
                    pool = new_pool()
                    for index in pending:
                        if not succeeded(futures[index]):
                            submit(index)
                    continue
                del pending[first]
                del futures[first]
                self._record(worker, seconds, cpu)
                yield result
        finally:
            _terminate(pool)

    def _dask(self, fn, items, shared: Shared, window):
        from concurrent.futures import CancelledError

        client = self.client
        items = iter(items)
        pending: collections.deque = collections.deque()  # (item, future)
        exhausted = False
        rescatters = 0
        try:
            while True:
                while not exhausted and len(pending) < window:
                    try:
                        item = next(items)
                    except StopIteration:
                        exhausted = True
                        break
                    # pure=False: equal items are still separate tasks; the
                    # scheduler reruns a task whose worker died.
                    pending.append((item, client.submit(_run_dask, fn, shared.ref, item,
                                                        pure=False)))
                if not pending:
                    return
                try:
                    result, worker, seconds, cpu = pending[0][1].result()
                except CancelledError:
                    # The scheduler forgot the shared state, so every task needing it:
                    # scattered data cannot be recomputed, and a cluster's active
                    # memory manager keeps one replica of a broadcast (every 2 s by
                    # default), so the death of the worker holding it loses it.
                    # Scatter it again and resubmit what is pending.
                    rescatters += 1
                    if shared.ref is None or rescatters > MAX_RESUBMITS:
                        raise
                    if shared.ref.status != "finished":
                        shared.ref = client.scatter(shared.value, broadcast=True, hash=False)
                    pending = collections.deque(
                        (item, client.submit(_run_dask, fn, shared.ref, item, pure=False))
                        for item, _ in pending)
                    continue
                pending.popleft()[1].release()
                self._record(worker, seconds, cpu)
                yield result
        finally:
            for _, future in pending:
                future.cancel()

    def summary(self) -> dict:
        """Scheduler, worker count and per-worker task counts and seconds (for ``--json``)."""
        return {
            "scheduler": self.scheduler,
            "address": self.address,
            "workers": self.workers,
            "startup_seconds": round(self.startup_seconds, 4),
            "setup_seconds": round(self.setup_seconds, 4),
            "per_worker": {name: {"tasks": s.tasks, "seconds": round(s.seconds, 4),
                                  "cpu_seconds": round(s.cpu_seconds, 4)}
                           for name, s in sorted(self.stats.items())},
        }


@dataclass
class Shared:
    """State shipped once to a pool's workers (:meth:`TaskPool.share`).

    Attributes
    ----------
    value : object
        The state itself (what each local worker gets pickled when it starts).
    ref : distributed.Future or None
        The state scattered to the Dask workers.
    setup : callable or None
        The workers' one-time set-up of the state.
    """

    value: Any
    ref: Any = None
    setup: Callable[[Any], None] | None = None


@contextmanager
def task_pool(scheduler: str | None = None, workers: int | None = None, *,
              n_tasks: int | None = None) -> Iterator[TaskPool]:
    """Open a :class:`TaskPool` (see the module docstring for the schedulers).

    Parameters
    ----------
    scheduler : str, optional
        None or ``"processes"`` (local worker processes), ``"inline"``,
        ``"local"`` (a Dask LocalCluster), ``"tcp://HOST:PORT"`` or a
        scheduler file.
    workers : int, optional
        Local workers (default: the usable cores); ignored for a remote cluster.
    n_tasks : int, optional
        Number of tasks, when known: local pools never start more workers
        than tasks, and one task runs inline.

    Raises
    ------
    InputError
        The scheduler cannot be reached, or ``dask``/``distributed`` are missing.
    """
    check_scheduler(scheduler)
    if workers is not None and not 1 <= workers <= MAX_LOCAL_WORKERS:
        raise InputError(f"--workers must be in 1..{MAX_LOCAL_WORKERS}, got {workers}")
    if not _is_dask(scheduler):
        n = workers or default_workers()
        if n_tasks is not None:
            n = max(1, min(n, n_tasks))
        kind = scheduler or "processes"
        if kind == "processes" and (n == 1 or not can_start_workers()):
            kind = "inline"
        yield TaskPool("inline" if kind == "inline" else "processes",
                       1 if kind == "inline" else n)
        return
    try:
        import distributed
    except ImportError:
        raise InputError("Dask is not installed: pip install 'shtools[distributed]'",
                         scheduler) from None
    cluster = None
    start = time.perf_counter()
    try:
        if scheduler == "local":
            import dask

            # Single-threaded workers: each task uses NumPy/BLAS on one core.
            with dask.config.set(EMBEDDED_CLUSTER_CONFIG):
                cluster = distributed.LocalCluster(
                    n_workers=workers or default_workers(), threads_per_worker=1,
                    processes=True, dashboard_address=":0", silence_logs=50)
                client = distributed.Client(cluster, timeout=CONNECT_TIMEOUT)
        elif "://" in scheduler:
            client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT)
        else:
            client = distributed.Client(scheduler_file=scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError, ValueError, TypeError) as exc:
        if cluster is not None:
            cluster.close()
        raise InputError(f"cannot reach the Dask scheduler ({type(exc).__name__}); "
                         "check the address and that the scheduler runs", scheduler) from None
    try:
        n = len(client.scheduler_info().get("workers", {})) or (workers or 1)
        yield TaskPool("dask", n, address=client.scheduler.address, client=client,
                       startup_seconds=time.perf_counter() - start)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
