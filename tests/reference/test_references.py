"""References: ray tracing of meshes and sphere unions, product-space accumulation."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.reference import (
    product_space_visibility,
    raytrace_visibility,
    relative_rmse,
    sphere_union_visibility,
)
from shtools.sh import cap, product

UP = np.array([0.0, 1.0, 0.0])
#: Projection of a binary function by a ~2000-direction product rule: the cap
#: boundary cuts quadrature cells, error of order 1e-2 in the coefficients.
QUAD_ATOL = 2e-2


def _one(order):
    g = np.zeros(order * order)
    g[0] = math.sqrt(4 * math.pi)
    return g


def test_single_sphere_union_equals_analytic_cap():
    p = np.zeros((1, 3))
    center, radius = np.array([[0.4, 2.0, -0.3]]), np.array([0.7])
    got = sphere_union_visibility(p, [UP], center, radius, 4, n_dirs=4000)
    d = np.linalg.norm(center[0])
    want = cap(math.asin(radius[0] / d), center[0] / d, 4)
    np.testing.assert_allclose(got[0], want, atol=QUAD_ATOL)


def test_directions_below_the_tangent_plane_count_as_visible():
    p = np.zeros((1, 3))
    # a sphere entirely below the plane y = 0 blocks nothing
    got = sphere_union_visibility(p, [UP], [[0.0, -2.0, 0.0]], [0.5], 4, self_shadow=False)
    np.testing.assert_allclose(got[0], _one(4), atol=1e-12)
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    mesh.apply_translation([0.0, -2.0, 0.0])
    got = raytrace_visibility(p, [UP], [mesh], 4)
    np.testing.assert_allclose(got[0], _one(4), atol=1e-12)


def test_mesh_ray_tracing_agrees_with_analytic_sphere():
    """An icosphere traced by Embree vs the exact sphere it approximates."""
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [-0.7, 0.0, -0.2]])
    nrm = np.tile(UP, (3, 1))
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=0.6)
    mesh.apply_translation([0.2, 1.5, 0.1])
    got = raytrace_visibility(pts, nrm, [mesh], 4)
    want = sphere_union_visibility(pts, nrm, [[0.2, 1.5, 0.1]], [0.6], 4)
    # same quadrature; only the tessellation (inscribed, 0.1% smaller) differs
    np.testing.assert_allclose(got, want, atol=5e-3)


def test_sphere_union_is_not_the_product_of_overlapping_caps():
    """Two overlapping spheres: union visibility is not the (double-counting) product."""
    p = np.zeros((1, 3))
    centers = np.array([[0.0, 2.0, 0.0], [0.3, 2.0, 0.0]])
    radii = np.array([0.6, 0.6])
    union = sphere_union_visibility(p, [UP], centers, radii, 4, n_dirs=4000)[0]
    single = sphere_union_visibility(p, [UP], centers[:1], radii[:1], 4, n_dirs=4000)[0]
    # blocked solid angle of the union is between one cap's and two caps'
    assert single[0] > union[0] > single[0] - (_one(4)[0] - single[0])


def test_product_space_single_sphere_is_its_cap():
    pts = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.5]])
    nrm = np.tile(UP, (2, 1))
    center, radius = np.array([[0.2, 1.0, 0.1]]), np.array([0.4])
    got = product_space_visibility(pts, nrm, (center, radius), 4)
    delta = center - pts
    d = np.linalg.norm(delta, axis=1)
    want = cap(np.arcsin(radius / d), delta / d[:, None], 4)
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_product_space_is_sequential_truncated_products():
    rng = np.random.default_rng(2)
    centers = rng.normal(size=(4, 3)) + np.array([0.0, 3.0, 0.0])
    radii = rng.uniform(0.2, 0.5, 4)
    p = np.zeros((1, 3))
    got = product_space_visibility(p, [UP], (centers, radii), 3, acc_order=5)
    d = np.linalg.norm(centers, axis=1)
    caps = cap(np.arcsin(radii / d), centers / d[:, None], 5)
    want = caps[0]
    for k in range(1, 4):
        want = product(want, caps[k])
    np.testing.assert_allclose(got[0], want[:9], atol=1e-12)
    # the sparse triple-tensor kernel evaluates the same products (float64 round-off)
    sparse = product_space_visibility(p, [UP], (centers, radii), 3, acc_order=5,
                                      kernel="sparse")
    np.testing.assert_allclose(sparse, got, atol=1e-12)


def test_product_space_close_to_ray_traced_union_for_separate_small_spheres():
    """Product space is accurate when the caps are small and do not overlap."""
    centers = np.array([[1.5, 2.0, 0.0], [-1.5, 2.0, 0.3], [0.0, 2.5, -1.5]])
    radii = np.array([0.3, 0.3, 0.3])
    pts = np.zeros((1, 3))
    prod = product_space_visibility(pts, [UP], (centers, radii), 4, acc_order=8)
    union = sphere_union_visibility(pts, [UP], centers, radii, 4, n_dirs=4000)
    np.testing.assert_allclose(prod, union, atol=QUAD_ATOL)


def test_relative_rmse():
    ref = np.array([[1.0, 2.0], [3.0, 4.0]])
    assert relative_rmse(ref, ref) == 0.0
    assert relative_rmse(ref * 1.1, ref) == pytest.approx(0.1)
    assert relative_rmse(np.zeros(2), np.zeros(2)) == 0.0
