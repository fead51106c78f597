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
    split_directions,
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
    # 112 rays on the shadowed vertices against 3,200 over the sphere: quadrature only
    # (measured 3.4 % of the SH vector; 2.9 % with 112 rays on every vertex); 32 rays on
    # every vertex measured 7.7 %
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


def test_split_keeps_the_count():
    assert split_directions(112) == (12, 100)
    assert split_directions(4) == (4, 0)  # too few to split: one pass
    assert sum(split_directions(33)) == 33
