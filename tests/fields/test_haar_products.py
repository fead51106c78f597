"""Several all-frequency occluders: products of posed Haar blockers against the product of
maps reconstructed from the explicit basis, and the world-frame resampling of a rotation."""

from __future__ import annotations

import math

import numpy as np
import trimesh

from shtools.fields.haar import build_haar_field
from shtools.runtime.haar import haar2
from shtools.runtime.haar_shading import HaarBlocker, combined_coefficients, combined_maps

from .test_haar import haar_basis

N = 16


def _field(extents):
    fld, _ = build_haar_field(trimesh.creation.box(extents=extents), shells=4, resolution=8,
                              map_size=N, min_resolution=8, threshold=1e-9)
    return fld


def _sample_point(fld, shell, s, t):
    """The object-frame position of sample (s, t) of a shell (cell-centred grid)."""
    R = int(fld.resolution[shell])
    th, ph = (s + 0.5) * math.pi / R, (t + 0.5) * 2 * math.pi / R
    d = np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])
    return fld.center + fld.shell_radii[shell] * d


def _explicit_map(fld, shell, s, t, basis):
    """The stored map of one sample: dequantized kept coefficients times the basis images."""
    R = int(fld.resolution[shell])
    vals = fld.values(shell)[s * R + t].astype(np.float64)
    idx = np.asarray(fld.index[shell][s, t], dtype=np.int64)
    return np.einsum("k,kab->ab", vals, basis[idx]).ravel()


def test_two_occluders_multiply_like_their_reconstructed_maps():
    basis = haar_basis(N)
    a, b = _field((0.8, 0.5, 0.6)), _field((0.3, 1.2, 0.4))
    # b sits so that one world point is sample (2, 5) of a's shell 1 and sample (6, 1) of
    # b's shell 2: each lookup is that one stored sample
    p = _sample_point(a, 1, 2, 5)
    offset = p - _sample_point(b, 2, 6, 1)
    ba = HaarBlocker.from_matrix(a, np.eye(4))
    m = np.eye(4)
    m[:3, 3] = offset
    bb = HaarBlocker.from_matrix(b, m)
    want = _explicit_map(a, 1, 2, 5, basis) * _explicit_map(b, 2, 6, 1, basis)
    # float32 dequantized values, float64 sums: rounding only
    np.testing.assert_allclose(combined_maps([ba, bb], p[None])[0], want, atol=1e-5)
    coeff = combined_coefficients([ba, bb], p[None])
    np.testing.assert_allclose(coeff[0], haar2(want.reshape(N, N)), atol=1e-5)


def test_a_rotation_by_one_cell_about_z_shifts_the_world_map_by_one_column():
    a = _field((0.8, 0.5, 0.6))
    ang = 2 * math.pi / N
    rot = np.eye(4)
    rot[:2, :2] = [[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]]
    p_local = _sample_point(a, 1, 3, 2) + np.array([0.01, 0.02, 0.0])
    world = rot[:3, :3] @ p_local
    plain = HaarBlocker.from_matrix(a, np.eye(4)).maps(p_local[None])[0].reshape(N, N)
    turned = HaarBlocker.from_matrix(a, rot).maps(world[None])[0].reshape(N, N)
    # world column t looks along the object's column t - 1
    np.testing.assert_allclose(turned, np.roll(plain, 1, axis=1), atol=1e-9)


def test_sparse_triple_product_equals_the_cell_wise_sum():
    from shtools.runtime.haar_shading import TripleShader, shade_cells

    a = _field((0.8, 0.5, 0.6))
    m = np.eye(4)
    m[:3, 3] = [0.1, -0.2, 0.9]
    blk = HaarBlocker.from_matrix(a, m)
    rng = np.random.default_rng(2)
    pts = rng.uniform(-1.5, 1.5, size=(40, 3))
    pts[:, 2] = -0.1
    nrm = np.tile([0.0, 0.0, 1.0], (40, 1))
    nrm[::3] = [0.3, 0.0, 0.954]
    env = rng.random((N * N, 3))
    env[37] = 300.0  # a sun in one cell
    cells = shade_cells(combined_maps([blk], pts), env, nrm)
    shader = TripleShader(env)
    # float32 lit transfer: rounding only
    np.testing.assert_allclose(shader.radiance_sparse(*blk.sparse_terms(pts), nrm), cells,
                               rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(shader.radiance(blk.coefficients(pts), nrm), cells,
                               rtol=1e-5, atol=1e-6)
