"""Mean value coordinates on closed triangle meshes (Ju et al. 2005)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from shtools.geometry.mvc import is_closed_surface, mean_value_coordinates

#: linear precision is exact in real arithmetic; the per-triangle formula divides
#: by sin(theta) and s_i, which costs a few digits near the surface (measured
#: <= 3e-10 relative to the mesh size on these meshes)
LINEAR_RTOL = 1e-8


def _bumpy_sphere():
    """Closed, non-convex, star-shaped about the origin."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    v = mesh.vertices
    r = 1.0 + 0.25 * np.sin(3 * v[:, 0]) * np.cos(2 * v[:, 1]) + 0.1 * v[:, 2] ** 2
    return v * r[:, None], mesh.faces


def _meshes():
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.4,
                                   major_sections=24, minor_sections=12)
    yield "torus", torus.vertices, torus.faces
    yield "bumpy", *_bumpy_sphere()
    box = trimesh.creation.box(extents=[2.0, 1.0, 0.5])
    yield "box", box.vertices, box.faces


@pytest.mark.parametrize("name,vertices,faces", list(_meshes()))
def test_linear_precision_inside_and_outside(name, vertices, faces):
    assert is_closed_surface(vertices, faces)
    rng = np.random.default_rng(0)
    lo, hi = vertices.min(0), vertices.max(0)
    points = rng.uniform(lo - 0.3, hi + 0.3, size=(150, 3))
    lam = mean_value_coordinates(points, vertices, faces)
    scale = np.linalg.norm(hi - lo)
    np.testing.assert_allclose(lam.sum(1), 1.0, atol=1e-12)
    np.testing.assert_allclose(lam @ vertices, points, atol=LINEAR_RTOL * scale)
    # any linear function of the vertices is reproduced at the point
    a, b = rng.normal(size=3), 0.7
    np.testing.assert_allclose(lam @ (vertices @ a + b), points @ a + b,
                               atol=LINEAR_RTOL * scale * np.abs(a).sum())


def test_points_on_the_surface():
    vertices, faces = _bumpy_sphere()
    # on a vertex: that vertex's indicator
    lam = mean_value_coordinates(vertices[[5, 40]], vertices, faces)
    want = np.zeros_like(lam)
    want[0, 5] = want[1, 40] = 1.0
    np.testing.assert_allclose(lam, want, atol=1e-12)
    # inside a face: that face's barycentric coordinates (independent: 2x2 solve)
    bary = np.array([0.2, 0.5, 0.3])
    f = faces[17]
    x = bary @ vertices[f]
    lam = mean_value_coordinates(x[None], vertices, faces)[0]
    np.testing.assert_allclose(lam[f], bary, atol=1e-9)
    assert np.abs(np.delete(lam, f)).max() < 1e-12
    # on an edge: the two edge end points only
    x = 0.25 * vertices[f[0]] + 0.75 * vertices[f[1]]
    lam = mean_value_coordinates(x[None], vertices, faces)[0]
    np.testing.assert_allclose(lam[f[:2]], [0.25, 0.75], atol=1e-9)


def test_points_just_off_the_surface_stay_precise():
    vertices, faces = _bumpy_sphere()
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    centers = mesh.triangles_center[:20]
    normals = mesh.face_normals[:20]
    for offset in (1e-4, 1e-7, -1e-7, -1e-4):
        x = centers + offset * normals
        lam = mean_value_coordinates(x, vertices, faces)
        # measured: 1e-12 at offset 1e-4; at 1e-7 the point is treated as on the face,
        # so the error equals the offset (~1e-7) -- the bound checks that snapping moves
        # a point by no more than its distance to the surface
        np.testing.assert_allclose(lam @ vertices, x, atol=1e-7)


def test_matches_ray_cast_integral_definition():
    """MVC weight of vertex i = integral over directions of b_i(u) / |p(u) - x|.

    Independent evaluation: rays from x over a Fibonacci sphere, hit points on
    a star-shaped mesh (one hit per ray), barycentric coordinates of the hit.
    """
    vertices, faces = _bumpy_sphere()
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    x = np.array([0.1, -0.05, 0.08])
    n = 60_000
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5**0.5) * k
    dirs = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], 1)
    loc, ray_idx, tri_idx = mesh.ray.intersects_location(np.tile(x, (n, 1)), dirs,
                                                         multiple_hits=False)
    assert len(ray_idx) == n
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[tri_idx], loc)
    dist = np.linalg.norm(loc - x, axis=1)
    w = np.zeros(len(vertices))
    np.add.at(w, faces[tri_idx], bary / dist[:, None])
    want = w / w.sum()
    lam = mean_value_coordinates(x[None], vertices, faces)[0]
    # Fibonacci quadrature (60k rays) of a piecewise-smooth integrand: measured
    # 1.3e-4 of the largest weight; 1e-3 leaves margin, a wrong formula is off by >1e-1
    assert np.abs(lam - want).max() < 1e-3 * want.max()
    assert np.all(lam > 0)  # inside a star-shaped mesh: positive weights


def test_open_mesh_is_detected():
    vertices, faces = _bumpy_sphere()
    assert not is_closed_surface(vertices, faces[:-3])
    # duplicated vertices (UV seams, per-face copies as in glTF) still count as closed
    unwelded = vertices[faces.reshape(-1)]
    assert is_closed_surface(unwelded, np.arange(unwelded.shape[0]).reshape(-1, 3))
