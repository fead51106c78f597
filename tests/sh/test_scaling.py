"""SH scaling matrices (Wang et al.): structure, maps, brute-force projection, duality."""

import math

import numpy as np
import pytest
from scipy.special import sph_harm_y

from shtools.sh import scaling as S

#: M is a sum of ~400 products of terms <= ~2 per entry; float64 round-off.
ROUNDOFF = 1e-12


def scipy_real_basis(theta, phi, order):
    """Real SH in the project convention from scipy's complex Y (docs/conventions.md)."""
    out = []
    for l in range(order):
        for m in range(-l, l + 1):
            y = sph_harm_y(l, abs(m), theta, phi)
            if m == 0:
                out.append(y.real)
            elif m > 0:
                out.append(math.sqrt(2) * (-1) ** m * y.real)
            else:
                out.append(math.sqrt(2) * (-1) ** m * y.imag)
    return np.stack(out, axis=-1)


def brute_force_matrix(k, order, function, alpha=math.pi / 4, energy=False):
    """Column j = 2-D (theta, phi) quadrature projection of y_j(phi_k(theta), phi) Lambda/sin.

    Independent of the 1-D code: scipy basis, a 2-D product rule, the map written
    out from geometry below (``reference_map``).
    """
    nt, nphi = 1500, 2 * order + 3  # uniform phi exact for |m1 +- m2| < nphi
    x, w = np.polynomial.legendre.leggauss(nt)
    theta = 0.5 * math.pi * (x + 1)
    wt = 0.5 * math.pi * w
    phi = 2 * math.pi * (np.arange(nphi) + 0.5) / nphi
    warped, dwarp = reference_map(theta, k, function, alpha)
    lam = np.sin(warped) * dwarp if energy else np.sin(theta)
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    ww, _ = np.meshgrid(wt * lam, phi, indexing="ij")
    y_out = scipy_real_basis(tt, pp, order)  # (nt, nphi, n^2)
    y_in = scipy_real_basis(np.meshgrid(warped, phi, indexing="ij")[0], pp, order)
    return np.einsum("tpi,tpj,tp->ij", y_out, y_in, ww) * (2 * math.pi / nphi)


def reference_map(theta, k, function, alpha):
    """phi_k(theta) written independently, derivative by central differences.

    cone: the spec's formula tan(phi) = k tan(t) / (1 + (1-k) cot(alpha) tan(t)) with
    the quadrant fixed by the signs of its numerator and denominator (times cos t);
    mid-range: ray-sphere intersection solved as a generic quadratic.
    """
    def phi_of(t):
        if function == "cone":
            num = k * np.sin(t)
            den = np.cos(t) + (1 - k) / math.tan(alpha) * np.sin(t)
            return np.where(den > 0, np.arctan(num / den),
                            np.where(den < 0, np.arctan(num / den) + math.pi, math.pi / 2))
        # receiver at (0,0,k) inside a unit sphere, ray at angle t from +z: solve
        # |p + s u|^2 = 1 for s > 0; phi is the polar angle of the hit point
        u = np.stack([np.sin(t), np.cos(t)])
        b = 2 * k * u[1]
        c = k * k - 1
        s = (-b + np.sqrt(b * b - 4 * c)) / 2
        hit = np.array([[0.0], [k]]) + s * u
        return np.arctan2(hit[0], hit[1])

    h = 1e-6
    return phi_of(theta), (phi_of(theta + h) - phi_of(theta - h)) / (2 * h)


def cone_hit_map(theta, k, alpha):
    """The cone map from ray casting: receiver at distance k (bounding radius 1) on +z,
    theta from the direction towards the centre; the ray hits the cone of half-angle
    alpha (apex at the centre, about +z); phi is the angle at which the sample point at
    distance 1 sees the same cone point.  Only rays that hit the near nappe (s > 0)."""
    ta = math.tan(alpha)
    s = ta * k / (np.sin(theta) + ta * np.cos(theta))
    hx, hz = s * np.sin(theta), k - s * np.cos(theta)
    valid = (s > 0) & (hz > 0)
    return np.arctan2(hx, 1 - hz), valid


@pytest.mark.parametrize("order", range(1, 7))
def test_pattern_count_and_m_selection(order):
    rows, cols = S.scaling_pattern(order)
    assert len(rows) == order * (2 * order**2 + 1) // 3 == S.pattern_size(order)
    assert len(set(zip(rows.tolist(), cols.tolist(), strict=True))) == len(rows)
    l_r, l_c = np.floor(np.sqrt(rows)), np.floor(np.sqrt(cols))
    np.testing.assert_array_equal(rows - l_r * (l_r + 1), cols - l_c * (l_c + 1))


def test_seed_count_44_at_order_4():
    assert S.pattern_size(4) == 44  # Wang et al.'s figure, "less than one-fifth" of 256


@pytest.mark.parametrize("function,k", [("cone", 0.3), ("cone", 2.5), ("midrange", 0.5),
                                        ("midrange", 0.9)])
@pytest.mark.parametrize("energy", [False, True])
def test_every_column_against_brute_force_projection(function, k, energy):
    order = 4
    brute = brute_force_matrix(k, order, function, energy=energy)
    ours = S.scaling_matrix([k], order, function, energy_preserving=energy)[0]
    # reference derivative by central differences (h = 1e-6): error ~1e-10 relative
    np.testing.assert_allclose(ours, brute, atol=1e-8)
    # positions outside the m-pattern are zero in the brute-force matrix too
    mask = np.ones_like(brute, dtype=bool)
    rows, cols = S.scaling_pattern(order)
    mask[rows, cols] = False
    assert np.max(np.abs(brute[mask])) < 1e-10


@pytest.mark.parametrize("alpha", [math.pi / 6, math.pi / 4, math.pi / 3])
def test_cone_map_against_ray_cast_cone(alpha):
    theta = np.linspace(0.01, math.pi - 0.01, 400)
    for k in (0.2, 0.7, 1.6, 5.0):
        phi, dphi = S.angular_map(theta, [k], "cone", alpha)
        hit, valid = cone_hit_map(theta, k, alpha)
        assert valid.sum() > 50
        np.testing.assert_allclose(phi[0][valid], hit[valid], atol=1e-12)
        ref, dref = reference_map(theta, k, "cone", alpha)
        np.testing.assert_allclose(phi[0], ref, atol=1e-12)
        np.testing.assert_allclose(dphi[0], dref, rtol=1e-6)  # central differences


def test_cone_map_matches_the_seed_formula_at_45_degrees():
    # seed: theta' = arctan(k tan(theta) / (1 + tan(theta) - k tan(theta))), where the
    # denominator is positive (the printed branch)
    theta = np.linspace(0.01, 1.2, 50)
    for k in (0.5, 2.0):
        t = np.tan(theta)
        den = 1 + t - k * t
        ok = den > 0
        printed = np.arctan(k * t[ok] / den[ok])
        np.testing.assert_allclose(S.angular_map(theta, [k])[0][0][ok], printed, atol=1e-14)


def test_midrange_map_matches_the_seed_formula_and_geometry():
    theta = np.linspace(0.01, math.pi - 0.01, 200)
    for k in (0.25, 0.6, 0.95):
        phi, dphi = S.angular_map(theta, [k], "midrange")
        cot = 1 / np.tan(theta)
        printed = 2 * np.arctan((np.sqrt(cot**2 + 1 - k * k) - cot) / (1 + k))
        np.testing.assert_allclose(phi[0], printed, atol=1e-12)
        ref, dref = reference_map(theta, k, "midrange", None)
        np.testing.assert_allclose(phi[0], ref, atol=1e-12)
        np.testing.assert_allclose(dphi[0], dref, rtol=1e-6)
        # phi(pi/2) = acos k
        assert S.angular_map([math.pi / 2], [k], "midrange")[0][0, 0] == pytest.approx(
            math.acos(k), abs=1e-14)


def test_cone_map_inverse_and_composition():
    theta = np.linspace(0, math.pi, 101)
    a = 0.6
    phi2 = S.angular_map(theta, [2.0], "cone", a)[0][0]
    back = S.angular_map(phi2, [0.5], "cone", a)[0][0]
    np.testing.assert_allclose(back, theta, atol=1e-13)
    both = S.angular_map(S.angular_map(theta, [1.5], "cone", a)[0][0], [2.0], "cone", a)[0][0]
    np.testing.assert_allclose(both, S.angular_map(theta, [3.0], "cone", a)[0][0], atol=1e-13)


@pytest.mark.parametrize("order", [1, 4, 6])
def test_identity_k_gives_identity(order):
    for energy in (False, True):
        np.testing.assert_allclose(
            S.scaling_matrix([1.0], order, "cone", energy_preserving=energy)[0],
            np.eye(order * order), atol=ROUNDOFF)
        np.testing.assert_allclose(
            S.scaling_matrix([0.0], order, "midrange", energy_preserving=energy)[0],
            np.eye(order * order), atol=ROUNDOFF)


@pytest.mark.parametrize("alpha", [math.pi / 6, math.pi / 4, 1.3])
def test_energy_preserving_is_plain_of_inverse_transposed(alpha):
    order = 5
    for k in (0.3, 1.7, 5.0):
        m_e = S.scaling_matrix([k], order, "cone", alpha=alpha, energy_preserving=True)[0]
        m_p = S.scaling_matrix([1 / k], order, "cone", alpha=alpha)[0]
        np.testing.assert_allclose(m_e, m_p.T, atol=ROUNDOFF)


@pytest.mark.parametrize("function,k", [("cone", 0.4), ("cone", 6.0), ("midrange", 0.8)])
def test_structure_e0_and_plus_minus_m(function, k):
    order = 5
    m_p = S.scaling_matrix([k], order, function)[0]
    m_e = S.scaling_matrix([k], order, function, energy_preserving=True)[0]
    e0 = np.eye(order * order)[0]
    np.testing.assert_allclose(m_p[:, 0], e0, atol=ROUNDOFF)  # a constant warps to itself
    np.testing.assert_allclose(m_e[0], e0, atol=ROUNDOFF)  # the integral is kept
    for l_out in range(order):
        for l_in in range(order):
            for m in range(1, min(l_out, l_in) + 1):
                i, j = l_out * l_out + l_out, l_in * l_in + l_in
                assert m_p[i + m, j + m] == pytest.approx(m_p[i - m, j - m], abs=ROUNDOFF)
    # cone: the e0 column holds the only exact zeros (n-1 of the pattern, spec 2.3a);
    # the mid-range map has more (measured: M[(4,m),(1,m)] = 0 for |m| <= 1 at n = 5)
    rows, cols = S.scaling_pattern(order)
    zeros = np.sum(np.abs(m_p[rows, cols]) < 1e-12)
    if function == "cone":
        assert zeros == order - 1
    else:
        assert zeros >= order - 1


def test_truncation_breaks_composition():
    # spec 2.1: M(2) M(1.5) != M(3) at n = 4 (0.16), although the maps compose exactly
    m = S.scaling_matrix([2.0, 1.5, 3.0], 4)
    assert np.max(np.abs(m[0] @ m[1] - m[2])) == pytest.approx(0.16, abs=0.01)


def test_quadrature_error_is_measured_and_small():
    # spec 2.2: 400 nodes give <= 1e-12 against 4000; 100 nodes are not enough at k = 1/8
    assert S.quadrature_error([1 / 8, 2, 8], 4, "cone", nodes=400) < 1e-12
    assert S.quadrature_error([0.95, 0.99], 4, "midrange", nodes=400) < 1e-12
    assert S.quadrature_error([1 / 8], 4, "cone", nodes=100) > 1e-6


def test_k_samples_contain_identity_and_bad_ranges():
    k, spacing = S.k_samples("cone", 40, 1 / 8, 8)
    assert spacing == "geometric-through-1" and k.size == 40 and 1.0 in k.tolist()
    assert np.all(np.diff(k) > 0) and k[0] == pytest.approx(1 / 8) and k[-1] == pytest.approx(8)
    k, _ = S.k_samples("midrange", 40, 0, 0.95)
    assert k[0] == 0 and k[-1] == pytest.approx(0.95) and np.all(np.diff(k) > 0)
    for args in [("cone", 40, 2, 1), ("cone", 40, 1.5, 8), ("midrange", 40, 0, 1.0),
                 ("midrange", 40, 0.1, 0.9), ("midrange", 40, 0.9, 0.1)]:
        with pytest.raises(ValueError):
            S.k_samples(*args)
    for alpha in (0.0, math.pi / 2, -0.1, 2.0):
        with pytest.raises(ValueError, match="alpha"):
            S.build_scaling_table(4, "cone", alpha=alpha)
