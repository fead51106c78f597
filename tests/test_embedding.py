"""No surprises for programs that embed shtools (docs/architecture.md, "Embedding")."""

from __future__ import annotations

import subprocess
import sys

import pytest

from shtools.runtime import ShadowSettings


def test_the_runtime_stays_in_the_calling_process_by_default():
    assert ShadowSettings().processes == 1


def test_importing_the_cli_and_demo_leaves_the_environment_alone():
    code = ("import os; before = dict(os.environ); import shtools.cli.main, shtools.demo; "
            "print(dict(os.environ) == before)")
    env = {k: v for k, v in __import__("os").environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         check=True)
    assert out.stdout.strip() == "True"


def test_one_blas_thread_limits_blas_unless_the_user_set_a_count(monkeypatch):
    threadpoolctl = pytest.importorskip("threadpoolctl", reason="the CLI extra is not installed")
    import numpy as np  # noqa: F401  (loads BLAS)

    from shtools.cli._common import BLAS_THREAD_VARIABLES, one_blas_thread

    blas = [i for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
    if not blas:
        pytest.skip("NumPy's BLAS is not visible to threadpoolctl on this build")
    for var in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(var, raising=False)
    with one_blas_thread():
        inside = [i["num_threads"] for i in threadpoolctl.threadpool_info()
                  if i["user_api"] == "blas"]
    assert inside and all(n == 1 for n in inside)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    before = [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
    with one_blas_thread():  # the user's count wins: nothing changes
        assert [i["num_threads"] for i in threadpoolctl.threadpool_info()
                if i["user_api"] == "blas"] == before
