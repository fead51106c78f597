"""Lat-long projection against closed forms and an independent per-pixel quadrature."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import eval_legendre

from shtools.lighting import (
    environment_rotation,
    latlong_directions,
    pixel_solid_angles,
    project_latlong,
)
from shtools.sh.basis import basis

#: Rounding budget for exact results: sums of ~1e4 float64 terms of size <= 1.
EXACT_TOL = 1e-12


def cap_closed_form(alpha, axis, order):
    """SH of the indicator of a cap of radius ``alpha`` about ``axis`` (no library code).

    Zonal coefficients: ``g_0 = 2 pi (1 - cos a) Y_00`` and, for ``l >= 1``,
    ``g_l = 2 pi sqrt((2l+1)/4pi) (P_{l-1}(cos a) - P_{l+1}(cos a)) / (2l+1)``;
    rotated to ``axis`` by ``f_lm = sqrt(4 pi/(2l+1)) g_l y_lm(axis)``.
    """
    t = np.cos(alpha)
    g = np.zeros(order)
    g[0] = 2 * np.pi * (1 - t) / np.sqrt(4 * np.pi)
    for l in range(1, order):
        g[l] = (2 * np.pi * np.sqrt((2 * l + 1) / (4 * np.pi))
                * (eval_legendre(l - 1, t) - eval_legendre(l + 1, t)) / (2 * l + 1))
    l = np.repeat(np.arange(order), 2 * np.arange(order) + 1)
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.sqrt(4 * np.pi / (2 * l + 1)) * g[l] * basis(axis, order)


def test_pixel_solid_angles_sum_to_the_sphere():
    w = pixel_solid_angles(7, 14)
    assert w.sum() == pytest.approx(4 * np.pi, rel=EXACT_TOL)
    # row band of the top row: 2 pi (1 - cos(pi/7)) / 14 per pixel
    assert w[0, 0] == pytest.approx(2 * np.pi * (1 - np.cos(np.pi / 7)) / 14, rel=EXACT_TOL)


@pytest.mark.parametrize(("height", "order"), [(4, 3), (16, 6), (33, 8)])
def test_constant_sky_is_pure_dc(height, order):
    """A constant sky c gives exactly (c sqrt(4 pi), 0, ...) at any resolution."""
    colour = np.array([0.5, 2.0, 7.25])
    image = np.broadcast_to(colour, (height, 2 * height, 3))
    coeffs = project_latlong(image, order)
    np.testing.assert_allclose(coeffs[0], colour * np.sqrt(4 * np.pi), rtol=EXACT_TOL)
    np.testing.assert_allclose(coeffs[1:], 0.0, atol=EXACT_TOL * colour.max())


@pytest.mark.parametrize("rows", [1, 5, 12])
def test_cap_about_up_aligned_with_rows_is_exact(rows):
    """Whole top rows form an exact cap about +y: closed form to rounding."""
    height, order = 16, 7
    image = np.zeros((height, 2 * height, 1))
    image[:rows] = 3.0
    coeffs = project_latlong(image, order)[:, 0]
    expected = 3.0 * cap_closed_form(np.pi * rows / height, [0, 1, 0], order)
    np.testing.assert_allclose(coeffs, expected, atol=EXACT_TOL * 10)


def test_tilted_cap_converges_to_closed_form_as_resolution_grows():
    """A rasterised cap (pixel centres inside) tends to the closed form.

    The only error is the staircase along the cap's rim, about one pixel wide,
    so it shrinks roughly like 1/H; at 256x128 it is ~0.4 %, we allow 0.6 %.
    """
    axis = np.array([0.3, 0.5, -0.8])
    axis /= np.linalg.norm(axis)
    alpha, order = 0.4, 6
    expected = cap_closed_form(alpha, axis, order)
    errors = []
    for height in (32, 64, 128):
        d = latlong_directions(height, 2 * height)
        image = (d @ axis > np.cos(alpha)).astype(float)[..., None]
        c = project_latlong(image, order)[:, 0]
        errors.append(np.linalg.norm(c - expected) / np.linalg.norm(expected))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 6e-3


@pytest.mark.parametrize(("height", "order", "nodes"), [(6, 5, 12), (2, 8, 40)])
def test_exact_per_pixel_integrals_match_brute_force_quadrature(height, order, nodes):
    """Independent check of the whole mapping and the per-pixel integrals.

    Each pixel is integrated with a nodes x nodes Gauss-Legendre rule in
    (theta, phi), evaluating the basis at the documented world direction
    (-sin t sin p, cos t, sin t cos p) with weight sin t: a different code path
    (no separation, no frame change).  The node counts make that rule accurate
    to ~1e-15 even on the coarse 4x2 image at order 8 (huge pixels, where the
    projection must add polar nodes); we allow 1e-12.
    """
    rng = np.random.default_rng(7)
    width = 2 * height
    image = rng.uniform(0, 4, size=(height, width, 2))
    x, w = np.polynomial.legendre.leggauss(nodes)
    expected = np.zeros((order * order, 2))
    for i in range(height):
        t = np.pi * (i + 0.5 * (x + 1)) / height
        for j in range(width):
            p = 2 * np.pi * (j + 0.5 * (x + 1)) / width
            tt, pp = np.meshgrid(t, p, indexing="ij")
            d = np.stack([-np.sin(tt) * np.sin(pp), np.cos(tt), np.sin(tt) * np.cos(pp)], -1)
            ww = np.outer(w, w) * np.sin(tt) * (np.pi / height / 2) * (np.pi / width)
            expected += np.einsum("ab,abk->k", ww, basis(d, order))[:, None] * image[i, j]
    np.testing.assert_allclose(project_latlong(image, order), expected, atol=1e-12)


def _band1_direction(coeffs):
    v = np.array([coeffs[3], coeffs[1], coeffs[2]])  # y(1,1)~x, y(1,-1)~y, y(1,0)~z
    return v / np.linalg.norm(v)


@pytest.mark.parametrize(
    ("u", "v", "direction"),
    [(0.5, 0.5, (0, 0, -1)), (0.75, 0.5, (1, 0, 0)), (0.25, 0.5, (-1, 0, 0)),
     (0.0, 0.5, (0, 0, 1)), (0.5, 0.0, (0, 1, 0))],
)
def test_orientation_of_the_mapping(u, v, direction):
    """Image centre -> -z, right of centre -> +x, edges -> +z, top -> +y."""
    height = 16
    image = np.zeros((height, 2 * height, 1))
    row = min(int(v * height), height - 1)
    col = int(u * 2 * height)
    if v == 0.0:
        image[:2] = 1.0
    else:
        for c in (col - 1, col):  # two columns straddling u, two rows straddling v
            image[row - 1 : row + 1, c % (2 * height)] = 1.0
    coeffs = project_latlong(image, 2)[:, 0]
    np.testing.assert_allclose(_band1_direction(coeffs), direction, atol=1e-12)


def test_rotate_y_equals_rolling_the_image():
    """Rolling columns right by W/4 turns the environment by -90 degrees about +y.

    An exact identity of the piecewise-constant image, so rounding tolerance.
    """
    rng = np.random.default_rng(1)
    image = rng.uniform(size=(8, 16, 3))
    rolled = project_latlong(np.roll(image, 4, axis=1), 6)
    rotated = project_latlong(image, 6, rotation=environment_rotation(-90.0))
    np.testing.assert_allclose(rotated, rolled, atol=EXACT_TOL)


def test_mirror_equals_flipping_the_image():
    rng = np.random.default_rng(2)
    image = rng.uniform(size=(8, 16, 3))
    flipped = project_latlong(image[:, ::-1], 5)
    mirrored = project_latlong(image, 5, rotation=environment_rotation(0.0, mirror=True))
    np.testing.assert_allclose(mirrored, flipped, atol=EXACT_TOL)
