"""Independent tasks on this machine's cores or on a Dask cluster: one engine for the pipeline.

A bake's frames, a batch of sphere fits and a field's shells are independent
pieces of work.  :func:`task_pool` runs them on one of three schedulers behind
one interface, :class:`TaskPool`:

``"inline"``
    In the calling process, one task after the other (one worker; nothing to
    set up).  Used for a single task, one worker, or where worker processes
    cannot be started (:func:`worker_context`).
``None`` / ``"processes"`` (the default)
    Worker processes on this machine
    (:class:`concurrent.futures.ProcessPoolExecutor`), forked by
    multiprocessing's fork server (:func:`worker_context`): the state the tasks
    share is pickled once to each worker when it starts; results come back
    pickled.
a Dask scheduler
    ``"local"`` starts a :class:`distributed.LocalCluster` of ``workers``
    single-threaded worker processes here (and stops it afterwards);
    ``"tcp://HOST:PORT"`` or the path of a scheduler file (``dask scheduler
    --scheduler-file``) joins an existing cluster (SLURM/PBS via
    dask-jobqueue, Kubernetes, ...).  The shared state is scattered once to
    every worker; assets it names travel by path, so the workers need the
    same shared storage (``docs/scale-out.md``).

A worker's one-time set-up of the shared state (building a runtime from a
prepared scene, ...) runs before its first task (:meth:`TaskPool.share`), so
it is start-up time (``setup_seconds``), not the first task's.

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
import contextlib
import json
import multiprocessing
import os
import signal
import sys
import threading
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
#: Dask settings of the ``LocalCluster`` that ``"local"`` starts.  Nobody looks
#: at an embedded cluster's dashboard, so nothing needs the statistical profiler
#: (which takes the GIL from the task every 10 ms) nor half-second system
#: metrics; the event-loop health check (every 20 ms) and the memory monitor
#: (every 100 ms) are slowed to once a second.  These periodic callbacks had
#: cost the scheduler/nanny loop and each worker's loop about 3x more CPU per
#: frame, on cores the frames need (measured per thread, docs/scale-out.md).
#: The active memory manager (every 2 s) is off: its one policy drops extra
#: replicas, and the only replicated data is the shared state broadcast on purpose.
EMBEDDED_CLUSTER_CONFIG = {
    "distributed.scheduler.active-memory-manager.start": False,
    "distributed.worker.profile.enabled": False,
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
}


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
    "shtools.tasks", "shtools.runtime.evaluator", "shtools.scene.bake", "shtools.scene.transfer",
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
        try:
            if setup is not None:
                # One set-up task per worker; loose restrictions so a worker
                # that dies meanwhile does not leave its set-up waiting forever.
                wait([client.submit(_setup_dask, setup, ref, workers=[w],
                                    allow_other_workers=True, pure=False)
                      for w in client.scheduler_info().get("workers", {})])
            self.setup_seconds += time.perf_counter() - start
            yield Shared(shared, ref, setup)
        finally:
            if ref is not None:
                ref.release()

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
            yield from self._dask(fn, items, shared.ref, window)

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

    def _dask(self, fn, items, shared_ref, window):
        client = self.client
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
                result, worker, seconds, cpu = future.result()
                future.release()
                self._record(worker, seconds, cpu)
                yield result
        finally:
            for future in pending:
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
        try:
            setup(_SHARED)
        except Exception:
            # An exception here would only break the pool ("a worker died"); the
            # first task repeats the same cached set-up and raises the real error.
            pass


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
            while not poller.poll():
                pass
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


def _setup_dask(setup, shared) -> None:
    _undo_dask_malloc_trim()
    setup(shared)


def _run_dask(fn, shared, item):
    from distributed import get_worker

    _undo_dask_malloc_trim()
    return _timed(fn, shared, item, get_worker().address)


def _terminate(pool) -> None:
    """Stop a process pool now: cancel queued tasks and kill running workers."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    results_writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)
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


# ---------------------------------------------------------------------- set-up
def _is_dask(scheduler: str | None) -> bool:
    return scheduler is not None and scheduler not in ("inline", "processes")


#: Dask's network schemes a cluster can be joined by (``inproc`` is in-process only).
SCHEMES = ("tcp", "tls", "ucx", "ws", "wss")
#: A scheduler file is a small JSON object; anything bigger is not one.
MAX_SCHEDULER_FILE = 1 << 20


def _address_problem(address: object) -> str | None:
    """Why ``address`` is not ``SCHEME://HOST:PORT``, or None when it is."""
    if not isinstance(address, str):
        return f"the address must be a string, got {address!r}"
    scheme, sep, rest = address.partition("://")
    if not sep or scheme not in SCHEMES:
        return (f"'{address}' is not an address SCHEME://HOST:PORT with SCHEME one of "
                f"{', '.join(SCHEMES)}")
    host, colon, port = rest.rpartition(":")
    if not colon or not host.strip("[]") or not port:
        return f"'{address}' needs a host and a port (e.g. tcp://10.0.0.5:8786)"
    if not (port.isdigit() and 1 <= int(port) <= 65535):
        return f"'{address}': the port must be a number in 1..65535, got '{port}'"
    return None


def check_scheduler(scheduler: str | None) -> None:
    """Refuse a scheduler value before anything starts (a one-line :class:`InputError`).

    Valid: None, a local name (:data:`LOCAL_NAMES`), an address
    ``SCHEME://HOST:PORT`` (:data:`SCHEMES`, a port in 1..65535), or a Dask
    scheduler file (JSON, as ``dask scheduler --scheduler-file`` writes it) whose
    ``address`` is such an address.  Whether the cluster answers is known only
    when joining it (:func:`task_pool`).
    """
    if scheduler is None or scheduler in LOCAL_NAMES:
        return
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise InputError("the scheduler is empty; give 'local', tcp://HOST:PORT or a "
                         "scheduler file")
    if "://" in scheduler:
        problem = _address_problem(scheduler)
        if problem:
            raise InputError(problem)
        return
    path = Path(scheduler)
    if not path.is_file():
        raise InputError(
            "is neither 'local', a scheduler address (tcp://HOST:PORT) nor an "
            "existing scheduler file", scheduler)
    what = ("is not a Dask scheduler file (JSON with the scheduler's 'address', as "
            "`dask scheduler --scheduler-file` writes it)")
    try:
        if path.stat().st_size > MAX_SCHEDULER_FILE:
            raise ValueError("too big")
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        raise InputError(what, scheduler) from None
    if not isinstance(info, dict) or "address" not in info:
        raise InputError(what, scheduler)
    problem = _address_problem(info["address"])
    if problem:
        raise InputError(f"in the scheduler file, {problem}", scheduler)


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
