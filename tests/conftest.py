"""Shared fixtures (the path to ../shared/data when present, a CLI runner), and the
stacks of every process of a test that hangs (see ``pytest_timeout_set_timer`` below)."""

from __future__ import annotations

import itertools
import os
import signal
import threading
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("SHTOOLS_SHARED_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture
def run_cli():
    """Run ``shtools`` in-process; returns (exit_code, stdout, stderr)."""
    import contextlib
    import io

    from shtools.cli.main import main

    def run(*args):
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = main([str(a) for a in args])
        return code, out.getvalue(), err.getvalue()

    return run


_CACHE_COUNT = itertools.count()


@pytest.fixture(scope="session", autouse=True)
def _setup_cache_session(tmp_path_factory):
    """The set-up cache (``shtools.cache``) of the whole session in its temp folder, never
    the user's ``~/.cache`` (module fixtures that bake and CLI subprocesses inherit it)."""
    saved = {k: os.environ.get(k) for k in ("SHTOOLS_CACHE", "SHTOOLS_NO_CACHE",
                                            "SHTOOLS_CACHE_SIZE")}
    base = tmp_path_factory.mktemp("setup-cache")
    os.environ["SHTOOLS_CACHE"] = str(base / "session")
    os.environ.pop("SHTOOLS_NO_CACHE", None)
    os.environ.pop("SHTOOLS_CACHE_SIZE", None)
    yield base
    for k, v in saved.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@pytest.fixture(autouse=True)
def _setup_cache(_setup_cache_session, monkeypatch, request):
    """A set-up cache folder of each test's own: a test sees only the entries it made, so
    a test that counts what a bake computes counts the same with or without other tests."""
    name = "".join(c if c.isalnum() else "_" for c in request.node.nodeid)[-80:]
    path = _setup_cache_session / f"{next(_CACHE_COUNT)}-{name}"
    monkeypatch.setenv("SHTOOLS_CACHE", str(path))
    return path


@pytest.fixture
def shared_data():
    """``../shared/data`` (real meshes, probes); skips with the reason when absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real-data check: {SHARED_DATA} is not present on this machine")
    return SHARED_DATA


# ---------------------------------------------------------------- a hung test's stacks
# pytest-timeout (pyproject.toml: timeout, timeout_method = "signal") fails a test that
# runs too long and prints the stacks of this process's threads.  A bake that hangs
# usually hangs in one of its worker processes, which that does not show: on a timeout
# every process below this one gets SIGABRT first, and faulthandler (on in each of them)
# prints all its threads' stacks to stderr, the CI log, before it dies.  Forked workers
# inherit pytest's faulthandler; processes started by exec (forkserver, Dask, the CLI
# in a subprocess) turn it on from this variable.
os.environ.setdefault("PYTHONFAULTHANDLER", "1")
#: Longest wait for the aborted processes to write their stacks.
ABORT_WAIT_SECONDS = 5.0


def _stat(pid) -> list[bytes]:
    """Fields of ``/proc/PID/stat`` after the command name: state, ppid, ..."""
    with open(f"/proc/{pid}/stat", "rb") as fh:
        return fh.read().rsplit(b")", 1)[1].split()  # the name may hold spaces


def descendants(pid: int) -> list[tuple[int, int]]:
    """``(pid, parent pid)`` of the processes below ``pid`` (Linux ``/proc``; else none)."""
    children: dict[int, list[int]] = {}
    try:
        entries = [e.name for e in os.scandir("/proc") if e.name.isdigit()]
    except OSError:
        return []
    for name in entries:
        try:
            children.setdefault(int(_stat(name)[1]), []).append(int(name))
        except (OSError, ValueError, IndexError):
            continue  # gone meanwhile
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for child in children.get(parent, []):
            found.append((child, parent))
            todo.append(child)
    return found


def _helper(pid: int) -> bool:
    """multiprocessing's fork server or resource tracker (no test's work runs in them)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            cmdline = fh.read()
    except OSError:
        return False
    return any(f"multiprocessing.{name} import main".encode() in cmdline
               for name in ("forkserver", "resource_tracker"))


def _running(pid: int) -> bool:
    """True until ``pid`` has died (a zombie waiting for its parent counts as dead)."""
    try:
        return _stat(pid)[0] not in (b"Z", b"X")
    except (OSError, IndexError):
        return False


def abort_descendants(nodeid: str) -> None:
    """SIGABRT to every process below this one but the helpers; wait for their dumps."""
    me = os.getpid()
    # the helpers are this process's children; what the fork server forks is a worker
    pids = [p for p, parent in descendants(me) if not (parent == me and _helper(p))]
    print(f"\n+++ {nodeid} timed out: SIGABRT to processes {pids or 'none'} below pid {me}; "
          "faulthandler prints their threads' stacks to stderr +++", flush=True)
    for pid in pids:
        try:
            os.kill(pid, signal.SIGABRT)
        except OSError:
            pass  # gone meanwhile
    deadline = time.monotonic() + ABORT_WAIT_SECONDS
    while time.monotonic() < deadline and any(_running(p) for p in pids):
        time.sleep(0.05)


@pytest.hookimpl(hookwrapper=True)
def pytest_timeout_set_timer(item, settings):
    """Dump the test's worker processes before pytest-timeout's own handler runs."""
    yield
    if settings.method != "signal" or threading.current_thread() is not threading.main_thread():
        return
    fail = signal.getsignal(signal.SIGALRM)  # pytest-timeout's: dump this process, fail

    def dump_workers_then_fail(signum, frame):
        abort_descendants(item.nodeid)
        fail(signum, frame)

    signal.signal(signal.SIGALRM, dump_workers_then_fail)
