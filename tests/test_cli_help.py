"""A bare ``shtools`` (or a bare group) prints its help on stdout and exits 0."""

from __future__ import annotations

import pytest


@pytest.mark.parametrize("args", [(), ("spheres",), ("light",)])
def test_bare_group_prints_help(run_cli, args):
    code, stdout, stderr = run_cli(*args)
    assert code == 0 and stderr == ""
    assert stdout.startswith("Usage: shtools") and "Commands:" in stdout
