"""Export: PLY/GLB readable back with colours, PNG previews, tone mapping, rasteriser."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from shtools.data_formats.bake import read_bake, write_bake
from shtools.export.raster import Camera, rasterize
from shtools.export.tonemap import aces, srgb_encode, tonemap
from shtools.scene.primitives import make_primitive


@pytest.fixture
def bake_file(tmp_path):
    """A plane with a radiance ramp along x over two frames (frame numbers 3, 4)."""
    prim = make_primitive("plane", {"size": [2.0, 2.0], "subdivisions": 8})
    v = np.asarray(prim.mesh.vertices)
    ramp = (v[:, 0] + 1.0) / 2.0  # 0 at x = -1 .. 1 at x = +1
    radiance = np.stack([np.stack([ramp, ramp, ramp], 1), np.stack([ramp, 0 * ramp, ramp], 1)])
    path = tmp_path / "baked.h5"
    write_bake(path, vertices=v, normals=prim.normals, faces=prim.mesh.faces,
               radiance=radiance, sh_order=2, frame_index=[3, 4], times=[0.1, 0.2])
    return path


def test_srgb_and_aces_closed_forms():
    # IEC 61966-2-1: 0.5 linear -> 0.7354 encoded; the linear toe below 0.0031308
    assert srgb_encode(np.array(0.5)) == pytest.approx(0.735357, abs=1e-6)
    assert srgb_encode(np.array(0.002)) == pytest.approx(0.002 * 12.92)
    # Narkowicz ACES fit at 1: 2.54 / 3.16
    assert aces(np.array(1.0)) == pytest.approx(2.54 / 3.16)
    assert tonemap(np.zeros(3), 1.0).tolist() == [0.0, 0.0, 0.0]


def test_ply_roundtrip_keeps_colours(bake_file, tmp_path, run_cli):
    out = tmp_path / "frame.ply"
    code, _, stderr = run_cli("export", bake_file, "--frame", 4, "-o", out, "--fixed-exposure")
    assert code == 0, stderr
    mesh = trimesh.load(out, process=False)
    bake = read_bake(bake_file)
    assert len(mesh.vertices) == bake.n_vertices
    # PLY stores float32 positions of unit-sized scenes: rounding ~1e-7
    np.testing.assert_allclose(mesh.vertices, bake.vertices, atol=1e-6)
    colors = mesh.visual.vertex_colors[:, :3].astype(float) / 255
    expected = srgb_encode(aces(bake.radiance[1]))
    np.testing.assert_allclose(colors, expected, atol=1 / 255 + 1e-9)  # 8-bit rounding
    assert np.all(mesh.visual.vertex_colors[:, 1] == 0)  # frame 4 has no green


def test_glb_roundtrip_keeps_colours_and_radiance(bake_file, tmp_path, run_cli):
    out = tmp_path / "frame.glb"
    code, _, stderr = run_cli("export", bake_file, "--frame", 3, "-o", out, "--fixed-exposure")
    assert code == 0, stderr
    mesh = trimesh.load(out, force="mesh", process=False, skip_materials=True)
    bake = read_bake(bake_file)
    # _RADIANCE is the bake's own float32 data written verbatim
    np.testing.assert_allclose(mesh.vertex_attributes["_RADIANCE"], bake.radiance[0], atol=1e-7)
    colors = mesh.visual.vertex_colors[:, :3].astype(float) / 255
    # glTF vertex colours are linear: the tone-mapped value before sRGB encoding
    np.testing.assert_allclose(colors, aces(bake.radiance[0]), atol=1 / 255 + 1e-9)


def test_png_preview_sheet_and_gif(bake_file, tmp_path, run_cli):
    from PIL import Image

    png = tmp_path / "f.png"
    code, _, stderr = run_cli("export", bake_file, "-o", png, "--size", 160, 120)
    assert code == 0, stderr
    with Image.open(png) as im:
        img = np.asarray(im)
    assert img.shape == (120, 160, 3)
    sheet = tmp_path / "sheet.png"
    code, _, stderr = run_cli("export", bake_file, "--frames", "3:5", "-o", sheet,
                              "--size", 80, 60, "--columns", 2)
    assert code == 0, stderr
    with Image.open(sheet) as im:
        assert np.asarray(im).shape == (60 + 8, 2 * 80 + 12, 3)
    gif = tmp_path / "a.gif"
    code, _, stderr = run_cli("export", bake_file, "-o", gif, "--size", 80, 60)
    assert code == 0, stderr
    with Image.open(gif) as im:
        assert im.n_frames == 2


def test_export_errors(bake_file, tmp_path, run_cli):
    for args, message in (
        (("--frame", 7, "-o", tmp_path / "x.png"), "frame 7 is not in this bake (it holds frames "
                                                   "3..4)"),
        (("-o", tmp_path / "x.obj"), "unsupported output format '.obj'"),
        (("--frames", "3:9", "-o", tmp_path / "x.ply"), "frame 5 is not in this bake"),
    ):
        code, _, stderr = run_cli("export", bake_file, *args)
        assert code == 1 and message in stderr, stderr
    assert list(tmp_path.glob("x.*")) == []
    code, _, stderr = run_cli("export", tmp_path / "missing.h5", "-o", tmp_path / "x.png")
    assert code == 1 and "file not found" in stderr


def test_rasterizer_covers_a_square_exactly_and_interpolates():
    """A 2x2 square facing a camera at distance 4 with a known field of view."""
    verts = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    colors = verts[:, :1] * 0.5 + 0.5  # 0 at x = -1, 1 at x = +1
    fov = 2 * np.arctan(0.5)  # the square spans half the image height at distance 4
    cam = Camera(eye=np.array([0.0, 0.0, 4.0]), target=np.zeros(3), fov_y=fov)
    img, cov = rasterize(verts, faces, colors, cam, 64, 64, supersample=1)
    # projected half-size: focal * 1 / 4 = (32 / tan(fov/2)) / 4 = 16 px -> 32x32 pixels
    assert cov.sum() == pytest.approx(32 * 32, abs=2)
    row = img[32, 16:48, 0]
    # colour follows x linearly (an affine attribute on a plane parallel to the image)
    expected = (np.arange(16, 48) + 0.5 - 32) / 16 * 0.5 + 0.5
    np.testing.assert_allclose(row, expected, atol=1e-9)
    # a nearer triangle hides the square (z-buffer)
    near = np.array([[-0.5, -0.5, 1.0], [0.5, -0.5, 1.0], [0.0, 0.5, 1.0]])
    img2, _ = rasterize(np.concatenate([verts, near]), np.concatenate([faces, [[4, 5, 6]]]),
                        np.concatenate([colors, np.full((3, 1), 7.0)]), cam, 64, 64,
                        supersample=1)
    assert img2[32, 32, 0] == pytest.approx(7.0)


def test_clip_negative_keeps_luminance_and_never_tints():
    from shtools.export.tonemap import LUMINANCE, clip_negative

    rgb = np.array([[-0.1, -0.06, 0.06],   # luminance < 0: a ringing shadow -> black
                    [0.5, -0.1, 0.2],      # luminance > 0, one negative channel
                    [0.2, 0.3, 0.4]])      # untouched
    out = clip_negative(rgb)
    np.testing.assert_array_equal(out[0], 0.0)
    assert out[1].min() >= 0.0 and np.isclose(out[1].min(), 0.0, atol=1e-12)
    # luminance preserved (exactly, up to rounding) where it was positive
    np.testing.assert_allclose(out[1:] @ LUMINANCE, rgb[1:] @ LUMINANCE, rtol=1e-12)
    np.testing.assert_array_equal(out[2], rgb[2])
