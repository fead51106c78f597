r"""SH scaling (Wang et al. 2005): the matrices M(k) of a polar-angle warp.

A spherical function is *scaled* about +z by a monotone angular map
:math:`\phi_k` that rescales only the polar angle (seed eq. 1):
:math:`F_d(\theta, \varphi) = F_r(\phi_k(\theta), \varphi)`.  On SH vectors this
is a linear map :math:`f_d = M(k) f_r` (eqs. 4–6) with

.. math::

    M_{ij} = \int_0^{2\pi}\!\!\int_0^{\pi} y_i(\theta,\varphi)\,
             y_j(\phi_k(\theta),\varphi)\,\Lambda(\theta)\, d\theta\, d\varphi ,

:math:`\Lambda = \sin\theta` (plain, eq. 1) or
:math:`\Lambda = \sin\phi_k(\theta)\,\phi_k'(\theta)` (energy-preserving,
eq. 2: keeps :math:`\int F\,d\omega`).  Because the warp leaves the azimuth
alone, :math:`M` couples only equal ``m`` and the azimuthal integral is 1, so
each entry is one 1-D integral in θ of the normalised Legendre parts
(Wang et al. 2005, Sec. 2.2), done here by Gauss–Legendre on ``[0, π]``.

Angular maps (Wang et al. 2005, Secs. 3.1 and 3.2; the atan2 forms are
**derived** here, the paper's printed formulas are the special cases noted):

``cone``
    an occluder modelled as a cone with its apex at the entity's centre and
    half-angle ``alpha`` about the radial axis, seen from ``k = d/r`` bounding
    radii: :math:`\phi_k(\theta) = \operatorname{atan2}(k\sin\theta,\
    \cos\theta + (1-k)\cot\alpha\sin\theta)`.  The paper prints the case
    ``alpha = π/4``.  :math:`\phi_1` is the identity and
    :math:`\phi_k^{-1} = \phi_{1/k}`.
``midrange``
    an environment on a sphere of radius ``R`` captured at its centre, seen
    from a point at ``k = d/R`` from the centre with θ measured from the
    displacement direction: the exact ray–sphere map
    :math:`t = -k\cos\theta + \sqrt{1-k^2\sin^2\theta}`,
    :math:`\phi_k(\theta) = \operatorname{atan2}(t\sin\theta,\ k + t\cos\theta)`.
    :math:`\phi_0` is the identity.

Structure (derived from the map's form, checked by the tests): the non-zero pattern has
``n(2n²+1)/3`` positions; the ``m`` and ``−m`` blocks are equal; a plain M has
column 0 equal to ``e0``, an energy-preserving one row 0 equal to ``e0``; and
:math:`M_E[\phi] = M_P[\phi^{-1}]^T` (so for the cone ``M_E(k) = M_P(1/k)^T``).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from shtools.sh.basis import basis, check_order

#: Angular maps this module knows.
FUNCTIONS = ("cone", "midrange")
#: Default cone half-angle: the paper's printed formula is the atan2 form with cot(alpha) = 1.
DEFAULT_ALPHA = math.pi / 4
#: Gauss–Legendre nodes in θ.  Measured (``quadrature_error``): <= 1e-12 against
#: twice the nodes for cone k in [1/8, 8] and midrange k <= 0.99 at n <= 6.
DEFAULT_NODES = 400
#: Quadrature error :func:`build_scaling_table` aims for with automatic nodes.
QUADRATURE_TARGET = 1e-12
#: ... and the most nodes it tries.
MAX_NODES = 25_600


def check_alpha(alpha: float) -> float:
    """``alpha`` as a float, or ``ValueError`` unless a cone half-angle in ``(0, pi/2)`` rad."""
    alpha = float(alpha)
    if not 0.0 < alpha < math.pi / 2:
        raise ValueError(f"cone half-angle alpha must be in (0, pi/2), got {alpha!r} rad")
    return alpha


def angular_map(theta, k, function: str = "cone", alpha: float = DEFAULT_ALPHA):
    """The backward polar-angle map ``phi_k(theta)`` and its derivative.

    Parameters
    ----------
    theta : array_like, shape (Q,)
        Polar angles in ``[0, pi]`` at the receiver (from the scaling axis).
    k : array_like, shape (K,)
        Scale parameters: ``d/r`` for the cone (``k > 0``), ``d/R`` in ``[0, 1)``
        for the mid-range map.
    function : {"cone", "midrange"}
    alpha : float
        Cone half-angle about the radial axis, radians in ``(0, pi/2)``.

    Returns
    -------
    phi, dphi : ndarray, shape (K, Q)
        ``phi_k(theta)`` in ``[0, pi]`` and ``d phi_k / d theta`` (> 0).
    """
    theta = np.asarray(theta, dtype=np.float64)[None, :]
    k = np.asarray(k, dtype=np.float64).reshape(-1, 1)
    s, c = np.sin(theta), np.cos(theta)
    if function == "cone":
        if np.any(k <= 0):
            raise ValueError("cone scale k must be > 0")
        cot = math.cos(check_alpha(alpha)) / math.sin(alpha)
        y = k * s
        x = c + (1.0 - k) * cot * s
        # x y' - y x' = k (cos^2 + sin^2): the derivative has no cancellation.
        num = np.broadcast_to(k, y.shape)
    elif function == "midrange":
        if np.any(k < 0) or np.any(k >= 1):
            raise ValueError("mid-range k = d/R must be in [0, 1) (inside the sphere)")
        root = np.sqrt(1.0 - (k * s) ** 2)
        t = -k * c + root
        dt = k * s - k * k * s * c / root
        y, x = t * s, k + t * c
        dy, dx = dt * s + t * c, dt * c - t * s
        num = x * dy - y * dx
    else:
        raise ValueError(f"unknown angular map {function!r}; use one of {', '.join(FUNCTIONS)}")
    phi = np.arctan2(y, x)
    return phi, num / (x * x + y * y)


def pattern_size(order: int) -> int:
    """Number of allowed non-zeros ``P = n(2n²+1)/3`` of an order-``n`` scaling matrix."""
    n = check_order(order)
    return n * (2 * n * n + 1) // 3


@functools.lru_cache(maxsize=16)
def _pattern(order: int) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = [], []
    for m in range(-(order - 1), order):
        for l_out in range(abs(m), order):
            for l_in in range(abs(m), order):
                rows.append(l_out * l_out + l_out + m)
                cols.append(l_in * l_in + l_in + m)
    r = np.array(rows, dtype=np.int32)
    c = np.array(cols, dtype=np.int32)
    r.setflags(write=False)
    c.setflags(write=False)
    return r, c


def scaling_pattern(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Non-zero pattern of an order-``n`` scaling matrix, canonical order.

    Returns
    -------
    rows, cols : ndarray of int32, shape (P,)
        Flat SH indices ``l*l + l + m`` with equal ``m``; ordered by ``m``
        ascending, then output band, then input band.  ``P = pattern_size(n)``.
        Read-only (cached).
    """
    return _pattern(check_order(order))


def _legendre_parts(theta: np.ndarray, order: int) -> np.ndarray:
    """Normalised Legendre parts ``T_l^|m|(theta)``, shape ``(..., n*n)``.

    ``y_lm(theta, phi) = T_l^|m|(theta) * S^m(phi)`` with ``∫ S^m S^m dphi = 1``:
    ``S^0 = 1/sqrt(2 pi)``, ``S^±m = {cos, sin}(m phi)/sqrt(pi)``.  Evaluated as
    the basis at azimuth 0 (where ``sin`` vanishes), so the ``-m`` slot holds
    zero; callers use the ``|m|`` slot.
    """
    dirs = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], axis=-1)
    y = basis(dirs, order)
    l = np.repeat(np.arange(order), 2 * np.arange(order) + 1)
    m = np.arange(order * order) - (l * l + l)
    scale = np.where(m == 0, math.sqrt(2 * math.pi), math.sqrt(math.pi))
    return y * scale


def scaling_values(k, order: int, function: str = "cone", *, alpha: float = DEFAULT_ALPHA,
                   energy_preserving: bool = False, nodes: int = DEFAULT_NODES) -> np.ndarray:
    """Entries of ``M(k)`` on the pattern of :func:`scaling_pattern`.

    Parameters
    ----------
    k : array_like, shape (K,)
        Scale parameters (see :func:`angular_map`).
    order : int
        SH order ``n``.
    function : {"cone", "midrange"}
    alpha : float
        Cone half-angle (radians); ignored by ``midrange``.
    energy_preserving : bool
        ``Lambda = sin(phi) phi'`` (eq. 2) instead of ``sin(theta)``.
    nodes : int
        Gauss–Legendre nodes in θ on ``[0, pi]``.

    Returns
    -------
    ndarray, shape (K, P)
        ``values[i, p] = M(k[i])[rows[p], cols[p]]``.
    """
    order = check_order(order)
    k = np.atleast_1d(np.asarray(k, dtype=np.float64))
    x, w = np.polynomial.legendre.leggauss(int(nodes))
    theta = 0.5 * math.pi * (x + 1.0)
    w = 0.5 * math.pi * w
    phi, dphi = angular_map(theta, k, function, alpha)  # (K, Q)
    lam = np.sin(phi) * dphi if energy_preserving else np.broadcast_to(np.sin(theta), phi.shape)
    t_out = _legendre_parts(theta, order)  # (Q, n^2)
    t_in = _legendre_parts(phi, order)  # (K, Q, n^2)
    rows, cols = scaling_pattern(order)
    # the |m| slot carries the Legendre part of both m and -m
    abs_r = _abs_m_index(rows)
    abs_c = _abs_m_index(cols)
    weighted = t_out[:, abs_r] * w[:, None]  # (Q, P)
    return np.einsum("qp,kqp,kq->kp", weighted, t_in[:, :, abs_c], lam, optimize=True)


def _abs_m_index(flat: np.ndarray) -> np.ndarray:
    l = np.floor(np.sqrt(flat)).astype(np.int64)
    m = flat - (l * l + l)
    return l * l + l + np.abs(m)


def dense_matrix(values, order: int) -> np.ndarray:
    """Scatter pattern values into dense matrices.

    Parameters
    ----------
    values : array_like, shape (..., P)
    order : int

    Returns
    -------
    ndarray, shape (..., n*n, n*n)
    """
    values = np.asarray(values)
    rows, cols = scaling_pattern(order)
    out = np.zeros((*values.shape[:-1], order * order, order * order), dtype=values.dtype)
    out[..., rows, cols] = values
    return out


def scaling_matrix(k, order: int, function: str = "cone", **kwargs) -> np.ndarray:
    """Dense ``M(k)`` computed directly (no table), shape ``(K, n*n, n*n)``.

    Keyword arguments are those of :func:`scaling_values`.
    """
    return dense_matrix(scaling_values(k, order, function, **kwargs), order)


def quadrature_error(k, order: int, function: str = "cone", *, nodes: int = DEFAULT_NODES,
                     **kwargs) -> float:
    """Estimated quadrature error of :func:`scaling_values` with ``nodes`` nodes.

    Returns
    -------
    float
        ``max |M_nodes(k) - M_{2 nodes}(k)|`` over every entry and every ``k``.
    """
    a = scaling_values(k, order, function, nodes=nodes, **kwargs)
    b = scaling_values(k, order, function, nodes=2 * nodes, **kwargs)
    return float(np.max(np.abs(a - b)))


def identity_k(function: str) -> float:
    """The ``k`` at which the map is the identity (cone: 1, mid-range: 0)."""
    if function == "cone":
        return 1.0
    if function == "midrange":
        return 0.0
    raise ValueError(f"unknown angular map {function!r}; use one of {', '.join(FUNCTIONS)}")


def k_samples(function: str, count: int, lo: float, hi: float) -> tuple[np.ndarray, str]:
    """Sampled ``k`` of a scaling table (the paper gives no range; docs/formats.md).

    ``cone``: geometric on ``[lo, 1]`` and on ``[1, hi]`` (steps split in
    proportion to ``log``-length), so ``k = 1`` (M = I) is a sample.
    ``midrange``: ``k = hi (1 - (1 - u)^2)`` for uniform ``u`` in ``[0, 1]``
    (dense near the sphere, where M changes fastest); requires ``lo = 0``.

    Returns
    -------
    k : ndarray, shape (count,)
        Strictly increasing, containing :func:`identity_k` exactly.
    spacing : str
        Name recorded in the asset (``"geometric-through-1"`` or
        ``"quadratic-near-kmax"``).
    """
    count = int(count)
    lo, hi = float(lo), float(hi)
    if not lo < hi:
        raise ValueError(f"k range must increase (lo < hi), got [{lo}, {hi}]")
    if function == "cone":
        if count < 3:
            raise ValueError("a cone table needs at least 3 samples of k")
        if not 0 < lo < 1 < hi or not math.isfinite(math.log(hi / lo)):
            raise ValueError(f"cone k range must satisfy 0 < lo < 1 < hi (hi / lo finite), "
                             f"got [{lo}, {hi}]")
        n_lo = round((count - 1) * math.log(1 / lo) / math.log(hi / lo))
        n_lo = min(max(n_lo, 1), count - 2)
        below = np.geomspace(lo, 1.0, n_lo + 1)
        above = np.geomspace(1.0, hi, count - n_lo)
        below[-1] = 1.0
        return np.concatenate([below, above[1:]]), "geometric-through-1"
    if function == "midrange":
        if count < 2:
            raise ValueError("a mid-range table needs at least 2 samples of k")
        if lo != 0.0 or not 0 < hi < 1:
            raise ValueError(f"mid-range k range must be [0, kmax] with kmax < 1, got [{lo}, {hi}]")
        u = np.linspace(0.0, 1.0, count)
        return hi * (1.0 - (1.0 - u) ** 2), "quadratic-near-kmax"
    raise ValueError(f"unknown angular map {function!r}; use one of {', '.join(FUNCTIONS)}")


def check_interpolation(function: str, interpolation: str) -> None:
    """``ValueError`` unless ``interpolation`` is a rule a ``function`` table can use
    (``linear-log-k`` needs k > 0: cone tables only)."""
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"unknown interpolation {interpolation!r}; use one of "
                         f"{', '.join(INTERPOLATIONS)}")
    if interpolation == "linear-log-k" and function != "cone":
        raise ValueError("linear-log-k interpolation needs k > 0 (cone tables only)")


def build_scaling_table(order: int, function: str = "cone", *, alpha: float = DEFAULT_ALPHA,
                        energy_preserving: bool = False, samples: int = 40,
                        k_range: tuple[float, float] | None = None,
                        interpolation: str = "linear", nodes: int | None = None) -> dict:
    """Everything a ``scaling`` asset stores (``shtools tables scaling``).

    Parameters
    ----------
    order : int
    function : {"cone", "midrange"}
    alpha : float
        Cone half-angle, radians in ``(0, pi/2)``.
    energy_preserving : bool
    samples : int
        Number ``K`` of sampled ``k``.
    k_range : (float, float), optional
        Default ``(1/8, 8)`` for the cone, ``(0, 0.95)`` for mid-range.
    interpolation : {"linear", "linear-log-k"}
        Rule the reader must use between samples (log-k needs k > 0: cone only).
    nodes : int, optional
        Gauss–Legendre nodes in θ; by default 400, doubled until the estimated
        error (against twice the nodes) is below :data:`QUADRATURE_TARGET`.

    Returns
    -------
    dict
        ``k (K,)``, ``rows (P,)``, ``cols (P,)``, ``values (K, P)`` and the
        metadata ``order``, ``function``, ``alpha`` (cone) , ``energy_preserving``,
        ``k_spacing``, ``interpolation``, ``out_of_range``, ``quadrature_nodes``,
        ``quadrature_error``.
    """
    order = check_order(order)
    if function not in FUNCTIONS:
        raise ValueError(f"unknown angular map {function!r}; use one of {', '.join(FUNCTIONS)}")
    if function == "cone":
        alpha = check_alpha(alpha)
    if k_range is None:
        k_range = (1 / 8, 8.0) if function == "cone" else (0.0, 0.95)
    check_interpolation(function, interpolation)
    k, spacing = k_samples(function, samples, *k_range)
    kw = {"alpha": alpha, "energy_preserving": energy_preserving}
    auto = nodes is None
    nodes = DEFAULT_NODES if auto else int(nodes)
    values = scaling_values(k, order, function, nodes=nodes, **kw)
    check = scaling_values(k, order, function, nodes=2 * nodes, **kw)
    # steep maps (small alpha with k far from 1, mid-range near the sphere) need
    # more nodes: double until the estimate meets the target
    while auto and np.max(np.abs(values - check)) > QUADRATURE_TARGET and nodes < MAX_NODES:
        nodes *= 2
        values, check = check, scaling_values(k, order, function, nodes=2 * nodes, **kw)
    rows, cols = scaling_pattern(order)
    out = {
        "k": k, "rows": np.array(rows), "cols": np.array(cols), "values": values,
        "order": order, "function": function, "energy_preserving": bool(energy_preserving),
        "k_spacing": spacing, "interpolation": interpolation,
        # beyond the cone range the entity is far (k > 8: < 7.2 deg) or deep inside
        # itself; a mid-range receiver beyond kmax is next to or outside the sphere
        "out_of_range": "clamp" if function == "cone" else "error",
        "quadrature_nodes": int(nodes),
        "quadrature_error": float(np.max(np.abs(values - check))),
    }
    if function == "cone":
        out["alpha"] = float(alpha)
    return out


#: Interpolation rules in k a table may name.
INTERPOLATIONS = ("linear", "linear-log-k")
