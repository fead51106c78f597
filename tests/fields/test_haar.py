"""2-D Haar occlusion maps: transform against the explicit basis, truncation, reduction."""

from __future__ import annotations

import math

import numpy as np

from shtools.fields.haar import (
    dequantize_sparse,
    haar2,
    ihaar2,
    kept_count,
    map_l1_error,
    quantize_sparse,
    reconstruct,
    reduce_haar_shell,
    truncate,
    truncated_maps,
)
from shtools.fields.sampling import direction_map


def haar_basis(n: int) -> np.ndarray:
    """Every nonstandard 2-D Haar basis image of an n x n map, built from its definition,
    shape (n*n, n, n), in haar2's coefficient layout."""
    out = np.zeros((n * n, n, n))
    out[0] = 1.0 / n  # the overall scaling function: constant, unit norm
    size = n
    while size > 1:
        h = size // 2  # wavelets of blocks of (n/h) x (n/h) pixels, h x h of them
        side = n // h
        for i in range(h):
            for j in range(h):
                img = np.zeros((n, n))
                blk = img[i * side:(i + 1) * side, j * side:(j + 1) * side]
                half = side // 2
                amp = 1.0 / side  # unit norm over side**2 pixels
                signs = {"h": ((1, -1), (1, -1)), "v": ((1, 1), (-1, -1)),
                         "d": ((1, -1), (-1, 1))}
                for name, (top, bottom) in signs.items():
                    b = np.zeros_like(blk)
                    b[:half, :half], b[:half, half:] = top[0] * amp, top[1] * amp
                    b[half:, :half], b[half:, half:] = bottom[0] * amp, bottom[1] * amp
                    row, col = {"h": (i, h + j), "v": (h + i, j), "d": (h + i, h + j)}[name]
                    out[row * n + col][i * side:(i + 1) * side, j * side:(j + 1) * side] = b
        size = h
    return out


def test_haar_coefficients_are_inner_products_with_the_explicit_basis():
    rng = np.random.default_rng(3)
    n = 8
    maps = rng.random((5, n, n))
    basis = haar_basis(n)
    # the explicit basis is orthonormal (independent check of the construction)
    gram = basis.reshape(n * n, -1) @ basis.reshape(n * n, -1).T
    np.testing.assert_allclose(gram, np.eye(n * n), atol=1e-12)
    direct = np.einsum("kij,pij->pk", basis, maps)
    np.testing.assert_allclose(haar2(maps).reshape(5, -1), direct, atol=1e-12)
    np.testing.assert_allclose(ihaar2(haar2(maps)), maps, atol=1e-12)


def test_truncated_reconstruction_is_the_sum_of_the_kept_basis_images():
    rng = np.random.default_rng(4)
    n = 16
    maps = (rng.random((3, n, n)) > 0.7).astype(float)  # binary, like visibility
    idx, val = truncate(haar2(maps), kept_count(n, 0.05))
    basis = haar_basis(n)
    direct = np.einsum("pk,pkij->pij", val, basis[idx.astype(np.int64)])
    np.testing.assert_allclose(reconstruct(idx, val, n), direct, atol=1e-12)
    # the kept ones are the largest: no dropped coefficient is bigger than a kept one
    full = np.abs(haar2(maps).reshape(3, -1))
    for p in range(3):
        dropped = np.delete(full[p], idx[p].astype(np.int64))
        assert dropped.max() <= np.abs(val[p]).min() + 1e-12


def test_quantized_values_are_within_half_a_step():
    rng = np.random.default_rng(5)
    n = 16
    idx, val = truncate(haar2(rng.random((6, n, n))), 12)
    assert np.all(idx[:, 0] == 0)  # the scaling coefficient of positive maps is kept first
    qs = quantize_sparse(val)
    back = dequantize_sparse(qs["q"], qs["offset"], qs["step"])
    half = np.where(np.arange(12) == 0, qs["step"][0], qs["step"][1]) / 2
    assert np.all(np.abs(back - val) <= half[None, :] * (1 + 1e-5) + 1e-6)


def test_map_error_is_the_mean_absolute_difference_over_the_sphere():
    dirs, w = direction_map(16)
    a = np.zeros((1, 256))
    b = (dirs[:, 2] > 0).astype(float)[None]  # the upper hemisphere
    # |a - b| is 1 on exactly half of the sphere (the map splits at the equator)
    np.testing.assert_allclose(map_l1_error(a, b, w), [0.5], rtol=1e-12)


def test_haar_reduction_keeps_a_sharp_feature_and_collapses_a_constant():
    _, w = direction_map(8)
    const = np.ones((16, 16, 64))
    red = reduce_haar_shell(const, 0.01, w, keep=0.05, min_resolution=4)
    assert red.resolution == 4 and red.cumulative_error < 1e-12
    sharp = np.ones((16, 16, 64))
    sharp[5, 9, :32] = 0.0  # one sample sees half its map blocked
    sharp = truncated_maps(sharp.reshape(-1, 8, 8), 0.05).reshape(16, 16, 64)
    red = reduce_haar_shell(sharp, 0.01, w, keep=0.05, min_resolution=4)
    assert red.resolution == 16 and red.level_errors[0] >= 0.01
    assert math.isfinite(red.cumulative_error)


def _ground_grid():
    """A 9 x 9 grid of receivers over [-1.2, 1.2]^2 in the plane z = 0, facing +z:
    points and normals, shape (81, 3) each."""
    xs = np.linspace(-1.2, 1.2, 9)
    X, Y = np.meshgrid(xs, xs)
    pts = np.c_[X.ravel(), Y.ravel(), np.zeros(X.size)]
    return pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1))


def test_haar_field_shadow_matches_ray_tracing_under_a_small_bright_light():
    import trimesh

    from shtools.fields.haar import build_haar_field
    from shtools.geometry.raycast import RayCaster
    from shtools.runtime.haar import haar_radiance

    box = trimesh.creation.box((1.0, 0.6, 0.4))
    box.apply_translation([0.0, 0.0, 0.8])
    fld, _ = build_haar_field(box, shells=16, resolution=16, map_size=32, min_resolution=8)
    pts, nrm = _ground_grid()
    dirs, w = direction_map(32)
    # a sun: the cells within 12 degrees of a direction 25 degrees off the zenith
    sun = np.array([math.sin(0.44), 0.0, math.cos(0.44)])
    env = np.where((dirs @ sun > math.cos(0.21))[:, None], 50.0, 0.2) * np.ones((1, 3))
    got = haar_radiance(fld.visibility_maps(pts), env, nrm, dirs, w)
    # reference: the same cell-constant light, the box ray traced at 4 x 4 directions
    # per cell (the Haar map holds each cell's mean visibility)
    fine, fw = direction_map(128)
    cell = (np.floor(np.arccos(np.clip(fine[:, 2], -1, 1)) / math.pi * 32).astype(int) * 32
            + np.floor((np.arctan2(fine[:, 1], fine[:, 0]) % (2 * math.pi)) / (2 * math.pi)
                       * 32).astype(int))
    vis = RayCaster(box.vertices, box.faces).visibility(pts, fine)
    ref = (vis * np.maximum(nrm @ fine.T, 0) * fw) @ env[cell] / math.pi
    err = np.linalg.norm(got - ref) / np.linalg.norm(ref)
    # 5 % of a 32 x 32 map's coefficients, coarse 16 x 16 shells, cell-centre cosines
    # and 8-bit values (2.2 % measured); an order-4 SH map could not hold a 12-degree sun
    assert err < 0.05, err


def test_two_haar_occluders_combine_by_the_product_of_their_maps():
    import trimesh

    from shtools.fields.haar import build_haar_field
    from shtools.geometry.raycast import RayCaster
    from shtools.runtime.haar import haar_radiance

    a = trimesh.creation.box((0.8, 0.4, 0.4))
    a.apply_translation([-0.5, 0.0, 0.7])
    b = trimesh.creation.icosphere(2, radius=0.3)
    b.apply_translation([0.5, 0.2, 0.9])
    # 32 shells: the ground reaches 4 bounding radii of each (the paper's 6.4 V_r)
    fa, _ = build_haar_field(a, shells=32, resolution=16, map_size=32, min_resolution=8)
    fb, _ = build_haar_field(b, shells=32, resolution=16, map_size=32, min_resolution=8)
    pts, nrm = _ground_grid()
    dirs, w = direction_map(32)
    env = np.ones((len(dirs), 3))
    got = haar_radiance(fa.visibility_maps(pts) * fb.visibility_maps(pts), env, nrm, dirs, w)
    fine, fw = direction_map(128)
    both = trimesh.util.concatenate([a, b])
    vis = RayCaster(both.vertices, both.faces).visibility(pts, fine)
    ref = (vis * np.maximum(nrm @ fine.T, 0) * fw) @ np.ones((len(fine), 3)) / math.pi
    # a uniform sky: each occluder's truncation and interpolation error, and the product
    # of cell means where both cover part of a cell (the two never overlap much here)
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) < 0.02  # 0.5 % measured
    # and the product darkens more than either alone where both shadow
    one = haar_radiance(fa.visibility_maps(pts), env, nrm, dirs, w)
    assert np.all(got <= one + 1e-9)
