"""Sphere quadrature exactness, basis orthonormality, projection/reconstruction."""

import math

import numpy as np
import pytest

from shtools.sh import basis, project, reconstruct, sphere_quadrature

# Quadrature sums of O(100) terms of size O(1): float64 round-off stays below this.
ROUNDOFF = 1e-12


def monomial_integral(a, b, c):
    """Closed form of the integral of x^a y^b z^c over the unit sphere (Folland 2001)."""
    if a % 2 or b % 2 or c % 2:
        return 0.0
    beta = [(e + 1) / 2 for e in (a, b, c)]
    return 2 * math.prod(math.gamma(t) for t in beta) / math.gamma(sum(beta))


@pytest.mark.parametrize("degree", [0, 1, 4, 7, 10])
def test_quadrature_integrates_monomials_exactly(degree):
    dirs, w = sphere_quadrature(degree)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=ROUNDOFF)
    for a in range(degree + 1):
        for b in range(degree + 1 - a):
            for c in range(degree + 1 - a - b):
                got = np.sum(w * dirs[:, 0] ** a * dirs[:, 1] ** b * dirs[:, 2] ** c)
                assert got == pytest.approx(monomial_integral(a, b, c), abs=ROUNDOFF)


def test_quadrature_is_not_exact_beyond_its_degree():
    # The check above can fail: one degree more is visibly wrong (z^2 with degree 1).
    dirs, w = sphere_quadrature(1)
    assert abs(np.sum(w * dirs[:, 2] ** 2) - monomial_integral(0, 0, 2)) > 0.1


@pytest.mark.parametrize("order", range(1, 9))
def test_basis_orthonormal_under_quadrature(order):
    dirs, w = sphere_quadrature(2 * (order - 1))
    y = basis(dirs, order)
    gram = y.T @ (w[:, None] * y)
    np.testing.assert_allclose(gram, np.eye(order * order), atol=ROUNDOFF)


def test_project_reconstruct_round_trip_and_constant():
    rng = np.random.default_rng(1)
    order = 5
    coeffs = rng.normal(size=(3, 2, order * order))
    dirs, w = sphere_quadrature(2 * (order - 1))
    values = reconstruct(coeffs, dirs)
    assert values.shape == (3, 2, dirs.shape[0])
    np.testing.assert_allclose(project(values, dirs, w, order), coeffs, atol=ROUNDOFF)
    one = project(np.ones(dirs.shape[0]), dirs, w, order)
    np.testing.assert_allclose(one, np.eye(order * order)[0] * math.sqrt(4 * math.pi),
                               atol=ROUNDOFF)


def test_bad_degree_rejected():
    with pytest.raises(ValueError, match="degree"):
        sphere_quadrature(-1)
