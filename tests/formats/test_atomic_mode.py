"""Atomic outputs get the umask-governed mode without touching the process umask."""

from __future__ import annotations

import os
import stat

import pytest

from shtools.data_formats._base import atomic_path


def test_outputs_get_the_umask_mode_and_the_umask_is_never_changed(tmp_path, monkeypatch):
    old = os.umask(0o027)  # this test's own umask (restored below)
    try:
        def no_umask(*_):  # the writer must not flip the process-wide umask
            raise AssertionError("os.umask was called")

        monkeypatch.setattr(os, "umask", no_umask)
        target = tmp_path / "out.h5"
        with atomic_path(target) as tmp:
            assert tmp.parent == tmp_path and tmp.name.startswith(".out.h5.")
            tmp.write_bytes(b"x")
        monkeypatch.undo()
        assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~0o027
        assert [p.name for p in tmp_path.iterdir()] == ["out.h5"]
    finally:
        os.umask(old)


def test_failure_leaves_nothing(tmp_path):
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "out.h5") as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("stop")
    assert list(tmp_path.iterdir()) == []
