"""SH rotation: caps, pointwise identity, composition, orthogonality."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from shtools.sh import basis, cap, rotate, rotation_matrix

# Rotation matrices come from an exact quadrature; float64 round-off of sums of
# ~n^2 terms of size < 2 stays below this up to order 8.
ROUNDOFF = 1e-12


def random_rotations(seed, count):
    return Rotation.random(count, random_state=seed).as_matrix()


@pytest.mark.parametrize("order", range(1, 9))
def test_rotated_cap_is_cap_about_rotated_axis(order):
    rng = np.random.default_rng(order)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    for R in random_rotations(order, 3):
        np.testing.assert_allclose(rotate(cap(0.7, axis, order), R), cap(0.7, R @ axis, order),
                                   atol=ROUNDOFF)


def test_rotated_function_pointwise():
    # (rotate f)(R s) = f(s) at arbitrary directions: a check that does not use any
    # quadrature, only the (scipy-verified) basis.
    rng = np.random.default_rng(11)
    order = 6
    f = rng.normal(size=(4, order * order))
    s = rng.normal(size=(40, 3))
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    R = random_rotations(11, 1)[0]
    lhs = rotate(f, R) @ basis(s @ R.T, order).T
    np.testing.assert_allclose(lhs, f @ basis(s, order).T, atol=1e-11)


def test_composition_orthogonality_and_identity():
    order = 5
    r1, r2 = random_rotations(3, 2)
    d1, d2 = rotation_matrix(r1, order), rotation_matrix(r2, order)
    np.testing.assert_allclose(rotation_matrix(r1 @ r2, order), d1 @ d2, atol=ROUNDOFF)
    np.testing.assert_allclose(d1 @ d1.T, np.eye(order * order), atol=ROUNDOFF)
    np.testing.assert_allclose(rotation_matrix(np.eye(3), order), np.eye(order * order),
                               atol=ROUNDOFF)
    np.testing.assert_allclose(rotation_matrix(r1.T, order), d1.T, atol=ROUNDOFF)


def test_batched_rotations_and_bad_input():
    order = 3
    rs = random_rotations(5, 4)
    d = rotation_matrix(rs, order)
    assert d.shape == (4, 9, 9)
    np.testing.assert_allclose(d[2], rotation_matrix(rs[2], order), atol=ROUNDOFF)
    f = np.random.default_rng(5).normal(size=(4, 9))
    np.testing.assert_allclose(rotate(f, rs)[1], rotate(f[1], rs[1]), atol=ROUNDOFF)
    with pytest.raises(ValueError, match="rotation"):
        rotate(f, np.diag([1.0, 1.0, -1.0]))
