"""Frame changes of SH vectors and inline coefficients."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.errors import InputError
from shtools.lighting import (
    RH_NAMES,
    frame_transform_matrix,
    light_from_coefficients,
    rotation_about_y,
)
from shtools.lighting.frames import Z_UP_TO_Y_UP
from shtools.sh.basis import basis

#: float64 rounding of a 64x64 quadrature-built matrix.
ROUNDING = 1e-12


def _random_dirs(rng, k):
    d = rng.normal(size=(k, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


@pytest.mark.parametrize(
    "m",
    [rotation_about_y(33.0), Z_UP_TO_Y_UP, np.diag([-1.0, 1.0, 1.0]),
     np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])],
    ids=["rot-y", "z-up", "mirror-x", "swap-xz"],
)
def test_transform_moves_the_function(m):
    """f'(M s) = f(s): checked by evaluating the basis at random directions."""
    rng = np.random.default_rng(5)
    order = 6
    f = rng.normal(size=order * order)
    moved = frame_transform_matrix(m, order) @ f
    s = _random_dirs(rng, 50)
    np.testing.assert_allclose(basis(s @ m.T, order) @ moved, basis(s, order) @ f,
                               atol=ROUNDING * 100)


def test_transform_refuses_non_orthogonal():
    with pytest.raises(ValueError, match="orthogonal"):
        frame_transform_matrix(np.diag([1.0, 2.0, 1.0]), 3)


def test_rotation_about_y_sign():
    np.testing.assert_allclose(rotation_about_y(90) @ [0, 0, -1], [-1, 0, 0], atol=1e-15)


def test_inline_flat_passes_through_and_grey_replicates():
    rng = np.random.default_rng(0)
    c = rng.normal(size=(16, 3))
    np.testing.assert_array_equal(light_from_coefficients(c.tolist()), c)
    grey = light_from_coefficients([1.0, 0.0, 0.5, 0.0], scale=2.0)
    np.testing.assert_array_equal(grey, [[2.0] * 3, [0.0] * 3, [1.0] * 3, [0.0] * 3])


def test_inline_rh_names_are_the_flat_order():
    """R&H basis: L1m1~y, L10~z, L11~x, L2m2~xy, L2m1~yz, L20~3z^2-1, L21~xz, L22~x^2-y^2.

    Evaluate each named polynomial (constants from R&H / probes_sh.json) at
    random directions and compare with the shtools basis row of that name.
    """
    polys = {
        "L00": lambda x, y, z: 0.282095 + 0 * x,
        "L1m1": lambda x, y, z: 0.488603 * y,
        "L10": lambda x, y, z: 0.488603 * z,
        "L11": lambda x, y, z: 0.488603 * x,
        "L2m2": lambda x, y, z: 1.092548 * x * y,
        "L2m1": lambda x, y, z: 1.092548 * y * z,
        "L20": lambda x, y, z: 0.315392 * (3 * z * z - 1),
        "L21": lambda x, y, z: 1.092548 * x * z,
        "L22": lambda x, y, z: 0.546274 * (x * x - y * y),
    }
    s = _random_dirs(np.random.default_rng(3), 20)
    y = basis(s, 3)
    for i, name in enumerate(RH_NAMES):
        # 6 printed digits in the R&H constants
        np.testing.assert_allclose(y[:, i], polys[name](*s.T), atol=5e-6)
    named = {name: [i, 2 * i, 3 * i] for i, name in enumerate(RH_NAMES)}
    named["L1-1"] = named.pop("L1m1")
    np.testing.assert_array_equal(light_from_coefficients(named, layout="rh"),
                                  [[i, 2 * i, 3 * i] for i in range(9)])


def test_inline_z_up_light_from_above_ends_up_at_plus_y():
    """A Z-up set whose light comes from +z must light the Y-up world from +y."""
    order = 3
    up_z = basis(np.array([0.0, 0.0, 1.0]), order)  # a lobe towards +z (source frame)
    world = light_from_coefficients(np.repeat(up_z[:, None], 3, 1), frame="z-up")
    s = _random_dirs(np.random.default_rng(4), 40)
    # f_world(s) = f_src(M^T s)
    np.testing.assert_allclose(basis(s, order) @ world[:, 0],
                               basis(s @ Z_UP_TO_Y_UP, order) @ up_z, atol=1e-10)
    peak = s[np.argmax(basis(s, order) @ world[:, 0])]
    assert peak[1] > 0.8


@pytest.mark.parametrize(
    ("values", "kwargs", "message"),
    [
        ([[1, 2, 3]] * 8, {}, "not a square number"),
        ([[1, 2, 3]] * 16, {"layout": "rh"}, "has 9 rows"),
        ({"L00": [1, 1, 1]}, {"layout": "rh"}, "missing SH coefficient"),
        ({"L33": [1, 1, 1]}, {"layout": "rh"}, "unknown SH coefficient name"),
        ({"L00": [1, 1, 1]}, {}, "need layout 'rh'"),
        ([[1, 2]] * 4, {}, "rows of \\[r, g, b\\]"),
        ([[1, 2, np.nan]] * 4, {}, "NaN"),
        ([["a", 2, 3]] * 4, {}, "must be numbers"),
        ([[1, 2, 3]] * 4, {"frame": "x-up"}, "unknown SH frame"),
        ([[1, 2, 3]] * 4, {"layout": "zyx"}, "unknown SH layout"),
    ],
)
def test_inline_errors(values, kwargs, message):
    with pytest.raises(InputError, match=message):
        light_from_coefficients(values, **kwargs)
