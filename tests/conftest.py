"""Shared fixtures: the path to ../shared/data when present, a CLI runner."""

from __future__ import annotations

import os
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


@pytest.fixture
def shared_data():
    """``../shared/data`` (real meshes, probes); skips with the reason when absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real-data check: {SHARED_DATA} is not present on this machine")
    return SHARED_DATA
