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
a worker that died (its ``allowed-failures``), and shared state lost with its
workers is scattered again.  Tasks are pure functions of
their inputs, so a rerun gives the same bytes.  Ctrl-C or SIGTERM in the
caller cancels the pending tasks and stops the local workers (and a
``LocalCluster`` started here) before the exception propagates.

This package imports only the standard library and :mod:`shtools.registry`;
``dask``/``distributed`` are imported when a Dask scheduler is asked for
(``pip install shtools[distributed]``).
"""

from shtools.registry import lazy_attributes

#: public name -> module, loaded on first use: a command that only asks how many cores
#: it may use (``shtools relight``) imports no multiprocessing or Dask machinery
_LAZY = {
    "CONNECT_TIMEOUT": "shtools.tasks.dask_cluster",
    "EMBEDDED_CLUSTER_CONFIG": "shtools.tasks.dask_cluster",
    "LOCAL_NAMES": "shtools.tasks.dask_cluster",
    "MAX_SCHEDULER_FILE": "shtools.tasks.dask_cluster",
    "SCHEMES": "shtools.tasks.dask_cluster",
    "check_scheduler": "shtools.tasks.dask_cluster",
    "MAX_RESUBMITS": "shtools.tasks.pool",
    "WINDOW_PER_WORKER": "shtools.tasks.pool",
    "Shared": "shtools.tasks.pool",
    "TaskPool": "shtools.tasks.pool",
    "WorkerStats": "shtools.tasks.pool",
    "task_pool": "shtools.tasks.pool",
    "HELD_SIGNALS": "shtools.tasks.workers",
    "MAX_LOCAL_WORKERS": "shtools.tasks.workers",
    "TRACKER_WARNINGS": "shtools.tasks.workers",
    "WORKER_PRELOAD": "shtools.tasks.workers",
    "abandon_futures": "shtools.tasks.workers",
    "blas_threads": "shtools.tasks.workers",
    "can_start_workers": "shtools.tasks.workers",
    "default_workers": "shtools.tasks.workers",
    "die_with_parent": "shtools.tasks.workers",
    "start_worker": "shtools.tasks.workers",
    "use_blas_threads": "shtools.tasks.workers",
    "worker_context": "shtools.tasks.workers",
}


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY)

__all__ = [
    "CONNECT_TIMEOUT",
    "EMBEDDED_CLUSTER_CONFIG",
    "HELD_SIGNALS",
    "LOCAL_NAMES",
    "MAX_LOCAL_WORKERS",
    "MAX_RESUBMITS",
    "MAX_SCHEDULER_FILE",
    "SCHEMES",
    "TRACKER_WARNINGS",
    "WINDOW_PER_WORKER",
    "WORKER_PRELOAD",
    "Shared",
    "TaskPool",
    "WorkerStats",
    "abandon_futures",
    "blas_threads",
    "can_start_workers",
    "check_scheduler",
    "default_workers",
    "die_with_parent",
    "start_worker",
    "task_pool",
    "use_blas_threads",
    "worker_context",
]
