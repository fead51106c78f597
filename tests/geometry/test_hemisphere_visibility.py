"""Per-frame self-visibility over each vertex's hemisphere (skinned objects):
against a closed form and the reference ray tracer."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.geometry.raycast import RayCaster
from shtools.geometry.visibility import (
    hemisphere_directions,
    hemisphere_visibility,
    tangent_frames,
)
from shtools.reference import raytrace_visibility


def test_directions_and_frames():
    d = hemisphere_directions(40)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert (d[:, 2] > 0).all()
    # equal-area bands: the mean height of a uniform hemisphere is 1/2
    assert d[:, 2].mean() == pytest.approx(0.5, abs=1e-12)
    rng = np.random.default_rng(1)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[0] = [0, 0, -1]  # the construction's special case
    t1, t2 = tangent_frames(n)
    frames = np.stack([t1, t2, n], axis=1)
    np.testing.assert_allclose(frames @ frames.transpose(0, 2, 1), np.broadcast_to(np.eye(3),
                               frames.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(frames), 1.0, atol=1e-12)


def _square_above(h: float, a: float):
    """A square of half-size ``a`` at height ``h`` above the origin (two triangles)."""
    v = np.array([[-a, -a, h], [a, -a, h], [a, a, h], [-a, a, h]], float)
    return trimesh.Trimesh(v, [[0, 1, 2], [0, 2, 3]], process=False)


def test_constant_term_matches_the_solid_angle_of_a_square():
    """A point under a square of half-size a at height h: the square blocks the solid
    angle 4 asin(a^2 / (a^2 + h^2)), so g_0 = (4 pi - Omega) / sqrt(4 pi)."""
    h, a = 1.0, 1.0
    omega = 4.0 * math.asin(a * a / (a * a + h * h))  # 2 pi / 3
    want = (4.0 * math.pi - omega) / math.sqrt(4.0 * math.pi)
    caster = RayCaster.from_meshes(_square_above(h, a))
    errors = []
    for n_dirs in (32, 512, 8192):
        g = hemisphere_visibility([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], caster, 3,
                                  n_dirs=n_dirs, offset=0.0)
        errors.append(abs(g[0, 0] - want))
    # each direction stands for 2 pi / n of solid angle and the square's edges cut about
    # sqrt(n) of the cells (measured 1.8e-2, 1.2e-3, 2.9e-4; g_0 is 2.95): a few times
    # the measured error, and it must keep falling with n
    assert errors[0] < 0.04
    assert errors[1] < 3e-3
    assert errors[2] < 1e-3
    assert errors[2] < errors[1] < errors[0]


def test_unblocked_vertices_get_exactly_the_constant_one():
    sphere = trimesh.creation.icosphere(2)
    caster = RayCaster.from_meshes(sphere)
    g = hemisphere_visibility(sphere.vertices, sphere.vertex_normals, caster, 4, n_dirs=16)
    want = np.zeros(16)
    want[0] = math.sqrt(4.0 * math.pi)
    # a convex mesh blocks no direction above its tangent planes: no quadrature at all
    np.testing.assert_array_equal(g, np.broadcast_to(want, g.shape))


def test_matches_the_reference_ray_tracer_on_a_torus():
    torus = trimesh.creation.torus(major_radius=0.6, minor_radius=0.3, major_sections=24,
                                   minor_sections=12)
    v, n = np.asarray(torus.vertices), np.asarray(torus.vertex_normals)
    ref = raytrace_visibility(v, n, [torus], 4, 12000)
    caster = RayCaster.from_meshes(torus)
    err = {}
    for n_dirs in (32, 256):
        g = hemisphere_visibility(v, n, caster, 4, n_dirs=n_dirs)
        err[n_dirs] = np.linalg.norm(g - ref) / np.linalg.norm(ref)
    # quadrature error of the binary visibility across the inner ring's shadow
    # boundaries: measured 4.8 % with 32 directions, 0.85 % with 256 (the reference's
    # own error at 12,000 directions: ~0.3 %; 3,200 vs 12,000 differ by 0.64 %)
    assert err[32] < 0.06
    assert err[256] < 0.012
    assert err[256] < 0.3 * err[32]


# -- receivers outside the mesh: rays only in the cone of its bounding sphere ------------


def _square_cone(normal, n_dirs):
    """g of a point at the origin under a square of half-size 0.5 at height 2, traced in
    the cone of the square's bounding sphere (centre (0, 0, 2), radius sqrt(0.5))."""
    from shtools.geometry.visibility import cone_visibility

    caster = RayCaster.from_meshes(_square_above(2.0, 0.5))
    return cone_visibility([[0.0, 0.0, 0.0]], [normal], caster, [0.0, 0.0, 2.0],
                           math.sqrt(0.5), 3, n_dirs=n_dirs, offset=0.0)


def test_cone_constant_term_matches_the_solid_angle_of_a_square():
    """g_0 = (4 pi - Omega) / sqrt(4 pi) with the square's closed-form solid angle; a
    receiver whose tangent plane halves the square sees Omega / 2 (by symmetry)."""
    omega = 4.0 * math.asin(0.25 / (0.25 + 4.0))  # 0.235 sr
    errors = {}
    for normal, blocked in (([0.0, 0.0, 1.0], omega), ([1.0, 0.0, 0.0], 0.5 * omega)):
        want = (4.0 * math.pi - blocked) / math.sqrt(4.0 * math.pi)
        errors[tuple(normal)] = [abs(_square_cone(normal, n)[0, 0] - want)
                                 for n in (64, 1024, 16384)]
    # the cone (half-angle 20.7 deg, 0.41 sr) holds k = 0.41 n / 2 pi rays (at least 4),
    # each standing for 0.41 sr / k, and the square's edges cut about sqrt(k) of the
    # cells (measured 2.1e-2 / 5.3e-3 / 4.7e-4 facing the square, half that tilted; g_0
    # is 3.48): about twice the measured error, and it must keep falling with n
    for e in errors.values():
        assert e[0] < 0.04
        assert e[1] < 0.011
        assert e[2] < 1e-3
        assert e[2] < e[1] < e[0]


def test_cone_outside_the_sphere_or_below_the_plane_is_exactly_unblocked():
    from shtools.geometry.visibility import bounding_cones, cone_visibility

    square = _square_above(2.0, 0.5)
    caster = RayCaster.from_meshes(square)
    # facing away from the square: the sphere is wholly below the tangent plane
    axis, cos_half = bounding_cones([[0.0, 0.0, 0.0]], [[0.0, 0.0, -1.0]], [0, 0, 2.0], 0.7)
    assert cos_half[0] == 1.0  # an empty cone: no ray is cast
    # beside the square, far: every ray of the cone misses (the square is seen edge-on)
    pts = [[0.0, 0.0, 0.0], [30.0, 0.0, 2.0]]
    g = cone_visibility(pts, [[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]], caster, [0, 0, 2.0],
                        math.sqrt(0.5), 4)
    want = np.zeros(16)
    want[0] = math.sqrt(4.0 * math.pi)
    np.testing.assert_array_equal(g, np.broadcast_to(want, g.shape))
    # inside the sphere the cone is the whole hemisphere about the normal
    axis, cos_half = bounding_cones([[0.1, 0.0, 2.0]], [[0.0, 1.0, 0.0]], [0, 0, 2.0], 0.7)
    np.testing.assert_array_equal(axis, [[0.0, 1.0, 0.0]])
    assert cos_half[0] == 0.0


def test_cone_visibility_matches_the_reference_ray_tracer_under_a_torus():
    """A ground grid under a tilted torus: every coefficient against the reference ray
    tracer over the whole sphere (12,000 directions), so the directions left out of the
    cones are indeed unblocked."""
    from shtools.geometry.visibility import cone_visibility

    torus = trimesh.creation.torus(major_radius=0.6, minor_radius=0.25, major_sections=24,
                                   minor_sections=12)
    torus.apply_transform(trimesh.transformations.rotation_matrix(0.7, [1, 0, 0]))
    torus.apply_translation([0.0, 0.0, 0.9])
    x, y = np.meshgrid(np.linspace(-2, 2, 13), np.linspace(-2, 2, 13))
    pts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    nrm = np.tile([0.0, 0.0, 1.0], (pts.shape[0], 1))
    ref = raytrace_visibility(pts, nrm, [torus], 4, 12000)
    caster = RayCaster.from_meshes(torus)
    v = np.asarray(torus.vertices)
    center = 0.5 * (v.min(axis=0) + v.max(axis=0))
    radius = float(np.linalg.norm(v - center, axis=1).max())
    errors = [np.linalg.norm(cone_visibility(pts, nrm, caster, center, radius, 4, n_dirs=n)
                             - ref) / np.linalg.norm(ref) for n in (64, 1024)]
    # relative error of all coefficients (measured 2.3 % at 64 rays a hemisphere, 0.32 %
    # at 1,024; the reference differs from one at 40,000 directions by 0.12 %)
    assert errors[0] < 0.04
    assert errors[1] < 0.006
    assert errors[1] < errors[0]
