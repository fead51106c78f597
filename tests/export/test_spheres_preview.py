"""``shtools spheres preview``: a PNG of the spheres over the mesh and a GLB for a DCC."""

from __future__ import annotations

import math

import numpy as np
import pygltflib
import pytest
import trimesh

from shtools.data_formats.spheres import write_spheres
from shtools.geometry.sphere_set import SphereSet


@pytest.fixture
def assets(tmp_path):
    box = trimesh.creation.box(extents=[0.6, 0.6, 0.6])
    mesh_path = tmp_path / "box.obj"
    box.export(mesh_path)
    centers = np.array([[0.0, 0.0, 0.0], [2.0, 0.5, -1.0]])
    radii = np.array([0.6, 0.25])
    path = tmp_path / "s.h5"
    write_spheres(path, SphereSet(centers, radii, outside_volume_ratio=1.0, coverage=1.0,
                                  method="octree", info={}))
    return mesh_path, path, centers, radii


def test_png_shows_each_sphere_at_its_projected_size(run_cli, assets, tmp_path):
    from PIL import Image

    from shtools.export.raster import fit_camera
    from shtools.export.spheres import BACKGROUND, _spheres_mesh
    from shtools.export.tonemap import srgb_encode

    mesh_path, spheres_path, centers, radii = assets
    out = tmp_path / "p.png"
    code, _, stderr = run_cli("spheres", "preview", mesh_path, spheres_path, "-o", out,
                              "--size", 320, 240, "--elevation", 0, "--azimuth", 0)
    assert code == 0, stderr
    img = np.asarray(Image.open(out)).astype(int)
    assert img.shape == (240, 640, 3)
    left = img[:, :320]
    bg = np.round(srgb_encode(BACKGROUND) * 255).astype(int)
    drawn = np.any(np.abs(left - bg) > 2, axis=2)
    # the same camera as the renderer (it frames mesh + sphere meshes together);
    # a sphere of angular radius a seen at angle t off the optical axis projects to
    # an ellipse of area pi f^2 sin^2(a) cos(a) / (cos^2(t) - sin^2(a))^(3/2)
    sv = _spheres_mesh(centers, radii)[0]
    box = trimesh.load(mesh_path, force="mesh")
    cam = fit_camera(np.vstack([box.vertices, sv]), elevation=0.0, azimuth=0.0,
                     aspect=320 / 240)
    focal = 120 / math.tan(cam.fov_y / 2)
    area = 0.0
    axis = (cam.target - cam.eye) / np.linalg.norm(cam.target - cam.eye)
    for c, r in zip(centers, radii, strict=True):
        d = np.linalg.norm(c - cam.eye)
        sin_a = r / d
        cos_t = np.dot(c - cam.eye, axis) / d
        area += (math.pi * focal ** 2 * sin_a ** 2 * math.sqrt(1 - sin_a ** 2)
                 / (cos_t ** 2 - sin_a ** 2) ** 1.5)
    # spheres drawn as level-2 icospheres (inscribed polyhedron: ~1.5 % less area),
    # anti-aliased edge pixels count as drawn (+~1 %); the discs do not overlap in
    # this view and the box is inside sphere 0
    assert drawn.sum() == pytest.approx(area, rel=0.03)


def test_glb_has_a_node_per_sphere(run_cli, assets, tmp_path, khronos):
    mesh_path, spheres_path, centers, radii = assets
    out = tmp_path / "p.glb"
    code, _, stderr = run_cli("spheres", "preview", mesh_path, spheres_path, "-o", out)
    assert code == 0, stderr
    gltf = pygltflib.GLTF2().load(str(out))
    assert [n.name for n in gltf.nodes] == ["box", "sphere_0", "sphere_1"]
    for k in range(2):
        node = gltf.nodes[1 + k]
        np.testing.assert_allclose(node.translation, centers[k])
        np.testing.assert_allclose(node.scale, [radii[k]] * 3)
        assert gltf.materials[gltf.meshes[node.mesh].primitives[0].material].alphaMode == "BLEND"
    issues = khronos(out)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]


def test_preview_refuses_other_assets(run_cli, assets, tmp_path):
    mesh_path, spheres_path, *_ = assets
    code, _, stderr = run_cli("spheres", "preview", mesh_path, spheres_path, "-o",
                              tmp_path / "p.jpg")
    assert code == 1 and "use .png or .glb" in stderr
