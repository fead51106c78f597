"""Caps, the zonal rotation rule, the clamped cosine and windows against quadrature."""

import math

import numpy as np
import pytest

from shtools.sh import (
    apply_window,
    band_of,
    basis,
    cap,
    cap_zh,
    clamped_cosine_zh,
    project,
    sphere_quadrature,
    window,
    zonal_to_sh,
)

# Gauss–Legendre with 40 nodes on each side of the discontinuity integrates the
# polynomial y_l0 (degree < 8) exactly; what remains is float64 round-off.
ROUNDOFF = 1e-12
# Brute-force quadrature of a discontinuous indicator converges only like
# O(1/degree): at degree 600 the nodes next to the cap boundary misclassify a band
# of ~pi/600 rad, i.e. an area < 0.033 sr where |y| < 0.7, with much cancellation
# (measured ~5e-4).  Wrong signs, bands or normalisation would be O(0.1).
INDICATOR_TOL = 3e-3


def zonal_by_split_gauss(func_of_z, split, order, nodes=40):
    """Coefficients of y_l0 of a z-only function, Gauss–Legendre on [-1, split] and [split, 1]."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    out = np.zeros(order)
    for lo, hi in ((-1.0, split), (split, 1.0)):
        if hi <= lo:
            continue
        z = 0.5 * (hi - lo) * x + 0.5 * (hi + lo)
        wz = 0.5 * (hi - lo) * w * 2 * math.pi  # azimuth integrates to 2 pi
        dirs = np.stack([np.sqrt(1 - z * z), np.zeros_like(z), z], axis=1)
        y = basis(dirs, order)[:, [l * l + l for l in range(order)]]
        out += (wz * func_of_z(z)) @ y
    return out


@pytest.mark.parametrize("order", [1, 2, 4, 8])
def test_cap_zh_matches_split_quadrature_of_indicator(order):
    for theta in [0.0, 0.05, 0.6, 1.0, math.pi / 2, 2.5, math.pi]:
        c = math.cos(theta)
        ref = zonal_by_split_gauss(lambda z, c=c: (z < c).astype(float), c, order)
        np.testing.assert_allclose(cap_zh(theta, order), ref, atol=ROUNDOFF)


def test_cap_about_tilted_axis_matches_brute_force_indicator():
    order = 4
    dirs, w = sphere_quadrature(600)
    rng = np.random.default_rng(3)
    for theta in (0.3, 0.9, 1.6):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        indicator = (dirs @ axis < math.cos(theta)).astype(float)
        np.testing.assert_allclose(cap(theta, axis, order), project(indicator, dirs, w, order),
                                   atol=INDICATOR_TOL)


def test_cap_batched_shapes():
    theta = np.full((2, 3), 0.4)
    axis = np.tile([0.0, 1.0, 0.0], (2, 3, 1))
    assert cap_zh(theta, 5).shape == (2, 3, 5)
    assert cap(theta, axis, 5).shape == (2, 3, 25)


def test_zonal_to_sh_is_projection_of_rotated_zonal_function():
    # A smooth zonal function exp(s . a) of degree-8 polynomial accuracy: compare
    # the rotation rule with direct projection (quadrature exact for the
    # degree-(30 + 7) polynomial part; the exp tail beyond degree 30 is < 1e-25).
    order = 8
    rng = np.random.default_rng(4)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    dirs, w = sphere_quadrature(60)
    direct = project(np.exp(dirs @ axis), dirs, w, order)
    zh = zonal_by_split_gauss(np.exp, 0.0, order)
    np.testing.assert_allclose(zonal_to_sh(zh, axis), direct, atol=ROUNDOFF)


def test_clamped_cosine_against_quadrature_and_known_values():
    order = 8
    zh = clamped_cosine_zh(order)
    ref = zonal_by_split_gauss(lambda z: np.maximum(z, 0) / math.pi, 0.0, order)
    np.testing.assert_allclose(zh, ref, atol=ROUNDOFF)
    # Ramamoorthi & Hanrahan 2001: integral of max(cos, 0) y_l0 is sqrt(pi)/2,
    # sqrt(pi/3), sqrt(5 pi)/8 for l = 0, 1, 2 and 0 for odd l >= 3.
    known = np.array([math.sqrt(math.pi) / 2, math.sqrt(math.pi / 3), math.sqrt(5 * math.pi) / 8])
    np.testing.assert_allclose(zh[:3] * math.pi, known, rtol=ROUNDOFF)
    np.testing.assert_allclose(zh[3::2], 0.0, atol=ROUNDOFF)


def test_windows():
    n = 4
    l = np.arange(n)
    # atol: cos(pi/2) evaluates to 6e-17, the window returns an exact 0 there.
    np.testing.assert_allclose(window(n), np.cos(np.pi / 2 * l / (2 * n)), atol=1e-15)
    np.testing.assert_allclose(window(n, "cosine", h=3), np.cos(np.pi / 2 * l / 3), atol=1e-15)
    np.testing.assert_allclose(window(n, "hann"), 0.5 * (1 + np.cos(np.pi * l / n)))
    np.testing.assert_allclose(window(n, "lanczos", h=2), [1, 2 / np.pi, 0, 0])
    np.testing.assert_array_equal(window(n, None), np.ones(n))
    f = np.arange(2 * n * n, dtype=float).reshape(2, n * n)
    np.testing.assert_allclose(apply_window(f, "hann"), f * window(n, "hann")[band_of(n)])
    with pytest.raises(ValueError, match="unknown window"):
        window(n, "gauss")
