"""The SH basis against scipy's complex harmonics converted to the real convention."""

import numpy as np
import pytest
import scipy.special as sps

from shtools.sh import basis


def real_sh_from_scipy(l, m, dirs):
    """Real SH without Condon–Shortley phase from scipy's complex Y_l^m (which has it)."""
    theta = np.arccos(np.clip(dirs[:, 2], -1, 1))
    phi = np.arctan2(dirs[:, 1], dirs[:, 0])
    y = sps.sph_harm_y(l, abs(m), theta, phi)
    if m > 0:
        return np.sqrt(2) * (-1) ** m * y.real
    if m < 0:
        return np.sqrt(2) * (-1) ** m * y.imag
    return y.real


@pytest.mark.parametrize("order", range(1, 9))
def test_basis_matches_scipy(order):
    rng = np.random.default_rng(order)
    d = rng.normal(size=(500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    got = basis(d, order)
    assert got.shape == (500, order * order)
    for l in range(order):
        for m in range(-l, l + 1):
            # 1e-12: both are float64 evaluations of the same polynomial (|y| < 2 at l < 8)
            np.testing.assert_allclose(got[:, l * l + l + m], real_sh_from_scipy(l, m, d),
                                       atol=1e-12)


def test_signs_follow_xyz():
    c = np.sqrt(3 / (4 * np.pi))
    y = basis(np.eye(3), 2)
    # rows are +x, +y, +z: y(1,-1) ∝ y, y(1,0) ∝ z, y(1,1) ∝ x
    np.testing.assert_allclose(y[:, 1:], c * np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]]),
                               atol=1e-15)


def test_batched_shapes_and_float32():
    d = np.tile(np.array([0.0, 0.0, 1.0], np.float32), (2, 3, 1))
    y = basis(d, 3)
    assert y.shape == (2, 3, 9) and y.dtype == np.float32
