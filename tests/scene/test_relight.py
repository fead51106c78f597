"""Relighting a stored-visibility bake equals a real re-bake under the new light.

Also streamed in tiny batches, within bounded memory, and on a mid-range bake's
environment sphere.
"""

from __future__ import annotations

import math
import tracemalloc

import numpy as np
import pytest

from shtools.data_formats.bake import read_bake
from shtools.data_formats.bake_stream import open_bake
from shtools.data_formats.light import write_light
from shtools.scene import relight as relight_module
from shtools.scene.bake import bake_to_file
from shtools.scene.relight import relight
from shtools.scene.scene import load_scene

ORDER = 3

SCENE = """
[settings]
order = {order}
frames = 3
fps = 4

[environment]
light = "{light}"
rotate_deg = {rotate}
{lamp}
[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [4, 4], subdivisions = 12 }}
role = "receiver"
{ground_keys}
[[objects]]
name = "ball"
primitive = {{ type = "sphere", radius = 0.5, subdivisions = 2 }}
role = "{ball_role}"
[[objects.keyframes]]
time = 0
translate = [-0.5, 0.7, 0]
[[objects.keyframes]]
time = 0.5
translate = [0.5, 0.6, 0.2]
"""

LAMP = """
[[lights]]
name = "lamp"
shadows = "{shadows}"
position = [1.0, 2.5, 0.5]
radius = 0.3
color = [6.0, 5.0, 4.0]
{lamp_keys}"""

#: keyframes that move the ground and the lamp (else only the ball moves)
GROUND_KEYS = """[[objects.keyframes]]
time = 0
[[objects.keyframes]]
time = 0.5
translate = [0.2, 0, 0.1]
"""
LAMP_KEYS = """[[lights.keyframes]]
time = 0
[[lights.keyframes]]
time = 0.5
position = [-1.0, 2.0, 1.0]
radius = 0.4
color = [3.0, 4.0, 6.0]
"""


def _sky(path, seed, order=ORDER):
    """A coloured sky: a bright DC term plus random higher bands (a directional part)."""
    rng = np.random.default_rng(seed)
    coeffs = rng.normal(0.0, 0.3, (order * order, 3))
    coeffs[0] = math.sqrt(4 * math.pi) * np.array([1.0, 0.9, 0.8])
    write_light(path, coeffs, source="inline", parameters={"order": order, "window": "none"})
    return path


def _scene(tmp_path, name, light, rotate=0.0, lamp=True, shadows="shexp", moving="all"):
    path = tmp_path / name
    keys = moving == "all"
    lamp = LAMP.format(shadows=shadows, lamp_keys=LAMP_KEYS if keys else "") if lamp else ""
    path.write_text(SCENE.format(order=ORDER, light=light, rotate=rotate, lamp=lamp,
                                 ground_keys=GROUND_KEYS if keys else "",
                                 ball_role="blocker" if moving == "none" else "both"))
    return path


@pytest.fixture(params=["all", "ball", "none"])
def moving(request):
    """What moves: ground and lamp keyframed (every vertex shaded per frame); only the
    ball (the ground from its fixed linear shading, the ball shaded per frame); or no
    receiver (the ball only blocks: a bake with one pose of the receivers)."""
    return request.param


@pytest.fixture
def baked_a(tmp_path, moving):
    """Light A, the lamp, visibility stored; and light B beside it."""
    _sky(tmp_path / "a.h5", 1)
    _sky(tmp_path / "b.h5", 2)
    scene = _scene(tmp_path, "a.toml", "a.h5", moving=moving)
    bake_to_file(load_scene(scene), tmp_path / "a_baked.h5", store_visibility=True,
                 processes=1, workers=1)
    return scene, tmp_path / "a_baked.h5"


def test_relight_equals_a_fresh_bake_under_the_new_light(baked_a, tmp_path, moving):
    scene_a, bake_a = baked_a
    scene_b = _scene(tmp_path, "b.toml", "b.h5", rotate=35.0, moving=moving)
    bake_to_file(load_scene(scene_b), tmp_path / "b_baked.h5", processes=1, workers=1)
    summary = relight(bake_a, tmp_path / "b.h5", tmp_path / "relit.h5", rotate=35.0,
                      scene=scene_a)
    assert summary["frames"] == 3 and summary["lights"] == 1
    relit, fresh, old = (read_bake(tmp_path / n) for n in ("relit.h5", "b_baked.h5",
                                                            "a_baked.h5"))
    # the relit frames differ from light A's (the test could not pass by copying) ...
    assert np.max(np.abs(old.radiance - fresh.radiance)) > 0.05 * np.max(fresh.radiance)
    # ... and equal the fresh bake: the same float32 shading of the same visibility;
    # rtol 1e-4 is float32 rounding of a sum of ~10 terms, atol the same relative to
    # the brightest vertex for the deep-shadow vertices near 0
    top = float(np.max(np.abs(fresh.radiance)))
    np.testing.assert_allclose(relit.radiance, fresh.radiance, rtol=1e-4, atol=1e-6 * top)
    # the geometry is carried over; the visibility is not by default: the output is
    # the bake a fresh one without --store-visibility is
    assert relit.visibility is None and fresh.visibility is None
    np.testing.assert_array_equal(relit.vertices, old.vertices)
    assert relit.object_names == old.object_names and relit.attrs["fps"] == old.attrs["fps"]


@pytest.mark.parametrize("moving", ["ball"])  # one bake is enough here
def test_kept_visibility_is_carried_and_relit_again(baked_a, tmp_path):
    scene_a, bake_a = baked_a
    relight(bake_a, tmp_path / "b.h5", tmp_path / "kept.h5", rotate=35.0, scene=scene_a,
            keep_visibility=True)
    kept, old = read_bake(tmp_path / "kept.h5"), read_bake(bake_a)
    np.testing.assert_array_equal(kept.visibility, old.visibility)
    # relit back under light A from the kept visibility: the original bake's radiance
    # (a fresh bake under A), to the same float32 rounding as a relight of the original
    relight(tmp_path / "kept.h5", tmp_path / "a.h5", tmp_path / "back.h5", scene=scene_a)
    top = float(np.max(np.abs(old.radiance)))
    np.testing.assert_allclose(read_bake(tmp_path / "back.h5").radiance, old.radiance,
                               rtol=1e-4, atol=1e-6 * top)


def test_relight_without_lights_is_the_environment_alone(baked_a, tmp_path, moving):
    _, bake_a = baked_a
    scene_b = _scene(tmp_path, "b.toml", "b.h5", lamp=False, moving=moving)
    bake_to_file(load_scene(scene_b), tmp_path / "b_baked.h5", processes=1, workers=1)
    relight(bake_a, tmp_path / "b.h5", tmp_path / "relit.h5")
    top = float(np.max(read_bake(tmp_path / "b_baked.h5").radiance))
    np.testing.assert_allclose(read_bake(tmp_path / "relit.h5").radiance,
                               read_bake(tmp_path / "b_baked.h5").radiance, rtol=1e-4,
                               atol=1e-6 * top)


def _one_line_error(run_cli, *args):
    code, _, stderr = run_cli(*args)
    assert code not in (0, 3) and stderr.count("\n") == 1 and "Traceback" not in stderr, stderr
    return stderr


@pytest.mark.parametrize("moving", ["ball"])  # one bake is enough here
def test_relight_refuses_bad_input_in_one_line(baked_a, tmp_path, run_cli):
    scene_a, bake_a = baked_a
    before = bake_a.read_bytes()
    out = tmp_path / "relit.h5"
    # a bake without stored visibility
    bake_to_file(load_scene(scene_a), tmp_path / "plain.h5", processes=1, workers=1)
    err = _one_line_error(run_cli, "relight", tmp_path / "plain.h5", "--light",
                          tmp_path / "b.h5", "-o", out)
    assert "--store-visibility" in err and "plain.h5" in err
    # a light of another SH order
    _sky(tmp_path / "c.h5", 3, order=ORDER + 1)
    err = _one_line_error(run_cli, "relight", bake_a, "--light", tmp_path / "c.h5", "-o", out)
    assert f"order {ORDER + 1}" in err and f"--order {ORDER}" in err
    # the output is the input
    err = _one_line_error(run_cli, "relight", bake_a, "--light", tmp_path / "b.h5", "-o", bake_a)
    assert "also an input" in err
    # not a bake
    err = _one_line_error(run_cli, "relight", tmp_path / "b.h5", "--light", tmp_path / "b.h5",
                          "-o", out)
    # a light the stored visibility cannot shadow
    ssoc = _scene(tmp_path, "ssoc.toml", "a.h5", shadows="ssoc", moving="none")
    err = _one_line_error(run_cli, "relight", bake_a, "--light", tmp_path / "b.h5",
                          "--lights", ssoc, "-o", out)
    assert "ssoc" in err
    # NaN in a later frame's visibility: found as the frames stream, nothing written
    import shutil

    import h5py

    shutil.copy(bake_a, tmp_path / "nan.h5")
    with h5py.File(tmp_path / "nan.h5", "r+") as f:
        f["visibility"][2, 3, 0] = np.nan
    err = _one_line_error(run_cli, "relight", tmp_path / "nan.h5", "--light",
                          tmp_path / "b.h5", "-o", out)
    assert "nan.h5" in err and "'visibility' contains NaN" in err
    assert not out.exists() and bake_a.read_bytes() == before
    # -o a file the scene names (its sky, a.h5), whether the lamp is read from the bake
    # or, for an older bake, from the parsed scene
    sky = (tmp_path / "a.h5").read_bytes()
    for bake in (bake_a, _older(bake_a, tmp_path / "old.h5")):
        err = _one_line_error(run_cli, "relight", bake, "--light", tmp_path / "b.h5",
                              "--lights", scene_a, "-o", tmp_path / "a.h5")
        assert "a.h5" in err and ("also an input" in err or "a file the scene" in err), err
    assert (tmp_path / "a.h5").read_bytes() == sky
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


@pytest.mark.parametrize("moving", ["ball"])
def test_relight_cli_writes_the_asset(baked_a, tmp_path, run_cli):
    scene_a, bake_a = baked_a
    code, stdout, stderr = run_cli("relight", bake_a, "--light", tmp_path / "b.h5",
                                   "--rotate", "90", "--lights", scene_a, "--compress",
                                   "-o", tmp_path / "relit.h5")
    assert code == 0, stderr
    assert "relit 3 frame(s)" in stdout
    relit = read_bake(tmp_path / "relit.h5")
    assert relit.parameters["relight"] == {"light": "b.h5", "rotate_deg": 90.0,
                                           "lights": "a.toml"}
    # --compress stores the radiance as a bake does (geometry copied as stored), the same
    # values as plain
    relight(bake_a, tmp_path / "b.h5", tmp_path / "plain.h5", rotate=90.0, scene=scene_a)
    plain = read_bake(tmp_path / "plain.h5")
    np.testing.assert_array_equal(plain.radiance, relit.radiance)
    np.testing.assert_array_equal(plain.vertices, relit.vertices)
    import h5py

    with h5py.File(tmp_path / "relit.h5") as f, h5py.File(tmp_path / "plain.h5") as g:
        assert f["radiance"].compression == "gzip" and g["radiance"].compression is None
    assert relit.visibility is None
    # --keep-visibility carries the stored visibility, so the output can be relit again
    code, _, stderr = run_cli("relight", bake_a, "--light", tmp_path / "b.h5",
                              "--keep-visibility", "-o", tmp_path / "kept.h5")
    assert code == 0, stderr
    np.testing.assert_array_equal(read_bake(tmp_path / "kept.h5").visibility,
                                  read_bake(bake_a).visibility)


@pytest.mark.parametrize("moving", ["ball"])
def test_relight_keeps_the_bakes_deringing(tmp_path, moving):
    """A bake with deringing = "none" keeps its negative lobes when relit, as a fresh bake."""
    _sky(tmp_path / "a.h5", 1)
    # a sky of strong low bands: its order-3 truncation rings below zero in places
    coeffs = np.zeros((ORDER * ORDER, 3))
    coeffs[0] = math.sqrt(4 * math.pi) * 0.3
    coeffs[2] = [3.0, 2.5, 2.0]
    coeffs[6] = [-2.0, -1.5, -1.0]
    write_light(tmp_path / "ring.h5", coeffs, source="inline", parameters={"window": "none"})
    for name, light in (("a.toml", "a.h5"), ("b.toml", "ring.h5")):
        path = _scene(tmp_path, name, light, moving=moving)
        path.write_text(path.read_text().replace("fps = 4", 'fps = 4\nderinging = "none"'))
    bake_to_file(load_scene(tmp_path / "a.toml"), tmp_path / "a_baked.h5",
                 store_visibility=True, processes=1, workers=1)
    bake_to_file(load_scene(tmp_path / "b.toml"), tmp_path / "b_baked.h5", processes=1,
                 workers=1)
    assert read_bake(tmp_path / "a_baked.h5").parameters["deringing"] == "none"
    relight(tmp_path / "a_baked.h5", tmp_path / "ring.h5", tmp_path / "relit.h5",
            scene=tmp_path / "a.toml")
    fresh = read_bake(tmp_path / "b_baked.h5").radiance
    assert (fresh < 0).any()  # the check below sees negative radiance kept, not removed
    top = float(np.max(np.abs(fresh)))
    np.testing.assert_allclose(read_bake(tmp_path / "relit.h5").radiance, fresh, rtol=1e-4,
                               atol=1e-6 * top)


@pytest.mark.parametrize("moving", ["ball"])
def test_relit_bytes_do_not_depend_on_the_thread_count(baked_a, tmp_path):
    scene_a, bake_a = baked_a
    for threads in (1, 3):
        relight(bake_a, tmp_path / "b.h5", tmp_path / f"t{threads}.h5", rotate=20.0,
                scene=scene_a, threads=threads)
    assert (tmp_path / "t1.h5").read_bytes() == (tmp_path / "t3.h5").read_bytes()


def _bake(scene, path, **kwargs):
    bake_to_file(load_scene(scene), path, processes=1, workers=1, **kwargs)
    return path


def _assert_fresh(relit_path, fresh_path):
    fresh = read_bake(fresh_path).radiance
    # float32 rounding of the same shading (tests/scene/test_relight.py says why)
    top = float(np.max(np.abs(fresh)))
    np.testing.assert_allclose(read_bake(relit_path).radiance, fresh, rtol=1e-4,
                               atol=1e-6 * top)


@pytest.mark.parametrize("held", [True, False], ids=["geometry-held", "geometry-reread"])
def test_streamed_relight_in_tiny_batches_equals_a_fresh_bake(tmp_path, monkeypatch, held):
    """One frame a batch, the K of the still ground built in parts of 5 rows, the moving
    ball's geometry kept in memory or read again per batch, the still rows taken as a
    slice or gathered by index: the same radiance."""
    _sky(tmp_path / "a.h5", 1)
    _sky(tmp_path / "b.h5", 2)
    scene_a = _scene(tmp_path, "a.toml", "a.h5", moving="ball")
    scene_b = _scene(tmp_path, "b.toml", "b.h5", rotate=25.0, moving="ball")
    _bake(scene_a, tmp_path / "a_baked.h5", store_visibility=True)
    _bake(scene_b, tmp_path / "b_baked.h5")
    monkeypatch.setattr(relight_module, "BATCH_ROWS", 5)
    if not held:
        monkeypatch.setattr(relight_module, "GEOMETRY_BYTES", 0)
        monkeypatch.setattr(relight_module, "MAX_RUNS", 0)
    relight(tmp_path / "a_baked.h5", tmp_path / "b.h5", tmp_path / "relit.h5", rotate=25.0,
            scene=scene_a, threads=2)
    _assert_fresh(tmp_path / "relit.h5", tmp_path / "b_baked.h5")


def _frames_scene(tmp_path, name, light, frames):
    """The ball scene with a finer ground, ``frames`` frames."""
    path = _scene(tmp_path, name, light, moving="ball")
    text = path.read_text().replace("frames = 3", f"frames = {frames}")
    path.write_text(text.replace("subdivisions = 12", "subdivisions = 30"))
    return path


def _peak_relight(bake, light, out, scene) -> int:
    tracemalloc.start()
    try:
        relight(bake, light, out, scene=scene, threads=1)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_relight_memory_does_not_grow_with_the_frame_count(tmp_path, monkeypatch):
    """6 and 48 frames relit one frame a batch: the peak of traced allocations grows by
    far less than the extra frames' visibility (the whole bake was read into memory)."""
    _sky(tmp_path / "a.h5", 1)
    _sky(tmp_path / "b.h5", 2)
    # 1,123 vertices: one frame a batch, the ground's K in one part
    monkeypatch.setattr(relight_module, "BATCH_ROWS", 1200)
    monkeypatch.setattr(relight_module, "GEOMETRY_BYTES", 0)
    peaks, sizes = [], []
    for frames in (6, 48):
        scene = _frames_scene(tmp_path, f"a{frames}.toml", "a.h5", frames)
        bake = _bake(scene, tmp_path / f"a{frames}.h5", store_visibility=True)
        sizes.append(read_bake(bake).visibility.nbytes)
        peaks.append(_peak_relight(bake, tmp_path / "b.h5", tmp_path / f"r{frames}.h5", scene))
    # 42 more frames of visibility (~2 MB); a streamed relight holds a few frames
    # whatever their count, so its peak moves by allocation noise only
    assert peaks[1] - peaks[0] < 0.25 * (sizes[1] - sizes[0]), (peaks, sizes)
    fresh = _bake(_frames_scene(tmp_path, "b48.toml", "b.h5", 48), tmp_path / "b48.h5")
    _assert_fresh(tmp_path / "r48.h5", fresh)


SPHERE = "radius = 6.0\ncenter = [0.3, 0.5, -0.2]"


def _midrange_scene(tmp_path, name, light, extra=SPHERE, rotate=0.0):
    path = _scene(tmp_path, name, light, rotate=rotate, moving="ball")
    text = path.read_text()
    assert f'light = "{light}"' in text
    path.write_text(text.replace(f'light = "{light}"', f'light = "{light}"\n{extra}', 1))
    return path


def test_midrange_bake_is_relit_on_its_sphere(tmp_path):
    """A bake under a finite environment sphere records it, and its relight equals a
    fresh bake of the new light on that sphere (not the light at infinity)."""
    _sky(tmp_path / "a.h5", 1)
    _sky(tmp_path / "b.h5", 2)
    scene_a = _midrange_scene(tmp_path, "a.toml", "a.h5")
    bake_a = _bake(scene_a, tmp_path / "a_baked.h5", store_visibility=True)
    assert read_bake(bake_a).parameters["environment_sphere"] == {
        "center": [0.3, 0.5, -0.2], "radius": 6.0, "scaling": None}
    fresh = _bake(_midrange_scene(tmp_path, "b.toml", "b.h5", rotate=40.0),
                  tmp_path / "b_baked.h5")
    distant = _bake(_scene(tmp_path, "far.toml", "b.h5", rotate=40.0, moving="ball"),
                    tmp_path / "far_baked.h5")
    # the sphere matters here: at infinity the radiance is visibly another
    far, near = read_bake(distant).radiance, read_bake(fresh).radiance
    assert np.max(np.abs(far - near)) > 1e-2 * np.max(np.abs(near))
    relight(bake_a, tmp_path / "b.h5", tmp_path / "relit.h5", rotate=40.0, scene=scene_a)
    _assert_fresh(tmp_path / "relit.h5", fresh)


def test_midrange_bake_with_a_scaling_asset_is_refused(tmp_path, run_cli):
    _sky(tmp_path / "a.h5", 1)
    _sky(tmp_path / "b.h5", 2)
    code, _, err = run_cli("tables", "scaling", "-n", 3, "--function", "midrange",
                           "--samples", 16, "-o", tmp_path / "mid.h5")
    assert code == 0, err
    scene = _midrange_scene(tmp_path, "a.toml", "a.h5",
                            extra='radius = 6.0\nscaling = "mid.h5"')
    bake = _bake(scene, tmp_path / "a_baked.h5", store_visibility=True)
    before = bake.read_bytes()
    code, _, err = run_cli("relight", bake, "--light", tmp_path / "b.h5",
                           "-o", tmp_path / "relit.h5")
    assert code not in (0, 3) and err.count("\n") == 1 and "Traceback" not in err, err
    assert "a_baked.h5" in err and "mid.h5" in err and "bake the scene" in err
    assert not (tmp_path / "relit.h5").exists() and bake.read_bytes() == before


def test_a_long_bake_is_not_refused_for_its_size_but_a_wide_one_is(tmp_path):
    """Memory is set by the vertex count: 10^5 frames x 10^4 vertices (76 GB to read
    whole) streams in a few MB; 10^7 vertices needs GiB per frame batch and is refused."""
    import h5py

    from shtools.cli._limits import MEMORY_LIMIT, asset_bytes
    from shtools.cli.relight import _check_memory
    from shtools.errors import InputError

    def declared(name, frames, vertices):  # metadata only: chunks are never written
        path = tmp_path / name
        with h5py.File(path, "w") as f:
            f.attrs["sh_order"] = 4
            f.create_dataset("radiance", (frames, vertices, 3), "f4", chunks=(1, 64, 3))
            f.create_dataset("visibility", (frames, vertices, 16), "f4", chunks=(1, 64, 16))
        return path

    long_bake = declared("long.h5", 10**5, 10**4)
    assert asset_bytes(long_bake) > 10 * MEMORY_LIMIT  # what reading it whole would take
    _check_memory(long_bake, force=False)  # streamed: accepted
    wide = declared("wide.h5", 10, 10**7)
    with pytest.raises(InputError, match=r"GiB of memory.*10,000,000 vertices.*--force"):
        _check_memory(wide, force=False)
    _check_memory(wide, force=True)


@pytest.mark.parametrize("moving", ["all", "ball"])  # lights per frame / the same lights
def test_nan_geometry_is_found_as_frames_stream(baked_a, tmp_path, run_cli, moving):
    import shutil

    import h5py

    scene_a, bake_a = baked_a
    shutil.copy(bake_a, tmp_path / "nan.h5")
    with h5py.File(tmp_path / "nan.h5", "r+") as f:
        f["vertices"][2, -1, 1] = np.inf  # a ball vertex (it moves in both bakes)
    err = _one_line_error(run_cli, "relight", tmp_path / "nan.h5", "--light",
                          tmp_path / "b.h5", "--lights", scene_a, "-o", tmp_path / "r.h5")
    assert "nan.h5" in err and "'vertices' contains NaN or inf" in err
    assert not (tmp_path / "r.h5").exists()


@pytest.mark.parametrize("moving", ["all"])  # the keyframed lamp
def test_bake_records_its_lamp_posed_at_each_frame(baked_a):
    """``light_poses`` holds the lamp at the frame times 0, 0.25, 0.5 s: the keyframes of
    LAMP_KEYS lerped by hand (the middle frame halfway)."""
    _, bake_a = baked_a
    start = np.array([1.0, 2.5, 0.5, 0.3, 6.0, 5.0, 4.0])  # position, radius, colour
    end = np.array([-1.0, 2.0, 1.0, 0.4, 3.0, 4.0, 6.0])
    np.testing.assert_allclose(read_bake(bake_a).light_poses[:, 0],
                               [start, (start + end) / 2, end], rtol=1e-12)


def _older(bake, path):
    """``bake`` as made before bakes recorded their lights (no ``light_poses``)."""
    import shutil

    import h5py

    shutil.copy(bake, path)
    with h5py.File(path, "r+") as f:
        del f["light_poses"]
    return path


@pytest.mark.parametrize("moving", ["all"])
def test_lights_of_an_older_bake_or_another_scene_are_parsed(baked_a, tmp_path):
    """The bake's own scene file gives the recorded lamp; an older bake (no record) and an
    edited scene (another sha256) go through the parser, and each relight equals a fresh
    bake under its lamp."""
    from shtools.scene.light_record import PosedLights, own_lights, scene_lights

    scene_a, bake_a = baked_a
    old = _older(bake_a, tmp_path / "old.h5")
    warm = scene_a.read_text().replace("color = [6.0, 5.0, 4.0]", "color = [9.0, 5.0, 2.0]")
    assert warm != scene_a.read_text()
    (tmp_path / "warm.toml").write_text(warm)
    with open_bake(bake_a) as b, open_bake(old) as o:
        assert isinstance(scene_lights(scene_a, b), PosedLights)
        assert own_lights(b, tmp_path / "warm.toml") is None
        assert own_lights(o, scene_a) is None
    for bake, scene, lamp in ((old, scene_a, "6.0, 5.0, 4.0"),
                              (bake_a, tmp_path / "warm.toml", "9.0, 5.0, 2.0")):
        fresh = _scene(tmp_path, "b.toml", "b.h5", rotate=35.0, moving="all")
        fresh.write_text(fresh.read_text().replace("color = [6.0, 5.0, 4.0]",
                                                   f"color = [{lamp}]"))
        _bake(fresh, tmp_path / "b_baked.h5")
        relight(bake, tmp_path / "b.h5", tmp_path / "relit.h5", rotate=35.0, scene=scene)
        _assert_fresh(tmp_path / "relit.h5", tmp_path / "b_baked.h5")
        # the relit bake records the lamp it was shaded with
        np.testing.assert_array_equal(read_bake(tmp_path / "relit.h5").light_poses,
                                      read_bake(tmp_path / "b_baked.h5").light_poses)


RING_SCENE = """
[settings]
order = 3
frames = 2
fps = 2

[environment]
light = "{light}"
rotate_deg = {rotate}

[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [12, 12], subdivisions = 48 }}
role = "receiver"

[[objects]]
name = "ring"
mesh = "torus.obj"
role = "blocker"
blocker = {{ spheres = "torus_spheres.h5" }}
[[objects.keyframes]]
time = 0
translate = [0.0, 1.0, 0.0]
[[objects.keyframes]]
time = 1
translate = [0.3, 1.0, 0.0]
"""


def _low_sun(path, order=3):
    """A grey sky: a dim floor and a sun lobe 15 degrees up toward +x (``sun_sky``)."""
    from helpers.skies import sun_sky

    sun = np.array([math.cos(math.radians(15.0)), math.sin(math.radians(15.0)), 0.0])
    lum = sun_sky(sun, order, floor=0.05)
    write_light(path, np.repeat(lum[:, None], 3, axis=1), source="inline",
                parameters={"order": order, "window": "none"})
    return path


def test_a_relit_traced_shadow_under_a_turned_sun_equals_a_fresh_bake(tmp_path):
    """A ring traced on the ground (its real mesh near it, its spheres far) under a low
    sun: a plain bake weighs the hand-over by the sun behind the ring, so its radiance
    changes with the sky beyond the shading; a bake that stores its visibility leaves
    the sky out, and its relight under the sun turned 90 degrees equals a fresh
    stored-visibility bake under it."""
    from helpers.scenes import bounded_torus

    bounded_torus(tmp_path)
    _low_sun(tmp_path / "sun.h5")
    for name, rotate in (("a", 0.0), ("b", 90.0)):
        (tmp_path / f"{name}.toml").write_text(RING_SCENE.format(light="sun.h5", rotate=rotate))
        bake_to_file(load_scene(tmp_path / f"{name}.toml"), tmp_path / f"{name}_stored.h5",
                     store_visibility=True, processes=1, workers=1)
    bake_to_file(load_scene(tmp_path / "b.toml"), tmp_path / "b_plain.h5", processes=1,
                 workers=1)
    relight(tmp_path / "a_stored.h5", tmp_path / "sun.h5", tmp_path / "relit.h5",
            rotate=90.0)
    relit, stored, plain = (read_bake(tmp_path / n).radiance
                            for n in ("relit.h5", "b_stored.h5", "b_plain.h5"))
    top = float(np.max(np.abs(stored)))
    # the sun's gain acts in the plain bake (the test sees the sky-dependent part)
    assert np.max(np.abs(plain - stored)) > 1e-3 * top
    # float32 shading of the same visibility, as the tests above
    np.testing.assert_allclose(relit, stored, rtol=1e-4, atol=1e-6 * top)


@pytest.mark.parametrize("moving", ["all"])
def test_relight_says_when_its_lamps_are_not_the_baked_ones(baked_a, tmp_path, run_cli):
    """A stored visibility keeps where the bake's lamps were (a hidden lamp's long shadow
    stays traced for them): relit with a lamp moved elsewhere, the command says so in
    one warning line; with the bake's own lamps, a recoloured one, or a bake that
    recorded none, it says nothing."""
    scene_a, bake_a = baked_a
    moved = tmp_path / "moved.toml"
    moved.write_text(scene_a.read_text().replace("position = [1.0, 2.5, 0.5]",
                                                 "position = [-2.0, 1.5, 0.5]"))
    warm = tmp_path / "warm.toml"
    warm.write_text(scene_a.read_text().replace("color = [6.0, 5.0, 4.0]",
                                                "color = [9.0, 5.0, 2.0]"))
    old = _older(bake_a, tmp_path / "old.h5")
    said = {}
    for name, bake, scene in (("moved", bake_a, moved), ("own", bake_a, scene_a),
                              ("warm", bake_a, warm), ("older", old, moved)):
        code, _, stderr = run_cli("relight", bake, "--light", tmp_path / "b.h5",
                                  "--lights", scene, "-o", tmp_path / f"{name}.h5")
        assert code == 0, stderr
        said[name] = [line for line in stderr.splitlines() if line.startswith("warning:")]
    assert len(said["moved"]) == 1 and str(bake_a) in said["moved"][0]
    assert said["own"] == said["warm"] == said["older"] == []
    assert relight(bake_a, tmp_path / "b.h5", tmp_path / "py.h5",
                   scene=moved)["lamps_as_baked"] is False


def test_lamps_as_baked_matches_each_lamp_to_a_recorded_one():
    """Lamps in another order, or some left out, are the baked ones; a moved or resized
    one is not; a relit bake's record (its relit lamps) and a bake without one cannot
    say."""
    from types import SimpleNamespace

    from shtools.runtime import SphereLight
    from shtools.scene.light_record import lamps_as_baked, pose_table

    def lamp(x, r=0.3, c=1.0):
        return SphereLight(position=np.array([x, 2.0, 0.0]), radius=r,
                           color=np.array([c, c, c]))

    baked = [[lamp(0.0), lamp(1.0)], [lamp(0.5), lamp(1.5)]]  # two frames, two lamps
    bake = SimpleNamespace(light_poses=pose_table(baked), parameters={})

    def check(frames, of=bake):
        return lamps_as_baked(of, pose_table(frames))

    assert check([[lamp(1.0), lamp(0.0, c=5.0)], [lamp(1.5), lamp(0.5)]]) is True
    assert check([[lamp(1.0)], [lamp(1.5)]]) is True
    assert check([[], []]) is True
    assert check([[lamp(0.0), lamp(1.2)], [lamp(0.5), lamp(1.5)]]) is False
    assert check([[lamp(0.0, r=0.4), lamp(1.0)], [lamp(0.5), lamp(1.5)]]) is False
    assert check([[lamp(0.0), lamp(1.0), lamp(3.0)], [lamp(0.5), lamp(1.5), lamp(3.0)]]) \
        is False
    relit = SimpleNamespace(light_poses=bake.light_poses, parameters={"relight": {}})
    assert check(baked, relit) is None
    assert check(baked, SimpleNamespace(light_poses=None, parameters={})) is None
