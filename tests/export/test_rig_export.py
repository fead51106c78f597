"""``export --rig OBJECT=RIG.glb``: a skinned character keeps its skin and clips, with colours."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pygltflib

from shtools.data_formats.bake import read_bake

SCENE = f"""
[settings]
order = 2
frames = 3
fps = 2

[environment]
coeffs = [[{2 * math.sqrt(4 * math.pi)}, 2, 2], [0, 0, 0], [1, 1, 1], [0, 0, 0]]

[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [3, 3], subdivisions = 4 }}
role = "receiver"

[[objects]]
name = "tube"
mesh = "tube.glb"
role = "receiver"
skin = {{ animation = 0 }}
translate = [0.5, 0, 0]

[[objects]]
name = "ball"
primitive = {{ type = "sphere", radius = 0.3, subdivisions = 1 }}
role = "blocker"
translate = [0, 1.2, 0.4]
"""


def _rig(path: Path, **kwargs) -> None:
    from helpers.rig import write_bending_tube

    write_bending_tube(path, **kwargs)


def _read(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    width = {"SCALAR": 1, "VEC3": 3}[acc.type]
    start = view.byteOffset + (acc.byteOffset or 0)
    data = np.frombuffer(gltf.binary_blob()[start:start + acc.count * width * 4], np.float32)
    return data.reshape(acc.count, width) if width > 1 else data


def test_rig_keeps_skin_clips_and_gets_the_frame_colours(run_cli, tmp_path, khronos):
    _rig(tmp_path / "tube.glb")
    (tmp_path / "scene.toml").write_text(SCENE)
    code, _, stderr = run_cli("bake", tmp_path / "scene.toml", "-o", tmp_path / "b.h5",
                              "--processes", 1)
    assert code == 0, stderr
    out = tmp_path / "tube_lit.glb"
    code, stdout, stderr = run_cli("export", tmp_path / "b.h5", "--frame", 1, "--rig",
                                   f"tube={tmp_path / 'tube.glb'}", "-o", out, "--json")
    assert code == 0, stderr
    assert json.loads(stdout)["animations"] == ["bend"]  # the rig's clip name
    src = pygltflib.GLTF2().load(str(tmp_path / "tube.glb"))
    got = pygltflib.GLTF2().load(str(out))
    # the rig is intact: nodes, skin, clips and the geometry accessors it had
    assert len(got.nodes) == len(src.nodes) and len(got.skins) == len(src.skins) == 1
    assert len(got.animations) == len(src.animations) == 1
    prim, src_prim = got.meshes[0].primitives[0], src.meshes[0].primitives[0]
    assert prim.attributes.POSITION == src_prim.attributes.POSITION
    assert prim.attributes.JOINTS_0 == src_prim.attributes.JOINTS_0
    # the baked values of frame 1 for the tube's vertices, in the rig's vertex order
    bake = read_bake(tmp_path / "b.h5")
    o = bake.object_names.index("tube")
    lo, hi = bake.object_offsets[o], bake.object_offsets[o + 1]
    np.testing.assert_array_equal(_read(got, prim.attributes._RADIANCE),
                                  bake.radiance[1, lo:hi])
    assert _read(got, prim.attributes.COLOR_0).shape == (hi - lo, 3)
    issues = khronos(out)
    assert issues["numErrors"] == 0, issues["messages"]


def test_rig_must_be_the_baked_one(run_cli, tmp_path):
    _rig(tmp_path / "tube.glb")
    (tmp_path / "scene.toml").write_text(SCENE)
    assert run_cli("bake", tmp_path / "scene.toml", "-o", tmp_path / "b.h5",
                   "--processes", 1)[0] == 0
    other = tmp_path / "other" / "tube.glb"
    other.parent.mkdir()
    _rig(other, bend_degrees=45.0)  # same name, other content
    for args, message in (
        (("--rig", f"tube={other}"), "hash differs"),
        (("--rig", "nope=x.glb"), "no receiver object 'nope'"),
        (("--rig", "tube"), "is not OBJECT=RIG.glb"),
        (("--frames", "0:2", "--sequence", "--rig", f"tube={tmp_path / 'tube.glb'}"),
         "--rig writes one .glb"),
    ):
        code, _, stderr = run_cli("export", tmp_path / "b.h5", "-o", tmp_path / "x.glb", *args)
        # a malformed option is a usage error (exit 2, naming no file); the others are
        # about the files (exit 1)
        want = 2 if "OBJECT=RIG" in message else 1
        assert code == want and message in stderr and stderr.count("\n") == 1, stderr
        assert want == 1 or "b.h5" not in stderr
    assert not (tmp_path / "x.glb").exists()


def test_rig_with_a_frame_range_plays_every_frame_colours(run_cli, tmp_path, khronos, glb):
    """--frames with --rig: the skin and clip kept, each frame's colours decode to that
    frame's single-frame rig export (one-hot STEP weights at the frames' scene times)."""
    _rig(tmp_path / "tube.glb")
    (tmp_path / "scene.toml").write_text(SCENE)
    assert run_cli("bake", tmp_path / "scene.toml", "-o", tmp_path / "b.h5",
                   "--processes", 1)[0] == 0
    rig = f"tube={tmp_path / 'tube.glb'}"
    out = tmp_path / "anim.glb"
    code, _, stderr = run_cli("export", tmp_path / "b.h5", "--frames", "0:3", "--rig", rig,
                              "--fixed-exposure", "-o", out)
    assert code == 0, stderr
    got = pygltflib.GLTF2().load(str(out))
    assert [a.name for a in got.animations] == ["bend", "bake"] and len(got.skins) == 1
    sampler = got.animations[1].samplers[0]
    bake = read_bake(tmp_path / "b.h5")
    prim = got.meshes[0].primitives[0]
    assert len(prim.targets) == 2
    for t in range(3):
        single = tmp_path / f"one{t}.glb"
        assert run_cli("export", tmp_path / "b.h5", "--frame", t, "--rig", rig,
                       "--fixed-exposure", "-o", single)[0] == 0
        ref = pygltflib.GLTF2().load(str(single))
        want = glb.read(ref, ref.meshes[0].primitives[0].attributes.COLOR_0)
        weights = glb.step(got, sampler, float(bake.times[t]))
        colour = glb.read(got, prim.attributes.COLOR_0) + sum(
            w * glb.read(got, target["COLOR_0"]) for w, target in zip(weights, prim.targets,
                                                                   strict=True))
        # one 8-bit step (a quarter for dropped changes, int16 rounding)
        assert np.abs(colour - want).max() * 255 <= 1.0, t
    issues = khronos(out)
    assert issues["numErrors"] == 0, issues["messages"]
