"""Worker processes (shtools.runtime.parallel) against the single-process runtime."""

from __future__ import annotations

import importlib
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from shtools.errors import InputError, ShtoolsError
from shtools.reference.scenes import capsule_scene
from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker
from shtools.runtime.parallel import resolve_processes, split_clusters, workers_supported

evaluator = importlib.import_module("shtools.runtime.evaluator")
parallel = importlib.import_module("shtools.runtime.parallel")

#: Tests that start workers; where none can start the runtime never starts any
#: (test_without_workers_the_runtime_stays_in_one_process checks that fallback).
needs_workers = pytest.mark.skipif(
    not workers_supported(), reason="this platform cannot start worker processes, so the "
    "runtime runs in one process and has no workers to test")


@pytest.fixture
def always_parallel(monkeypatch):
    """Use the workers for any frame size (the real threshold is 200k pairs)."""
    monkeypatch.setattr(evaluator, "MIN_PARALLEL_PAIRS", 0)


@needs_workers
@pytest.mark.parametrize("hierarchy", [True, False])
def test_processes_reproduce_the_single_process_visibility_bytes(always_parallel, hierarchy):
    """The frame is cut into the same FRAME_PARTS parts whatever the process count,
    so 1, 2 and 3 processes give the same bytes (CI compares golden bakes exactly)."""
    sc = capsule_scene(grid=24)
    blockers = [SphereBlocker(sc.centers, sc.radii)]
    common = dict(order=4, acc_order=6, vertices_per_cluster=40, hierarchy=hierarchy,
                  chunk_pairs=2048)
    one = ShadowRuntime(ShadowSettings(processes=1, **common))
    want = one.visibility(sc.vertices, sc.normals, blockers)
    assert one.last_stats["processes"] == 1
    for processes in (2, 3):
        with ShadowRuntime(ShadowSettings(processes=processes, **common)) as rt:
            got = rt.visibility(sc.vertices, sc.normals, blockers)
            assert rt.last_stats["processes"] == processes
            again = rt.visibility(sc.vertices, sc.normals, blockers)  # workers are reused
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(again, want)


def test_small_frames_stay_in_process():
    sc = capsule_scene(grid=8)
    rt = ShadowRuntime(ShadowSettings(processes=2))
    rt.visibility(sc.vertices, sc.normals, [SphereBlocker(sc.centers, sc.radii)])
    assert rt.last_stats["processes"] == 1 and rt._workers is None


@needs_workers
def test_close_stops_the_workers_and_the_runtime_stays_usable(always_parallel):
    sc = capsule_scene(grid=12)
    rt = ShadowRuntime(ShadowSettings(processes=2, vertices_per_cluster=20))
    blockers = [SphereBlocker(sc.centers, sc.radii)]
    first = rt.visibility(sc.vertices, sc.normals, blockers)  # starts the worker
    rt.close()
    assert rt._workers is None
    np.testing.assert_array_equal(rt.visibility(sc.vertices, sc.normals, blockers), first)
    rt.close()


@needs_workers
def test_worker_failures_reach_the_caller(always_parallel):
    import os
    import signal

    sc = capsule_scene(grid=12)
    with ShadowRuntime(ShadowSettings(processes=2, vertices_per_cluster=20)) as rt:
        rt.visibility(sc.vertices, sc.normals, [SphereBlocker(sc.centers, sc.radii)])
        workers = rt._workers
        with pytest.raises(ValueError):  # an exception inside a worker is re-raised here
            workers.result(workers.submit(("clusters",)))
        for pid in list(workers._pool._processes):
            os.kill(pid, signal.SIGKILL)
        with pytest.raises(ShtoolsError, match="processes=1"):
            workers.result(workers.submit(("clusters",)))


def test_without_workers_the_runtime_stays_in_one_process(always_parallel, monkeypatch):
    monkeypatch.setattr(parallel, "workers_supported", lambda: False)
    assert resolve_processes(None) == 1 and resolve_processes(4) == 1
    sc = capsule_scene(grid=12)
    rt = ShadowRuntime(ShadowSettings(processes=4, vertices_per_cluster=20))
    g = rt.visibility(sc.vertices, sc.normals, [SphereBlocker(sc.centers, sc.radii)])
    assert rt.processes == 1 and rt._workers is None
    assert rt.last_stats["processes"] == 1 and np.isfinite(g).all()


def test_split_clusters_balances_cost():
    costs = np.array([10, 1, 7, 3, 3, 9, 2, 5])
    groups = split_clusters(costs, 2)
    loads = [costs[g].sum() for g in groups]
    assert sorted(np.concatenate(groups).tolist()) == list(range(costs.size))
    # longest-processing-time is within 4/3 of the optimum (here 20 / 20)
    assert max(loads) <= 4 / 3 * costs.sum() / 2


def test_processes_setting_is_validated():
    with pytest.raises(InputError, match="processes"):
        ShadowSettings(processes=0)



#: A close (``KILL``: killing) stopped at each of its spots in turn (see STOPS).
INTERRUPTED = """
    from functools import partial
    from stop_helpers import runs_to_end, wait_for

    go = os.path.join(sys.argv[1], "go")
    part = workers._pool.submit(wait_for, go)  # a part that outlasts the stops
    # every spot of a killing close, until one runs to its end; a graceful close
    # waits for the part: its first pass and a few rounds of its wait
    for landing in range(1, 3000 if KILL else 120):
        finished = runs_to_end(partial(workers.close, kill=KILL), landing)
        if finished:
            break
    # killed (its future abandoned), or still running for the exit to wait for
    assert finished == KILL and not part.done()
    open(go, "w").close()
"""

#: Stops of the workers the way the CLI's stop path meets them, then the exit.
#: "interrupted" / "interrupted-kill": a graceful / killing close interrupted by stop
#: signals, landing on each of its lines in turn (the CLI re-sends its stop every
#: 0.2 s, and Python raises it wherever the main thread is).
#: "cancel-interrupted": a frame's take-back of a queued part (Future.cancel)
#: interrupted at each of its lines, then close(kill=True), as the frame does.
#: "half-result": close(kill=True) of a worker killed halfway through sending a result.
#: "cancelled": close(kill=True) with parts taken back (cancelled) still queued.
STOPS = {"cancelled": """
    futures = [workers._pool.submit(time.sleep, 60) for _ in range(4)]
    while not futures[0].running():  # the first two parts are with the worker
        time.sleep(0.01)
    assert all(f.cancel() for f in futures[2:])  # the last two are taken back
    workers.close(kill=True)
""", "interrupted": "\n    KILL = False" + INTERRUPTED,
         "interrupted-kill": "\n    KILL = True" + INTERRUPTED, "cancel-interrupted": """
    from stop_helpers import runs_to_end

    futures = [workers._pool.submit(time.sleep, 60) for _ in range(6)]
    while not futures[0].running():
        time.sleep(0.01)
    for future in reversed(futures):  # queued ones, then those with the worker
        for landing in range(1, 20):  # past the end of cancel()
            runs_to_end(future.cancel, landing)
    workers.close(kill=True)
""", "half-result": """
    from stop_helpers import half_a_result  # a task must be importable in a worker

    marker = os.path.join(sys.argv[1], "sent")
    workers._pool.submit(half_a_result, marker)
    while not os.path.exists(marker):
        time.sleep(0.01)
    workers.close(kill=True)
"""}


#: The stops' helpers, a module in the test's folder (on the script's path): a
#: worker's task must be importable there.
STOP_HELPERS = """
import linecache, os, struct, sys, time


class Stop(BaseException):
    '''What a stop signal's handler raises (here: the trace function of stop_at).'''


def runs_to_end(call, landing) -> bool:
    '''Whether ``call()`` ran to its end, with a stop at its landing-th spot.'''
    sys.settrace(stop_at(landing))
    try:
        call()
        return True
    except Stop:
        return False
    finally:
        sys.settrace(None)


def stop_at(landing):
    # A trace function raising at the landing-th line or call under the traced
    # call: a stop signal lands wherever the main thread is, so every spot is
    # tried in turn.  Not at a with statement's second line event, its exit: no
    # signal can land between a with body and its __exit__ (CPython checks for
    # signals at calls and backward jumps), and a raise there leaks the lock.
    seen, lines = 0, {}

    def trace(frame, event, arg):
        nonlocal seen
        if event == "line":
            again = frame.f_lineno in lines.setdefault(frame, set())
            lines[frame].add(frame.f_lineno)
            code = linecache.getline(frame.f_code.co_filename, frame.f_lineno)
            if again and code.lstrip().startswith("with "):
                return trace
        if event in ("call", "line"):
            seen += 1
            if seen == landing:
                raise Stop
        return trace
    return trace


def wait_for(path):
    while not os.path.exists(path):
        time.sleep(0.01)


def half_a_result(marker):
    # in the worker: the header of a result (above 16 KiB, the size of a real
    # part's result) whose body never comes, as when a kill lands between them
    frame = sys._getframe()
    while "result_queue" not in frame.f_locals:
        frame = frame.f_back
    frame.f_locals["result_queue"]._writer._send(struct.pack("!i", 100_000))
    open(marker, "w").close()
    time.sleep(60)
"""


@needs_workers
@pytest.mark.parametrize("stop", STOPS)
def test_stopped_workers_let_the_process_exit(stop, tmp_path):
    """Regressions of a bake that printed "stopped by" and never exited: Thread.join
    interrupted by a signal handler's exception marked the pool's manager thread
    stopped (CPython 3.11), so the exit waited forever for a worker no one told to
    stop (Thread.is_alive too, so no stop may land in either); a half-sent result
    left that thread reading forever; failing a cancelled part killed that
    thread (CPython 3.11), leaving a traceback; and a stop landing in
    Future.cancel left the future's lock held, which that thread then waited on."""
    (tmp_path / "stop_helpers.py").write_text(STOP_HELPERS)
    script = textwrap.dedent("""
        import os, signal, struct, sys, time
        from shtools.runtime import ShadowRuntime, ShadowSettings
        from shtools.runtime.parallel import VertexWorkers

        workers = VertexWorkers(1, ShadowSettings(processes=2), None,  # default tables
                                ShadowRuntime)
    """) + textwrap.dedent(STOPS[stop]) + 'print("stopped", flush=True)\nsys.exit(3)\n'
    # the test's folder on the script's (and its workers') path, for stop_helpers
    path = os.pathsep.join(p for p in (str(tmp_path), os.environ.get("PYTHONPATH")) if p)
    proc = subprocess.Popen([sys.executable, "-c", script, str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=dict(os.environ, PYTHONPATH=path))
    try:
        # each stop takes at most ~2 s; 60 s is far beyond any load, and the bugs
        # never exit
        out, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the script and its worker (same session)
        proc.communicate()
        pytest.fail("the process did not exit after its workers were stopped")
    assert (proc.returncode, out, err) == (3, "stopped\n", "")
