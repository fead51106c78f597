"""Receivers blended over neighbouring clusters (shtools.runtime.cluster_blend).

The seams are measured against the flat sum of every leaf sphere at every receiver
(``hierarchy = False``: SHEXP eq. 38 with no cut, no ratio vector), which has no
clusters and so no seam, with bench_look's figures
(:func:`shtools.reference.look.smoothness_ratio`: the mesh-graph Laplacian energy of
the ground's luminance, bake over reference; the relative RMSE of the radiance).
"""

import numpy as np
import pytest

from shtools.reference import relative_rmse
from shtools.reference.evaluation import grid_faces
from shtools.reference.look import smoothness_ratio
from shtools.reference.scenes import ground_grid, sky_light
from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker
from shtools.runtime.cluster_blend import blend_entries, blend_rows
from shtools.runtime.clusters import lloyd_clusters

GRID = 72


def _blockers():
    """Two trees of spheres over the ground: a column and a ring of balls, high enough
    that their shadows are soft (where a cut's seams show most)."""
    from shtools.geometry.sphere_tree import build_tree

    t = np.linspace(0.0, 2.0, 14)
    column = np.column_stack([0.4 + 0.15 * np.cos(5 * t), 0.65 + t, -0.3 + 0.15 * np.sin(5 * t)])
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.column_stack([-0.6 + 0.5 * np.cos(a), 0.95 + 0.1 * np.sin(3 * a),
                            0.5 + 0.5 * np.sin(a)])
    out = []
    for centers, radius in ((column, 0.16), (ring, 0.13)):
        radii = np.full(len(centers), radius)
        tree = build_tree(centers, radii)
        out.append(SphereBlocker(centers, radii, tree=(tree.parent, tree.leaf)))
    return out


def _ground_radiance(**settings):
    v, n = ground_grid(GRID, (0.0, 0.0), 3.0)
    with ShadowRuntime(ShadowSettings(order=4, vertices_per_cluster=120, **settings)) as rt:
        g = rt.visibility(v, n, _blockers(), rt.clusters(v))
        return rt.shade(g, v, n, sky_light(4), []), rt.last_stats


@pytest.fixture(scope="module")
def flat():
    return _ground_radiance(hierarchy=False)[0]


def test_blend_removes_the_seams_of_the_cluster_cuts(flat):
    cut, cut_stats = _ground_radiance()
    blended, stats = _ground_radiance(cluster_blend=0.5)
    faces = grid_faces(GRID)
    # the cuts' seams: a network of steps along the cluster boundaries (measured 1.49x
    # the flat sum's roughness here); the blend ramps them over its band (measured
    # 1.09x); the bounds sit between the two, clear of BLAS rounding
    assert smoothness_ratio(cut, flat, faces) > 1.3
    assert smoothness_ratio(blended, flat, faces) < 1.15
    # and it is no less accurate than the cuts it blends
    assert relative_rmse(blended, flat) <= relative_rmse(cut, flat)
    assert stats["pairs"] > cut_stats["pairs"]  # the price: receivers evaluated twice


def test_blend_is_continuous_across_a_cluster_boundary():
    """Receivers on a line crossing cluster boundaries, 1e-4 apart: no jump."""
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(-2, 2, 3000), np.zeros(3000), rng.uniform(-2, 2, 3000)])
    clusters = lloyd_clusters(pts, 150)
    centers, radii = clusters.bounds(pts)
    line = np.column_stack([np.linspace(-1.9, 1.9, 38001), np.zeros(38001), np.full(38001, 0.1)])
    # a membership of the line's samples: mostly the nearest centre, every 7th the
    # second nearest (the blend must not depend on it), radii covering the members
    from shtools.runtime.clusters import ReceiverClusters

    d2 = ((line[:, None, :] - centers[None, :, :]) ** 2).sum(-1)
    member = np.argmin(d2, axis=1)
    member[::7] = np.argsort(d2[::7], axis=1)[:, 1]
    touched, dense = np.unique(member, return_inverse=True)
    line_clusters = ReceiverClusters.from_labels(dense)
    reach = radii[touched].copy()
    np.maximum.at(reach, dense, np.sqrt(d2[np.arange(len(line)), member]))
    entries = blend_entries(line, line_clusters, centers[touched], reach,
                            np.zeros(touched.size, dtype=np.int64), 0.5)
    phi = np.zeros((len(line), touched.size))
    np.add.at(phi, (entries.order, np.repeat(np.arange(touched.size),
                                             np.diff(entries.offsets))), entries.weights)
    # the weights are normalised in float64: 1 to its rounding
    np.testing.assert_allclose(phi.sum(axis=1), 1.0, atol=1e-12)
    # weights of a position alone: steps of 1e-4 move them by at most a few 1e-4 (the
    # smoothstep's slope 1.5 over a band of 0.5 radius ~ 0.1 units)
    assert np.abs(np.diff(phi, axis=0)).max() < 0.01
    assert (phi > 0.2).sum(axis=1).max() >= 2  # the line does cross blended bands


def test_blend_rows_sums_each_receivers_entries():
    rng = np.random.default_rng(0)
    order = np.concatenate([np.arange(50), rng.integers(0, 50, 30)])
    values = rng.normal(size=(order.size, 5)).astype(np.float32)
    weights = rng.uniform(0.1, 1.0, order.size)
    expected = np.zeros((50, 5))
    np.add.at(expected, order, weights[:, None] * values)
    # rtol: float32 values scaled and summed in float32 against a float64 sum
    np.testing.assert_allclose(blend_rows(values, order, weights, 50), expected, rtol=1e-5)
    with pytest.raises(ValueError, match="cover"):
        blend_rows(values[:10], order[:10], weights[:10], 50)


def test_blend_bytes_do_not_depend_on_the_processes():
    v, n = ground_grid(48, (0.0, 0.0), 3.0)
    out = []
    for processes in (1, 2):
        with ShadowRuntime(ShadowSettings(order=4, vertices_per_cluster=60, cluster_blend=0.5,
                                          processes=processes)) as rt:
            out.append(rt.visibility(v, n, _blockers(), rt.clusters(v)))
            assert rt.last_stats["processes"] == processes  # the parts did go to a worker
    assert out[0].tobytes() == out[1].tobytes()


def test_blend_stays_within_an_object_group_and_its_exclusion_label():
    """Two objects side by side, one of them split by the blockers it skips: no
    receiver is evaluated with a cluster of the other object or of another label."""
    from shtools.runtime.frame_work import frame_work
    from shtools.runtime.self_visibility import Skipped

    rng = np.random.default_rng(4)
    pts = np.column_stack([rng.uniform(-2, 2, 4000), np.zeros(4000), rng.uniform(-1, 1, 4000)])
    groups = (pts[:, 0] > 0).astype(np.int64)  # two objects meeting along x = 0
    clusters = lloyd_clusters(pts, 200, groups=groups)
    assert clusters.groups is not None and clusters.groups.shape == (clusters.n_clusters,)
    # the second object's far half skips the blockers (label 1): its clusters split
    labels = ((pts[:, 0] > 1.0) & (pts[:, 2] > 0)).astype(np.int64)
    exclude = Skipped(labels, np.array([[False, False], [True, False]]))
    split = clusters.split(labels)
    first = split.order[split.offsets[:-1]]
    np.testing.assert_array_equal(split.groups, groups[first])  # carried by the split
    with ShadowRuntime(ShadowSettings(order=4, cluster_blend=1.0)) as rt:
        work, _ = frame_work(rt.settings, rt.table, pts, _blockers(), clusters, exclude,
                             rt._clusters_for)
    entry_cluster = np.repeat(np.arange(split.n_clusters), np.diff(work.offsets))
    owner = split.labels[work.order]  # the cluster each entry's receiver belongs to
    np.testing.assert_array_equal(split.groups[entry_cluster], split.groups[owner])
    np.testing.assert_array_equal(labels[first][entry_cluster], labels[work.order])
    assert (entry_cluster != owner).mean() > 0.1  # the band at 1.0 does blend


def test_eval_and_an_empty_frame_take_the_setting():
    from types import SimpleNamespace

    from shtools.reference.evaluation import eval_settings

    assert eval_settings(SimpleNamespace(settings={"cluster_blend": 0.5})).cluster_blend == 0.5
    with ShadowRuntime(ShadowSettings(order=4, cluster_blend=0.5)) as rt:
        none = np.zeros((0, 3))
        g = rt.visibility(none, none, _blockers(), rt.clusters(none))
    assert g.shape == (0, 16)
