"""`shtools relight` loads no geometry stack: its process start is part of its cost."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from shtools.data_formats.light import write_light
from shtools.scene.bake import bake_to_file
from shtools.scene.scene import load_scene

#: Packages relighting does not use (meshes, ray tracing, fitting): importing them
#: takes longer than relighting a demo bake.
FORBIDDEN = ("trimesh", "scipy", "embreex", "pymeshlab", "igl", "matplotlib")

SCENE = """
[settings]
order = 2
frames = 2
fps = 4

[environment]
light = "sky.h5"

[[lights]]
name = "lamp"
shadows = "shexp"
position = [1.0, 2.5, 0.5]
radius = 0.3
color = [6.0, 5.0, 4.0]

[[objects]]
name = "ground"
primitive = { type = "plane", size = [2, 2], subdivisions = 3 }
role = "receiver"

[[objects]]
name = "ball"
primitive = { type = "sphere", radius = 0.4, subdivisions = 1 }
role = "blocker"
[[objects.keyframes]]
time = 0
translate = [0, 0.6, 0]
[[objects.keyframes]]
time = 0.25
translate = [0.3, 0.6, 0]
"""


#: What relighting under an environment alone, or keeping the lights of the scene the
#: bake was made from (the bake records them), does not read: the scene parser
#: (pydantic, every registered kind), the scene preparation and posing; nor tqdm (no
#: progress bar for a stage this short) or the modules of the other commands.
SCENE_STACK = ("pydantic", "shtools.scene.scene", "shtools.scene.schema",
               "shtools.scene.prepare", "shtools.scene.pose", "tqdm")
#: The command modules ``shtools relight`` uses: the group, its own, the shared helpers.
RELIGHT_CLI = {"shtools.cli", "shtools.cli.main", "shtools.cli.relight", "shtools.cli._common",
               "shtools.cli._limits", "shtools.cli._outputs"}


def _relight_modules(tmp_path, *extra) -> list[str]:
    """The modules a ``shtools relight`` process has imported when it ends."""
    coeffs = [[3.5, 3.2, 3.0], [0.1, 0.2, 0.3], [0.5, 0.4, 0.3], [0.0, 0.1, 0.0]]
    write_light(tmp_path / "sky.h5", coeffs, source="inline", parameters={"window": "none"})
    (tmp_path / "scene.toml").write_text(SCENE)
    bake_to_file(load_scene(tmp_path / "scene.toml"), tmp_path / "a.h5",
                 store_visibility=True, processes=1, workers=1)
    args = [str(tmp_path / "a.h5"), "--light", str(tmp_path / "sky.h5"), "--rotate", "30",
            *extra, "-o", str(tmp_path / "relit.h5")]
    code = (
        "import json, sys\n"
        "from shtools.cli.main import main\n"
        f"code = main(['relight', *{args!r}])\n"
        "print(json.dumps([code, sorted(sys.modules)]))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=120)
    status, loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert status == 0 and (tmp_path / "relit.h5").exists(), done.stderr
    return loaded


def test_relight_command_imports_no_geometry_stack(tmp_path):
    loaded = _relight_modules(tmp_path, "--lights", str(tmp_path / "scene.toml"))
    bad = sorted({m.split(".")[0] for m in loaded if m.split(".")[0] in FORBIDDEN})
    assert bad == [], f"shtools relight imported {bad}"


@pytest.mark.parametrize("lights", [False, True], ids=["environment", "own-lights"])
def test_relight_imports_no_scene_parser_nor_other_commands(tmp_path, lights):
    extra = ["--lights", str(tmp_path / "scene.toml")] if lights else []
    loaded = set(_relight_modules(tmp_path, *extra))
    assert "shtools.runtime.shading" in loaded  # the check sees the shading modules
    bad = sorted(m for m in SCENE_STACK if m in loaded)
    assert bad == [], f"shtools relight {' '.join(extra)} imported {bad}"
    commands = sorted(m for m in loaded if m.startswith("shtools.cli") and m not in RELIGHT_CLI)
    assert commands == [], f"shtools relight imported other commands' modules {commands}"


def test_relight_of_another_scene_parses_it(tmp_path):
    """The check above can fail: lights from a scene the bake was not made from (its
    bytes differ) go through the parser."""
    (tmp_path / "other.toml").write_text(SCENE.replace("radius = 0.3", "radius = 0.35"))
    loaded = set(_relight_modules(tmp_path, "--lights", str(tmp_path / "other.toml")))
    assert {"pydantic", "shtools.scene.scene"} <= loaded
