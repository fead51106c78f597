"""The bake's exact self-transfer from hemisphere rays
(:func:`shtools.geometry.transfer.hemisphere_transfer`) against the independent
reference ray tracer, at the accuracy of the product-rule transfer it replaces."""

from __future__ import annotations

import math

import numpy as np
import trimesh

from shtools.geometry.transfer import (
    FIRST_DIRECTIONS,
    TRANSFER_DIRECTIONS,
    hemisphere_transfer,
    mesh_transfer,
)
from shtools.geometry.visibility import DEFAULT_DIRECTIONS, self_visibility_log
from shtools.reference import raytrace_visibility


def _torus():
    return trimesh.creation.torus(major_radius=0.6, minor_radius=0.3, major_sections=20,
                                  minor_sections=10)


def test_as_accurate_as_the_product_rule_with_fewer_rays(monkeypatch):
    from shtools.geometry.raycast import RayCaster

    torus = _torus()
    v, n = np.asarray(torus.vertices), np.asarray(torus.vertex_normals)
    order = 6
    ref = raytrace_visibility(v, n, [torus], order, 60000)  # an independent module
    cast = []
    real = RayCaster.occluded_embree
    monkeypatch.setattr(RayCaster, "occluded_embree",
                        lambda self, o, d: cast.append(len(o)) or real(self, o, d))
    g, f, params = hemisphere_transfer(torus, order)
    monkeypatch.undo()
    product, _, _ = mesh_transfer(torus, order)
    err = np.linalg.norm(g - ref) / np.linalg.norm(ref)
    err_product = np.linalg.norm(product - ref) / np.linalg.norm(ref)
    # the quadrature error of the binary visibility across the inner ring's shadow
    # boundaries: measured 0.39 % for 1,600 directions refined from 256 first rays
    # (0.42 % at 1,280 rays in one pass), 0.60 % for the 3,200-node product rule, whose
    # ~1,600 nodes above each tangent plane are the rays it casts (the 60,000-node
    # reference differs from a 120,000-node one by 0.24 %)
    assert err < 0.005
    assert err <= err_product, (err, err_product)
    # fewer rays than the rule casts: 445 a vertex on this torus (256 first, the rest in
    # the refined cells)
    assert sum(cast) / len(v) < DEFAULT_DIRECTIONS / 2
    assert params["n_dirs"] == TRANSFER_DIRECTIONS and params["estimator"] == "hemisphere"
    assert params["n_first"] == FIRST_DIRECTIONS
    np.testing.assert_array_equal(f, self_visibility_log(g))
    g2, f2, _ = hemisphere_transfer(torus, order, with_log=False)
    assert f2 is None
    np.testing.assert_array_equal(g2, g)


def test_refinement_gives_the_dense_estimate_where_boundaries_are_found():
    # the two-pass estimate against the one-pass one over the same dense set, on the
    # same caster: they differ only where a shadow boundary slips between first
    # directions that agree, which the torus's smooth shadows never do (measured: equal
    # to rounding, 1.5e-16 relative; 1.1e-4 with a 1,920-direction dense set)
    from shtools.geometry.raycast import RayCaster
    from shtools.geometry.transfer import (
        hemisphere_transfer_visibility,
        refined_transfer_visibility,
        refinement_cells,
    )
    from shtools.geometry.visibility import hemisphere_directions

    torus = _torus()
    v, n = np.asarray(torus.vertices), np.asarray(torus.vertex_normals)
    caster = RayCaster(v, np.asarray(torus.faces), robust=False)
    dense = hemisphere_transfer_visibility(v, n, caster, 4, n_dirs=TRANSFER_DIRECTIONS)
    refined = refined_transfer_visibility(v, n, caster, 4)
    assert np.abs(dense[:, 1:]).max() > 0.1  # the comparison sees shadows
    assert np.linalg.norm(refined - dense) / np.linalg.norm(dense) < 1e-3
    # every dense direction lies in the cell of its nearest first direction (by angle,
    # checked against arccos), listed once; each first direction has neighbours
    first, neighbours, cell, members, starts, counts = refinement_cells(FIRST_DIRECTIONS,
                                                                        TRANSFER_DIRECTIONS)
    dense_dirs = hemisphere_directions(TRANSFER_DIRECTIONS)
    angle = np.arccos(np.clip(dense_dirs @ first.T, -1.0, 1.0))
    np.testing.assert_allclose(angle[np.arange(len(cell)), cell], angle.min(axis=1), atol=1e-12)
    assert counts.sum() == TRANSFER_DIRECTIONS and (counts > 0).all()
    np.testing.assert_array_equal(np.sort(members), np.arange(TRANSFER_DIRECTIONS))
    for q in range(len(first)):
        assert (cell[members[starts[q]:starts[q] + counts[q]]] == q).all()
    assert ((neighbours != np.arange(len(first))[:, None]).sum(axis=1) >= 5).all()


def test_degenerate_normals_are_unblocked_and_progress_reaches_every_vertex():
    torus = _torus()
    n = np.array(torus.vertex_normals)
    n[:5] = 0.0  # no tangent plane: nothing above it
    seen = []
    g, _, _ = hemisphere_transfer(torus, 3, n_dirs=64, normals=n,
                                  progress=lambda done, total: seen.append((done, total)))
    want = np.zeros(9)
    want[0] = math.sqrt(4 * math.pi)
    np.testing.assert_array_equal(g[:5], np.broadcast_to(want, (5, 9)))
    assert np.abs(g[5:] - want).max(axis=1).max() > 0.1  # the inner ring is shadowed
    assert seen[-1] == (len(n), len(n))


def test_tangent_frame_projection_matches_per_ray_basis_sums():
    # two independent projections of the same rays: one basis evaluation per blocked
    # ray summed per vertex (hemisphere_visibility) against one matrix product in the
    # tangent frame rotated by an exact product rule; they differ by rounding only
    # (the per-ray path sums float32 basis values: ~1e-7 of g_0 = 3.54)
    from shtools.geometry.raycast import RayCaster
    from shtools.geometry.transfer import hemisphere_transfer_visibility
    from shtools.geometry.visibility import hemisphere_visibility

    torus = _torus()
    v, n = np.asarray(torus.vertices), np.asarray(torus.vertex_normals)
    caster = RayCaster(v, np.asarray(torus.faces), robust=False)
    for order in (3, 6):
        per_ray = hemisphere_visibility(v, n, caster, order, n_dirs=200)
        local = hemisphere_transfer_visibility(v, n, caster, order, n_dirs=200)
        np.testing.assert_allclose(local, per_ray, rtol=0, atol=2e-5)
        assert np.abs(per_ray[:, 1:]).max() > 0.1  # the comparison sees shadows


def test_spatial_order_is_a_deterministic_permutation_along_the_box():
    from shtools.geometry.transfer import spatial_order

    rng = np.random.default_rng(3)
    p = rng.uniform(-5.0, 5.0, size=(2000, 3))
    order = spatial_order(p)
    np.testing.assert_array_equal(np.sort(order), np.arange(len(p)))
    np.testing.assert_array_equal(order, spatial_order(p.copy()))
    # consecutive points are near each other: their mean step is far below that of
    # the input order (a random walk over the box has steps ~ its size / 2)
    step = np.linalg.norm(np.diff(p[order], axis=0), axis=1).mean()
    assert step < 0.25 * np.linalg.norm(np.diff(p, axis=0), axis=1).mean()
    assert spatial_order(np.zeros((0, 3))).size == 0
