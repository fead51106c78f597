"""SH exp and log against independent references (expm, Bessel closed form, product space)."""

import math

import numpy as np
import pytest
import scipy.linalg
import scipy.special

from shtools.sh import EXP_METHODS, cap, exp, log, product, product_matrix, squarings

SQRT_4PI = math.sqrt(4 * math.pi)


def rel_l2(a, b):
    return np.linalg.norm(a - b, axis=-1) / np.linalg.norm(b, axis=-1)


def random_cap_scenes(rng, n_scenes, order, min_caps=3, max_caps=25, radius=(0.05, 0.6)):
    """Per scene: summed log vectors (log space) and the left-to-right truncated product
    of the cap visibility vectors (product space, the shadow-fields baseline)."""
    counts = rng.integers(min_caps, max_caps + 1, size=n_scenes)
    theta = rng.uniform(*radius, size=(n_scenes, max_caps))
    axes = rng.normal(size=(n_scenes, max_caps, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    present = np.arange(max_caps)[None, :] < counts[:, None]
    g = cap(theta, axes, order)
    g[~present] = 0.0
    g[~present, 0] = SQRT_4PI  # an absent cap is the constant 1 (log 0)
    log_sum = np.where(present[..., None], log(g), 0.0).sum(axis=1)
    accumulated = g[:, 0]
    for i in range(1, max_caps):
        accumulated = product(accumulated, g[:, i])
    return log_sum, accumulated


@pytest.fixture(scope="module")
def scenes():
    return random_cap_scenes(np.random.default_rng(2024), 300, 4)


@pytest.mark.parametrize("order", [1, 4, 8])
def test_exact_equals_matrix_exponential_of_product_matrix(order):
    # eq. 26: exp*(f) = sum_k M_f^k 1 / k! = expm(M_f) 1; scipy's Padé expm is independent
    # of the eigen-decomposition of eq. 28.  Relative 1e-10: both are backward-stable
    # float64 evaluations of an exponential with ||M_f|| < 10.
    rng = np.random.default_rng(order)
    size = order * order
    f = rng.normal(size=(6, size)) / order
    f[:, 0] -= 4.0
    one = np.eye(size)[0] * SQRT_4PI
    ref = np.stack([scipy.linalg.expm(m) @ one for m in product_matrix(f)])
    np.testing.assert_allclose(exp(f, "exact"), ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


def test_ps_of_high_degree_converges_to_exact():
    # PS-p is the truncated series of exp*; at ||f|| ~ 1 the degree-30 tail is < 1e-25.
    rng = np.random.default_rng(1)
    f = rng.normal(size=(5, 25))
    f /= np.linalg.norm(f, axis=1, keepdims=True)
    np.testing.assert_allclose(exp(f, "ps", degree=30), exp(f, "exact"), atol=1e-12)


def test_volterra_matches_bessel_closed_form():
    # f(s) = a/sqrt(4 pi) + beta z: exp(f) has zonal coefficients
    # e^(a/sqrt(4pi)) 2 pi K_l int_-1^1 e^(beta x) P_l(x) dx = ... 4 pi K_l i_l(beta)
    # (modified spherical Bessel).  The default quadrature (degree 42) leaves a Taylor
    # remainder below beta^43/43! ~ 1e-40 of e^beta: float64 round-off remains.
    order = 4
    beta = np.array([0.3, 1.5, 3.0])
    a = np.array([-2.0, 0.0, 1.0])
    k1 = math.sqrt(3 / (4 * math.pi))
    f = np.zeros((3, 16))
    f[:, 0] = a
    f[:, 2] = beta / k1
    got = exp(f, "volterra")
    m0 = [l * l + l for l in range(order)]
    for l in range(order):
        kl = math.sqrt((2 * l + 1) / (4 * math.pi))
        ref = np.exp(a / SQRT_4PI) * 4 * math.pi * kl * scipy.special.spherical_in(l, beta)
        # atol: projection sums of terms up to e^3 ~ 20 leave ~1e-14 absolute round-off
        np.testing.assert_allclose(got[:, m0[l]], ref, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(np.delete(got, m0, axis=1), 0.0, atol=1e-12)


@pytest.mark.parametrize("method", EXP_METHODS)
def test_every_method_exact_on_constants(method):
    # exp of the constant c is e^c: DC isolation makes PS*, OL and HYB exact; PS-8 and
    # the references are exact up to the series remainder (c in [-1, 1]: < 3e-6 / 8!).
    c = np.array([-1.0, 0.0, 0.5, 1.0])
    f = np.zeros((4, 9))
    f[:, 0] = c * SQRT_4PI
    ref = np.zeros((4, 9))
    ref[:, 0] = np.exp(c) * SQRT_4PI
    tol = 1e-5 if method == "ps" else 1e-12
    np.testing.assert_allclose(exp(f, method), ref, atol=tol)


@pytest.mark.parametrize("order", [2, 6, 8])
def test_fast_methods_track_exact_at_other_orders(order):
    # Scenes of 3–8 caps at orders 2, 6, 8, median relative L2 against exp*.  Measured:
    # PS*-2 6e-5, 0.2 %, 0.6 %; HYB 7e-7, 2.1 %, 2.3 % (HYB's error is OL's missing
    # non-DC second-order term, amplified by the squarings).  Bounds: ~2x margin.
    log_sum, _ = random_cap_scenes(np.random.default_rng(order), 40, order, max_caps=8)
    exact = exp(log_sum, "exact")
    assert np.median(rel_l2(exp(log_sum, "ps*"), exact)) < 0.015
    assert np.median(rel_l2(exp(log_sum, "hyb"), exact)) < 0.05


@pytest.mark.parametrize("method", ["ps*", "hyb", "ps"])
def test_methods_close_to_exact_on_cap_scenes(scenes, method):
    # Series and scaling/squaring methods approximate exp* (eq. 28).  Measured medians
    # vs exact: PS-8 < 0.1 %, PS*-2 0.07 %, HYB 2.2 % (OL's linear term); bounds leave
    # ~2x margin.
    log_sum, _ = scenes
    bound = {"ps*": 0.003, "ps": 0.003, "hyb": 0.04}[method]
    assert np.median(rel_l2(exp(log_sum, method), exp(log_sum, "exact"))) < bound


def test_statistical_accuracy_against_product_space(scenes):
    """3–25 caps of radius 0.05–0.6 rad at order 4, relative L2 of log-space
    exponentials against product-space accumulation of the same caps."""
    log_sum, accumulated = scenes
    hyb = rel_l2(exp(log_sum, "hyb", acc_order=6), accumulated)
    ps2 = rel_l2(exp(log_sum, "ps*", degree=2), accumulated)
    paper_hyb = rel_l2(exp(log_sum, "hyb"), accumulated)
    exact = rel_l2(exp(log_sum, "exact"), accumulated)
    # Targets of the issue: HYB median 3 % / p90 7 %, PS*-2 median 2.5 %.  HYB meets
    # them with its squarings accumulated at order 6 (measured 2.9 % / 6.3 % on other
    # seeds; 300 scenes give the median to ~ +-0.2 %).
    assert np.median(hyb) < 0.03 and np.percentile(hyb, 90) < 0.07
    assert np.median(ps2) < 0.025
    # With squarings truncated to order 4 (the paper's HYB) it is measurably worse
    # (3.6 % / 7.7 %) -- guard that figure against regressions.
    assert np.median(paper_hyb) < 0.04 and np.percentile(paper_hyb, 90) < 0.085
    # The log-space floor itself (exact exp*): ~2.1 %; no method can beat it by much.
    assert np.median(exact) < 0.025


def test_ol_accurate_below_4_8_and_not_beyond():
    # Blocker "models": clusters of 2–5 overlapping caps.  The paper reports that the a/b
    # curves fitted on circles hold for other models up to ||f_hat|| ~ 4.8 (Fig. 3).
    # Measured vs exp*: median 0.5–3.2 % per norm bin below 4.8, 19–90 % above.
    rng = np.random.default_rng(5)
    n_scenes, most = 500, 5
    counts = rng.integers(2, most + 1, size=n_scenes)
    centre = rng.normal(size=(n_scenes, 1, 3))
    axes = centre / np.linalg.norm(centre, axis=-1, keepdims=True)
    axes = axes + rng.uniform(0, 0.5, size=(n_scenes, 1, 1)) * rng.normal(size=(n_scenes, most, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    g = cap(rng.uniform(0.1, 1.0, size=(n_scenes, most)), axes, 4)
    present = np.arange(most)[None, :] < counts[:, None]
    f = np.where(present[..., None], log(g), 0.0).sum(axis=1)
    norm = np.linalg.norm(f[:, 1:], axis=1)
    exact = exp(f, "exact")
    err_ol = rel_l2(exp(f, "ol"), exact)
    err_two_term = rel_l2(exp(f, "ps", degree=1), exact)  # 1 + f
    inside, outside = norm < 4.8, norm > 6.0
    assert inside.sum() > 100 and outside.sum() > 100
    assert np.median(err_ol[inside]) < 0.03 and np.percentile(err_ol[inside], 90) < 0.1
    # "much more accurate than the simple two-term series within this domain"
    assert np.median(err_ol[inside]) < 0.25 * np.median(err_two_term[inside])
    assert np.median(err_ol[outside]) > 0.3


@pytest.mark.parametrize(("order", "bound"), [(2, 0.01), (3, 0.01), (4, 0.01), (6, 0.05),
                                             (8, 0.05)])
def test_log_eigen_round_trip_for_caps_up_to_50_degrees(order, bound):
    # exp*(log g) within 1 % of g holds at the paper's low orders: measured
    # max over 0–50 deg 1e-16 (n=2), 9e-5 (n=3), 0.85 % (n=4).  At n >= 5 the 0.02
    # eigenvalue floor clips more of the spectrum: 3.8 % (n=5), 3.2 % (n=6), 2.3 % (n=8).
    rng = np.random.default_rng(order)
    theta = np.linspace(0.01, math.radians(50), 60)
    axes = rng.normal(size=(60, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    g = cap(theta, axes, order)
    assert rel_l2(exp(log(g), "exact"), g).max() < bound


@pytest.mark.parametrize("order", [2, 4, 6, 8])
def test_log_zonal_equals_the_full_eigen_log(order):
    # the block-diagonal eigenproblem of a zonal vector against the full n^2 one:
    # caps up to 90 deg (the floor clips the spectrum at these orders) and random
    # zonal vectors, some with negative eigenvalues; the blocks and the full matrix
    # give the same eigenvalues to rounding, so the logs agree to ~1e-13 of their size
    from shtools.sh.logarithm import log_zonal

    l = np.arange(order)
    m0 = l * l + l
    caps = cap(np.linspace(0.01, 0.5 * math.pi, 40), np.array([0.0, 0.0, 1.0]), order)
    rng = np.random.default_rng(order)
    noise = np.zeros((40, order * order))
    noise[:, m0] = rng.normal(size=(40, order))
    noise[:, 0] += 2.0 * SQRT_4PI
    g = np.concatenate([caps, noise])
    full = log(g)
    off_zonal = np.setdiff1d(np.arange(order**2), m0)
    assert np.abs(full[:, off_zonal]).max() < 1e-10  # the full log of a zonal vector is zonal
    np.testing.assert_allclose(log_zonal(g), full, rtol=0, atol=1e-12 * np.abs(full).max())


def test_log_naive_is_worse_than_eigen():
    # Sec. 5: the clipped projection (eq. 25) ignores truncation; its round trip error is
    # several times the eigen log's for large caps (measured 5.5 % vs 0.5 % at 50 deg).
    g = cap(np.radians([40.0, 50.0]), np.array([0.0, 0.0, 1.0]), 4)
    naive = rel_l2(exp(log(g, "naive"), "exact"), g)
    eigen = rel_l2(exp(log(g), "exact"), g)
    assert np.all(naive > 3 * eigen)


def test_log_of_constant_and_bad_method():
    g = np.zeros((2, 9))
    g[:, 0] = SQRT_4PI * np.array([1.0, 0.5])
    f = log(g)
    np.testing.assert_allclose(f[:, 0], SQRT_4PI * np.log([1.0, 0.5]), atol=1e-12)
    np.testing.assert_allclose(f[:, 1:], 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="log method"):
        log(g, "taylor")
    with pytest.raises(ValueError, match="exp method"):
        exp(g, "pade")


def test_squaring_rule_and_hyb_without_squarings_is_ol():
    # Sec. 4.1: p = max(0, floor(log2 ||f_hat||) + 3)
    np.testing.assert_array_equal(squarings([0.0, 0.1, 0.2499, 0.25, 1.0, 4.8, 9.0]),
                                  [0, 0, 0, 1, 3, 5, 6])
    rng = np.random.default_rng(3)
    f = rng.normal(size=(10, 16))
    f[:, 1:] *= 0.2 / np.linalg.norm(f[:, 1:], axis=1, keepdims=True)  # ||f_hat|| < 1/4
    np.testing.assert_allclose(exp(f, "hyb"), exp(f, "ol"), rtol=1e-14)
    # PS*-2 without squarings is 1 + f + f*f/2 times the DC factor, i.e. PS-2 on f_hat.
    f_hat = f.copy()
    f_hat[:, 0] = 0
    dc = np.exp(f[:, :1] / SQRT_4PI)
    np.testing.assert_allclose(exp(f, "ps*", degree=2), dc * exp(f_hat, "ps", degree=2),
                               rtol=1e-13)


@pytest.mark.parametrize("method", EXP_METHODS)
def test_exp_chunking_batching_and_float32(method, monkeypatch):
    rng = np.random.default_rng(4)
    f = rng.normal(size=(3, 70, 9)) * 0.7
    f[..., 0] -= 3.0
    whole = exp(f, method)
    assert whole.shape == (3, 70, 9)
    monkeypatch.setattr("shtools.sh.exponential.CHUNK_BYTES", 1)  # one vector per chunk
    # Same arithmetic, but BLAS may block sums differently for other batch sizes:
    # round-off relative to the largest coefficient.
    tol = 1e-13 * np.abs(whole).max()
    np.testing.assert_allclose(exp(f, method), whole, rtol=1e-13, atol=tol)
    np.testing.assert_allclose(exp(f[1, 5], method), whole[1, 5], rtol=1e-13, atol=tol)
    single = exp(f.astype(np.float32), method)
    assert single.dtype == np.float32
    # float32 keeps ~1e-6 relative accuracy through a handful of products/squarings
    np.testing.assert_allclose(single, whole, rtol=1e-4, atol=1e-5 * np.abs(whole).max())


def test_ps_star_factored_series_converges_with_degree():
    # Without squarings (||f_hat|| = 0.2), PS*-p differs from exp* by the series remainder
    # (~0.2^(p+1)/(p+1)!: 1e-3, 7e-5, 3e-6 for p = 2, 3, 4 before normalisation) plus a
    # floor from regrouping truncated products (measured 2.6e-7).
    rng = np.random.default_rng(3)
    f = rng.normal(size=(50, 16))
    f[:, 1:] *= 0.2 / np.linalg.norm(f[:, 1:], axis=1, keepdims=True)
    exact = exp(f, "exact")
    errors = [rel_l2(exp(f, "ps*", degree=p), exact).max() for p in (2, 3, 4, 8)]
    assert errors[0] < 2e-4 and errors[1] < 1e-5 and errors[2] < 1e-6 and errors[3] < 1e-6
    assert errors[0] > errors[1] > errors[2]


def test_ps_star_is_continuous_where_its_squaring_count_steps(monkeypatch):
    """PS*-2 at margin 1 steps from 2 to 3 squarings at |f_hat| = 4; the band blend
    (``SQUARING_BLEND``: ``e(x)`` toward ``e(x/2)^2``, the latter from the square of
    ``x`` the series already made) keeps the exp continuous there and within PS*-2's
    own error of the exact exp (scipy's expm of the product matrix)."""
    import shtools.sh.exponential as exponential

    rng = np.random.default_rng(3)
    order = 6
    axes = rng.normal(size=(5, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    f_hat = log(cap(rng.uniform(0.2, 0.5, 5), axes, order)).sum(axis=0)
    f_hat[0] = 0.0
    f_hat /= np.linalg.norm(f_hat)
    t = np.linspace(3.8, 4.2, 801)  # across the step, ~1/5500 of an octave apart
    f = t[:, None] * f_hat[None]

    def largest_step_over_median(g):
        steps = np.linalg.norm(np.diff(g, axis=0), axis=1)
        return steps.max() / np.median(steps)

    g = exp(f, "ps*", margin=1)
    # a smooth curve sampled evenly: neighbouring steps alike (measured 1.03)
    assert largest_step_over_median(g) < 1.2
    exact = np.array([scipy.linalg.expm(product_matrix(x))[:, 0] * SQRT_4PI for x in f])
    # PS*-2's own error at a scaled norm near 1 (measured 0.30-0.33 % here)
    assert rel_l2(g, exact).max() < 0.006
    # the test can fail: without the band the series' error jumps at the step (~64x)
    monkeypatch.setattr(exponential, "SQUARING_BLEND", 1e-9)
    assert largest_step_over_median(exp(f, "ps*", margin=1)) > 20
