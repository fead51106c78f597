"""Worker processes (shtools.runtime.parallel) against the single-process runtime."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from shtools.errors import InputError, ShtoolsError
from shtools.reference.scenes import capsule_scene
from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker
from shtools.runtime.parallel import fork_supported, resolve_processes, split_clusters

evaluator = importlib.import_module("shtools.runtime.evaluator")
parallel = importlib.import_module("shtools.runtime.parallel")

#: Tests that start workers; where fork is missing the runtime never starts any
#: (test_without_fork_the_runtime_stays_in_one_process checks that fallback).
needs_fork = pytest.mark.skipif(
    not fork_supported(), reason="this platform cannot fork, so the runtime runs in one "
    "process and has no workers to test")


@pytest.fixture
def always_parallel(monkeypatch):
    """Use the workers for any frame size (the real threshold is 200k pairs)."""
    monkeypatch.setattr(evaluator, "MIN_PARALLEL_PAIRS", 0)


@needs_fork
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


@needs_fork
def test_close_stops_the_workers_and_the_runtime_stays_usable(always_parallel):
    sc = capsule_scene(grid=12)
    rt = ShadowRuntime(ShadowSettings(processes=2, vertices_per_cluster=20))
    blockers = [SphereBlocker(sc.centers, sc.radii)]
    first = rt.visibility(sc.vertices, sc.normals, blockers)  # forks the worker
    rt.close()
    assert rt._workers is None
    np.testing.assert_array_equal(rt.visibility(sc.vertices, sc.normals, blockers), first)
    rt.close()


@needs_fork
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


def test_without_fork_the_runtime_stays_in_one_process(always_parallel, monkeypatch):
    monkeypatch.setattr(parallel, "fork_supported", lambda: False)
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
