r"""Real spherical harmonics in the shtools convention.

Convention (``"real-orthonormal-xyz"``, the same as sphericart): for a unit
direction :math:`s = (x, y, z)` with polar angle :math:`\vartheta` and azimuth
:math:`\varphi`,

.. math::

    y_{l m}(s) = \begin{cases}
        \sqrt{2}\, K_{l|m|}\, P_l^{|m|}(z)\, \sin(|m|\varphi) & m < 0 \\
        K_{l0}\, P_l^0(z) & m = 0 \\
        \sqrt{2}\, K_{lm}\, P_l^{m}(z)\, \cos(m\varphi) & m > 0
    \end{cases},
    \qquad K_{lm} = \sqrt{\frac{2l+1}{4\pi}\frac{(l-m)!}{(l+m)!}},

with associated Legendre functions :math:`P_l^m` **without** the Condon–Shortley
phase, so ``y(1,-1) = c*y``, ``y(1,0) = c*z``, ``y(1,1) = c*x`` with
``c = sqrt(3/(4*pi))``.  The flat index is ``i = l*l + l + m``; order ``n``
means bands ``l = 0..n-1`` and ``n*n`` coefficients.  The basis is orthonormal
on the unit sphere, so the constant function 1 is ``(sqrt(4*pi), 0, ...)``.

The evaluation works in Cartesian form: :math:`P_l^m(z)\,\{\cos,\sin\}(m\varphi)
= Q_l^m(z)\,\{\mathrm{Re},\mathrm{Im}\}(x + i y)^m` with polynomials
:math:`Q_l^m` from the standard three-term recurrence, so no trigonometric
function is called and the result is a polynomial in ``x, y, z``.
"""

from __future__ import annotations

import math

import numpy as np

SH_CONVENTION = "real-orthonormal-xyz"
"""Name of the convention, recorded in every asset that stores SH data."""

SQRT_4PI = math.sqrt(4.0 * math.pi)
"""The only coefficient of the constant function 1: ``(SQRT_4PI, 0, ...)``."""


def n_coeffs(order: int) -> int:
    """Number of coefficients ``order**2`` of an order-``order`` SH vector."""
    return int(order) * int(order)


def sh_index(l: int, m: int) -> int:
    """Flat index ``l*l + l + m`` of the coefficient of band ``l`` and index ``m``."""
    if not -l <= m <= l:
        raise ValueError(f"m={m} out of range for l={l}")
    return l * l + l + m


def band_of(order: int) -> np.ndarray:
    """Band ``l`` of every flat index, shape ``(order**2,)``, dtype int.

    Useful to expand per-band (zonal) factors: ``zh[..., band_of(n)]``.
    """
    return np.repeat(np.arange(order), 2 * np.arange(order) + 1)


def order_from_size(size: int) -> int:
    """Inverse of :func:`n_coeffs`; raises ``ValueError`` if ``size`` is not a square."""
    n = math.isqrt(int(size))
    if n * n != size or n < 1:
        raise ValueError(f"{size} coefficients is not a square number n*n with n >= 1")
    return n


def check_order(order: int) -> int:
    """Validate an SH order (``int >= 1``) and return it as ``int``."""
    if isinstance(order, bool) or int(order) != order or order < 1:
        raise ValueError(f"SH order must be an integer >= 1, got {order!r}")
    return int(order)


def normalisation(order: int) -> np.ndarray:
    """Normalisation ``K_{lm}`` (times sqrt(2) for m != 0) of the real basis.

    Returns
    -------
    ndarray, shape (order, order)
        Indexed ``[l, |m|]``; entries with ``|m| > l`` are 0.
    """
    k = np.zeros((order, order))
    for l in range(order):
        for m in range(l + 1):
            k[l, m] = math.sqrt(
                (2 * l + 1) / (4 * math.pi) * math.factorial(l - m) / math.factorial(l + m)
            )
            if m > 0:
                k[l, m] *= math.sqrt(2.0)
    return k


_NORM_CACHE: dict[int, np.ndarray] = {}

BASIS_CHUNK = 16384
"""Directions per pass of :func:`basis`."""


def basis(dirs, order: int, *, dtype=None) -> np.ndarray:
    """Evaluate the real SH basis at unit directions.

    Parameters
    ----------
    dirs : array_like, shape (..., 3)
        Unit direction vectors.  They are **not** renormalised (the result is a
        polynomial in x, y, z); normalise first if unsure.
    order : int
        SH order ``n >= 1`` (bands ``0..n-1``).
    dtype : numpy dtype, optional
        ``float32`` or ``float64``; by default that of ``dirs`` if floating, else
        float64.

    Returns
    -------
    ndarray, shape (..., order**2)
        ``y_i(dirs)`` with flat index ``i = l*l + l + m``.  The array may be a
        transposed (Fortran-ordered) view for speed; call
        ``np.ascontiguousarray`` if you need C order.
    """
    order = check_order(order)
    d = np.asarray(dirs)
    if d.shape[-1:] != (3,):
        raise ValueError(f"dirs must have shape (..., 3), got {d.shape}")
    if dtype is None:
        dtype = d.dtype if d.dtype in (np.float32, np.float64) else np.float64
    dtype = np.dtype(dtype)
    lead = d.shape[:-1]
    flat = d.reshape(-1, 3)
    out = np.empty((order * order, flat.shape[0]), dtype=dtype)  # coefficient-major
    # Chunks keep the recurrence temporaries in cache; contiguous x, y, z rows
    # avoid strided arithmetic (faster than one pass).
    for start in range(0, flat.shape[0], BASIS_CHUNK):
        xyz = np.ascontiguousarray(flat[start : start + BASIS_CHUNK].T, dtype=dtype)
        _fill_basis(out[:, start : start + BASIS_CHUNK], xyz[0], xyz[1], xyz[2], order)
    return out.T.reshape(*lead, order * order)


def _fill_basis(out: np.ndarray, x, y, z, order: int) -> None:
    """Write y_i(x, y, z) into rows of ``out`` (shape (order**2, V))."""
    if order not in _NORM_CACHE:
        _NORM_CACHE[order] = normalisation(order)
    k = _NORM_CACHE[order].astype(out.dtype)
    # c_m + i s_m = (x + i y)^m
    c_prev, s_prev = np.ones_like(x), np.zeros_like(x)
    for m in range(order):
        if m > 0:
            c_prev, s_prev = c_prev * x - s_prev * y, c_prev * y + s_prev * x
        # Q_l^m(z) for l = m..order-1, no Condon–Shortley phase.
        q_lm2 = None
        q_lm1 = np.full_like(z, float(double_factorial(2 * m - 1)))
        for l, (a, c, d) in legendre_recurrence(m, order):
            if l == m:
                q = q_lm1
            elif l == m + 1:
                q = a * z * q_lm1
                q_lm2, q_lm1 = q_lm1, q
            else:
                q = (a * z * q_lm1 - c * q_lm2) / d
                q_lm2, q_lm1 = q_lm1, q
            base = l * l + l
            if m == 0:
                np.multiply(q, k[l, 0], out=out[base])
            else:
                kq = q * k[l, m]
                np.multiply(kq, c_prev, out=out[base + m])
                np.multiply(kq, s_prev, out=out[base - m])


def legendre_recurrence(m: int, order: int) -> list[tuple[int, tuple[int, int, int]]]:
    """Integer coefficients of the associated Legendre recurrence for ``l = m..order-1``.

    ``Q_m^m = (2m-1)!!``, ``Q_{m+1}^m = (2m+1) z Q_m^m`` and
    ``Q_l^m = ((2l-1) z Q_{l-1}^m - (l+m-1) Q_{l-2}^m) / (l-m)``; entry ``l`` is
    ``(l, (2l-1, l+m-1, l-m))`` (no Condon–Shortley phase).  The one statement of
    the recurrence: :func:`basis` and the runtime's fused accumulation kernel
    (:mod:`shtools.runtime.accumulate`) both iterate it.
    """
    return [(l, (2 * l - 1, l + m - 1, l - m)) for l in range(m, order)]


def double_factorial(n: int) -> int:
    """``n!! = n (n-2) (n-4) ...``, with ``n!! = 1`` for ``n <= 0`` (so ``Q_m^m = (2m-1)!!``)."""
    return 1 if n <= 0 else n * double_factorial(n - 2)
