"""The demo pipeline end to end, shortened (2 frames, k-means spheres) to stay in seconds."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from shtools.data_formats.bake import read_bake
from shtools.demo import run_demo, scene_toml
from shtools.scene.scene import parse_scene


def test_demo_scene_parses_and_animates(tmp_path):
    # the generated scene names files that exist only after the stages ran; parse it
    # against stand-ins to check the scene text itself
    for name in ("tables.h5", "sky.h5"):
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "meshes").mkdir()
    (tmp_path / "spheres").mkdir()
    for part in ("torso", "leg", "arm", "column"):
        (tmp_path / "meshes" / f"{part}.obj").write_text("")
        (tmp_path / "spheres" / f"{part}_tree.h5").write_bytes(b"")
    scene = parse_scene(scene_toml(frames=48), tmp_path / "scene.toml")
    from shtools.scene.animation import world_matrices

    start = world_matrices(scene.objects, 0.0)
    end = world_matrices(scene.objects, 47 / 24)
    # the walker crosses the ground along +x, the ball rolls along -x
    assert end["torso"][0, 3] - start["torso"][0, 3] > 3.5
    assert end["ball"][0, 3] - start["ball"][0, 3] < -3.5
    # limbs hang from the torso: the left leg's pivot follows the torso
    np.testing.assert_allclose(end["leg_left"][:3, 3] - end["torso"][:3, 3],
                               end["torso"][:3, :3] @ [0.0, -0.22, 0.1], atol=1e-12)


@pytest.mark.slow  # every demo stage, even shortened: ~35 s on a loaded 2-core machine
def test_demo_runs_and_writes_outputs(tmp_path):
    timings = run_demo(tmp_path, frames=2, quiet=True, fit_method="kmeans")
    for name in ("baked.h5", "demo.glb", "frame.png", "sheet.png", "demo.gif", "scene.toml",
                 "sky.hdr", "sky.h5", "tables.h5"):
        assert (tmp_path / name).is_file(), name
    bake = read_bake(tmp_path / "baked.h5")
    assert bake.n_frames == 2 and np.all(np.isfinite(bake.radiance))
    assert bake.object_names[0] == "ground"
    mesh = trimesh.load(tmp_path / "demo.glb", force="mesh", process=False, skip_materials=True)
    assert len(mesh.vertices) == bake.n_vertices
    assert set(timings) >= {"spheres fit + tree", "bake", "export", "total"}
