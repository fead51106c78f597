"""The per-frame traced self-visibility of skinned meshes
(:mod:`shtools.scene.skinned_visibility`) against the project's ray tracer of the
same mesh at 3,200 directions."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from shtools.geometry.visibility import hemisphere_visibility
from shtools.reference import raytrace_visibility
from shtools.scene.skinned_visibility import (
    SKINNED_DIRECTIONS,
    adaptive_self_visibility,
    strata,
)
from shtools.scene.transfer import posed_caster


@pytest.fixture(scope="module")
def torus():
    m = trimesh.creation.torus(major_radius=0.6, minor_radius=0.25, major_sections=32,
                               minor_sections=16)
    v, f, n = (np.asarray(a) for a in (m.vertices, m.faces, m.vertex_normals))
    return v, f, n, posed_caster(v, f), raytrace_visibility(v, n, [m], 4, 3200)


def _error(g, ref, mask):
    return float(np.sqrt(((g - ref)[mask] ** 2).sum(axis=1).mean()
                         / (ref[mask] ** 2).sum(axis=1).mean()))


def test_rays_go_where_the_mesh_shadows_itself(torus):
    """A torus shadows the inside of its ring: there the default count is far closer to
    the reference than the former 32 rays on every vertex; outside, where nothing of
    the mesh is above the tangent plane, the visibility is exactly 1."""
    v, f, n, caster, ref = torus
    shadowed = ref[:, 0] < 0.98 * math.sqrt(4 * math.pi)
    g = adaptive_self_visibility(v, n, f, caster, 4, SKINNED_DIRECTIONS)
    old = hemisphere_visibility(v, n, caster, 4, n_dirs=32)
    # at most 120 rays on the shadowed vertices against 3,200 over the sphere: quadrature
    # only (measured 2.9 % of the SH vector, 2.8 % with 120 rays on every vertex); 32
    # rays on every vertex measured 7.7 %
    err, err_old = _error(g, ref, shadowed), _error(old, ref, shadowed)
    assert err < 0.05, err
    assert err < 0.6 * err_old, (err, err_old)
    outside = np.linalg.norm(v[:, :2], axis=1) > 0.6 + 0.2  # the ring's outer side
    assert outside.sum() > 50
    np.testing.assert_array_equal(g[outside, 1:], 0.0)
    np.testing.assert_array_equal(g[outside, 0], math.sqrt(4 * math.pi))
    # more rays converge on the reference (measured 1.9 % at 256)
    fine = adaptive_self_visibility(v, n, f, caster, 4, 256)
    assert _error(fine, ref, shadowed) < 0.75 * err


def test_strata_cut_the_set():
    """Every point of the set is in one stratum, each first point in its own; touching
    strata are symmetric; a set too small to cut is one stratum per point."""
    local, first, cell, touching = strata(112)
    assert len(local) == 112 and len(first) == 13  # every 9th point
    np.testing.assert_array_equal(cell[first], np.arange(len(first)))
    assert np.bincount(cell, minlength=len(first)).min() >= 1
    np.testing.assert_array_equal(touching, touching.T)
    assert np.all(np.diag(touching) == 1) and 2 <= touching.sum(axis=1).min()
    # the strata are compact: a point is never farther from its first point than the
    # set's spacing allows (13 strata of 2π/13 sr: a cap of that area has a 41° radius;
    # twice that is loose for a Voronoi cell of a spread-out set)
    cos = np.einsum("qk,qk->q", local, local[first][cell])
    assert cos.min() > math.cos(math.radians(82)), cos.min()
    _, first4, cell4, _ = strata(4)  # too few to cut: every point is cast first
    np.testing.assert_array_equal(first4, np.arange(4))
    np.testing.assert_array_equal(cell4, np.arange(4))


class _Counting:
    """A caster that counts the rays cast through it."""

    def __init__(self, caster):
        self.caster, self.rays = caster, 0
        self.diagonal = caster.diagonal

    def embree_points(self, points):
        return self.caster.embree_points(points)

    def occluded_embree(self, origins, directions):
        self.rays += len(origins)
        return self.caster.occluded_embree(origins, directions)


def test_legs_side_by_side_and_buried_in_a_hip():
    """One mesh of two capsules 3 cm apart with their tops inside a third (a posed
    character's legs and hip, interpenetrating as skinned parts do): the shadows
    between the legs and the buried vertices, against the ray tracer of that mesh.
    The strata cast only where the first rays (or a neighbour's) found the mesh: less
    than half the rays of the whole set on every vertex, at about its error."""
    parts = []
    for z in (-0.1, 0.1):
        leg = trimesh.creation.capsule(height=0.55, radius=0.085, count=[16, 16])
        leg.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0]))
        leg.apply_translation([0.0, -0.36, z])
        parts.append(leg)
    hip = trimesh.creation.capsule(height=0.3, radius=0.17, count=[20, 20])
    hip.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, [0, 1, 0]))
    mesh = trimesh.util.concatenate([*parts, hip])
    v, f, n = (np.asarray(a) for a in (mesh.vertices, mesh.faces, mesh.vertex_normals))
    ref = raytrace_visibility(v, n, [mesh], 4, 3200)
    shadowed = ref[:, 0] < 0.98 * math.sqrt(4 * math.pi)
    assert shadowed.mean() > 0.2  # between the legs, under the hip, and inside it
    caster = _Counting(posed_caster(v, f))
    g = adaptive_self_visibility(v, n, f, caster, 4, SKINNED_DIRECTIONS)
    whole = hemisphere_visibility(v, n, caster.caster, 4, n_dirs=SKINNED_DIRECTIONS)
    # quadrature against 3,200 directions: measured 2.0 % of the SH vector, 2.0 % with
    # the 120 rays on every vertex
    err, err_whole = _error(g, ref, shadowed), _error(whole, ref, shadowed)
    assert err < 0.03, err
    assert err < 1.2 * err_whole, (err, err_whole)
    # measured 57 rays a vertex (two passes of two sets, 12 rays then 100 more on every
    # vertex of the second pass: 70 rays a vertex and 2.3 %)
    assert caster.rays < 0.55 * SKINNED_DIRECTIONS * len(v), caster.rays / len(v)
