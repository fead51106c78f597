"""Shading (Sec. 7) against shtools.sh.triple and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shtools.runtime import ShadowRuntime, ShadowSettings, SphereLight
from shtools.runtime.shading import (
    cosine_transfer,
    light_matrices,
    on_the_fly_radiance,
    shade,
    tabulated_radiance,
)
from shtools.sh import (
    apply_window,
    cap,
    clamped_cosine_zh,
    product,
    project,
    sphere_quadrature,
    triple,
)

#: float32 shading arithmetic on values of order 1.
SHADE_TOL = 2e-5


def _random(order, v=40, seed=0):
    rng = np.random.default_rng(seed)
    n2 = order * order
    g = rng.normal(size=(v, n2)) * 0.3
    g[:, 0] += 2.5
    env = rng.normal(size=(n2, 3)) * 0.2
    env[0] += 3.0
    nrm = rng.normal(size=(v, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return g, env, nrm


@pytest.mark.parametrize("order", [3, 4])
def test_tabulated_and_on_the_fly_forms_equal_the_triple_product(order):
    g, env, nrm = _random(order)
    h = cosine_transfer(nrm, order).astype(np.float64)
    mats = light_matrices(env)
    want = np.stack([triple(h, np.broadcast_to(env[:, c], g.shape), g) for c in range(3)], 1)
    np.testing.assert_allclose(tabulated_radiance(h, mats, g), want, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(on_the_fly_radiance(h, mats, g), want, rtol=1e-10, atol=1e-10)


def test_shade_windows_light_and_visibility():
    order = 4
    g, env, nrm = _random(order, seed=1)
    got = shade(g, np.zeros_like(nrm), nrm, env, order=order, window_kind="cosine")
    h = cosine_transfer(nrm, order).astype(np.float64)
    gw = apply_window(g, "cosine")
    want = np.stack([triple(h, np.broadcast_to(apply_window(env[:, c], "cosine"), g.shape), gw)
                     for c in range(3)], 1)
    np.testing.assert_allclose(got, want, rtol=SHADE_TOL, atol=SHADE_TOL)


def test_unshadowed_uniform_white_sky_gives_radiance_one():
    # (1/pi) * integral of max(0, N.s) over the sphere = 1 for a white Lambertian receiver
    order = 4
    rt = ShadowRuntime(ShadowSettings(order=order, window=None))
    nrm = np.array([[0.0, 1.0, 0.0], [0.6, 0.0, 0.8]])
    g = np.zeros((2, 16))
    g[:, 0] = math.sqrt(4 * math.pi)
    env = np.zeros((16, 3))
    env[0] = math.sqrt(4 * math.pi)
    # the runtime shades in float32 (relative rounding ~1e-7 over 16 terms)
    np.testing.assert_allclose(rt.shade(g, np.zeros((2, 3)), nrm, env), 1.0, rtol=1e-6)


def test_baked_local_visibility_uses_h_times_gp():
    order = 4
    g, env, nrm = _random(order, seed=2)
    gp, _, _ = _random(order, seed=3)
    got = shade(g, np.zeros_like(nrm), nrm, env, order=order, window_kind=None,
                local_visibility=gp)
    hp = product(cosine_transfer(nrm, order).astype(np.float64), gp)
    want = np.stack([triple(hp, np.broadcast_to(env[:, c], g.shape), g) for c in range(3)], 1)
    # float32 shading path vs the float64 triple product
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4)


def test_sphere_light_matches_quadrature_projection_of_the_light_cap():
    """A spherical light's per-vertex SH radiance vs projecting its cap by quadrature."""
    order = 4
    light = SphereLight((1.0, 3.0, -0.5), 0.6, (2.0, 1.0, 0.5))
    pts = np.array([[0.0, 0.0, 0.0], [2.0, 0.5, 1.0], [-1.0, 0.2, 0.3]])
    nrm = np.array([[0.0, 1.0, 0.0], [0.0, 0.8, 0.6], [0.6, 0.8, 0.0]])
    g = np.zeros((3, 16))
    g[:, 0] = math.sqrt(4 * math.pi)
    got = shade(g, pts, nrm, None, [light], order=order, window_kind=None)
    dirs, w = sphere_quadrature(400)  # discontinuous cap: dense rule, error ~1e-3
    for k in range(3):
        to = light.position - pts[k]
        dist = np.linalg.norm(to)
        inside = dirs @ (to / dist) >= math.cos(math.asin(light.radius / dist))
        l_sh = project(inside.astype(float), dirs, w, order)
        h = cosine_transfer(nrm[k:k + 1], order)[0].astype(np.float64)
        want = triple(h, l_sh, g[k]) * light.color
        # the reference projects a discontinuous cap by quadrature (error ~1e-3, above)
        np.testing.assert_allclose(got[k], want, rtol=2e-3, atol=2e-4)


def test_sphere_light_overhead_matches_closed_form_when_small():
    """Light straight above, unshadowed: (H_n, L, 1) = integral of H_n over the light's cap.

    For a small cap that is the solid angle times H_n at the pole, where H_n is the
    order-n truncation of max(0, cos)/pi: H_n(pole) = sum_l h_l sqrt((2l+1)/(4 pi)).
    The cap (0.1 rad) is small enough that H_n varies < 0.5% over it.
    """
    order = 4
    light = SphereLight((0.0, 4.0, 0.0), 0.4, (1.0, 1.0, 1.0))
    g = np.zeros((1, 16))
    g[0, 0] = math.sqrt(4 * math.pi)
    got = shade(g, np.zeros((1, 3)), [[0.0, 1.0, 0.0]], None, [light], order=order,
                window_kind=None)
    theta = math.asin(0.4 / 4.0)
    solid_angle = 2 * math.pi * (1 - math.cos(theta))
    h_pole = sum(h * math.sqrt((2 * l + 1) / (4 * math.pi))
                 for l, h in enumerate(clamped_cosine_zh(order)))
    assert got[0, 0] == pytest.approx(solid_angle * h_pole, rel=5e-3)
    # and the truncated H is within 7% of the exact (1/pi) max(0, cos) = 1/pi at the pole
    assert h_pole == pytest.approx(1 / math.pi, rel=0.07)


def test_cap_visibility_dims_a_sky():
    """Visibility of a blocking cap overhead reduces the radiance by its cosine-weighted share."""
    order = 4
    theta = 0.5
    g = cap(np.array([theta]), np.array([[0.0, 1.0, 0.0]]), order)
    env = np.zeros((16, 3))
    env[0] = math.sqrt(4 * math.pi)  # uniform sky of radiance 1
    got = shade(g, np.zeros((1, 3)), [[0.0, 1.0, 0.0]], env, order=order, window_kind=None)
    # unshadowed 1 minus the blocked cosine-weighted part sin^2(theta); order-4 truncation
    # of the cap and H leaves a few percent
    assert got[0, 0] == pytest.approx(1 - math.sin(theta) ** 2, rel=0.05)


@pytest.mark.parametrize("change", ["normals", "light"])
def test_cached_tables_follow_changed_normals_and_lights(change):
    """The runtime keeps H(N) and L_H of static receivers while the light is unchanged;
    turned normals and a new light must be re-evaluated."""
    order = 4
    g, env, nrm = _random(order, seed=4)
    settings = ShadowSettings(order=order, acc_order=order)
    rt = ShadowRuntime(settings)
    pts = np.zeros_like(nrm)
    rt.shade(g, pts, nrm, env)
    if change == "normals":
        nrm = nrm.copy()
        nrm[::3] = nrm[::3, [2, 0, 1]]  # some receivers turn
    else:
        env = env[:, ::-1] * 0.5
    got = rt.shade(g, pts, nrm, env)
    fresh = ShadowRuntime(settings).shade(g, pts, nrm, env)
    # the tables are float32 and a matrix product over a subset of rows may round
    # differently from the full product (BLAS kernel choice): a few ulp
    np.testing.assert_allclose(got, fresh, rtol=1e-6, atol=1e-6)
    # and the tabulated cache equals the on-the-fly form of the same light
    otf = rt.shade(g, pts, nrm, env, form="on_the_fly")
    np.testing.assert_allclose(got, otf, rtol=1e-5, atol=1e-5)  # float32 sums, other order


@pytest.mark.parametrize("order", [2, 4, 6])  # one quadrature class below order 5, four above
@pytest.mark.parametrize("environment", ["distant", "per-vertex", "none"])
def test_shading_matrix_is_the_linear_map_of_shade(order, environment):
    """``K g`` equals ``shade(g)`` for random visibility (any g: the map is linear), with
    the environment at infinity or per vertex and two spherical lights, one of them
    around some receivers; ``shade`` evaluates the triple product by quadrature, ``K``
    through its symmetry."""
    from shtools.runtime.shading import shading_matrix

    rng = np.random.default_rng(order)
    g, env, nrm = _random(order, v=300, seed=order)
    g = g.astype(np.float32)
    pts = rng.normal(size=(300, 3))
    env = {"distant": env, "none": None,
           "per-vertex": env[None] + rng.normal(size=(300, order * order, 3)) * 0.1}[environment]
    lights = [SphereLight([1.0, 2.0, 0.5], 0.3, [5.0, 4.0, 3.0]),
              SphereLight([0.0, 0.0, 0.0], 0.8, [1.0, 2.0, 3.0])]  # some receivers inside
    for window in ("cosine", None):
        ref = shade(g, pts, nrm, env, lights, order=order, window_kind=window)
        K = shading_matrix(pts, nrm, env, lights, order=order, window_kind=window)
        assert K.shape == (300, 3, order * order) and K.dtype == np.float32
        # float32 sums of n*n terms in another order than shade's (values of order 1-10)
        np.testing.assert_allclose(np.einsum("vcj,vj->vc", K, g), ref, rtol=1e-5,
                                   atol=1e-5 * np.max(np.abs(ref)))
