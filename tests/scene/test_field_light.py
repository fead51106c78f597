"""Field lights in scenes: ``[[lights]] field = "lamp.srf.h5"``, moving, nearer blockers only."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.data_formats.srf import write_radiance_field
from shtools.errors import InputError
from shtools.fields import FieldParameters
from shtools.fields.emitter import make_emitter
from shtools.fields.radiance import sample_radiance_field
from shtools.reference import relative_rmse
from shtools.reference.emitter import shaded_lamp, shadowed_and_free
from shtools.scene.bake import bake_scene
from shtools.scene.pose import pose_frame
from shtools.scene.prepare import prepare_scene
from shtools.scene.scene import parse_scene

GRID = 16  # ground subdivisions: (GRID + 1)^2 receivers


@pytest.fixture(scope="module")
def lamp_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("lamp")
    bulb, shade = shaded_lamp()
    em = make_emitter(bulb, (10.0, 9.0, 8.0), [shade])
    fld, _ = sample_radiance_field(em, FieldParameters(shells=32, resolution=16, map_size=12,
                                                       min_resolution=4), scheduler="inline")
    write_radiance_field(d / "lamp.srf.h5", fld)
    return d, em


def scene_text(extra_objects="", light_extra=""):
    return f"""
[settings]
order = 4
frames = 3
fps = 1

[[lights]]
name = "lamp"
field = "lamp.srf.h5"
position = [0.0, 1.2, 0.0]
rotate = [-90.0, 0.0, 0.0]    # the lamp's +z (its shade's narrow end) up
{light_extra}
[[lights.keyframes]]
frame = 0
position = [0.0, 1.2, 0.0]
[[lights.keyframes]]
frame = 2
position = [-0.4, 1.2, 0.1]
rotate = [-90.0, 0.0, 35.0]

[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [2.4, 2.4], subdivisions = {GRID} }}
role = "receiver"
{extra_objects}
"""


BALL = """
[[objects]]
name = "ball"
primitive = { type = "sphere", radius = 0.18, subdivisions = 3 }
role = "blocker"
translate = [0.15, 0.3, 0.1]
"""

LID = """
[[objects]]
name = "lid"
primitive = { type = "sphere", radius = 0.8, subdivisions = 3 }
role = "blocker"
translate = [0.0, 3.0, 0.0]
"""


def _parse(text, d):
    return parse_scene(text, d / "scene.toml")


def _against_ray_tracing(lamp_dir, light_extra=""):
    """Per frame: baked, baked without the ball, ray traced, ray traced without the ball."""
    d, em = lamp_dir
    scene = _parse(scene_text(BALL, light_extra), d)
    prep = prepare_scene(scene)
    alone = list(bake_scene(_parse(scene_text("", light_extra), d), scheduler="inline"))
    n = (GRID + 1) ** 2
    for frame, result in enumerate(bake_scene(scene, scheduler="inline")):
        st = pose_frame(prep, frame / scene.settings.fps, with_meshes=True)
        m = st.lights[0].matrix
        lamp_v = em.vertices @ m[:3, :3].T + m[:3, 3]
        pts, nrm = st.vertices[:n], st.normals[:n]
        ref, free = shadowed_and_free(pts, nrm, em, lamp_v, st.blocker_meshes,
                                      n_samples=4096)
        yield result.radiance[:n], alone[frame].radiance[:n], ref, free


def test_moving_shaded_lamp_over_a_blocker_matches_ray_tracing(lamp_dir):
    for got, got_free, ref, free in _against_ray_tracing(lamp_dir):
        # the field's unshadowed light (order-4 truncation ~3 %, the coarse test field's
        # interpolation) times the traced fraction of its emission past the ball
        # (64 strata): 4 % measured at this grid
        assert relative_rmse(got_free, free) < 0.065
        assert relative_rmse(got, ref) < 0.07
        shadow = (ref[:, 0] < 0.5 * free[:, 0]) & (free[:, 0] > 0.1 * free[:, 0].max())
        assert shadow.sum() >= 3
        # in the ball's shadow, the error relative to the light the ball takes away: a
        # product of order-4 SH leaves ~45 % of it (below), the traced fraction ~2 %
        err = np.linalg.norm(got[shadow] - ref[shadow]) / np.linalg.norm(free[shadow])
        assert err < 0.08


def test_the_sh_product_path_still_casts_the_ball_shadow(lamp_dir):
    for got, got_free, ref, free in _against_ray_tracing(lamp_dir, 'shadows = "shexp"'):
        # order-4 SH of the lamp and of the ball's visibility: the hard-edged shadow of
        # a 6-degree bulb is what order 4 cannot hold
        assert relative_rmse(got, ref) < 0.2
        assert relative_rmse(got_free, free) < 0.065  # as the field test, unshadowed
        # the shadow is where the ray tracer puts it: the ball takes most of the lamp's
        # light there and little elsewhere
        shadow = (ref[:, 0] < 0.5 * free[:, 0]) & (free[:, 0] > 0.1 * free[:, 0].max())
        clear = (ref[:, 0] > 0.99 * free[:, 0]) & (free[:, 0] > 0.1 * free[:, 0].max())
        assert shadow.sum() >= 3 and clear.sum() >= 3
        assert np.mean(got[shadow, 0] / got_free[shadow, 0]) < 0.7
        assert np.mean(got[clear, 0] / got_free[clear, 0]) > 0.85
        err = np.linalg.norm(got[shadow] - ref[shadow]) / np.linalg.norm(free[shadow])
        assert err > 0.2  # what the traced default removes


@pytest.mark.parametrize("way", ["", 'shadows = "shexp"'])
def test_a_blocker_beyond_the_lamp_does_not_shadow_its_light(lamp_dir, way):
    d, _ = lamp_dir
    alone = next(bake_scene(_parse(scene_text(light_extra=way), d), scheduler="inline")).radiance
    scene = _parse(scene_text(LID, way), d)
    with_lid = next(bake_scene(scene, scheduler="inline")).radiance
    # the lid is above the lamp, farther from every ground vertex: the lamp's light is
    # not multiplied by its visibility (only blockers nearer than the light count) ...
    np.testing.assert_allclose(with_lid, alone, rtol=1e-6, atol=1e-9)
    # ... although it stands right behind the lamp as the ground sees it: multiplied in,
    # the frame's visibility would take a good part of the lamp's light
    from shtools.data_formats.srf import read_radiance_field
    from shtools.runtime import ShadowRuntime
    from shtools.runtime.radiance import FieldLight, field_light_radiance

    st = pose_frame(prepare_scene(scene), 0.0)
    vis = ShadowRuntime(scene.settings).visibility(st.vertices, st.normals, st.blockers)
    light = FieldLight.from_matrix(read_radiance_field(d / "lamp.srf.h5"), st.lights[0].matrix)
    all_blockers = field_light_radiance(light, vis, st.vertices, st.normals, order=4,
                                        window_kind=scene.settings.resolved_window(),
                                        window_h=scene.settings.window_h)
    assert relative_rmse(all_blockers, alone) > 0.1


def test_field_light_keys_are_checked(lamp_dir):
    d, _ = lamp_dir
    lamp = _parse(scene_text(), d).lights[0]
    assert (lamp.shadows, lamp.samples) == ("field", 256)  # traced, the field's default
    lamp = _parse(scene_text(light_extra='shadows = "raytrace"\nsamples = 16'), d).lights[0]
    assert (lamp.shadows, lamp.samples) == ("field", 16)
    assert _parse(scene_text(light_extra='shadows = "shexp"'), d).lights[0].shadows \
        == "field-shexp"
    with pytest.raises(InputError, match=r"lights\[0\].radius: 'radius' does not apply"):
        _parse(scene_text(light_extra="radius = 0.2"), d)
    bad = scene_text().replace('field = "lamp.srf.h5"', 'field = "nope.srf.h5"')
    with pytest.raises(InputError, match=r"nope\.srf\.h5' not found"):
        _parse(bad, d)
    sphere = """
[[lights]]
position = [0, 2, 0]
radius = 0.2
color = [1, 1, 1]
shadows = "field"
[[objects]]
name = "ground"
primitive = "plane"
role = "receiver"
"""
    with pytest.raises(InputError, match=r"shadows: must be one of shexp, ssoc, raytrace"):
        _parse(sphere, d)
    with pytest.raises(InputError, match=r"lights\[0\]\.shadows: a field light takes "
                                         r"shadows = 'raytrace' .* or 'shexp'.*got 'ssoc'"):
        _parse(scene_text(light_extra='shadows = "ssoc"'), d)


def test_a_version_1_lamp_asset_needs_the_product_path(lamp_dir, tmp_path):
    import h5py

    from shtools.errors import AssetError

    d, _ = lamp_dir
    old = tmp_path / "lamp.srf.h5"
    old.write_bytes((d / "lamp.srf.h5").read_bytes())
    with h5py.File(old, "r+") as f:  # as the format's first version wrote it
        for name in ("lamp_vertices", "lamp_faces", "lamp_emissive"):
            del f[name]
        f.attrs["format_version"] = 1
    with pytest.raises(AssetError, match=r"lamp\.srf\.h5.*no lamp mesh.*shadows = \"shexp\""):
        next(bake_scene(_parse(scene_text(BALL), tmp_path), scheduler="inline"))
    product = next(bake_scene(_parse(scene_text(BALL, 'shadows = "shexp"'), tmp_path),
                              scheduler="inline")).radiance
    want = next(bake_scene(_parse(scene_text(BALL, 'shadows = "shexp"'), d),
                           scheduler="inline")).radiance
    np.testing.assert_allclose(product, want, rtol=1e-6, atol=1e-9)


def test_a_lamp_inside_a_closed_receiver_is_refused(lamp_dir):
    d, _ = lamp_dir
    room = """
[[objects]]
name = "room"
primitive = { type = "box", extents = [3.0, 3.0, 3.0], subdivisions = 2, center = [0.0, 1.0, 0.0] }
role = "receiver"
"""
    scene = _parse(scene_text(room), d)
    with pytest.raises(InputError, match="the lamp is inside the receiver 'room'"):
        next(bake_scene(scene, scheduler="inline"))


@pytest.mark.parametrize("way", ["", 'shadows = "shexp"'])
def test_field_light_combines_with_a_shadow_field_blocker(lamp_dir, tmp_path, way):
    import trimesh

    from shtools.data_formats.field import write_field
    from shtools.fields import FieldParameters as FP
    from shtools.fields import sample_field

    d, _ = lamp_dir
    ball = trimesh.creation.icosphere(3, radius=0.18)
    fld, _ = sample_field(ball, FP(shells=32, resolution=8, map_size=16, min_resolution=4),
                          scheduler="inline")
    write_field(d / "ball.field.h5", fld)
    ball_obj = d / "ball.obj"
    ball.export(ball_obj)
    fielded = BALL.replace('primitive = { type = "sphere", radius = 0.18, subdivisions = 3 }',
                           'mesh = "ball.obj"\nblocker = { field = "ball.field.h5" }')
    exact = next(bake_scene(_parse(scene_text(BALL, way), d), scheduler="inline")).radiance
    with_field = next(bake_scene(_parse(scene_text(fielded, way), d), scheduler="inline")).radiance
    alone = next(bake_scene(_parse(scene_text(light_extra=way), d), scheduler="inline")).radiance
    n = (GRID + 1) ** 2
    # the same ball as an exact sphere and as a coarse shadow field (8 x 8 shells, 16 x 16
    # maps) casts nearly the same shadow of the lamp (3 % apart measured with "shexp";
    # traced, both are the ball's mesh); it takes ~8 % of the lamp's light off the ground
    assert relative_rmse(with_field[:n], exact[:n]) < 0.06
    assert with_field[:n, 0].sum() < 0.95 * alone[:n, 0].sum()
    lid = LID.replace('primitive = { type = "sphere", radius = 0.8, subdivisions = 3 }',
                      'mesh = "ball.obj"\nscale = 4.0\nblocker = { field = "ball.field.h5" }')
    above = next(bake_scene(_parse(scene_text(lid, way), d), scheduler="inline")).radiance
    np.testing.assert_allclose(above, alone, rtol=1e-6, atol=1e-9)  # beyond the lamp
