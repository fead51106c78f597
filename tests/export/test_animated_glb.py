"""The animated GLB of a frame range: decoded frame by frame against the single-frame exports.

The file is read back with a decoder written here from the glTF 2.0 text alone
(the ``glb`` fixture of ``conftest.py``: accessors with byte strides,
normalised integers and sparse substitution; morph targets as
``base + sum(w_i * target_i)``; STEP samplers; node TRS), so the comparison
does not go through the exporter's own code.
"""

from __future__ import annotations

import math

import numpy as np
import pygltflib
import pytest
from helpers.exports import export_json

from shtools.data_formats.bake import write_bake
from shtools.export.tonemap import srgb_encode
from shtools.scene.primitives import make_primitive

FRAMES = [5, 6, 7, 8, 9]
FPS = 10.0


def _rotation_y(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


@pytest.fixture(scope="module")
def bake_file(tmp_path_factory):
    """Four receivers over five frames, each exercising one way of storing a frame:

    * ``ground``: static; its colour changes visibly at 6 of its vertices per frame
      only (sparse targets), and frame 7 repeats frame 6 exactly (a shared target);
    * ``ball``: moves and turns rigidly (TRS), new random radiance every frame
      (dense targets);
    * ``flag``: a plane that waves (not rigid: POSITION/NORMAL targets);
    * ``post``: static, radiance the same every frame (no targets at all).
    """
    rng = np.random.default_rng(11)
    plane = make_primitive("plane", {"size": [2.0, 2.0], "subdivisions": 6})
    ball = make_primitive("sphere", {"radius": 0.3, "subdivisions": 1})
    flag = make_primitive("plane", {"size": [0.6, 0.4], "subdivisions": 3})
    post = make_primitive("box", {"extents": [0.1, 1.0, 0.1], "subdivisions": 1})
    parts = [plane, ball, flag, post]
    counts = [len(p.mesh.vertices) for p in parts]
    offsets = np.concatenate([[0], np.cumsum(counts)])
    T = len(FRAMES)
    verts, normals = [], []
    for t in range(T):
        rot = _rotation_y(0.4 * t)
        bv = np.asarray(ball.mesh.vertices) @ rot.T + [0.2 * t, 0.5, 0.1 * t]
        fv = np.asarray(flag.mesh.vertices) + np.array([0.0, 1.0, -0.5])
        fv[:, 1] += 0.05 * np.sin(3.0 * fv[:, 0] + t)  # a wave: no rigid motion fits it
        verts.append(np.concatenate([plane.mesh.vertices, bv, fv, post.mesh.vertices]))
        normals.append(np.concatenate([plane.normals, ball.normals @ rot.T, flag.normals,
                                       post.normals]))
    radiance = np.empty((T, offsets[-1], 3))
    g = slice(offsets[0], offsets[1])
    radiance[:, g] = rng.uniform(0.2, 1.5, (1, counts[0], 3))
    for t in range(1, T):
        radiance[t, g] = radiance[t - 1, g]
        # 6 vertices of the ground change by a few 8-bit steps, the rest by ~0.05 step
        radiance[t, g] *= 1.0002
        radiance[t, 6 * t: 6 * t + 6] *= 1.03
    radiance[2, g] = radiance[1, g]  # frame 7 = frame 6 on the ground
    radiance[:, offsets[1]:offsets[3]] = rng.uniform(0.0, 2.0, (T, offsets[3] - offsets[1], 3))
    radiance[:, offsets[3]:] = rng.uniform(0.0, 2.0, (1, counts[3], 3))
    albedo = np.tile([0.8, 0.6, 0.5], (offsets[-1], 1))
    faces = np.concatenate([p.mesh.faces + o for p, o in zip(parts, offsets, strict=False)])
    path = tmp_path_factory.mktemp("anim") / "baked.h5"
    write_bake(path, vertices=np.stack(verts), normals=np.stack(normals), faces=faces,
               radiance=radiance, sh_order=2, frame_index=FRAMES,
               times=np.asarray(FRAMES) / FPS, albedo=albedo, object_offsets=offsets,
               object_names=["ground", "ball", "flag", "post"], fps=FPS)
    return path


@pytest.mark.parametrize("frames_text", ["5:10", "5:10:2"])
def test_frames_decode_to_the_single_frame_exports(run_cli, bake_file, tmp_path, khronos,
                                                   glb, frames_text):
    out = tmp_path / "shot.glb"
    summary = export_json(run_cli, bake_file, out, "--frames", frames_text)
    assert summary["files"] == [str(out)] and sorted(tmp_path.iterdir()) == [out]
    frames = list(range(5, 10, 2 if frames_text.endswith(":2") else 1))
    gltf = pygltflib.GLTF2().load(str(out))
    names = ["ground", "ball", "flag", "post"]
    assert [n.name for n in gltf.nodes] == [m.name for m in gltf.meshes] == names
    assert summary["moving"] == ["ball"] and summary["deforming"] == ["flag"]
    assert summary["colour_animated"] == ["ground", "ball", "flag"]
    assert gltf.meshes[3].primitives[0].targets in ([], None)  # 'post' never changes
    for frame in frames:
        single = tmp_path / f"single{frame}.glb"
        export_json(run_cli, bake_file, single, "--frame", frame)
        ref = pygltflib.GLTF2().load(str(single))
        time = (frame - frames[0]) / FPS
        for o in range(len(names)):
            attrs = ref.meshes[o].primitives[0].attributes
            want_pos, want_col = glb.read(ref, attrs.POSITION), glb.read(ref, attrs.COLOR_0)
            pos, col = glb.frame(gltf, o, time)
            # within one 8-bit step, linear and sRGB-encoded (the drop threshold is a
            # quarter step, int16 rounding 1/65534)
            assert np.abs(col - want_col).max() * 255 <= 1.0, (frame, names[o])
            assert np.abs(srgb_encode(np.clip(col, 0, 1)) - srgb_encode(want_col)).max() \
                * 255 <= 1.0, (frame, names[o])
            # float32 storage of metre-scale positions, and of the fitted rotation
            np.testing.assert_allclose(pos, want_pos, atol=2e-5, err_msg=f"{frame} {o}")
    issues = khronos(out)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]


def test_three_js_plays_the_frames_of_the_single_frame_exports(run_cli, bake_file, tmp_path,
                                                              glb, threejs):
    """three.js's own loader and animation mixer, at each frame's time, show the colours
    and positions of ``--frame F`` (three.js r170, as the Makefile pins it)."""
    out = tmp_path / "shot.glb"
    export_json(run_cli, bake_file, out, "--frames", "5:10")
    # half-way through each frame's interval (STEP holds a frame until the next key;
    # a key's own time, stored as float32, may round just past the double asked for)
    shown = threejs(out, [(f - FRAMES[0] + 0.5) / FPS for f in FRAMES])
    for frame, view in zip(FRAMES, shown, strict=True):
        single = tmp_path / f"single{frame}.glb"
        export_json(run_cli, bake_file, single, "--frame", frame)
        ref = pygltflib.GLTF2().load(str(single))
        for mesh in ref.meshes:
            attrs = mesh.primitives[0].attributes
            got = view["meshes"][mesh.name]
            # one 8-bit step, as the decoder's test
            assert np.abs(got["color"] - glb.read(ref, attrs.COLOR_0)).max() * 255 <= 1.0, (
                frame, mesh.name)
            np.testing.assert_allclose(got["position"], glb.read(ref, attrs.POSITION),
                                       atol=2e-5, err_msg=f"{frame} {mesh.name}")


def test_targets_are_sparse_shared_or_dense_as_their_content_asks(run_cli, bake_file,
                                                                  tmp_path):
    out = tmp_path / "shot.glb"
    export_json(run_cli, bake_file, out, "--frames", "5:10")
    gltf = pygltflib.GLTF2().load(str(out))
    ground = gltf.meshes[0].primitives[0].targets
    assert len(ground) == len(FRAMES) - 1
    # frames 6 and 7 are the same on the ground: one accessor
    assert ground[0]["COLOR_0"] == ground[1]["COLOR_0"]
    for target in ground:
        acc = gltf.accessors[target["COLOR_0"]]
        # 6 changed vertices per frame (12 by frame 8: changes add up from frame 5)
        assert acc.bufferView is None and acc.sparse is not None and acc.sparse.count <= 24
    ball = gltf.accessors[gltf.meshes[1].primitives[0].targets[0]["COLOR_0"]]
    assert ball.sparse is None and ball.componentType == 5122 and ball.normalized
    assert "POSITION" not in gltf.meshes[1].primitives[0].targets[0]  # rigid: moved by TRS
    flag = gltf.meshes[2].primitives[0].targets
    assert all({"POSITION", "NORMAL", "COLOR_0"} <= set(t) for t in flag)
    assert gltf.meshes[0].extras["targetNames"] == [f"frame {f}" for f in FRAMES[1:]]


def test_sequence_option_and_single_frame_keep_the_old_files(run_cli, bake_file, tmp_path):
    summary = export_json(run_cli, bake_file, tmp_path / "s.glb", "--frames", "5:7", "--sequence")
    assert summary["files"] == [str(tmp_path / "s.0005.glb"), str(tmp_path / "s.0006.glb")]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.0005.glb", "s.0006.glb"]
    gltf = pygltflib.GLTF2().load(str(tmp_path / "s.0005.glb"))
    assert not gltf.animations and gltf.meshes[0].primitives[0].attributes._RADIANCE is not None
    code, _, err = run_cli("export", bake_file, "--sequence", "-o", tmp_path / "x.usda")
    assert code != 0 and "--sequence" in err and not (tmp_path / "x.usda").exists()


def test_output_files_lists_what_export_writes(bake_file, tmp_path):
    from shtools.data_formats.bake import read_bake
    from shtools.export.writer import export_bake, output_files

    bake = read_bake(bake_file)
    cases = [("a.glb", {"frames_text": "5:8"}), ("b.glb", {"frames_text": "5:8",
                                                           "sequence": True}),
             ("c.ply", {"frames_text": "6:8"}), ("d.exr", {}), ("e.usda", {}),
             ("f.glb", {"frame": 6})]
    for name, kwargs in cases:
        folder = tmp_path / name.replace(".", "_")
        folder.mkdir()
        planned = output_files(bake, folder / name, **kwargs)
        export_bake(bake, folder / name, **kwargs)
        assert sorted(planned) == sorted(folder.iterdir()), name
