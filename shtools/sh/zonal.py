r"""Zonal (circularly symmetric) functions: caps, the clamped cosine, windowing.

A function :math:`g(s) = \gamma(s \cdot a)` symmetric about an axis ``a`` has SH
coefficients (addition theorem; the rotation rule of Sec. 6.1, eq. 34)

.. math::

    g_{lm} = \sqrt{4\pi/(2l+1)}\; g_l\; y_{lm}(a),
    \qquad g_l = 2\pi K_l \int_{-1}^{1} \gamma(x) P_l(x)\,dx,
    \quad K_l = \sqrt{(2l+1)/(4\pi)},

where ``g_l`` is the coefficient of ``y_{l0}`` of the same function about
``+z``.  :func:`zonal_to_sh` applies this rule.

Caps (eq. 33): the visibility of a blocking cap of angular radius
:math:`\theta` about ``+z`` is 0 for :math:`z \ge \cos\theta` and 1 elsewhere.
Its zonal coefficients follow in closed form from the Legendre identity
:math:`\int_c^1 P_l(x)\,dx = (P_{l-1}(c) - P_{l+1}(c))/(2l+1)` for ``l >= 1``:

.. math::

    g_0 = \sqrt{\pi}\,(1 + \cos\theta), \qquad
    g_l = -2\pi K_l \frac{P_{l-1}(\cos\theta) - P_{l+1}(\cos\theta)}{2l+1}.

The clamped cosine :math:`H(N) = \frac1\pi \max(s\cdot N, 0)` (eq. 9) uses
:math:`x P_l = ((l+1)P_{l+1} + l P_{l-1})/(2l+1)` and the same identity at
``c = 0``.

Windowing multiplies band ``l`` by a factor ``w_l`` to reduce ringing; the
paper's cosine filter is :math:`w_l = \cos(\frac{\pi}{2}\frac{l}{h})` with
``h = 2n`` by default.
"""

from __future__ import annotations

import math
from enum import StrEnum

import numpy as np

from shtools.sh.basis import band_of, basis, check_order, order_from_size


def _legendre_upto(x: np.ndarray, lmax: int) -> np.ndarray:
    """Legendre polynomials P_0..P_lmax at ``x``, shape ``(lmax + 1, *x.shape)``, dtype of ``x``."""
    p = np.empty((lmax + 1, *x.shape), dtype=x.dtype)
    p[0] = 1.0
    if lmax >= 1:
        p[1] = x
    for l in range(1, lmax):
        p[l + 1] = ((2 * l + 1) * x * p[l] - l * p[l - 1]) / (l + 1)
    return p


def cap_zh(theta, order: int) -> np.ndarray:
    """Zonal coefficients of the visibility of a blocking cap about ``+z`` (closed form).

    Parameters
    ----------
    theta : array_like, shape (...)
        Angular radius of the cap in radians, in ``[0, pi]``.
    order : int
        SH order ``n``.

    Returns
    -------
    ndarray, shape (..., n)
        ``g_l``: the coefficient of ``y_{l0}`` of the function that is 0 for
        directions within ``theta`` of ``+z`` and 1 elsewhere.
    """
    return cap_zh_cos(np.cos(np.asarray(theta, dtype=np.float64)), order)


def cap_zh_cos(cos_theta, order: int) -> np.ndarray:
    """:func:`cap_zh` from the cosine of the cap's angular radius (no arccos needed).

    Parameters
    ----------
    cos_theta : array_like, shape (...)
        ``cos(theta)`` in ``[-1, 1]``; float32 input gives float32 output.
    order : int

    Returns
    -------
    ndarray, shape (..., n)
    """
    order = check_order(order)
    c = np.asarray(cos_theta)
    if c.dtype not in (np.float32, np.float64):
        c = c.astype(np.float64)
    p = _legendre_upto(c, order)  # (n+1, ...)
    out = np.empty((*c.shape, order), dtype=c.dtype)
    out[..., 0] = math.sqrt(math.pi) * (1.0 + c)
    for l in range(1, order):
        k = math.sqrt((2 * l + 1) / (4 * math.pi))
        out[..., l] = -2.0 * math.pi * k * (p[l - 1] - p[l + 1]) / (2 * l + 1)
    return out


def zonal_to_sh(zh, axis) -> np.ndarray:
    """Rotate zonal coefficients about ``+z`` to an axis (eq. 34 rotation rule).

    Parameters
    ----------
    zh : array_like, shape (..., n)
        Coefficients ``g_l`` of ``y_{l0}`` of a function symmetric about ``+z``.
    axis : array_like, shape (..., 3)
        Unit symmetry axes (broadcast against ``zh``'s leading axes).

    Returns
    -------
    ndarray, shape (..., n*n)
        ``sqrt(4 pi / (2l+1)) * zh_l * y_lm(axis)``.
    """
    zh = np.asarray(zh, dtype=np.float64)
    order = zh.shape[-1]
    check_order(order)
    scale = np.sqrt(4.0 * np.pi / (2.0 * np.arange(order) + 1.0))
    y = basis(np.asarray(axis, dtype=np.float64), order)
    return (zh * scale)[..., band_of(order)] * y


def cap(theta, axis, order: int) -> np.ndarray:
    """Visibility vector of a blocking cap (0 inside, 1 outside).

    Parameters
    ----------
    theta : array_like, shape (...)
        Angular radius in radians.
    axis : array_like, shape (..., 3)
        Unit cap centres.
    order : int
        SH order ``n``.

    Returns
    -------
    ndarray, shape (..., n*n)
        ``zonal_to_sh(cap_zh(theta, order), axis)``.
    """
    return zonal_to_sh(cap_zh(theta, order), axis)


def clamped_cosine_zh(order: int) -> np.ndarray:
    """Zonal coefficients of ``H(N) = max(s . N, 0) / pi`` about ``+z`` (eq. 9).

    Parameters
    ----------
    order : int
        SH order ``n``.

    Returns
    -------
    ndarray, shape (n,)
        So that ``H(N) = zonal_to_sh(clamped_cosine_zh(n), N)``.
    """
    order = check_order(order)
    p0 = _legendre_upto(np.zeros(()), order + 2)  # P_l(0), l = 0..n+1

    def int_p_0_1(l: int) -> float:  # integral_0^1 P_l(x) dx
        if l == 0:
            return 1.0
        return float(p0[l - 1] - p0[l + 1]) / (2 * l + 1)

    out = np.empty(order)
    for l in range(order):
        upper = (l + 1) * int_p_0_1(l + 1)
        lower = l * int_p_0_1(l - 1) if l >= 1 else 0.0
        x_pl = (upper + lower) / (2 * l + 1)  # integral_0^1 x P_l(x) dx
        out[l] = 2.0 * math.pi * math.sqrt((2 * l + 1) / (4 * math.pi)) * x_pl / math.pi
    return out


class WindowKind(StrEnum):
    """Window kinds of :func:`window` (``None`` or ``"none"``: no window)."""

    COSINE = "cosine"
    HANN = "hann"
    LANCZOS = "lanczos"


WINDOW_KINDS = tuple(k.value for k in WindowKind)


def window(order: int, kind: str | None = "cosine", h: float | None = None) -> np.ndarray:
    """Per-band window factors.

    Parameters
    ----------
    order : int
        SH order ``n``.
    kind : {"cosine", "hann", "lanczos", None}
        ``"cosine"``: ``cos(pi/2 * l/h)``, the paper's filter, ``h = 2n`` by
        default.  ``"hann"``: ``(1 + cos(pi l/h)) / 2`` and ``"lanczos"``:
        ``sinc(l/h)``, both with ``h = n`` by default (zero at band ``n``) and
        zero for ``l >= h``.  ``None``: all ones.
    h : float, optional
        Window width in bands (> 0).

    Returns
    -------
    ndarray, shape (n,)
        Factor ``w_l`` for each band ``l``.
    """
    order = check_order(order)
    l = np.arange(order, dtype=np.float64)
    if kind is None or kind == "none":
        return np.ones(order)
    if kind not in WINDOW_KINDS:
        raise ValueError(f"unknown window kind {kind!r}; use one of {WINDOW_KINDS} or None")
    if h is None:
        h = 2.0 * order if kind == "cosine" else float(order)
    if not h > 0:
        raise ValueError(f"window width h must be > 0, got {h!r}")
    t = l / h
    if kind == "cosine":
        return np.where(t < 1.0, np.cos(0.5 * np.pi * t), 0.0)
    if kind == "hann":
        return np.where(t < 1.0, 0.5 * (1.0 + np.cos(np.pi * t)), 0.0)
    return np.where(t < 1.0, np.sinc(t), 0.0)


def apply_window(f, kind: str | None = "cosine", h: float | None = None) -> np.ndarray:
    """Multiply each band of SH vectors by :func:`window` factors.

    Parameters
    ----------
    f : array_like, shape (..., n*n)
        SH vectors.
    kind, h
        As in :func:`window`.

    Returns
    -------
    ndarray, shape (..., n*n)
        Windowed vectors (same dtype as ``f`` if floating).
    """
    f = np.asarray(f)
    order = order_from_size(f.shape[-1])
    w = window(order, kind, h)[band_of(order)]
    return f * w.astype(f.dtype if f.dtype.kind == "f" else np.float64)
