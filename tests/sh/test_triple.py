"""The triple-product tensor against Gaunt coefficients, products against quadrature."""

import functools
import math

import numpy as np
import pytest

from benchmarks import unrolled_kernel  # noqa: F401  (registers "unrolled": the benchmarks' kernel)
from shtools.sh import (
    basis,
    product,
    product_matrix,
    project,
    reconstruct,
    sphere_quadrature,
    square,
    triple,
    triple_tensor,
)
from shtools.sh._kernels import run_product

# Sums of a few hundred float64 terms of size O(1): round-off stays below this.
ROUNDOFF = 1e-12
# Gaunt values have |Γ| > 4e-3 when nonzero; anything below 1e-9 is a zero.
GAUNT_ZERO = 1e-9


@functools.cache
def wigner_3j(j1, j2, j3, m1, m2, m3):
    """Wigner 3j symbol by Racah's closed formula (exact integers until the final sqrt)."""
    if m1 + m2 + m3 != 0 or not abs(j1 - j2) <= j3 <= j1 + j2:
        return 0.0
    if abs(m1) > j1 or abs(m2) > j2 or abs(m3) > j3:
        return 0.0
    f = math.factorial
    delta = f(j1 + j2 - j3) * f(j1 - j2 + j3) * f(-j1 + j2 + j3) / f(j1 + j2 + j3 + 1)
    pref = (-1) ** (j1 - j2 - m3) * math.sqrt(
        delta * f(j1 + m1) * f(j1 - m1) * f(j2 + m2) * f(j2 - m2) * f(j3 + m3) * f(j3 - m3))
    total = 0
    for k in range(0, j1 + j2 - j3 + 1):
        args = (k, j3 - j2 + k + m1, j3 - j1 + k - m2, j1 + j2 - j3 - k, j1 - k - m1, j2 - k + m2)
        if min(args) < 0:
            continue
        total += (-1) ** k / math.prod(f(a) for a in args)
    return pref * total


def real_gaunt_tensor(order):
    """Γ of the real basis from complex Gaunt coefficients and the real/complex unitary map.

    Complex (Condon–Shortley) Y: integral Y1 Y2 Y3 = sqrt((2l1+1)(2l2+1)(2l3+1)/(4 pi))
    (l1 l2 l3; 0 0 0)(l1 l2 l3; m1 m2 m3).  Real y without the phase (docs/conventions.md):
    y_{l,m>0} = ((-1)^m Y^m + Y^-m)/sqrt2, y_{l,-m} = ((-1)^m Y^m - Y^-m)/(i sqrt2).
    """
    lm = [(l, m) for l in range(order) for m in range(-l, l + 1)]
    size = len(lm)
    u = np.zeros((size, size), complex)  # y_real[a] = sum_b u[a, b] Y[b]
    for a, (l, m) in enumerate(lm):
        pos, neg = lm.index((l, abs(m))), lm.index((l, -abs(m)))
        if m == 0:
            u[a, a] = 1
        elif m > 0:
            u[a, pos], u[a, neg] = (-1) ** m / math.sqrt(2), 1 / math.sqrt(2)
        else:
            u[a, pos], u[a, neg] = (-1) ** m / (1j * math.sqrt(2)), -1 / (1j * math.sqrt(2))
    g = np.zeros((size, size, size))
    for a, (l1, m1) in enumerate(lm):
        for b, (l2, m2) in enumerate(lm):
            for c, (l3, m3) in enumerate(lm):
                if m1 + m2 + m3 == 0 and (l1 + l2 + l3) % 2 == 0:
                    g[a, b, c] = (math.sqrt((2 * l1 + 1) * (2 * l2 + 1) * (2 * l3 + 1)
                                            / (4 * math.pi))
                                  * wigner_3j(l1, l2, l3, 0, 0, 0)
                                  * wigner_3j(l1, l2, l3, m1, m2, m3))
    real = np.einsum("ai,bj,ck,ijk->abc", u, u, u, g)
    assert np.abs(real.imag).max() < ROUNDOFF
    return real.real


def test_gamma_matches_gaunt_and_counts_at_order_4():
    t = triple_tensor(4)
    dense = t.todense()
    ref = real_gaunt_tensor(4)
    np.testing.assert_allclose(dense, ref, atol=ROUNDOFF)
    ref_nonzero = np.abs(ref) > GAUNT_ZERO
    i, j, k = np.nonzero(ref_nonzero)
    # The figures, recomputed here from Wigner 3j symbols: 353 ordered
    # nonzeros among the 16^3 entries, 77 of them with i <= j <= k.  (The paper's
    # table says 369 for n = 4; the real-basis Gaunt count is 353.)
    assert ref_nonzero.sum() == 353
    assert np.sum((i <= j) & (j <= k)) == 77
    assert t.nnz == 353


@pytest.mark.parametrize("order", [2, 5, 8])
def test_gamma_symmetric_and_selection_rules(order):
    dense = triple_tensor(order).todense()
    for perm in [(0, 2, 1), (1, 0, 2), (2, 1, 0), (1, 2, 0)]:
        np.testing.assert_array_equal(dense, dense.transpose(perm))
    band = np.repeat(np.arange(order), 2 * np.arange(order) + 1)
    li, lj, lk = np.meshgrid(band, band, band, indexing="ij")
    allowed = ((li + lj + lk) % 2 == 0) & (np.abs(lj - lk) <= li) & (li <= lj + lk)
    assert not np.any(dense[~allowed])


def test_gamma_with_higher_output_order_extends_square_tensor():
    small = triple_tensor(3).todense()
    big = triple_tensor(3, out_order=4).todense()
    assert big.shape == (16, 9, 9)
    np.testing.assert_allclose(big[:9], small, atol=ROUNDOFF)
    # order 4 out, not 5: the independent Gaunt reference costs ~n^9 (20 s at 5 under load)
    np.testing.assert_allclose(big, real_gaunt_tensor(4)[:, :9, :9], atol=ROUNDOFF)


@pytest.mark.parametrize("order", [1, 2, 4, 6, 8])
def test_product_matches_quadrature_of_reconstructions(order):
    rng = np.random.default_rng(order)
    f, g = rng.normal(size=(2, 7, order * order))
    dirs, w = sphere_quadrature(3 * (order - 1))
    ref = project(reconstruct(f, dirs) * reconstruct(g, dirs), dirs, w, order)
    np.testing.assert_allclose(product(f, g), ref, atol=ROUNDOFF * order**2)
    np.testing.assert_allclose(square(f), project(reconstruct(f, dirs) ** 2, dirs, w, order),
                               atol=ROUNDOFF * order**2)
    mf = product_matrix(f)
    np.testing.assert_allclose(mf, np.swapaxes(mf, -1, -2), atol=ROUNDOFF)
    np.testing.assert_allclose(np.einsum("bij,bj->bi", mf, g), ref, atol=ROUNDOFF * order**2)


@pytest.mark.parametrize(("order", "out_order"), [(1, 1), (3, 3), (4, 4), (4, 7), (6, 6)])
def test_sparse_and_cp_kernels_match_quadrature(order, out_order):
    # Every kernel is exact (the benchmarks' generated one too: its timings compare exact
    # products); compare each with the quadrature of the pointwise product.
    rng = np.random.default_rng(out_order)
    f, g = rng.normal(size=(2, 300, order * order))
    dirs, w = sphere_quadrature(out_order - 1 + 2 * (order - 1))
    ref = project(reconstruct(f, dirs) * reconstruct(g, dirs), dirs, w, out_order)
    ref_sq = project(reconstruct(f, dirs) ** 2, dirs, w, out_order)
    for kernel in ("cp", "sparse", "unrolled"):
        np.testing.assert_allclose(run_product(f, g, order, out_order, kernel), ref,
                                   atol=ROUNDOFF * order**2)
        np.testing.assert_allclose(run_product(f, None, order, out_order, kernel), ref_sq,
                                   atol=ROUNDOFF * order**2)
        f32 = f.astype(np.float32)
        # float32: 6e-8 relative per operation, ~100 terms of size ~3 -> < 1e-4
        np.testing.assert_allclose(run_product(f32, f32, order, out_order, kernel), ref_sq,
                                   atol=1e-4)


def test_product_at_full_order_is_pointwise_product():
    # Two order-4 functions multiply to an order-7 function: no truncation, so the
    # reconstruction equals the pointwise product at arbitrary directions.
    rng = np.random.default_rng(7)
    f, g = rng.normal(size=(2, 3, 16))
    d = rng.normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    full = product(f, g, order=7)
    assert full.shape == (3, 49)
    np.testing.assert_allclose(full @ basis(d, 7).T, (f @ basis(d, 4).T) * (g @ basis(d, 4).T),
                               atol=1e-11)
    # truncating the accumulated product gives the order-4 product
    np.testing.assert_allclose(full[:, :16], product(f, g), atol=ROUNDOFF)


def test_product_mixed_orders_broadcast_and_float32():
    rng = np.random.default_rng(8)
    f = rng.normal(size=(4, 1, 16))
    g = rng.normal(size=(5, 9))
    padded = np.zeros((5, 16))
    padded[:, :9] = g
    out = product(f, g)
    assert out.shape == (4, 5, 16)
    np.testing.assert_allclose(out, product(np.broadcast_to(f, (4, 5, 16)), padded),
                               atol=ROUNDOFF)
    out32 = product(f.astype(np.float32), padded.astype(np.float32))
    assert out32.dtype == np.float32
    # float32 has 6e-8 relative precision; 100 terms of size ~3 accumulate < 1e-4.
    np.testing.assert_allclose(out32, out, atol=1e-4)


def test_triple_integral_against_quadrature():
    rng = np.random.default_rng(9)
    a, b, c = rng.normal(size=(3, 6, 25))
    dirs, w = sphere_quadrature(12)
    ref = np.sum(w * reconstruct(a, dirs) * reconstruct(b, dirs) * reconstruct(c, dirs), axis=-1)
    np.testing.assert_allclose(triple(a, b, c), ref, atol=1e-11)
