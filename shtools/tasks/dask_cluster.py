"""Dask clusters for the task pool: checking a scheduler value and the workers' set-up.

What ``--scheduler`` may be (:func:`check_scheduler`: a local name, an address or
a scheduler file), the settings of a ``LocalCluster`` started here
(:data:`EMBEDDED_CLUSTER_CONFIG`), and what runs on a Dask worker around each task
(:func:`_run_dask`, :func:`_undo_dask_malloc_trim`).  ``dask``/``distributed``
are imported only on a worker, never here.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

from shtools.errors import InputError
from shtools.tasks.workers import _timed

#: Seconds to wait for a Dask scheduler before giving up with an error.
CONNECT_TIMEOUT = 10.0
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
    import ctypes

    with contextlib.suppress(OSError, AttributeError):  # not glibc: its defaults stay
        libc = ctypes.CDLL(None)
        M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's <malloc.h>
        libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)
        libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD)


def _setup_dask(setup, shared) -> None:
    _undo_dask_malloc_trim()
    setup(shared)


def _run_dask(fn, shared, item):
    from distributed import get_worker

    _undo_dask_malloc_trim()
    return _timed(fn, shared, item, get_worker().address)


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
