"""Ng et al.'s Haar triple and double products against brute-force sums of reconstructed maps.

The reference reconstructs every function from the explicit basis images
(built from the basis' definition in ``test_haar.haar_basis``, not from the
transform) and sums products over the map's pixels, so it shares no code
with the parent-child rules under test.
"""

from __future__ import annotations

import itertools

import numpy as np

from shtools.fields.sampling import direction_map
from shtools.runtime.haar_triple import haar_product, haar_triple, tripling_coefficient

from .test_haar import haar_basis


def _positions(n):
    return [(r, c) for r in range(n) for c in range(n)]


def test_tripling_coefficients_are_the_integrals_of_three_basis_images():
    n = 4
    basis = haar_basis(n)
    pos = _positions(n)
    brute = np.einsum("iab,jab,kab->ijk", basis, basis, basis)
    got = np.array([[[tripling_coefficient(i, j, k, n) for k in pos] for j in pos] for i in pos])
    # both are sums of a few exact binary fractions: equal to rounding
    np.testing.assert_allclose(got, brute, atol=1e-12)
    assert np.count_nonzero(np.abs(brute) > 1e-12) < brute.size / 10  # sparse, as Ng's theorem says


def test_tripling_coefficients_at_a_finer_size_on_random_triples():
    n = 16
    basis = haar_basis(n)
    pos = _positions(n)
    rng = np.random.default_rng(5)
    picks = rng.integers(0, n * n, size=(600, 3))
    # nested triples are rare among random picks: add parent-child ones on purpose
    nested = [(0, 17, 17), (2, 9, 9), (1, 1, 0), (4, 33, 33),
              (16 * 3 + 5, 16 * 9 + 10, 16 * 9 + 10)]
    for i, j, k in itertools.chain(picks, nested):
        brute = float((basis[i] * basis[j] * basis[k]).sum())
        got = tripling_coefficient(pos[i], pos[j], pos[k], n)
        assert abs(got - brute) < 1e-12, (pos[i], pos[j], pos[k], got, brute)


def _recon(coeffs, basis):
    return np.einsum("...k,kab->...ab", coeffs.reshape(*coeffs.shape[:-2], -1), basis)


def test_triple_product_equals_quadrature_of_the_three_reconstructed_functions():
    n = 16
    basis = haar_basis(n)
    rng = np.random.default_rng(7)
    # a sparse visibility (5 % kept), a dense light with one bright cell, a cosine transfer
    vis = np.zeros((6, n * n))
    for row in vis:
        row[rng.choice(n * n, 13, replace=False)] = rng.normal(size=13)
    vis = vis.reshape(6, n, n)
    light = rng.random((n, n))
    light[3, 5] = 500.0
    light_c = np.einsum("kab,ab->k", basis, light).reshape(n, n)
    dirs, w = direction_map(n)
    normals = rng.normal(size=(6, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    transfer = (np.maximum(normals @ dirs.T, 0) * w).reshape(6, n, n)
    transfer_c = np.einsum("kab,pab->pk", basis, transfer).reshape(6, n, n)
    got = haar_triple(light_c, vis, transfer_c)
    brute = (_recon(light_c, basis) * _recon(vis, basis) * _recon(transfer_c, basis)).sum((-2, -1))
    # the same finite sum in two orders: rounding only
    np.testing.assert_allclose(got, brute, rtol=1e-10, atol=1e-10)
    # and it is the solid-angle integral of light x visibility x cosine (weights in T)
    direct = (light * _recon(vis, basis) * transfer).sum((-2, -1))
    np.testing.assert_allclose(got, direct, rtol=1e-10, atol=1e-10)


def test_triple_product_broadcasts_rgb_light_over_receivers():
    n = 8
    rng = np.random.default_rng(1)
    light = rng.normal(size=(3, n, n))
    a = rng.normal(size=(4, 1, n, n))
    b = rng.normal(size=(4, 1, n, n))
    got = haar_triple(light, a, b)
    assert got.shape == (4, 3)
    basis = haar_basis(n)
    brute = (_recon(light, basis)[None] * _recon(a, basis) * _recon(b, basis)).sum((-2, -1))
    np.testing.assert_allclose(got, brute, rtol=1e-10, atol=1e-10)


def test_haar_product_is_the_projection_of_the_product_of_reconstructed_maps():
    n = 16
    basis = haar_basis(n)
    rng = np.random.default_rng(11)
    a = rng.normal(size=(3, n, n))
    b = np.zeros((3, n * n))
    for row in b:
        row[rng.choice(n * n, 20, replace=False)] = rng.normal(size=20)
    b = b.reshape(3, n, n)
    prod_map = _recon(a, basis) * _recon(b, basis)
    brute = np.einsum("kab,pab->pk", basis, prod_map).reshape(3, n, n)
    np.testing.assert_allclose(haar_product(a, b), brute, atol=1e-10)
    # three occluders: the products chain (associative up to rounding)
    c = rng.normal(size=(3, n, n))
    brute3 = np.einsum("kab,pab->pk", basis, prod_map * _recon(c, basis)).reshape(3, n, n)
    np.testing.assert_allclose(haar_product(haar_product(a, b), c), brute3, atol=1e-9)
