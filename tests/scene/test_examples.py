"""examples/Makefile: real file dependencies, so touching one mesh rebuilds only its chain."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

BUILT = [  # every file the pipeline makes, in dependency order
    "build/meshes/arch.obj", "build/meshes/pillar.obj", "build/meshes/crate.obj",
    "build/sky.hdr", "build/arch_spheres.h5", "build/pillar_spheres.h5", "build/arch_tree.h5",
    "build/pillar_tree.h5", "build/crate.field.h5", "build/tables.h5", "build/sky.h5",
    "build/baked.h5",
    "build/frame.png", "build/sheet.png", "build/scene.glb",
]


@pytest.fixture
def built_copy(tmp_path):
    if shutil.which("make") is None:
        pytest.skip("GNU make is not on PATH: the example pipeline is a Makefile, so "
                    "there is nothing to run without it (install make to check it)")
    for name in ("Makefile", "scene.toml", "make_meshes.py"):
        shutil.copy(EXAMPLES / name, tmp_path / name)
    (tmp_path / "build" / "meshes").mkdir(parents=True)
    # stand-in outputs with increasing modification times: everything up to date
    base = time.time() - 1000
    for k, name in enumerate(BUILT):
        (tmp_path / name).write_bytes(b"")
        os.utime(tmp_path / name, (base + k, base + k))
    old = base - 100
    for name in ("Makefile", "scene.toml", "make_meshes.py"):
        os.utime(tmp_path / name, (old, old))
    return tmp_path


def dry_run(directory: Path) -> list[str]:
    out = subprocess.run(["make", "-n", "-C", str(directory), "SHTOOLS=shtools",
                          "PYTHON=python"], capture_output=True, text=True, check=True)
    return [line for line in out.stdout.splitlines() if line.startswith(("shtools", "python"))]


def test_up_to_date_pipeline_does_nothing(built_copy):
    assert dry_run(built_copy) == []


def test_touching_one_mesh_rebuilds_only_its_chain(built_copy):
    os.utime(built_copy / "build/meshes/pillar.obj")  # now newer than everything
    commands = dry_run(built_copy)
    joined = "\n".join(commands)
    assert "spheres fit build/meshes/pillar.obj" in joined
    assert "spheres tree build/pillar_spheres.h5" in joined
    assert "bake scene.toml" in joined
    assert "arch" not in joined  # the other mesh's chain is untouched
    assert "tables log" not in joined and "light project" not in joined
    # order: fit -> tree -> bake -> exports
    kinds = [c.split()[1] for c in commands]
    assert kinds.index("spheres") < kinds.index("bake") < kinds.index("export")


def test_touching_the_sky_reprojects_the_light_only(built_copy):
    os.utime(built_copy / "build/sky.hdr")
    joined = "\n".join(dry_run(built_copy))
    assert "light project build/sky.hdr" in joined and "spheres" not in joined


def test_touching_the_crate_resamples_its_field_only(built_copy):
    os.utime(built_copy / "build/meshes/crate.obj")
    commands = dry_run(built_copy)
    joined = "\n".join(commands)
    assert "field sample build/meshes/crate.obj" in joined and "bake scene.toml" in joined
    assert "spheres" not in joined
