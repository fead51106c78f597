"""Local worker processes: how they start, what they inherit, and how they stop.

Workers are forked by multiprocessing's fork server (:func:`worker_context`), hold
stop signals back while one starts (:func:`start_worker`), get the caller's BLAS
threads (:func:`blas_threads`), die with the caller (:func:`die_with_parent`) and
are stopped at once when a run ends or is interrupted (:func:`_terminate`).  The
task pool (:mod:`shtools.tasks.pool`) and the runtime's in-frame workers
(:mod:`shtools.runtime.parallel`) both start theirs here.

Standard library only.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

#: Local worker processes at most (a typo such as ``--workers 100000`` must not
#: fork a machine to death; a bigger machine than this wants a Dask cluster).
MAX_LOCAL_WORKERS = 256


def default_workers() -> int:
    """Cores this process may use (``os.sched_getaffinity`` where available)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)


#: Modules the fork server imports once, before it forks any worker: a worker
#: starts with them imported (the tasks of bakes, fits and field shells, and the
#: runtime's frame parts, with the libraries they import lazily: a worker that
#: imported trimesh, SciPy and Embree itself took ~1.5 s more per bake).  One that
#: cannot be imported (a core install) is skipped.
WORKER_PRELOAD = (
    "shtools.tasks.pool", "shtools.tasks.workers", "shtools.tasks.dask_cluster",
    "shtools.runtime.evaluator", "shtools.scene.bake", "shtools.scene.transfer",
    "shtools.scene.midrange", "shtools.scene.primitives", "shtools.fields.build",
    "shtools.fields.deformable", "shtools.geometry.assets", "shtools.geometry.raycast",
    "shtools.sh.scaling", "shtools.progress",
    "trimesh", "scipy.linalg", "scipy.optimize", "scipy.sparse", "scipy.spatial",
    "scipy.special", "embreex.rtcore_scene", "embreex.mesh_construction", "threadpoolctl",
    "tqdm",
)


def worker_context():
    """The multiprocessing context of local worker processes: ``forkserver``; None without one.

    Not ``fork``: the calling process has threads of its own -- oneTBB's workers
    once Embree has built a scene, tqdm's monitor -- and a fork copies a lock one
    of them holds at that instant, locked for ever, into a child that has no
    thread to release it.  A frame worker forked just after this process had ray
    traced hung in oneTBB's ``private_server::wake_some`` at its first Embree
    build (a test that stalled until its timeout; docs/scale-out.md).  The fork
    server is a fresh single-threaded process, started once (by exec) on first
    use with :data:`WORKER_PRELOAD` imported; every worker is forked from it,
    so no worker inherits this process's threads or locks.  Used by the frame
    pool here and by the runtime's in-frame workers
    (:class:`shtools.runtime.parallel.VertexWorkers`).
    """
    import multiprocessing  # here: a caller of default_workers alone starts no worker

    if "forkserver" not in multiprocessing.get_all_start_methods():  # Windows
        return None
    from multiprocessing import forkserver

    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(WORKER_PRELOAD))  # no effect once the server runs
    _quiet_resource_tracker()
    # start the server now (once): outside start_worker's held signals, so that Ctrl-C
    # during its imports stops the caller at once
    forkserver.ensure_running()
    return context


#: Warning filter of the resource tracker: after ``kill -9`` of the parent it frees the
#: pools' semaphores (its job) and would print a two-line UserWarning saying so.
TRACKER_WARNINGS = "ignore::UserWarning:multiprocessing.resource_tracker"


def _quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker (once) with :data:`TRACKER_WARNINGS`.

    The tracker is a separate process started with this interpreter's ``-W``
    options; the filter is added to them only while it starts.
    """
    from multiprocessing import resource_tracker

    added = TRACKER_WARNINGS not in sys.warnoptions
    if added:
        sys.warnoptions.append(TRACKER_WARNINGS)
    try:
        resource_tracker.ensure_running()
    finally:
        if added:
            sys.warnoptions.remove(TRACKER_WARNINGS)


#: Signals :func:`start_worker` holds back (the CLI's stop signals and Ctrl-C).
HELD_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, name))


def start_worker(submit: Callable, *args):
    """``submit(*args)`` of a process pool with stop signals held until it returns.

    A submit may start a worker, which then reads its pickled start-up data from
    this process through the fork server: a signal handler's exception
    (Ctrl-C, the CLI's SIGTERM) halfway through that write would leave the new
    worker a truncated pickle, and it would print a traceback as it dies, after
    the CLI's one-line message.  Held, a signal is raised again as soon as the
    submit returns (milliseconds later).  Only the main thread can set signal
    handlers; from any other thread nothing is held.
    """
    if threading.current_thread() is not threading.main_thread():
        return submit(*args)
    held: list[int] = []
    previous = {}
    try:
        for sig in HELD_SIGNALS:
            if signal.getsignal(sig) is not None:  # None: set outside Python, left alone
                previous[sig] = signal.signal(sig, lambda signum, _frame: held.append(signum))
        return submit(*args)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for sig in dict.fromkeys(held):
            signal.raise_signal(sig)


def can_start_workers() -> bool:
    """Whether local worker processes are available (not on Windows)."""
    import multiprocessing

    return "forkserver" in multiprocessing.get_all_start_methods()


def blas_threads() -> int | None:
    """BLAS threads of this process (threadpoolctl), for its workers; None if unknown.

    A worker does not inherit this process's BLAS limit (the CLI sets one thread,
    ``shtools.cli._common.one_blas_thread``), so it is handed over explicitly.
    """
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return None
    counts = [lib["num_threads"] for lib in threadpool_info() if lib.get("user_api") == "blas"]
    return min(counts) if counts else None


def use_blas_threads(count: int | None) -> None:
    """Set this (worker) process's BLAS threads to ``count`` (None: leave them)."""
    if count is None:
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    threadpool_limits(limits=int(count), user_api="blas")


# ---------------------------------------------------------------------- worker side
#: The state the tasks of this worker share (set by :func:`_worker_init`).
_SHARED: Any = None


def _worker_init(parent_pid: int, shared, setup=None, blas: int | None = None) -> None:
    """Local workers die with their parent, leave Ctrl-C to it, and run the set-up."""
    global _SHARED
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent cancels and terminates us
    die_with_parent(parent_pid)
    use_blas_threads(blas)
    _SHARED = shared
    if setup is not None:
        # An exception here would only break the pool ("a worker died"); the first
        # task repeats the same cached set-up and raises the real error.
        with contextlib.suppress(Exception):
            setup(_SHARED)


def die_with_parent(parent_pid: int) -> None:
    """Make this worker exit when ``parent_pid``, the process of its pool, dies (no orphans).

    A worker is a child of the fork server (:func:`worker_context`), not of
    ``parent_pid``, and it holds the pipe whose end-of-file would stop the server,
    so neither a parent-death signal nor the server ends it: a daemon thread
    here waits for ``parent_pid`` to end (Linux: ``pidfd_open`` + ``poll``, woken
    at once, even after ``kill -9``; elsewhere a check every 0.5 s) and exits the
    worker.  The server and multiprocessing's resource tracker then see their
    pipes close and exit too.  Used by the frame pool here and by the runtime's
    in-frame workers.
    """
    import select

    try:
        pidfd = os.pidfd_open(parent_pid)
    except ProcessLookupError:  # gone already
        os._exit(1)
    except (AttributeError, OSError):  # not Linux (>= 5.3)
        pidfd = None

    def watch():
        if pidfd is not None:
            poller = select.poll()
            poller.register(pidfd, select.POLLIN)  # readable once the process has ended
            poller.poll()  # no timeout: returns once the process has ended
        else:
            while _exists(parent_pid):
                time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="shtools-parent-watch", daemon=True).start()


def _exists(pid: int) -> bool:
    """Whether process ``pid`` is still there (signal 0 checks without sending)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # there, owned by someone else
        return True
    return True


def _timed(fn, shared, item, worker: str):
    """``fn(shared, item)``, the worker's name, and the call's wall and thread-CPU seconds."""
    start, cpu = time.perf_counter(), time.thread_time()
    result = fn(shared, item)
    return result, worker, time.perf_counter() - start, time.thread_time() - cpu


def _run_local(fn, item):
    return _timed(fn, _SHARED, item, f"pid {os.getpid()}")


def abandon_futures(pool) -> None:
    """Give every queued or running task of a process pool a stand-in future.

    For a pool stopped because its caller was interrupted, which waits for none
    of its tasks.  The pool's manager thread fails a stopped pool's tasks
    through their futures, and two kinds would stop it there, so that the exit
    waits for it forever: a cancelled future, on which ``set_exception`` raises
    (CPython 3.11), killing the thread; and a future whose lock a stop signal
    left held (landing in the Python-level ``Condition.__exit__`` of
    ``Future.cancel`` or ``Future.result``), on which it blocks.  Stand-ins are
    futures nobody else holds.
    """
    from concurrent.futures import Future

    for item in list((getattr(pool, "_pending_work_items", None) or {}).values()):
        item.future = Future()


def _terminate(pool) -> None:
    """Stop a process pool now: cancel queued tasks and kill running workers."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    results_writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)
    abandon_futures(pool)
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.terminate()
    for p in processes:
        p.join(timeout=5)
    # a worker stopped halfway through sending a result leaves the pool's manager
    # thread reading it forever (and the exit waiting for that thread): with the
    # workers gone, closing this process's copy of the pipe's write end (only
    # workers write to it) ends that read (shtools.runtime.parallel._shutdown)
    if results_writer is not None:
        with contextlib.suppress(OSError):
            results_writer.close()
