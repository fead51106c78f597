r"""Circle (cap) tables: visibility and log zonal coefficients, and OL coefficients.

Sec. 6.1: a cap of angular radius :math:`\theta` about ``+z`` has zonal
visibility coefficients :math:`g_l(\theta)` (closed form,
:func:`shtools.sh.zonal.cap_zh`); the table stores the *scaled* coefficients
:math:`g^*_l = g_l\sqrt{4\pi/(2l+1)}` so that a cap about axis ``s`` is
``vis_zh[t, band_of(n)] * basis(s, n)`` (eq. 34).  ``log_zh`` holds
:math:`f^*_l(\theta)`, the same scaling of the eigen-inverted log (eqs. 30–32)
of the cap vector.

Sec. 4.2 (eqs. 23–24): for each cap, with the log ``f``, its DC-free part
:math:`\hat f` and :math:`\hat g = e^{-f_0/\sqrt{4\pi}} g`, the optimal linear
coefficients are :math:`a = \hat g_0/\sqrt{4\pi}` and
:math:`b = \hat g\cdot\hat f / \hat f\cdot\hat f`, tabulated against
:math:`\|\hat f\|` (``ol_norm``, strictly increasing, starting at the exact limit
``(0, 1, 1)`` of a vanishing cap).
"""

from __future__ import annotations

import functools

import numpy as np

from shtools.sh.basis import SQRT_4PI, check_order
from shtools.sh.logarithm import LOG_EPS, log_zonal
from shtools.sh.zonal import cap_zh, zonal_to_sh


def _zonal_scale(order: int) -> np.ndarray:
    return np.sqrt(4.0 * np.pi / (2.0 * np.arange(order) + 1.0))


def build_log_tables(order: int, samples: int = 256, eps: float = LOG_EPS) -> dict:
    """Tabulate cap visibility, cap log and the OL coefficients for one SH order.

    Parameters
    ----------
    order : int
        SH order ``n``.
    samples : int
        Number ``T`` of cap radii ``theta_t = (t + 1) / T * pi / 2``, ``t = 0..T-1``.
    eps : float
        Eigenvalue floor of the log (eq. 32).

    Returns
    -------
    dict
        ``theta (T,)``, ``vis_zh (T, n)`` (``g*_l``), ``log_zh (T, n)``
        (``f*_l``), ``ol_norm (K,)`` (strictly increasing ``||f_hat||``,
        first entry 0), ``ol_a (K,)``, ``ol_b (K,)``.  All float64.
    """
    order = check_order(order)
    if isinstance(samples, bool) or int(samples) != samples or samples < 2:
        raise ValueError(f"samples must be an integer >= 2, got {samples!r}")
    samples = int(samples)
    theta = (np.arange(samples) + 1.0) / samples * (0.5 * np.pi)
    vis = cap_zh(theta, order)  # (T, n)
    g = zonal_to_sh(vis, np.array([0.0, 0.0, 1.0]))  # (T, n^2), zonal about +z
    f = log_zonal(g, eps)  # the eigen log (eqs. 30-32) of the zonal caps
    m0 = np.arange(order) * (np.arange(order) + 1)  # flat index of (l, 0)
    scale = _zonal_scale(order)
    norm, a, b = _ol_coefficients(f, g)
    # Keep entries whose ||f_hat|| exceeds every earlier one: it grows with theta
    # but, with eigenvalue clipping, dips slightly near pi/2 at some orders (3, 5-8);
    # np.interp needs a strictly increasing abscissa.
    previous_max = np.maximum.accumulate(np.concatenate([[0.0], norm[:-1]]))
    keep = norm > previous_max
    return {
        "theta": theta,
        "vis_zh": vis * scale,
        "log_zh": f[:, m0] * scale,
        "ol_norm": np.concatenate([[0.0], norm[keep]]),
        "ol_a": np.concatenate([[1.0], a[keep]]),
        "ol_b": np.concatenate([[1.0], b[keep]]),
    }


def _ol_coefficients(f: np.ndarray, g: np.ndarray):
    """Eq. 24 for pairs of log ``f`` and visibility ``g``, shapes ``(T, n*n)``."""
    f_hat = f.copy()
    f_hat[:, 0] = 0.0
    g_hat = g * np.exp(-f[:, :1] / SQRT_4PI)
    ff = np.sum(f_hat * f_hat, axis=1)
    a = g_hat[:, 0] / SQRT_4PI
    dot = np.sum(g_hat * f_hat, axis=1)
    b = np.divide(dot, ff, out=np.ones_like(ff), where=ff > 0)  # order 1: no f_hat
    return np.sqrt(ff), a, b


@functools.lru_cache(maxsize=16)
def _default_tables(order: int) -> dict:
    tables = build_log_tables(order)
    for v in tables.values():
        v.setflags(write=False)
    return tables


def default_tables(order: int) -> dict:
    """:func:`build_log_tables` with default parameters, cached per order.

    Returns a new dict each call (the cached arrays in it are read-only), so a
    caller that adds or replaces a key does not change what the next caller gets.
    """
    return dict(_default_tables(order))
