"""Exact self-shadowing in the runtime: a precomputed self-visibility (rotated with the
object) replaces the object's own spheres on its own vertices, combined in log space."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.errors import InputError
from shtools.geometry.visibility import self_visibility, self_visibility_log
from shtools.reference import raytrace_visibility, relative_rmse
from shtools.reference.scenes import sky_light
from shtools.runtime import SelfVisibility, ShadowRuntime, ShadowSettings, SphereBlocker
from shtools.sh import rotation_matrix

N_DIRS = 1500


def _torus_scene():
    """A torus (own frame) with a ring of bounding spheres, and a ball beside it."""
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.4, major_sections=40,
                                   minor_sections=20)
    phi = np.linspace(0.0, 2 * math.pi, 16, endpoint=False)
    centers = np.stack([np.cos(phi), np.zeros_like(phi), np.sin(phi)], axis=1)
    # spacing 2 sin(pi/16) = 0.39 along the ring: radius sqrt(0.4^2 + 0.2^2) covers the tube
    radii = np.full(16, math.hypot(0.4, 0.2))
    return torus, centers, radii


@pytest.mark.parametrize("hierarchy", [True, False])
def test_rotated_self_visibility_matches_ray_tracing_of_the_real_mesh(hierarchy):
    torus, centers, radii = _torus_scene()
    # transfer in the torus' own frame (what `shtools transfer` stores)
    acc = 6
    g_local = self_visibility(torus.vertices, torus.vertex_normals, torus, acc, n_dirs=N_DIRS)
    log_local = self_visibility_log(g_local)
    # the object this frame: tilted and moved; a ball blocker beside it
    rot = trimesh.transformations.rotation_matrix(0.7, [1.0, 0.3, 0.2])[:3, :3]
    move = np.array([0.3, 1.2, -0.4])
    v_w = torus.vertices @ rot.T + move
    n_w = torus.vertex_normals @ rot.T
    ball_c, ball_r = np.array([0.4, 3.3, -0.2]), 0.45
    ball = trimesh.creation.icosphere(subdivisions=4, radius=ball_r)
    ball.apply_translation(ball_c)
    world_torus = trimesh.Trimesh(v_w, torus.faces, process=False)
    blockers = [SphereBlocker(centers @ rot.T + move, radii), SphereBlocker([ball_c], [ball_r])]
    env = sky_light(4)
    rt = ShadowRuntime(ShadowSettings(order=4, acc_order=acc, hierarchy=hierarchy,
                                      vertices_per_cluster=100, processes=1))
    sv = SelfVisibility(log_local, slice(None), rotation=rot, blocker=0)
    new = rt.shade(rt.visibility(v_w, n_w, blockers, self_visibility=[sv]), v_w, n_w, env)
    old = rt.shade(rt.visibility(v_w, n_w, blockers), v_w, n_w, env)
    # independent reference: ray tracing of the real meshes in the world frame
    g_ref = raytrace_visibility(v_w, n_w, [world_torus, ball], 4, N_DIRS)
    ref = rt.shade(g_ref, v_w, n_w, env)
    err_new, err_old = relative_rmse(new, ref), relative_rmse(old, ref)
    # what is left: the ball as a sphere in SHEXP (the runtime's ~2 % vs its spheres),
    # exp(log) of the transfer at order 6 truncated to 4 and quadrature noise; measured
    # 1.4 % here, while the ring of spheres with the self-shadow rules gives 25 %
    assert err_new < 0.03
    assert err_old > 5 * err_new


def test_rotation_equals_tracing_the_rotated_mesh():
    """Rotating the stored log by R = projecting visibility traced on the rotated mesh."""
    torus, _, _ = _torus_scene()
    rot = trimesh.transformations.rotation_matrix(1.1, [0.2, 1.0, -0.5])[:3, :3]
    idx = np.arange(0, len(torus.vertices), 7)
    g_local = self_visibility(torus.vertices[idx], torus.vertex_normals[idx], torus, 4,
                              n_dirs=4000)
    world = trimesh.Trimesh(torus.vertices @ rot.T, torus.faces, process=False)
    g_world = self_visibility(world.vertices[idx], torus.vertex_normals[idx] @ rot.T, world, 4,
                              n_dirs=4000)
    rotated = g_local @ rotation_matrix(rot, 4).T
    # two 4000-node rules see the same indicators from different angles: ~1e-2 RMS
    # quadrature noise (the closed-form bowl test gives 2e-2 per coefficient at 8000)
    rms = np.sqrt(np.mean((rotated - g_world) ** 2) / np.mean(g_world ** 2))
    assert rms < 2e-2


def test_clusters_mixing_rows_that_skip_different_blockers_are_split():
    """A cluster whose rows skip different blockers (a traced shadow covering part of
    it) is evaluated as its parts; a log at the wrong order is refused."""
    torus, centers, radii = _torus_scene()
    v, n = torus.vertices, torus.vertex_normals
    log = np.zeros((len(v) // 2, 36), np.float32)
    rt = ShadowRuntime(ShadowSettings(order=4, acc_order=6, processes=1))
    sv = SelfVisibility(log, np.arange(len(v) // 2), blocker=0)
    from shtools.runtime.clusters import ReceiverClusters

    mixed = ReceiverClusters.from_labels(np.zeros(len(v), dtype=int))
    skips = (np.arange(len(v)) < len(v) // 2).astype(int)
    blockers = [SphereBlocker(centers, radii)]
    got = rt.visibility(v, n, blockers, mixed, self_visibility=[sv])
    want = rt.visibility(v, n, blockers, mixed.split(skips), self_visibility=[sv])
    np.testing.assert_array_equal(got, want)
    # the rows that skip the torus' spheres see nothing else: exp(0), the constant 1
    np.testing.assert_allclose(got[: len(v) // 2, 1:], 0.0, atol=1e-6)
    with pytest.raises(InputError, match="accumulates at order 6"):
        rt.visibility(v, n, [SphereBlocker(centers, radii)],
                      self_visibility=[SelfVisibility(np.zeros((len(v), 16)), slice(None))])


def test_zero_self_log_without_exclusion_changes_nothing():
    """A zero log on every row and no skipped blocker gives the plain runtime result."""
    torus, centers, radii = _torus_scene()
    v, n = torus.vertices, torus.vertex_normals
    rt = ShadowRuntime(ShadowSettings(order=4, acc_order=6, processes=1))
    blockers = [SphereBlocker(centers, radii)]
    plain = rt.visibility(v, n, blockers)
    with_zero = rt.visibility(v, n, blockers, self_visibility=[
        SelfVisibility(np.zeros((len(v), 36)), slice(None))])
    np.testing.assert_allclose(with_zero, plain, atol=1e-6)  # float32 round-off
