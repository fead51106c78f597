"""Worker processes that share the per-vertex stages of a frame (accumulate + exp).

The per-pair work of a frame is hundreds of small NumPy array passes per block.
Threads do not speed it up: every pass releases and re-takes the GIL, and two
threads contending for it spend most of the frame handing it over (on the
2-core reference machine two threads gave 1.0-1.3x).  Processes do: the frame's
receiver clusters are split into parts of about equal work (pairs), the calling
process evaluates one part while worker processes evaluate the others, and each
part goes through accumulation *and* exponentiation before it comes back, so
only receivers, cuts and the ``(V, n*n)`` result cross process boundaries.

Workers are forked by multiprocessing's fork server, never from the caller,
whose threads (oneTBB's, after Embree) may hold a lock at the instant of a fork
(:func:`shtools.tasks.worker_context`); the settings and log tables are pickled
to each worker once.  They are started on the first frame large enough
to gain from them (:data:`MIN_PARALLEL_PAIRS`), and stopped by
:meth:`VertexWorkers.close`, when the runtime is garbage-collected, or at exit.
They never outlive the caller (:func:`shtools.tasks.die_with_parent`: on Linux
the kernel kills a worker when the fork server goes, which it does when the
caller dies, even by ``kill -9``).  SIGTERM kills a worker
(the default action), and an interrupted frame kills the
workers instead of waiting for their parts (:meth:`VertexWorkers.close`);
a stop waits for killed workers a bounded time, and one interrupted by the next
stop signal is finished by the next call or at exit (see ``_shutdown``).
A part's result does not depend on the other parts, and the frame is always cut
into the same :data:`FRAME_PARTS` parts (one process evaluates them one after
the other), so the visibility is byte-identical for any process count.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
import weakref
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass

import numpy as np

from shtools.errors import ShtoolsError
from shtools.tasks import (
    abandon_futures,
    blas_threads,
    can_start_workers,
    die_with_parent,
    start_worker,
    use_blas_threads,
    worker_context,
)

#: Frames with fewer sphere-receiver pairs run in one process: a worker round
#: trip (pickling receivers, cuts and the result) costs about a millisecond.
MIN_PARALLEL_PAIRS = 200_000
#: ``processes=None`` uses the available cores, at most this many.
MAX_AUTO_PROCESSES = 8
#: Parts a large frame is split into, whatever the process count: fixing the split
#: fixes every float32 reduction order, so a bake is the same bytes with 1, 2 or
#: 8 processes (more processes than parts are not used).
FRAME_PARTS = 8

#: The evaluator of a worker process (set by :func:`_init_worker`).
_WORKER_RUNTIME = None


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS reports it)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def workers_supported() -> bool:
    """True where worker processes can be started (Linux, other Unixes)."""
    return can_start_workers()


def resolve_processes(processes: int | None) -> int:
    """The number of processes a runtime uses (``None``: the available cores)."""
    if not workers_supported():
        return 1
    if processes is None:
        return max(1, min(available_cores(), MAX_AUTO_PROCESSES))
    return int(processes)


def split_clusters(costs: np.ndarray, parts: int) -> list[np.ndarray]:
    """Clusters dealt into ``parts`` groups of about equal total cost.

    Longest-processing-time rule: clusters by decreasing cost, each to the
    group with the least cost so far (deterministic: ties go to the lower
    group and the stable sort keeps cluster order).

    Parameters
    ----------
    costs : ndarray, shape (C,)
        Work per cluster (receivers x cut size).
    parts : int

    Returns
    -------
    list of ndarray of int
        Ascending cluster indices of each group (some may be empty).
    """
    load = np.zeros(parts)
    owner = np.empty(costs.size, dtype=np.int64)
    for c in np.argsort(-np.asarray(costs, dtype=np.float64), kind="stable"):
        k = int(np.argmin(load))
        owner[c] = k
        load[k] += costs[c]
    return [np.flatnonzero(owner == k) for k in range(parts)]


class VertexWorkers:
    """Worker processes evaluating parts of a frame; see the module docstring.

    Parameters
    ----------
    count : int
        Worker processes (the caller evaluates one more part itself).
    settings : ShadowSettings
        The runtime's settings (workers run single-process).
    tables : dict
        Log/OL tables of the runtime.
    runtime_type : type
        The evaluator class each worker builds (``ShadowRuntime``; passed in, so
        this module does not import the evaluator that uses it).
    """

    def __init__(self, count: int, settings, tables: dict, runtime_type):
        self._pool = ProcessPoolExecutor(max_workers=int(count), mp_context=worker_context(),
                                         initializer=_init_worker,
                                         initargs=(runtime_type, settings, tables,
                                                   os.getpid(), blas_threads()))
        self._stop = _PoolStop(self._pool)
        self._close = weakref.finalize(self, _shutdown, self._stop)

    def submit(self, task):
        """Start one part on a worker; returns a future of ``(g, pairs_evaluated)``."""
        try:
            return start_worker(self._pool.submit, _run_task, task)
        except BrokenProcessPool as exc:
            raise _worker_died() from exc

    @staticmethod
    def result(future):
        """Wait for a part, turning a dead worker into a readable error."""
        try:
            return future.result()
        except BrokenProcessPool as exc:
            raise _worker_died() from exc

    def close(self, *, kill: bool = False) -> None:
        """Stop the workers (idempotent); ``kill=True`` does not wait for running parts
        (nor resolves their futures: it is for a frame that was interrupted).

        A call interrupted by a stop signal (the CLI re-sends it every 0.2 s) is
        finished by the next call, or at exit; once asked, every later call kills.
        """
        _shutdown(self._stop, kill=kill)
        self._close.detach()


class PoolParts:
    """A frame's parts as tasks of a :class:`shtools.tasks.TaskPool` (a Dask cluster).

    For one huge frame, or fewer frames than workers, on a cluster: the
    settings and log tables are shipped to every worker once (with a
    one-time runtime set-up there), then each frame's parts go out as tasks
    and their visibility comes back, in part order.  A part evaluates the
    same bytes on any worker, so the frame is the same bytes as in one
    process.

    Parameters
    ----------
    pool : shtools.tasks.TaskPool
    settings : ShadowSettings
        The runtime's settings (the workers run single-process).
    tables : dict
        Log/OL tables of the runtime.
    runtime_type : type
        The evaluator class each worker builds (``ShadowRuntime``).
    """

    def __init__(self, pool, settings, tables: dict, runtime_type):
        import uuid
        from contextlib import ExitStack
        from dataclasses import replace

        self._pool = pool
        self._stack = ExitStack()
        job = _PartJob(runtime_type, replace(settings, processes=1), tables, uuid.uuid4().hex)
        self._shared = self._stack.enter_context(pool.share(job, setup=_pool_runtime))

    def map(self, tasks: list) -> list[tuple[np.ndarray, int]]:
        """``run_part`` of each task on the pool: ``(g, pairs_evaluated)`` in task order."""
        return list(self._pool.map_ordered(_run_pool_part, tasks, shared=self._shared,
                                           window=len(tasks)))

    def close(self) -> None:
        """Release the shipped settings and tables (idempotent)."""
        self._stack.close()


@dataclass
class _PartJob:
    """What the part tasks of one runtime share: its class, settings and tables."""

    runtime_type: type
    settings: object
    tables: dict
    token: str  # tells one runtime's job from another's in a long-lived worker


#: The part runtime of a pool worker, by job token (one job at a time).
_POOL_RUNTIME: dict = {}


def _pool_runtime(job: _PartJob):
    """This worker's runtime for ``job`` (built once: the pool's per-worker set-up)."""
    runtime = _POOL_RUNTIME.get(job.token)
    if runtime is None:
        _POOL_RUNTIME.clear()
        runtime = _POOL_RUNTIME[job.token] = job.runtime_type(job.settings, tables=job.tables)
    return runtime


def _run_pool_part(job: _PartJob, task) -> tuple[np.ndarray, int]:
    return _pool_runtime(job).run_part(task)


def _worker_died() -> ShtoolsError:
    return ShtoolsError("a shadow worker process died (out of memory?); run with "
                        "processes=1 (bake: --processes 1) to evaluate in one process")


#: Longest wait for killed workers (and the pool's manager thread that reaps them).
KILL_WAIT_SECONDS = 10.0


class _PoolStop:
    """What stopping a pool needs, kept so that a later call can finish an interrupted stop."""

    def __init__(self, pool: ProcessPoolExecutor):
        self.pool = pool
        self.kill = False
        self.processes: list = []
        self.manager = None  # the pool's manager thread, once started
        self.results_writer = None  # this process's copy of the result pipe's write end


def _shutdown(stop: _PoolStop, kill: bool = False) -> None:
    """Stop a pool's workers: wait for running parts, or kill them (a stop signal).

    Never ``Thread.join`` or ``Thread.is_alive``: CPython 3.11 marks a running
    thread stopped when a signal handler's exception interrupts either (the
    bpo-45274 fix, in ``Thread._wait_for_tstate_lock``, which both call); the
    pool's manager thread is then not waited for at exit, and the exit deadlocks
    with a worker left waiting for work (seen as a bake that printed "stopped by"
    and never exited).  :func:`_running` asks ``threading.enumerate`` instead.
    """
    stop.kill = stop.kill or kill  # first: an interrupted kill is still a kill next time
    if stop.manager is None:  # ProcessPoolExecutor.shutdown drops these references
        stop.processes = list((getattr(stop.pool, "_processes", None) or {}).values())
        stop.manager = getattr(stop.pool, "_executor_manager_thread", None)
        stop.results_writer = getattr(getattr(stop.pool, "_result_queue", None), "_writer",
                                      None)
    if stop.kill:
        # ProcessPoolExecutor has no public way to stop busy workers (3.14 adds
        # terminate_workers); its internals used here are stable across 3.11-3.13.
        # a kill comes from an interrupted frame, which waits for none of its parts
        abandon_futures(stop.pool)
        for proc in stop.processes:
            with contextlib.suppress(Exception):
                proc.kill()
        # A worker killed between the header and the body of a result (sent as two
        # writes above 16 KiB) leaves the manager thread reading the body forever:
        # this process holds the pipe's write end too, so no end-of-file ever comes,
        # and the exit waits for that thread.  Once the killed workers are gone,
        # closing our copy (only workers write to it) ends that read with EOF.
        for proc in stop.processes:
            with contextlib.suppress(Exception):
                proc.join(KILL_WAIT_SECONDS)
        if stop.results_writer is not None:
            with contextlib.suppress(OSError):
                stop.results_writer.close()
    stop.pool.shutdown(wait=False, cancel_futures=True)
    # the manager thread joins the workers, then exits: wait for it.  Graceful:
    # as long as the running parts take; killed: bounded (SIGKILL ends a worker
    # at once, and its parent-death signal ends it at our exit at the latest)
    deadline = time.monotonic() + KILL_WAIT_SECONDS
    while stop.manager is not None and _running(stop.manager):
        if stop.kill and time.monotonic() > deadline:
            break
        time.sleep(0.005)


def _running(thread) -> bool:
    """Whether ``thread`` still runs; safe to interrupt (see :func:`_shutdown`).

    ``threading.enumerate`` lists a thread until its run has returned, and only
    takes a lock that its ``with`` releases, so a stop raised inside it changes
    nothing.
    """
    return thread in threading.enumerate()


def _init_worker(runtime_type, settings, tables, parent_pid, blas) -> None:
    from dataclasses import replace

    die_with_parent(parent_pid)
    use_blas_threads(blas)
    # Ctrl-C reaches the whole process group: the caller handles it and stops
    # the workers, which must not print tracebacks of their own.  SIGTERM/SIGHUP
    # keep their default action (set again: a worker must never turn them into
    # an exception, whatever the process it came from had installed).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGHUP, signal.SIG_DFL)

    global _WORKER_RUNTIME
    _WORKER_RUNTIME = runtime_type(replace(settings, processes=1), tables=tables)


def _run_task(task):
    return _WORKER_RUNTIME.run_part(task)
