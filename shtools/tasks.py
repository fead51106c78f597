"""Independent tasks on this machine's cores or on a Dask cluster: one engine for the pipeline.

A bake's frames, a batch of sphere fits and a field's shells are independent
pieces of work.  :func:`task_pool` runs them on one of three schedulers behind
one interface, :class:`TaskPool`:

``"inline"``
    In the calling process, one task after the other (one worker; nothing to
    set up).  Used for a single task, one worker, or where ``fork`` is missing.
``None`` / ``"processes"`` (the default)
    Forked worker processes on this machine
    (:class:`concurrent.futures.ProcessPoolExecutor`, ``fork`` start method):
    the state the tasks share reaches the workers through ``fork``, without
    pickling; results come back pickled.
a Dask scheduler
    ``"local"`` starts a :class:`distributed.LocalCluster` of ``workers``
    single-threaded worker processes here (and stops it afterwards);
    ``"tcp://HOST:PORT"`` or the path of a scheduler file (``dask scheduler
    --scheduler-file``) joins an existing cluster (SLURM/PBS via
    dask-jobqueue, Kubernetes, ...).  The shared state is scattered once to
    every worker; assets it names travel by path, so the workers need the
    same shared storage (``docs/scale-out.md``).

Results are yielded **in submission order** while at most ``window`` tasks are
in flight, so the caller (the one writer of an asset) never holds more than
``window`` results however long the run: memory is bounded by the window, not
by the number of tasks.

Faults.  A local worker that dies (killed, out of memory) breaks the process
pool; the pool is rebuilt and the unfinished tasks are submitted again, up to
:data:`MAX_RESUBMITS` times.  On Dask the scheduler itself reruns the tasks of
a worker that died (its ``allowed-failures``).  Tasks are pure functions of
their inputs, so a rerun gives the same bytes.  Ctrl-C or SIGTERM in the
caller cancels the pending tasks and stops the local workers (and a
``LocalCluster`` started here) before the exception propagates.

This module imports only the standard library; ``dask``/``distributed`` are
imported when a Dask scheduler is asked for (``pip install shtools[distributed]``).
"""

from __future__ import annotations

import collections
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from shtools.errors import InputError

#: Rebuilds of a broken local process pool before the run is given up.
MAX_RESUBMITS = 3
#: Tasks in flight per worker (the result window is ``WINDOW_PER_WORKER * workers``):
#: two keep every worker busy while the caller consumes results in order.
WINDOW_PER_WORKER = 2
#: Seconds to wait for a Dask scheduler before giving up with an error.
CONNECT_TIMEOUT = 10.0
#: Local worker processes at most (a typo such as ``--workers 100000`` must not
#: fork a machine to death; a bigger machine than this wants a Dask cluster).
MAX_LOCAL_WORKERS = 256
#: Scheduler names that are not addresses or files.
LOCAL_NAMES = ("inline", "processes", "local")


def default_workers() -> int:
    """Cores this process may use (``os.sched_getaffinity`` where available)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)


def can_fork() -> bool:
    """Whether forked worker processes are available (not on Windows)."""
    return "fork" in multiprocessing.get_all_start_methods()


@dataclass
class WorkerStats:
    """Tasks run and seconds spent by one worker (``--json`` summaries)."""

    tasks: int = 0
    seconds: float = 0.0


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

    def map_ordered(self, fn: Callable[[Any, Any], Any], items: Iterable, *,
                    shared: Any = None, window: int | None = None) -> Iterator[Any]:
        """Yield ``fn(shared, item)`` for each item, in the order of ``items``.

        Parameters
        ----------
        fn : callable
            A module-level function (picklable by reference) of ``(shared, item)``.
        items : iterable
            Task inputs (small, picklable).
        shared : object, optional
            State every task needs (a prepared scene, options): forked into
            local workers, scattered once to Dask workers.
        window : int, optional
            Tasks in flight at most (default ``WINDOW_PER_WORKER * workers``).

        Yields
        ------
        object
            Each task's result, in submission order.
        """
        window = max(1, window or WINDOW_PER_WORKER * self.workers)
        if self.scheduler == "inline":
            yield from self._inline(fn, items, shared)
        elif self.scheduler == "processes":
            yield from self._processes(fn, items, shared, window)
        else:
            yield from self._dask(fn, items, shared, window)

    # ------------------------------------------------------------------ schedulers
    def _record(self, worker: str, seconds: float) -> None:
        s = self.stats.setdefault(worker, WorkerStats())
        s.tasks += 1
        s.seconds += seconds

    def _inline(self, fn, items, shared):
        for item in items:
            start = time.perf_counter()
            result = fn(shared, item)
            self._record(f"pid {os.getpid()}", time.perf_counter() - start)
            yield result

    def _processes(self, fn, items, shared, window):
        from concurrent.futures import ProcessPoolExecutor
        from concurrent.futures.process import BrokenProcessPool

        global _SHARED
        _SHARED = shared  # reaches the workers through fork, not pickling
        context = multiprocessing.get_context("fork")
        items = iter(items)
        pending: collections.OrderedDict = collections.OrderedDict()  # index -> item
        futures: dict[int, Any] = {}  # index -> Future, None when the pool was broken
        resubmits = 0
        next_index = 0
        exhausted = False

        def new_pool():
            return ProcessPoolExecutor(self.workers, mp_context=context,
                                       initializer=_worker_init, initargs=(os.getpid(),))

        def submit(index):
            try:
                futures[index] = pool.submit(_run_local, fn, pending[index])
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
                    result, worker, seconds = futures[first].result()
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
                self._record(worker, seconds)
                yield result
        finally:
            _terminate(pool)
            _SHARED = None

    def _dask(self, fn, items, shared, window):
        from distributed import wait

        client = self.client
        shared_ref = client.scatter(shared, broadcast=True, hash=False) if shared is not None \
            else None
        items = iter(items)
        pending: collections.deque = collections.deque()
        exhausted = False
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
                    pending.append(client.submit(_run_dask, fn, shared_ref, item, pure=False))
                if not pending:
                    return
                future = pending.popleft()
                wait([future])
                result, worker, seconds = future.result()
                future.release()
                self._record(worker, seconds)
                yield result
        finally:
            for future in pending:
                future.cancel()
            if shared_ref is not None:
                shared_ref.release()

    def summary(self) -> dict:
        """Scheduler, worker count and per-worker task counts and seconds (for ``--json``)."""
        return {
            "scheduler": self.scheduler,
            "address": self.address,
            "workers": self.workers,
            "startup_seconds": round(self.startup_seconds, 4),
            "per_worker": {name: {"tasks": s.tasks, "seconds": round(s.seconds, 4)}
                           for name, s in sorted(self.stats.items())},
        }


# ---------------------------------------------------------------------- worker side
_SHARED: Any = None


def _worker_init(parent_pid: int) -> None:
    """Local workers die with their parent and leave Ctrl-C to it."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent cancels and terminates us
    die_with_parent(parent_pid)


def die_with_parent(parent_pid: int) -> None:
    """Make this (forked) process exit when ``parent_pid`` dies (no orphaned workers).

    Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)``, then a check that the parent did
    not die before the call.  Elsewhere: a daemon thread polling ``getppid``.
    Used by the frame pool here and by the runtime's in-frame workers.
    """
    import signal
    import threading

    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1  # <sys/prctl.h>
        armed = libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
    except (OSError, AttributeError):  # no libc prctl: not Linux
        armed = False
    if os.getppid() != parent_pid:
        os._exit(1)
    if armed:
        return

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="shtools-parent-watch", daemon=True).start()


def _run_local(fn, item):
    start = time.perf_counter()
    result = fn(_SHARED, item)
    return result, f"pid {os.getpid()}", time.perf_counter() - start


#: glibc malloc settings a Dask worker gets back (see :func:`_undo_dask_malloc_trim`):
#: the values glibc's own dynamic thresholds grow to on 64-bit Linux.
MMAP_THRESHOLD = 32 << 20
TRIM_THRESHOLD = 64 << 20
_MALLOC_TUNED = False


def _undo_dask_malloc_trim() -> None:
    """Give a Dask worker process glibc's usual large-allocation behaviour back.

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``; setting
    any malloc threshold turns glibc's dynamic mmap threshold off, so every
    NumPy temporary over 128 KiB is a fresh ``mmap`` whose pages fault in again
    on every use: a bake frame ran 1.6-1.8x slower in such a worker than in
    any other process (measured, docs/scale-out.md).  Here the thresholds are
    set to where glibc's dynamic ones settle (32 MiB mmap, 64 MiB trim), once
    per process.  Linux/glibc only; elsewhere nothing is done.
    """
    global _MALLOC_TUNED
    if _MALLOC_TUNED:
        return
    _MALLOC_TUNED = True
    if "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's <malloc.h>
        libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)
        libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD)
    except (OSError, AttributeError):  # not glibc
        pass


def _run_dask(fn, shared, item):
    from distributed import get_worker

    _undo_dask_malloc_trim()
    start = time.perf_counter()
    result = fn(shared, item)
    return result, get_worker().address, time.perf_counter() - start


def _terminate(pool) -> None:
    """Stop a process pool now: cancel queued tasks and kill running workers."""
    processes = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.terminate()
    for p in processes:
        p.join(timeout=5)


# ---------------------------------------------------------------------- set-up
def _is_dask(scheduler: str | None) -> bool:
    return scheduler is not None and scheduler not in ("inline", "processes")


def check_scheduler(scheduler: str | None) -> None:
    """Refuse a scheduler value that is neither a name, an address nor an existing file."""
    if scheduler is None or scheduler in LOCAL_NAMES or "://" in scheduler:
        return
    if not Path(scheduler).is_file():
        raise InputError(
            "is neither 'local', a scheduler address (tcp://HOST:PORT) nor an existing "
            "scheduler file", scheduler)


@contextmanager
def task_pool(scheduler: str | None = None, workers: int | None = None, *,
              n_tasks: int | None = None) -> Iterator[TaskPool]:
    """Open a :class:`TaskPool` (see the module docstring for the schedulers).

    Parameters
    ----------
    scheduler : str, optional
        None or ``"processes"`` (forked local workers), ``"inline"``,
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
        if kind == "processes" and (n == 1 or not can_fork()):
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
            # Single-threaded workers: each task uses NumPy/BLAS on one core.
            cluster = distributed.LocalCluster(
                n_workers=workers or default_workers(), threads_per_worker=1,
                processes=True, dashboard_address=":0", silence_logs=50)
            client = distributed.Client(cluster, timeout=CONNECT_TIMEOUT)
        elif "://" in scheduler:
            client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT)
        else:
            client = distributed.Client(scheduler_file=scheduler, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError) as exc:
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
