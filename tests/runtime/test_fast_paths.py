"""The runtime's fast paths against the library: split products, truncated exp, culling.

These paths are exact rewrites (symmetry-class quadrature products, a last squaring
projected onto fewer coefficients, per-tile removal of spheres that the self-shadow
rules would remove anyway), so the references are the straightforward computations.
"""

from __future__ import annotations

import numpy as np
import pytest

from shtools.runtime import CapLogTable, apply_self_shadow_rules
from shtools.runtime.fast_exp import QuadratureProducts, fast_exp
from shtools.runtime.tiling import accumulate_clusters
from shtools.sh import band_of, basis, exp, product, square
from shtools.sh.tables import default_tables


@pytest.mark.parametrize("order", [4, 5, 6, 8])
def test_quadrature_products_match_triple_tensor_products(order):
    rng = np.random.default_rng(order)
    f, g = rng.normal(size=(2, 40, order * order))
    ops = QuadratureProducts(order, np.float64)
    # both are exact truncated SH products in float64: agreement to rounding
    np.testing.assert_allclose(ops.product(f, g), product(f, g), atol=1e-11)
    np.testing.assert_allclose(ops.square(f), square(f), atol=1e-11)


@pytest.mark.parametrize("method,order", [("ps*", 6), ("hyb", 6), ("ps*", 5), ("hyb", 4)])
def test_exp_with_out_order_is_the_truncated_exp(method, order):
    rng = np.random.default_rng(7)
    f = rng.normal(size=(50, order * order)) * 0.5
    f[:, 0] -= 1.5
    tables = default_tables(order)
    full = fast_exp(f, method, tables)
    cut = fast_exp(f, method, tables, out_order=4)
    # projecting only the kept coefficients in the last squaring changes nothing else
    np.testing.assert_allclose(cut, full[:, :16], atol=1e-10 * np.abs(full).max())


def test_exp_of_zero_log_is_the_constant_one():
    f = np.zeros((5, 36))
    f[2, 3] = 0.1  # one row that is not skipped
    g = fast_exp(f, "ps*", default_tables(6))
    one = np.zeros(36)
    one[0] = np.sqrt(4 * np.pi)
    np.testing.assert_array_equal(g[[0, 1, 3, 4]], np.tile(one, (4, 1)))
    np.testing.assert_allclose(g[2], exp(f[2], "ps*"), atol=1e-12)


def reference_with_rules(points, normals, centers, radii, tables, order):
    """Eq. 34 sums in float64 with the Sec. 6.2 rules applied pair by pair."""
    out = np.zeros((len(points), order * order))
    theta_grid = np.concatenate([[0.0], tables["theta"]])
    for v, (p, n) in enumerate(zip(points, normals, strict=True)):
        d = centers - p
        dx, dy, dz, r = apply_self_shadow_rules(d[:, 0], d[:, 1], d[:, 2], radii, *n)
        delta = np.stack([dx, dy, dz], axis=-1)
        dist = np.linalg.norm(delta, axis=-1)
        keep = r > 0
        theta = np.arcsin(np.clip(r[keep] / dist[keep], 0, 1))
        zh = np.stack([np.interp(theta, theta_grid,
                                 np.concatenate([[0.0], tables["log_zh"][:, l]]))
                       for l in range(order)], axis=-1)
        out[v] = np.einsum("sk,sk->k", zh[:, band_of(order)],
                           basis(delta[keep] / dist[keep, None], order))
    return out


def test_tile_culling_matches_rules_applied_pair_by_pair():
    """Spheres all around bumpy receivers: many behind, some straddling, some containing."""
    rng = np.random.default_rng(3)
    order = 4
    tables = default_tables(order)
    table = CapLogTable(tables, order)
    n_v = 96
    points = rng.uniform(-1, 1, size=(n_v, 3)) * [2.0, 0.2, 2.0]
    normals = rng.normal(size=(n_v, 3)) * 0.3 + [0, 1, 0]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    centers = rng.uniform(-2.5, 2.5, size=(30, 3)) * [1.0, 0.5, 1.0]
    radii = rng.uniform(0.1, 0.8, 30)
    # two clusters, each with the full sphere list as its cut
    order_idx = np.arange(n_v)
    offsets = np.array([0, n_v // 2, n_v])
    sc = np.broadcast_to(centers, (2, 30, 3)).copy()
    sr = np.broadcast_to(radii, (2, 30)).copy()
    got = accumulate_clusters(points, normals, order_idx, offsets, sc, sr, None,
                              np.array([30, 30]), table, self_shadow=True)
    want = reference_with_rules(points, normals, centers, radii, tables, order)
    # float32 accumulation of ~30 terms and table interpolation in 1-cos vs theta
    # (the same 2e-4 budget as test_accumulate.ACC_RTOL)
    np.testing.assert_allclose(got, want, atol=2e-4 * np.abs(want).max())


@pytest.mark.parametrize("method", ["ps*", "hyb", "ps"])
def test_an_all_zero_log_skips_the_exp(method):
    """A frame no blocker reaches (all-zero logs) is not exponentiated: exp(0) of the
    same method, the same bytes; a log with any non-zero row goes through the exp."""
    from shtools.runtime import ShadowRuntime, ShadowSettings

    rt = ShadowRuntime(ShadowSettings(order=4, exp_method=method, processes=1))
    zeros = np.zeros((30, rt.acc_order ** 2), dtype=np.float32)
    got = rt.exponentiate(zeros)
    np.testing.assert_array_equal(got, rt._exp(zeros))
    want = np.zeros(16)
    want[0] = np.sqrt(4 * np.pi)
    np.testing.assert_allclose(got, np.broadcast_to(want, got.shape), atol=1e-6)
    rng = np.random.default_rng(5)
    f = zeros.copy()
    f[7] = 0.3 * rng.normal(size=f.shape[1])
    np.testing.assert_array_equal(rt.exponentiate(f), rt._exp(f))


def test_half_rule_integrates_even_functions_and_rejects_asymmetric_rules():
    from shtools.runtime.fast_exp import half_rule, lebedev_rule

    dirs, w = half_rule(*lebedev_rule(15))
    assert dirs.shape == (43, 3)
    # every even-band SH up to degree 14 has the integral sqrt(4 pi) delta_l0 (closed
    # form); the Lebedev rule is exact to degree 15, so to rounding
    y = basis(dirs, 15)
    even = band_of(15) % 2 == 0
    want = np.zeros(int(even.sum()))
    want[0] = np.sqrt(4 * np.pi)
    np.testing.assert_allclose(w @ y[:, even], want, atol=1e-13)
    with pytest.raises(ValueError, match="centrally symmetric"):
        half_rule(dirs, w)


def blended_ps2_reference(f, margin):
    """PS*-2 with the squaring count's band blend, written out in float64 with the
    library's tensor products: ``e(x) = 1 + x + x^2 / 2`` at ``x = f_hat / 2^q``,
    blended as ``(1 - w) e(x) + w e(x/2)^2``, squared ``q`` times, times ``exp(dc)``."""
    from shtools.sh.exponential import squaring_weights

    sqrt_4pi = np.sqrt(4 * np.pi)
    f_hat = np.array(f, dtype=np.float64)
    dc = np.exp(f_hat[:, 0] / sqrt_4pi)
    f_hat[:, 0] = 0.0
    q, w = squaring_weights(np.linalg.norm(f_hat, axis=1), margin)
    x = f_hat * np.ldexp(1.0, -q)[:, None]
    one = np.zeros_like(x)
    one[:, 0] = sqrt_4pi
    e = one + x + 0.5 * square(x)
    half = one + 0.5 * x + 0.5 * square(0.5 * x)
    e = (1.0 - w)[:, None] * e + w[:, None] * square(half)
    for k in range(int(q.max())):
        more = q > k
        e[more] = square(e[more])
    return e * dc[:, None], w


@pytest.mark.parametrize("order", [4, 6, 8])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_ps_star_blend_band_is_the_written_out_blend(order, dtype):
    """The runtime's PS*-2 (symmetry-class quadrature products, the band's e(x/2) from
    the square of x it already made) against the blend written out with tensor
    products, on |f_hat| spread over 0.3-20 (squaring counts 0-5 at margin 1, a fifth to
    a quarter of the rows in a band)."""
    rng = np.random.default_rng(order)
    f = rng.normal(size=(300, order * order))
    f[:, 1:] *= (np.exp(rng.uniform(np.log(0.3), np.log(20.0), 300))
                 / np.linalg.norm(f[:, 1:], axis=1))[:, None]
    f[:, 0] = -0.5
    want, w = blended_ps2_reference(f, 1)
    assert 50 < np.count_nonzero((w > 0) & (w < 1)) < 150  # the band is exercised
    got = fast_exp(f.astype(dtype), "ps*", margin=1)
    # float64: both exact truncated products, agreement to rounding over <= 5 squarings;
    # float32: its rounding (1e-7) grown by the squarings (measured <= 4.3e-6 of the peak)
    tol = 1e-10 if dtype == np.float64 else 2e-5
    np.testing.assert_allclose(got, want, atol=tol * np.abs(want).max())


def test_empty_sphere_lists_give_zero_logs():
    """Blocks and clusters with no sphere at all (every cut empty) sum to zero."""
    from shtools.runtime.accumulate import accumulate_blocks

    table = CapLogTable(default_tables(4), 4)
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(2, 8, 3)).astype(np.float32)
    nrm = np.broadcast_to(np.float32([0, 1, 0]), (2, 8, 3)).copy()
    got = accumulate_blocks(pts, nrm, np.zeros((2, 0, 3), np.float32),
                            np.zeros((2, 0), np.float32), table)
    np.testing.assert_array_equal(got, np.zeros((2, 8, 16), np.float32))
    got = accumulate_clusters(pts.reshape(-1, 3), nrm.reshape(-1, 3), np.arange(16),
                              np.array([0, 8, 16]), np.zeros((2, 0, 3)), np.zeros((2, 0)),
                              None, np.array([0, 0]), table)
    np.testing.assert_array_equal(got, np.zeros((16, 16), np.float32))
