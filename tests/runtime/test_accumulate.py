"""Log-space accumulation (eq. 34/38) against an independent float64 evaluation."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.runtime import CapLogTable, accumulate_log
from shtools.runtime.tiling import accumulate_clusters
from shtools.sh import band_of, basis, log
from shtools.sh import cap as sh_cap
from shtools.sh.tables import build_log_tables, default_tables

#: float32 accumulation of ~40 terms of size <= ~10 plus the table lookup: the
#: runtime's piecewise-constant ratio table is within 6e-4 of each band's largest
#: value (shtools.runtime.log_table), the reference interpolates in theta.
ACC_RTOL = 1e-3


def reference_log_sum(points, centers, radii, tables, order, weights=None):
    """sum_i W_i F(asin(r/d)) y(s) in float64, interpolating the table in theta."""
    delta = centers[None, :, :] - points[:, None, :]
    d = np.linalg.norm(delta, axis=-1)
    theta = np.arcsin(np.clip(radii[None, :] / d, 0, 1))
    zh = np.stack([np.interp(theta, np.concatenate([[0.0], tables["theta"]]),
                             np.concatenate([[0.0], tables["log_zh"][:, l]]))
                   for l in range(order)], axis=-1)  # (V, S, n)
    if weights is not None:
        zh = zh * weights[None]
    return np.einsum("vsk,vsk->vk", zh[..., band_of(order)], basis(delta / d[..., None], order))


@pytest.mark.parametrize("order", [2, 4, 6])
def test_accumulation_matches_float64_sum(order):
    rng = np.random.default_rng(order)
    tables = default_tables(order)
    table = CapLogTable(tables, order)
    pts = rng.normal(size=(150, 3))
    centers = rng.normal(size=(23, 3)) * 3 + [0, 6, 0]
    radii = rng.uniform(0.05, 1.5, 23)
    weights = rng.uniform(0.5, 1.2, size=(23, order))
    got = accumulate_log(pts, np.tile([0, 1.0, 0], (150, 1)), centers, radii, table,
                         weights=weights, self_shadow=False, chunk_pairs=512)
    want = reference_log_sum(pts, centers, radii, tables, order, weights)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, want, atol=ACC_RTOL * np.abs(want).max())


def test_single_sphere_log_exponentiates_to_the_cap_visibility():
    """One sphere: exp of its log vector is the cap visibility vector (the log inverts)."""
    from shtools.sh import exp

    order = 4
    table = CapLogTable(build_log_tables(order, samples=2048), order)
    p = np.zeros((1, 3))
    center, radius = np.array([[0.3, 2.0, -0.4]]), np.array([0.9])
    f = accumulate_log(p, [[0, 1.0, 0]], center, radius, table).astype(np.float64)
    d = np.linalg.norm(center[0])
    g_cap = sh_cap(np.arcsin(radius[0] / d), center[0] / d, order)
    # log is the eigen log with an eigenvalue floor, so compare with the log of the cap
    np.testing.assert_allclose(f[0], log(g_cap), atol=2e-3)
    np.testing.assert_allclose(exp(f, "exact")[0], g_cap, atol=5e-3)


def test_zero_radius_spheres_contribute_nothing():
    table = CapLogTable(build_log_tables(4), 4)
    pts = np.random.default_rng(0).normal(size=(10, 3))
    f = accumulate_log(pts, np.tile([0, 1.0, 0], (10, 1)), np.ones((5, 3)) * 4, np.zeros(5),
                       table)
    assert np.all(f == 0)


def test_log_table_interpolation_matches_direct_log():
    """The 1 - cos(theta) table against the eigen log of the cap computed directly."""
    order = 4
    table = CapLogTable(build_log_tables(order, samples=256), order)
    theta = np.linspace(0.01, 1.5, 37)
    direct = log(sh_cap(theta, np.array([0.0, 0.0, 1.0]), order))  # (T, n*n)
    m0 = np.arange(order) * (np.arange(order) + 1)
    want = direct[:, m0] * np.sqrt(4 * np.pi / (2 * np.arange(order) + 1))
    got = table.lookup(1 - np.cos(theta)).T
    # linear interpolation of a 256-sample table: error ~ (pi/512)^2 * |f''| / 8
    np.testing.assert_allclose(got, want, atol=2e-3 * np.abs(want).max())


def test_clustered_tiles_equal_per_cluster_accumulation():
    """Tiling clusters into padded blocks gives the per-cluster sums exactly (float32)."""
    rng = np.random.default_rng(5)
    order = 4
    table = CapLogTable(build_log_tables(order), order)
    sizes = [3, 70, 33, 1]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    n_v = offsets[-1]
    perm = rng.permutation(n_v)
    pts = rng.normal(size=(n_v, 3))
    nrm = rng.normal(size=(n_v, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    cuts = [rng.integers(1, 12) for _ in sizes]
    s_max = max(cuts)
    cen = rng.normal(size=(len(sizes), s_max, 3)) * 2
    rad = rng.uniform(0.1, 0.8, size=(len(sizes), s_max))
    wts = rng.uniform(0.5, 1.5, size=(len(sizes), s_max, order))
    for c, k in enumerate(cuts):
        rad[c, k:] = 0.0
    got = accumulate_clusters(pts, nrm, perm, offsets, cen, rad, wts, np.array(cuts), table,
                              chunk_pairs=300)
    for c in range(len(sizes)):
        rows = perm[offsets[c]:offsets[c + 1]]
        want = accumulate_log(pts[rows], nrm[rows], cen[c, :cuts[c]], rad[c, :cuts[c]], table,
                              weights=wts[c, :cuts[c]])
        # both are float32 sums of the same terms in different block orders: rounding only
        np.testing.assert_allclose(got[rows], want, rtol=1e-5, atol=1e-5)


def test_threaded_accumulation_and_exp_equal_single_thread():
    """Two worker threads produce exactly the single-thread result."""
    from shtools.reference.scenes import capsule_scene
    from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker

    sc = capsule_scene(grid=20)
    blockers = [SphereBlocker(sc.centers, sc.radii)]
    results = []
    for threads in (1, 2):
        rt = ShadowRuntime(ShadowSettings(order=4, acc_order=4, threads=threads,
                                          chunk_pairs=1024, vertices_per_cluster=50))
        results.append(rt.visibility(sc.vertices, sc.normals, blockers))
    np.testing.assert_array_equal(results[0], results[1])
    from shtools.runtime.fast_exp import fast_exp
    from shtools.sh.tables import default_tables

    f = np.random.default_rng(1).normal(size=(300, 16)).astype(np.float32)
    for method in ("hyb", "ps*"):
        one = fast_exp(f, method, default_tables(4), chunk=64, threads=1)
        two = fast_exp(f, method, default_tables(4), chunk=64, threads=2)
        np.testing.assert_array_equal(one, two)


def test_ratio_table_lookup_matches_float64_table():
    """The kernel's x * G_l(cell) form against the float64 linear interpolation."""
    order = 6
    tables = build_log_tables(order)
    table = CapLogTable(tables, order)
    x = np.random.default_rng(2).uniform(0.0, 1.0, 20_000) ** 3  # dense near small caps
    # the table's definition: linear interpolation in x of the source samples
    x_src = np.concatenate([[0.0], 1.0 - np.cos(tables["theta"])])
    want = np.stack([np.interp(x, x_src, np.concatenate([[0.0], tables["log_zh"][:, l]]))
                     for l in range(order)])
    got = table.lookup_ratio(x)
    # piecewise-constant ratio over 16384 cells: error <= |G'| x / (2 * 16384), measured
    # below 6e-4 of each band's largest value; 1e-3 leaves room for float32 rounding
    scale = np.abs(table.values64).max(axis=1)[:, None]
    assert np.all(np.abs(got - want) < 1e-3 * scale)
    # and small caps keep their relative accuracy (the ratio is exact in the limit)
    small = x < 1e-3
    rel = np.abs(got[:, small] - want[:, small]) / np.maximum(np.abs(want[:, small]), 1e-30)
    assert np.median(rel) < 1e-4  # float32 rounding and 1/K cells: ~1e-5 measured
