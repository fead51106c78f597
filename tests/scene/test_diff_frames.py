"""``shtools diff`` on bakes: provenance is not data, and a frame range can be compared."""

from __future__ import annotations

import json
import math

from helpers.scenes import ground, scene_text

SCENE = scene_text(
    settings={"order": 2, "frames": 4, "fps": 2},
    environment={"coeffs": [[1.5 * math.sqrt(4 * math.pi), 1, 1], [0, 0, 0],
                            [0.5, 0.5, 0.5], [0, 0, 0]]},
    objects=[ground(size=4, subdivisions=8),
             {"name": "ball", "primitive": {"type": "sphere", "radius": 0.5, "subdivisions": 1},
              "role": "blocker", "keyframes": [{"time": 0, "translate": [-0.5, 0.7, 0]},
                                               {"time": 2, "translate": [0.5, 0.7, 0]}]}])


def _bake(run_cli, tmp_path, scene_name, out, *args):
    scene = tmp_path / scene_name
    scene.write_text(SCENE)
    code, _, stderr = run_cli("bake", scene, "-o", tmp_path / out, "--processes", 1, *args)
    assert code == 0, stderr
    return tmp_path / out


def test_scene_file_name_is_provenance(run_cli, tmp_path):
    a = _bake(run_cli, tmp_path, "shot_a.toml", "a.h5")
    b = _bake(run_cli, tmp_path, "shot_b.toml", "b.h5")
    code, stdout, stderr = run_cli("diff", a, b, "--rtol", 0, "--atol", 0)
    assert code == 0, stdout + stderr
    # with --inputs provenance counts, and the scene name is named as the difference
    code, stdout, _ = run_cli("diff", a, b, "--inputs", "--json")
    problems = json.loads(stdout)["problems"]
    assert code == 1 and any("parameters.scene" in p for p in problems), problems


def test_frame_range_of_a_partial_bake(run_cli, tmp_path):
    whole = _bake(run_cli, tmp_path, "s.toml", "whole.h5")
    part = _bake(run_cli, tmp_path, "s.toml", "part.h5", "--frames", "2:4")
    # the whole ranges differ in shape ...
    code, stdout, _ = run_cli("diff", part, whole, "--json")
    assert code == 1 and json.loads(stdout)["problems"]
    # ... the shared frames are identical (static receivers: same clusters, same sums)
    code, stdout, stderr = run_cli("diff", part, whole, "--frames", "2:4", "--rtol", 0,
                                   "--atol", 0, "--json")
    assert code == 0, stdout + stderr
    names = {d["name"]: d for d in json.loads(stdout)["datasets"]}
    assert names["radiance"]["shape"][0] == 2 and names["radiance"]["status"] == "identical"
    # a step, and a frame only one of them holds
    assert run_cli("diff", part, whole, "--frames", "2:4:2", "--rtol", 0, "--atol", 0)[0] == 0
    code, _, stderr = run_cli("diff", part, whole, "--frames", "0:2")
    assert code == 1 and "does not hold frame 0" in stderr and stderr.count("\n") == 1
