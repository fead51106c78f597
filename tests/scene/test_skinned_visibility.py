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
    # at most 112 rays on the shadowed vertices against 3,200 over the sphere: quadrature
    # only (measured 3.0 % of the SH vector; 2.9 % with 112 rays on every vertex); 32
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
