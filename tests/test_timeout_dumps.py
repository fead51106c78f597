"""A test that hangs leaves the stacks of its worker processes in the log (tests/conftest.py).

pytest-timeout prints the stacks of the test process's threads only; a bake that hangs
in a worker showed nothing but the caller waiting for a result.  The conftest's timeout
hook sends SIGABRT to every process below the test's, whose faulthandler prints all
their threads' stacks.  Checked on a throw-away suite run with this conftest and a
10 s timeout (two xdist workers: the two tests at once): each test leaves a worker
stuck in ``stuck_in_worker``.  About 15-20 s under load: a slow test.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent

SUITE = textwrap.dedent("""
    import multiprocessing
    import time
    from concurrent.futures import ProcessPoolExecutor

    from shtools.tasks import task_pool, worker_context

    # the fork server starts (imports shtools and its libraries: seconds under load) and
    # forks a first worker now, at collection, not inside a test's few seconds
    with ProcessPoolExecutor(1, mp_context=worker_context()) as _pool:
        _pool.submit(int).result()


    def stuck_in_worker(*_):
        time.sleep(120)


    def test_a_forked_worker_hangs():
        context = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(1, mp_context=context) as pool:
            pool.submit(stuck_in_worker).result()


    def test_a_task_pool_worker_hangs():  # started by the fork server
        with task_pool(None, 2) as pool:
            list(pool.map_ordered(stuck_in_worker, range(2)))
""")


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"),
                    reason="the conftest finds the processes below a test in /proc")
def test_a_timed_out_test_prints_its_workers_stacks(tmp_path):
    shutil.copy(HERE / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_hangs.py").write_text(SUITE)
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-n", "2",
         "--rootdir", str(tmp_path), "-o", "timeout_method=signal", "--timeout", "10",
         str(tmp_path / "test_hangs.py")],
        capture_output=True, text=True, timeout=300, cwd=tmp_path)
    log = done.stdout + done.stderr
    assert done.returncode == 1, log  # both tests fail on their timeout
    assert log.count("timed out: SIGABRT to processes [") == 2, log
    # the workers' own stacks: the function they are stuck in, under faulthandler's header
    # (the caller waits in result(); its stack alone never names stuck_in_worker); at
    # least the forked worker and one of the pool's two (the second may still be starting)
    assert log.count("Fatal Python error: Aborted") >= 2, log
    # counted as names, not by a line pattern: the pool's two workers abort at the same
    # instant and their dumps interleave on the shared stderr, write by write, across
    # lines (seen in CI: 'line , line 1515 in  in stuck_in_workerstuck_in_worker').  A
    # function name is one write, so it stays whole; the only other mentions are the
    # suite's own call sites that pytest echoes, '(stuck_in_worker' (the callers wait in
    # result(), so their stacks never name it)
    dumped = log.count("stuck_in_worker") - log.count("(stuck_in_worker")
    assert dumped >= 2, log
