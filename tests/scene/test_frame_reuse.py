"""What a frame reuses instead of redoing (shtools.scene.traced_shadows,
shtools.scene.contact_shadows, shtools.scene.kept_traces): a rigid object's neighbours
from its rest geometry, a still object's kept trace among moving ones."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from shtools.geometry.raycast import RayCaster
from shtools.scene.contact_shadows import similarity_scale
from shtools.scene.kept_traces import GROUND_KEPT, kept
from shtools.scene.receiver_filter import FILTER_MIN_COS, FILTER_NEIGHBOURS, neighbours
from shtools.scene.traced_shadows import traced_ground


def _blob(seed=3):
    """A lumpy sphere (no two vertex distances equal: the nearest neighbours are unique)."""
    rng = np.random.default_rng(seed)
    mesh = trimesh.creation.icosphere(subdivisions=3)
    v = mesh.vertices * (1.0 + 0.05 * rng.standard_normal((len(mesh.vertices), 1)))
    mesh = trimesh.Trimesh(v, mesh.faces, process=False)
    return np.asarray(mesh.vertices), np.asarray(mesh.vertex_normals)


def test_similarity_scale():
    r = Rotation.from_rotvec([0.3, -1.1, 0.4]).as_matrix()
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = 2.5 * r, [1.0, -2.0, 0.5]
    assert abs(similarity_scale(m) - 2.5) < 1e-12
    m[:3, :3] = r @ np.diag([1.0, 1.0, 1.3])  # an unequal scale changes distances unequally
    assert similarity_scale(m) is None
    assert similarity_scale(np.zeros((4, 4))) is None


def test_a_rigid_objects_neighbours_are_its_rest_geometrys():
    """Posed by a rotation, translation and scale 1.7, the neighbours from the rest
    geometry are those of a k-d tree of the posed points (scipy's, searched here
    independently), at the posed distances, with the same facing-away cut."""
    v, n = _blob()
    r = Rotation.from_rotvec([0.7, 0.2, -0.5]).as_matrix()
    world_v = 1.7 * v @ r.T + np.array([3.0, 0.2, -1.0])
    world_n = n @ r.T
    idx, dist = neighbours(world_v, world_n, rest=(v, n, 1.7))
    k = min(FILTER_NEIGHBOURS, len(v))
    d_ref, i_ref = cKDTree(world_v).query(world_v, k=k)
    assert np.all(i_ref[:, 0] == np.arange(len(v)))  # distinct points: self first
    facing = np.einsum("vk,vnk->vn", world_n, world_n[i_ref]) >= FILTER_MIN_COS
    np.testing.assert_array_equal(idx, np.where(facing, i_ref, -1))
    # distances: the rest ones times the scale, against the posed ones (rounding only)
    np.testing.assert_allclose(dist, d_ref, rtol=1e-12, atol=1e-12)


def test_a_still_trace_outlives_moving_ones():
    """A still object's kept trace stays kept while more than ``GROUND_KEPT`` moving
    objects' per-frame scenes come and go (each frame's freed: a static column beside a
    walker is traced once per bake, not every few frames)."""
    v, _ = _blob()
    faces = trimesh.creation.icosphere(subdivisions=3).faces
    g = np.stack(np.meshgrid(np.linspace(-3, 3, 12), np.linspace(-3, 3, 12)), -1).reshape(-1, 2)
    points = np.column_stack([g[:, 0], np.full(len(g), -1.2), g[:, 1]])
    normals = np.tile([0.0, 1.0, 0.0], (len(points), 1))
    still = RayCaster(v, faces, robust=False)
    args = (points, normals, v, faces, still, 3, 48)
    traced_ground(*args)
    key = (still, points, normals, v, faces, 3, 48, None, (), False, None)
    assert kept(key) is not None
    for step in range(GROUND_KEPT + 4):  # moving objects: a new scene each frame
        moved = v + np.array([0.05 * step, 0.0, 0.0])
        traced_ground(points, normals, moved, faces, RayCaster(moved, faces, robust=False),
                      3, 48)
        assert traced_ground(*args)[0].size  # the still object's, kept
    assert kept(key) is not None
