"""Running ``shtools export`` from tests through the ``run_cli`` fixture."""

from __future__ import annotations

import json


def export_json(run_cli, bake_file, out, *args) -> dict:
    """``shtools export BAKE -o OUT --fixed-exposure --json ARGS``; asserts it exits 0
    and returns its JSON summary."""
    code, stdout, stderr = run_cli("export", bake_file, "-o", out, "--fixed-exposure",
                                   "--json", *args)
    assert code == 0, stderr
    return json.loads(stdout)
