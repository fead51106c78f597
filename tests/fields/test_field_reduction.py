"""Adaptive reduction (Tamura Sec. 4), eq. (1) and quantization vs independent computations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shtools.fields import l1_error, quantize, reduce_shell
from shtools.fields.quantize import dequantize
from shtools.fields.reduction import box2
from shtools.fields.sampling import grid_directions
from shtools.sh import basis, sphere_quadrature

ORDER = 3
K = ORDER * ORDER


def upsample_by_hand(coarse):
    """Coarse (r, r, K) at the 2r x 2r cell centres: weights 3/4, 1/4 per axis (the spec's
    separable rule), theta clamped at the poles, phi wrapped -- written without the lookup."""
    r = coarse.shape[0]
    out = np.empty((2 * r, 2 * r, coarse.shape[2]))
    for i in range(2 * r):
        near_s = i // 2
        far_s = near_s - 1 if i % 2 == 0 else near_s + 1
        far_s = min(max(far_s, 0), r - 1)  # clamp in theta
        for j in range(2 * r):
            near_t = j // 2
            far_t = (near_t - 1 if j % 2 == 0 else near_t + 1) % r  # wrap in phi
            out[i, j] = (0.75 * 0.75 * coarse[near_s, near_t] + 0.75 * 0.25 * coarse[near_s, far_t]
                         + 0.25 * 0.75 * coarse[far_s, near_t]
                         + 0.25 * 0.25 * coarse[far_s, far_t])
    return out


def l1_by_quadrature(a, b, degree=96):
    """Eq. (1) with a much finer rule (independent of the rule used by the code)."""
    dirs, w = sphere_quadrature(degree)
    y = basis(dirs, ORDER)
    return np.abs((a - b) @ y.T) @ w / (4 * math.pi)


def smooth_field(R=64, wiggle=1.0, seed=0):
    """OCV-like vectors varying smoothly over the shell (a cap whose axis follows the sample)."""
    rng = np.random.default_rng(seed)
    d = grid_directions(R)
    coef = rng.normal(size=(3, K)) * 0.3
    base = np.zeros(K)
    base[0] = math.sqrt(4 * math.pi)
    g = base + wiggle * (d @ coef)
    return g


def test_eq1_quadrature_is_converged():
    # the error's |.| is not polynomial: a rule twice as fine must agree far below tau
    a, b = smooth_field(8), smooth_field(8, seed=1)
    coarse = l1_error(a.reshape(-1, K), b.reshape(-1, K))
    fine = l1_by_quadrature(a.reshape(-1, K), b.reshape(-1, K), degree=64)
    assert np.allclose(coarse, fine, rtol=0.02)  # < 2 % of the error itself


def test_box_average_is_bilinear_at_new_centres():
    g = smooth_field(16)
    assert np.allclose(box2(g)[3, 5], g[6:8, 10:12].mean(axis=(0, 1)), atol=1e-12)


@pytest.mark.parametrize("wiggle,tau", [(0.05, 0.01), (0.3, 0.01), (1.0, 0.005), (3.0, 0.02)])
def test_reduction_never_halves_past_a_point_above_threshold(wiggle, tau):
    g = smooth_field(64, wiggle)
    red = reduce_shell(g, tau, 8)
    assert red.resolution in (8, 16, 32, 64)
    # replay the levels independently: every accepted halving was below tau at every
    # sample of the level it replaced; the first refused one (if any) was not
    current = g
    while current.shape[0] > red.resolution:
        coarse = box2(current)
        err = l1_by_quadrature(upsample_by_hand(coarse).reshape(-1, K), current.reshape(-1, K))
        # the code's rule is degree 32; allow 3 % of tau for the quadrature difference
        assert err.max() < tau * 1.03
        current = coarse
    assert np.allclose(current, red.grid, atol=1e-12)
    if red.resolution > 8:
        coarse = box2(current)
        err = l1_by_quadrature(upsample_by_hand(coarse).reshape(-1, K), current.reshape(-1, K))
        assert err.max() >= tau * 0.97


def test_constant_field_collapses_to_the_floor():
    g = np.tile(np.arange(K, dtype=float), (64, 64, 1))
    red = reduce_shell(g, 0.01, 8)
    assert red.resolution == 8
    assert red.cumulative_error == pytest.approx(0.0, abs=1e-12)


def test_sharp_feature_keeps_full_resolution():
    g = smooth_field(64, 0.01)
    g[40, 17, 0] += 1.0  # one sample sees a much darker sky
    red = reduce_shell(g, 0.01, 8)
    assert red.resolution == 64


def interpolate_with_scipy(coarse, res):
    """Coarse grid at a finer grid's cell centres with scipy: rows padded by copies at the
    poles (theta clamps), columns wrapped (phi), then plain linear interpolation."""
    from scipy.interpolate import RegularGridInterpolator

    r = coarse.shape[0]
    theta = (np.arange(r) + 0.5) * np.pi / r
    phi = (np.arange(r) + 0.5) * 2 * np.pi / r
    padded = np.concatenate([coarse[:, -1:], coarse, coarse[:, :1]], axis=1)
    padded = np.concatenate([padded[:1], padded, padded[-1:]], axis=0)
    th = np.concatenate([[0.0], theta, [np.pi]])
    ph = np.concatenate([[phi[0] - 2 * np.pi / r], phi, [phi[-1] + 2 * np.pi / r]])
    f = RegularGridInterpolator((th, ph), padded)
    t2 = (np.arange(res) + 0.5) * np.pi / res
    p2 = (np.arange(res) + 0.5) * 2 * np.pi / res
    tt, pp = np.meshgrid(t2, p2, indexing="ij")
    return f(np.stack([tt.ravel(), pp.ravel()], axis=-1))


@pytest.mark.parametrize("cumulative", [False, True])
def test_reported_cumulative_error_against_the_initial_samples(cumulative):
    g = smooth_field(64, 1.5)
    red = reduce_shell(g, 0.01, 8, cumulative=cumulative)
    assert red.resolution < 64  # the case is meant to reduce
    up = interpolate_with_scipy(red.grid, 64)
    err = l1_by_quadrature(up, g.reshape(-1, K))
    assert red.cumulative_error == pytest.approx(err.max(), rel=0.03)  # quadrature rules differ
    if cumulative:  # the beyond-paper option bounds the error against the initial samples
        assert err.max() < 0.01 * 1.03


@pytest.mark.parametrize("bits", [8, 4])
def test_quantization_error_is_at_most_half_a_step(bits):
    rng = np.random.default_rng(3)
    g = rng.normal(size=(16, 16, K)) * np.linspace(0.01, 5, K)
    g[..., 4] = 0.7  # a constant coefficient: step 0, exact
    q, off, step = quantize(g, bits)
    back = dequantize(q, off, step)
    # float32 offset/step add ~1e-7 relative round-off on top of step/2
    assert np.all(np.abs(back - g) <= step / 2 + 1e-6 * (1 + np.abs(g)))
    assert step[4] == 0 and np.allclose(back[..., 4], 0.7, atol=1e-7)
    assert q.dtype == np.uint8 and q.max() <= (1 << bits) - 1
