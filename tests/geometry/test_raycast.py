"""RayCaster against closed forms (ray-sphere) and trimesh's own Embree intersector."""

import numpy as np
import pytest
import trimesh

from shtools.geometry.raycast import RayCaster


@pytest.fixture(scope="module")
def sphere():
    # Subdivision 5: the facets sit within ~2e-4 of the unit sphere, far below the
    # 1e-2 margin that the analytic comparison keeps away from tangent rays.
    return trimesh.creation.icosphere(5)


def _random_rays(rng, n, spread=3.0):
    o = rng.normal(size=(n, 3)) * spread
    d = rng.normal(size=(n, 3))
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


def _analytic_hit(o, d, radius=1.0):
    """Ray parameter of the first unit-sphere hit (inf on a miss; origins outside)."""
    b = np.einsum("ij,ij->i", o, d)
    c = np.einsum("ij,ij->i", o, o) - radius**2
    disc = b * b - c
    t = -b - np.sqrt(np.maximum(disc, 0))
    return np.where((disc > 0) & (t > 0), t, np.inf), disc


@pytest.mark.parametrize("robust", [True, False])  # Embree's watertight traversal or not
@pytest.mark.parametrize("scale", [1e-6, 1.0, 1e6])
def test_occluded_and_first_hit_match_ray_sphere(sphere, scale, robust):
    rng = np.random.default_rng(0)
    o, d = _random_rays(rng, 20000)
    outside = np.linalg.norm(o, axis=1) > 1.05
    o, d = o[outside], d[outside]
    t_exact, disc = _analytic_hit(o, d)
    # Stay away from grazing rays, where the faceted sphere and the true one differ.
    clear = np.abs(disc) > 1e-2
    rc = RayCaster(sphere.vertices * scale, sphere.faces, robust=robust)
    hit = rc.occluded(o * scale, d)
    assert np.array_equal(hit[clear], np.isfinite(t_exact)[clear])
    t, face = rc.first_hit(o * scale, d)
    both = clear & np.isfinite(t_exact)
    # Facets lie inside the unit sphere by at most ~2e-4 (subdivision 5).
    np.testing.assert_allclose(t[both] / scale, t_exact[both], atol=2e-3)
    assert np.all(face[~np.isfinite(t)] == -1)


def test_t_far_limits_hits(sphere):
    rc = RayCaster(sphere.vertices, sphere.faces)
    o = np.array([[-3.0, 0, 0]] * 2)
    d = np.array([[1.0, 0, 0]] * 2)
    # The sphere is entered at t = 2.
    assert rc.occluded(o, d, t_far=[1.9, 2.1]).tolist() == [False, True]


def test_matches_trimesh_intersector():
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    mesh = trimesh.creation.torus(1.0, 0.3)
    rng = np.random.default_rng(1)
    o, d = _random_rays(rng, 5000)
    ours = RayCaster.from_meshes([mesh]).occluded(o, d)
    theirs = RayMeshIntersector(mesh).intersects_any(o, d)
    # Same Embree, same float32 frame up to rounding: rays grazing an edge may differ.
    assert np.mean(ours != theirs) < 1e-3


def test_visibility_masks_and_back_hemisphere():
    slab = trimesh.creation.box(extents=[4, 0.1, 4]).apply_translation([0, 2, 0])
    rc = RayCaster.from_meshes(slab)
    p = np.zeros((2, 3))
    n = np.array([[0, 1.0, 0], [0, -1.0, 0]])
    dirs = np.array([[0, 1.0, 0], [0, -1.0, 0]])
    vis = rc.visibility(p, dirs, normals=n)
    # Receiver 0 faces the slab and is blocked upwards; receiver 1 faces away:
    # upward is behind its tangent plane and counts as visible.
    assert vis.tolist() == [[False, True], [True, True]]
    vis = rc.visibility(p, dirs, mask=np.array([[False, True], [True, True]]))
    assert vis.tolist() == [[True, True], [False, True]]
