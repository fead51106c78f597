"""Sphere-centre binding to a skin: exact at rest, exact under rigid motion, LBS-consistent."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from shtools.geometry.binding import bind_spheres, truncation_error
from shtools.geometry.mvc import mean_value_coordinates
from shtools.runtime.spheres import pose_bound_spheres

#: exactness checks: MVC linear precision (~1e-10 of the size) plus rounding
EXACT_ATOL = 1e-8


@dataclass
class Rig:
    """Duck-typed skinned model (what bind_spheres reads)."""

    rest_vertices: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    joint_count: int

    def skin(self, mats):
        hom = np.concatenate([self.rest_vertices, np.ones((len(self.rest_vertices), 1))], 1)
        out = np.zeros((len(hom), 3))
        for k in range(self.joints.shape[1]):
            out += self.weights[:, [k]] * np.einsum("vij,vj->vi", mats[self.joints[:, k]],
                                                     hom)[:, :3]
        return out


def capsule_rig(n_joints=5, open_mesh=False):
    """A capsule along z with joints spread along it, 4 influences per vertex."""
    mesh = trimesh.creation.capsule(height=3.0, radius=0.5, count=[16, 16])
    v, f = mesh.vertices, mesh.faces
    if open_mesh:
        f = f[:-6]
    anchors = np.linspace(v[:, 2].min(), v[:, 2].max(), n_joints)
    d = np.abs(v[:, 2:3] - anchors[None])
    joints = np.argsort(d, axis=1)[:, :4]
    w = np.exp(-np.take_along_axis(d, joints, 1) ** 2 / 0.3)
    return Rig(v, f, joints, w / w.sum(1, keepdims=True), n_joints)


def random_rigid(rng):
    m = np.eye(4)
    m[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    m[:3, 3] = rng.normal(size=3)
    return m


CENTERS = np.array([[0.0, 0.0, 0.0], [0.1, -0.2, 1.3], [0.0, 0.3, -1.4], [0.2, 0.1, 0.6],
                    [0.0, 0.0, 1.9]])


@pytest.mark.parametrize("k", [1, 2, 4])
def test_rest_pose_and_rigid_motion_are_exact(k):
    rig = capsule_rig()
    binding = bind_spheres(CENTERS, rig, bones_per_sphere=k)
    assert binding.bone_index.shape == (len(CENTERS), k)
    assert binding.mesh_closed and not binding.fallback.any()
    np.testing.assert_allclose(binding.bone_vectors[..., 3].sum(1), 1.0, atol=1e-12)
    identity = np.tile(np.eye(4), (rig.joint_count, 1, 1))
    np.testing.assert_allclose(binding.pose(identity), CENTERS, atol=EXACT_ATOL)
    rng = np.random.default_rng(k)
    m = random_rigid(rng)
    posed = binding.pose(np.tile(m, (rig.joint_count, 1, 1)))
    np.testing.assert_allclose(posed, CENTERS @ m[:3, :3].T + m[:3, 3], atol=EXACT_ATOL)


def test_all_bones_equal_mvc_of_skinned_vertices():
    """Untruncated binding == MVC (rest) applied to the LBS-skinned vertices."""
    rig = capsule_rig()
    rng = np.random.default_rng(1)
    mats = np.stack([random_rigid(rng) for _ in range(rig.joint_count)])
    binding = bind_spheres(CENTERS, rig, bones_per_sphere=rig.joint_count)
    lam = mean_value_coordinates(CENTERS, rig.rest_vertices, rig.faces)
    want = lam @ rig.skin(mats)
    np.testing.assert_allclose(binding.pose(mats), want, atol=1e-9)
    assert np.all(binding.dropped_weight < 1e-12)


def test_truncation_error_matches_documented_formula():
    rig = capsule_rig(n_joints=7)
    rng = np.random.default_rng(2)
    mats = np.stack([random_rigid(rng) for _ in range(rig.joint_count)])
    k2 = bind_spheres(CENTERS, rig, bones_per_sphere=2)
    full = bind_spheres(CENTERS, rig, bones_per_sphere=rig.joint_count)
    err = truncation_error(CENTERS, rig, k2, mats)
    np.testing.assert_allclose(err, np.linalg.norm(full.pose(mats) - k2.pose(mats), axis=1))
    # bound: sum_d ||M_d - M_bar|| ||q_d|| over dropped bones (module docstring)
    q = np.zeros((len(CENTERS), rig.joint_count, 4))
    np.put_along_axis(q, full.bone_index[..., None].astype(int), full.bone_vectors, axis=1)
    for n in range(len(CENTERS)):
        kept = k2.bone_index[n]
        beta = np.abs(q[n, kept, 3])
        m_bar = np.tensordot(beta / beta.sum(), mats[kept], axes=1)
        dropped = np.setdiff1d(np.arange(rig.joint_count), kept)
        bound = sum(np.linalg.norm(mats[d] - m_bar, 2) * np.linalg.norm(q[n, d])
                    for d in dropped)
        assert err[n] <= bound + 1e-9


def test_open_mesh_still_exact_at_rest_and_rigid():
    rig = capsule_rig(open_mesh=True)
    binding = bind_spheres(CENTERS, rig, bones_per_sphere=3)
    assert not binding.mesh_closed
    identity = np.tile(np.eye(4), (rig.joint_count, 1, 1))
    np.testing.assert_allclose(binding.pose(identity), CENTERS, atol=EXACT_ATOL)
    m = random_rigid(np.random.default_rng(5))
    posed = pose_bound_spheres(binding.bone_index, binding.bone_vectors,
                               np.tile(m, (rig.joint_count, 1, 1)))
    np.testing.assert_allclose(posed, CENTERS @ m[:3, :3].T + m[:3, 3], atol=EXACT_ATOL)


def test_pose_batches_over_frames():
    rig = capsule_rig()
    binding = bind_spheres(CENTERS, rig)
    rng = np.random.default_rng(3)
    frames = np.stack([np.stack([random_rigid(rng) for _ in range(rig.joint_count)])
                       for _ in range(3)])
    batched = binding.pose(frames)
    assert batched.shape == (3, len(CENTERS), 3)
    for t in range(3):
        q = binding.bone_vectors
        m = frames[t][binding.bone_index]
        loop = np.array([sum(m[n, k] @ q[n, k] for k in range(q.shape[1]))[:3]
                         for n in range(len(CENTERS))])
        np.testing.assert_allclose(batched[t], loop, atol=1e-12)
