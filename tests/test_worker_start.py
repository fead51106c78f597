"""Worker processes start clean: no lock held by another thread of the caller.

A bake's caller has threads besides its main one (oneTBB's workers once Embree has
built a scene, tqdm's monitor).  A worker forked from it got a copy of every lock one
of them held at that instant, locked for ever: a frame worker hung in oneTBB's
``private_server::wake_some`` at its first Embree build, 2 times in ~145 runs of
tests/scene/test_scaling_scene.py's deformable bakes (a forked child of a process that
had just ray traced).  Workers now come from multiprocessing's fork server
(``shtools.tasks.worker_context``).  The race itself is rare; these tests make its
condition certain instead: a lock another thread holds while the workers start.  With
forked workers each of them fails (the worker's copy of the lock stays locked).
"""

from __future__ import annotations

import threading

import pytest

from shtools.runtime import ShadowRuntime, ShadowSettings
from shtools.runtime.parallel import VertexWorkers, workers_supported
from shtools.tasks import task_pool

pytestmark = pytest.mark.skipif(not workers_supported(),
                                reason="this platform cannot start worker processes")

#: Held by a thread of the test process while workers start (as oneTBB's worker held
#: its mutex); a worker imports this module afresh, so its own copy must be free.
HELD = threading.Lock()
#: Seconds a worker tries the lock: a free lock is taken at once.
TRY_SECONDS = 2.0


def _lock_is_free(_shared=None, _item=None) -> bool:
    """In a worker: can it take ``HELD``?  Released again at once: the pool may give
    both items to one worker, which must then find the lock free again (unreleased, the
    second item timed out in that worker: a flaky [True, False]).  A worker that
    inherited the held copy still cannot take it."""
    taken = HELD.acquire(timeout=TRY_SECONDS)
    if taken:
        HELD.release()
    return taken


@pytest.fixture
def held_by_another_thread():
    """``HELD`` locked by another thread of this process for the test's duration."""
    taken, done = threading.Event(), threading.Event()

    def hold():
        with HELD:
            taken.set()
            done.wait()

    thread = threading.Thread(target=hold, name="lock-holder", daemon=True)
    thread.start()
    assert taken.wait(10)
    yield
    done.set()
    thread.join(10)


def test_frame_pool_workers_do_not_inherit_a_held_lock(held_by_another_thread):
    # shtools.tasks: the pool that bakes frames, fits batches and samples field shells
    with task_pool(None, 2) as pool:
        assert list(pool.map_ordered(_lock_is_free, range(2), window=2)) == [True, True]


def test_frame_part_workers_do_not_inherit_a_held_lock(held_by_another_thread):
    # shtools.runtime.parallel: the processes that share one large frame
    workers = VertexWorkers(1, ShadowSettings(processes=2), None,  # default tables
                            ShadowRuntime)
    try:
        assert workers.result(workers._pool.submit(_lock_is_free)) is True
    finally:
        workers.close(kill=True)
