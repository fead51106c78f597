"""Scenes with an all-frequency field, ``blocker = { field = "x.haar.h5" }``, mixed with an
SH blocker, against ray tracing of the real meshes under a small bright sun."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.reference.metrics import relative_rmse

HAAR_ARGS = ("--basis", "haar", "--shells", 12, "--resolution", 16, "--map", 32,
             "--min-resolution", 4, "--keep", 0.1)
SH_ARGS = ("--shells", 12, "--resolution", 16, "--map", 32, "--min-resolution", 4,
           "--no-self-visibility")
BOX = (0.8, 0.5, 0.6)


def sun_image(height=32):
    """A dim sky and a bright sun patch 50 degrees up (Y-up lat-long)."""
    from shtools.lighting.latlong import latlong_directions

    d = latlong_directions(height, 2 * height)
    sun = np.array([0.5, math.sin(math.radians(50)), 0.3])
    sun /= np.linalg.norm(sun)
    img = np.where((d @ sun > math.cos(math.radians(9)))[..., None], 60.0, 0.0) + \
        np.where(d[..., 1:2] > 0, [0.3, 0.4, 0.6], [0.05, 0.05, 0.05])
    return img.astype(np.float32)


SECOND_BOX = """
[[objects]]
name = "box2"
mesh = "box.obj"
role = "blocker"
translate = [0.2, 0.4, -0.9]
blocker = { field = "box.haar.h5" }
"""


def scene_text(field="box.haar.h5", sphere=True):
    ball = """
[[objects]]
name = "ball"
primitive = { type = "sphere", radius = 0.25 }
role = "blocker"
translate = [-0.7, 0.35, 0.5]
""" if sphere else ""
    return f"""
[settings]
order = 4
[environment]
image = "sun.hdr"
[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [3.0, 3.0], subdivisions = 16 }}
role = "receiver"
[[objects]]
name = "box"
mesh = "box.obj"
role = "blocker"
translate = [0.1, 0.45, 0.0]
rotate = [0, 30, 0]
blocker = {{ field = "{field}" }}
{ball}"""


@pytest.fixture(scope="module")
def haar_dir(tmp_path_factory):
    from shtools.cli.main import main
    from shtools.demo import write_hdr

    d = tmp_path_factory.mktemp("haarscene")
    trimesh.creation.box(extents=BOX).export(d / "box.obj")
    write_hdr(d / "sun.hdr", sun_image())
    assert main(["field", "sample", str(d / "box.obj"), "-o", str(d / "box.haar.h5"),
                 *map(str, HAAR_ARGS)]) == 0
    assert main(["field", "sample", str(d / "box.obj"), "-o", str(d / "box.field.h5"),
                 *map(str, SH_ARGS)]) == 0
    return d


def _bake(path, method=None):
    from shtools.scene.bake import bake_scene
    from shtools.scene.scene import load_scene

    return next(iter(bake_scene(load_scene(path), method=method, processes=1)))


def _traced_reference(frame, sphere: bool, image, second_box: bool = False):
    """Per-pixel quadrature of the lat-long sun image, one shadow ray per pixel through the
    posed real meshes (the box rotated 30 degrees about +y, the ball as a fine icosphere)."""
    from shtools.geometry.raycast import RayCaster
    from shtools.lighting.latlong import latlong_directions, pixel_solid_angles

    box = trimesh.creation.box(extents=BOX)
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    box.vertices = box.vertices @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]).T + [0.1, 0.45, 0]
    meshes = [box]
    if second_box:
        meshes.append(trimesh.creation.box(extents=BOX).apply_translation([0.2, 0.4, -0.9]))
    if sphere:
        meshes.append(trimesh.creation.icosphere(5, 0.25).apply_translation([-0.7, 0.35, 0.5]))
    both = trimesh.util.concatenate(meshes)
    H, W = image.shape[:2]
    dirs = latlong_directions(H, W).reshape(-1, 3)
    w = pixel_solid_angles(H, W).reshape(-1)
    vis = RayCaster(both.vertices, both.faces).visibility(frame.vertices, dirs,
                                                          normals=frame.normals)
    cos = np.maximum(frame.normals @ dirs.T, 0)
    return (vis * cos * w) @ image.reshape(-1, 3).astype(np.float64) / math.pi


@pytest.mark.parametrize("sphere,method", [(False, None), (True, None), (True, "product")])
def test_haar_blocker_bake_matches_ray_tracing_under_a_sun(haar_dir, sphere, method):
    (haar_dir / "scene.toml").write_text(scene_text(sphere=sphere))
    frame = _bake(haar_dir / "scene.toml", method=method)
    ref = _traced_reference(frame, sphere, sun_image())
    err = relative_rmse(frame.radiance, ref)
    # 32 x 32 maps, 10 % kept, R = 16 on 12 shells, nearest-cell resampling of the rotated
    # box's maps: measured 4.8 %; the ball's shadow is its order-4 SH cap on the cells,
    # soft under the sun: measured 7.4 % with it
    assert err < (0.10 if sphere else 0.07), err
    # the shadows are there: the reference without any blocker is clearly brighter
    free = (np.maximum(frame.normals @ _dirs().T, 0) * _w()) @ \
        sun_image().reshape(-1, 3).astype(np.float64) / math.pi
    assert relative_rmse(free, ref) > 3 * err


def _dirs():
    from shtools.lighting.latlong import latlong_directions

    return latlong_directions(32, 64).reshape(-1, 3)


def _w():
    from shtools.lighting.latlong import pixel_solid_angles

    return pixel_solid_angles(32, 64).reshape(-1)


def test_two_haar_blockers_multiply_like_ray_tracing_of_both(haar_dir):
    (haar_dir / "two.toml").write_text(scene_text(sphere=False) + SECOND_BOX)
    frame = _bake(haar_dir / "two.toml")
    ref = _traced_reference(frame, False, sun_image(), second_box=True)
    one = _traced_reference(frame, False, sun_image())
    err = relative_rmse(frame.radiance, ref)
    # as one box (4.8 %), the two shadows multiplied cell by cell: measured 5.8 %
    assert err < 0.08, err
    # the second box's shadow is there (the one-box reference is much further off)
    assert relative_rmse(one, ref) > 2 * err


def test_haar_field_with_an_sh_field_and_a_sphere_matches_ray_tracing_of_all(haar_dir):
    text = scene_text(sphere=True) + SECOND_BOX.replace("box.haar.h5", "box.field.h5")
    (haar_dir / "mixed.toml").write_text(text)
    frame = _bake(haar_dir / "mixed.toml")
    ref = _traced_reference(frame, True, sun_image(), second_box=True)
    only_haar = _traced_reference(frame, True, sun_image())
    err = relative_rmse(frame.radiance, ref)
    # the SH field's and the ball's shadows are order-4 SH on the cells (soft under the
    # sun), the Haar box's all-frequency: measured 10.2 % (14.0 % with both boxes SH fields)
    assert err < 0.13, err
    # the SH field's shadow is multiplied in (without it the error is far larger)
    assert relative_rmse(only_haar, ref) > 2 * err


def test_haar_beats_the_sh_field_of_the_same_shells_under_the_sun(haar_dir):
    (haar_dir / "sh.toml").write_text(scene_text("box.field.h5", sphere=False))
    (haar_dir / "haar.toml").write_text(scene_text(sphere=False))
    sh, haar = _bake(haar_dir / "sh.toml"), _bake(haar_dir / "haar.toml")
    ref = _traced_reference(haar, False, sun_image())
    # measured 4.8 % (Haar) vs 9.8 % (order-4 SH field of the same shells and maps)
    assert relative_rmse(haar.radiance, ref) < 0.6 * relative_rmse(sh.radiance, ref)


def test_cell_and_triple_product_schemes_agree(haar_dir, monkeypatch):
    import shtools.scene.haar_blocker as hb

    (haar_dir / "scene.toml").write_text(scene_text(sphere=True))
    monkeypatch.setattr(hb, "SCHEME", "cells")
    cells = _bake(haar_dir / "scene.toml").radiance
    monkeypatch.setattr(hb, "SCHEME", "triple")
    triple = _bake(haar_dir / "scene.toml").radiance
    # the same finite sum (pixel domain vs tripling coefficients): rounding only, of the
    # float32 lit transfer the triple product keeps (measured 7e-7 relative at most)
    np.testing.assert_allclose(triple, cells, rtol=1e-5, atol=1e-6)


def test_raytrace_method_traces_the_haar_object_too(haar_dir):
    (haar_dir / "scene.toml").write_text(scene_text(sphere=False))
    traced = _bake(haar_dir / "scene.toml", method="raytrace")
    ref = _traced_reference(traced, False, sun_image())
    # SH order 4 of ray-traced visibility and of the image: low-frequency, but shadowed
    free = (np.maximum(traced.normals @ _dirs().T, 0) * _w()) @ \
        sun_image().reshape(-1, 3).astype(np.float64) / math.pi
    assert traced.radiance[:, 1].mean() < free[:, 1].mean() - 0.5 * (free - ref)[:, 1].mean()


def test_bad_haar_scenes_give_one_line(haar_dir, run_cli):
    bad = haar_dir / "bad.haar.h5"
    bad.write_bytes(b"not an hdf5 file")
    (haar_dir / "bad.toml").write_text(scene_text("bad.haar.h5", sphere=False))
    code, _, err = run_cli("bake", haar_dir / "bad.toml", "-o", haar_dir / "bad_out.h5")
    assert code not in (0, 3) and len(err.strip().splitlines()) == 1 and "bad.haar.h5" in err
    assert not (haar_dir / "bad_out.h5").exists()
    text = scene_text(sphere=False).replace("[environment]", "[environment]\nradius = 20.0")
    (haar_dir / "mid.toml").write_text(text)
    code, _, err = run_cli("bake", haar_dir / "mid.toml", "-o", haar_dir / "mid_out.h5")
    assert code not in (0, 3) and len(err.strip().splitlines()) == 1 and "infinity" in err, err
    assert not (haar_dir / "mid_out.h5").exists()


def test_auto_takes_the_triple_product_for_one_unrotated_field_on_a_plane(haar_dir,
                                                                         monkeypatch):
    import shtools.scene.haar_blocker as hb

    text = scene_text(sphere=False).replace("rotate = [0, 30, 0]\n", "")
    (haar_dir / "plain.toml").write_text(text)
    picked = []
    real = hb._triple_is_faster
    monkeypatch.setattr(hb, "_triple_is_faster", lambda *a: picked.append(real(*a)) or real(*a))
    auto = _bake(haar_dir / "plain.toml").radiance
    assert picked == [True]
    monkeypatch.setattr(hb, "SCHEME", "cells")
    cells = _bake(haar_dir / "plain.toml").radiance
    # float32 lit transfer of the triple product: rounding only
    np.testing.assert_allclose(auto, cells, rtol=1e-5, atol=1e-6)


LIGHT = """
[[lights]]
position = [0.3, 2.5, 0.2]
radius = 0.3
color = [5.0, 5.0, 5.0]
"""


def test_a_spherical_light_sees_the_haar_field_projected_to_sh(haar_dir):
    def light_only(field):
        text = scene_text(field, sphere=False)
        head, rest = text.split("[environment]\nimage = \"sun.hdr\"\n")
        return head + rest + LIGHT

    for name, field in (("lh", "box.haar.h5"), ("ls", "box.field.h5")):
        (haar_dir / f"{name}.toml").write_text(light_only(field))
    haar, sh = _bake(haar_dir / "lh.toml"), _bake(haar_dir / "ls.toml")
    free_text = light_only("box.haar.h5").replace('role = "blocker"\ntranslate = [0.1',
                                                  'role = "receiver"\ntranslate = [0.1')
    free_text = free_text.replace('blocker = { field = "box.haar.h5" }', "")
    (haar_dir / "lf.toml").write_text(free_text)
    free = _bake(haar_dir / "lf.toml").radiance[: len(haar.radiance)]
    ground = slice(0, 289)
    # order-4 SH of the box's visibility from the Haar maps (10 % kept, nearest-cell
    # resampled for the rotation) vs the SH field's exact projection and rotation:
    # measured 4.9 % apart, both shadowing (ground 0.83 / 0.80 of unshadowed)
    assert relative_rmse(haar.radiance[ground], sh.radiance[ground]) < 0.08
    assert haar.radiance[ground].mean() < 0.9 * free[ground].mean()


@pytest.mark.parametrize("rotate", [0.0, 70.0])
def test_environment_cells_project_to_the_scenes_environment_sh(haar_dir, rotate):
    from shtools.runtime.haar_shading import map_directions
    from shtools.scene.bake import prepare_scene
    from shtools.scene.haar_blocker import environment_cells
    from shtools.scene.scene import load_scene
    from shtools.scene.shadows import BakeRun
    from shtools.sh import basis

    text = scene_text(sphere=False).replace('image = "sun.hdr"',
                                            f'image = "sun.hdr"\nrotate_deg = {rotate}\n'
                                            'intensity = 2.0')
    (haar_dir / "rot.toml").write_text(text)
    prepared = prepare_scene(load_scene(haar_dir / "rot.toml"), cache=False)
    cells = environment_cells(BakeRun(prepared, None, "default"), 64)
    dirs, w = map_directions(64)
    got = (basis(dirs, 4) * w[:, None]).T @ cells
    # the image binned into 64 x 64 cells vs projected per pixel (the SH path, with its own
    # rotation and intensity): the same low-order moments up to the binning (< 1 %)
    np.testing.assert_allclose(got, prepared.env_sh, atol=0.01 * np.abs(prepared.env_sh).max())


def test_relighting_a_bake_with_haar_blockers_is_refused_in_one_line(haar_dir, run_cli):
    # the stored SH visibility leaves the Haar field's shadow out: a relight would
    # silently shade the box as if it cast none
    (haar_dir / "store.toml").write_text(scene_text(sphere=False))
    baked, light, out = (haar_dir / n for n in ("store.h5", "light.h5", "relit.h5"))
    assert run_cli("bake", haar_dir / "store.toml", "-o", baked, "--store-visibility")[0] == 0
    assert run_cli("light", "project", haar_dir / "sun.hdr", "-n", 4, "-o", light)[0] == 0
    code, _, err = run_cli("relight", baked, "--light", light, "-o", out)
    assert code not in (0, 3) and len(err.strip().splitlines()) == 1, err
    assert "all-frequency" in err and "box" in err and "store.h5" in err
    assert not out.exists()
