"""`shtools relight` loads no geometry stack: its process start is part of its cost."""

from __future__ import annotations

import json
import subprocess
import sys

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


def test_relight_command_imports_no_geometry_stack(tmp_path):
    coeffs = [[3.5, 3.2, 3.0], [0.1, 0.2, 0.3], [0.5, 0.4, 0.3], [0.0, 0.1, 0.0]]
    write_light(tmp_path / "sky.h5", coeffs, source="inline", parameters={"window": "none"})
    (tmp_path / "scene.toml").write_text(SCENE)
    bake_to_file(load_scene(tmp_path / "scene.toml"), tmp_path / "a.h5",
                 store_visibility=True, processes=1, workers=1)
    code = (
        "import json, sys\n"
        "from shtools.cli.main import main\n"
        f"code = main(['relight', {str(tmp_path / 'a.h5')!r}, '--light', "
        f"{str(tmp_path / 'sky.h5')!r}, '--rotate', '30', '--lights', "
        f"{str(tmp_path / 'scene.toml')!r}, '-o', {str(tmp_path / 'relit.h5')!r}])\n"
        "print(json.dumps([code, sorted(sys.modules)]))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=120)
    status, loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert status == 0 and (tmp_path / "relit.h5").exists(), done.stderr
    bad = sorted({m.split(".")[0] for m in loaded if m.split(".")[0] in FORBIDDEN})
    assert bad == [], f"shtools relight imported {bad}"
