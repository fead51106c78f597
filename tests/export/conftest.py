"""Fixtures of the export tests: the Khronos glTF validator."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
VALIDATOR = REPO / ".venv" / "node" / "node_modules" / "gltf-validator"


@pytest.fixture
def khronos():
    """``khronos(path) -> issues``: the Khronos glTF validator's report of a GLB.

    The npm package is installed by ``make test`` into ``.venv/node``; without
    node or npm the tests that use it skip with that reason (the strict
    accessor reads of the tests still run).
    """
    node = shutil.which("node")
    if node is None or not VALIDATOR.is_dir():
        pytest.skip("Khronos glTF validator not installed (make test installs it with npm)")

    def validate(path: Path) -> dict:
        script = ("const v=require(process.argv[1]);const fs=require('fs');"
                  "v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[2])))"
                  ".then(r=>console.log(JSON.stringify(r.issues)))"
                  ".catch(e=>{console.error(String(e));process.exit(2)});")
        proc = subprocess.run([node, "-e", script, str(VALIDATOR), str(path)],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return json.loads(proc.stdout)

    return validate
