r"""Self-shadowing rules for sphere blockers (SHEXP Sec. 6.2, Figure 5).

For a receiver ``p`` with unit normal ``N`` (tangent plane :math:`T_p`) and a
blocker sphere ``S = (P, r)``, with :math:`h = (P - p)\cdot N` the height of the
centre above :math:`T_p` and :math:`q_1 = P - hN` its projection on the plane:

1. **behind** (:math:`h \le -r`): S is removed.
2. **p inside S** (:math:`|P - p| < r`): removed if the centre is behind the
   plane (:math:`h \le 0`), else shrunk about its centre to tangency:
   radius ``h`` (tangent at :math:`q_1`).
3. **straddling, p outside** (:math:`|h| < r`): replaced by the sphere
   :math:`S'` whose diameter is :math:`q_0 q_1`, with :math:`q_0 = P + rN` the
   point of S farthest in front of the plane: centre :math:`q_1 + \rho' N`,
   radius :math:`\rho' = (h + r)/2`.
4. **in front** (:math:`h \ge r`): unaltered.

Continuity (the paper's scale factor :math:`\alpha`).  The paper scales the
radius of :math:`S'` by :math:`\alpha` as a function of p's distance
:math:`D = |p - q_1|` along the plane from S, with
:math:`d = \sqrt{r^2 - (r - |q_1 - q_0|)^2} = \sqrt{r^2 - h^2}` (the radius of
:math:`S \cap T_p`).  Its printed form :math:`\max(1, (D - d)/d)` grows without
bound far from S, so it must be :math:`\alpha = \min(1, (D - d)/d)`, which is 0
on the boundary of S (``D = d``) and 1 from ``D = 2d`` on.  We use that
:math:`\alpha` to blend, along the same tangency point :math:`q_1`, from the
sphere rule 2 would give on the boundary (radius :math:`\max(h, 0)`) to
:math:`S'`:

.. math::

    \rho = (1 - \alpha)\max(h, 0) + \alpha\,\frac{h + r}{2},
    \qquad \text{centre } q_1 + \rho N .

This is continuous in ``p`` everywhere: across the sphere boundary (both sides
give radius :math:`\max(h,0)` tangent at :math:`q_1`), at :math:`h = r`
(:math:`S' = S`), at :math:`h = -r` and at :math:`h = 0` with p inside
(radius 0).  Every kept sphere lies in the closed half-space in front of
:math:`T_p`, so p is never inside one.
"""

from __future__ import annotations

import numpy as np


def apply_self_shadow_rules(dx, dy, dz, radius, nx, ny, nz):
    """Apply the Sec. 6.2 rules to sphere-receiver pairs (broadcast, any float dtype).

    Parameters
    ----------
    dx, dy, dz : ndarray, shape (...)
        Components of ``P - p`` (sphere centre relative to the receiver).
    radius : ndarray, shape (...)
        Sphere radii.
    nx, ny, nz : ndarray, shape (...)
        Unit receiver normal components (broadcast against the pairs).

    Returns
    -------
    dx, dy, dz, radius : ndarray, shape (...)
        The replacement spheres relative to ``p``; removed spheres get radius 0
        (an empty cap: log visibility 0, visibility 1).
    """
    dx, dy, dz, radius = np.broadcast_arrays(dx, dy, dz, radius)
    h = dx * nx + dy * ny + dz * nz
    d2 = dx * dx + dy * dy + dz * dz
    r2 = radius * radius
    inside = d2 < r2
    straddle = np.abs(h) < radius
    # distance from p to q1 along the plane, and the radius of S ∩ T_p
    big_d = np.sqrt(np.maximum(d2 - h * h, 0.0))
    small_d = np.sqrt(np.maximum(r2 - h * h, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = np.where(small_d > 0, (big_d - small_d) / small_d, 1.0)
    alpha = np.clip(alpha, 0.0, 1.0)
    alpha = np.where(inside, 0.0, alpha)
    rho = (1.0 - alpha) * np.maximum(h, 0.0) + alpha * 0.5 * (h + radius)
    shift = rho - h  # centre moves from P to q1 + rho N = P + (rho - h) N
    new_dx = np.where(straddle, dx + shift * nx, dx)
    new_dy = np.where(straddle, dy + shift * ny, dy)
    new_dz = np.where(straddle, dz + shift * nz, dz)
    new_r = np.where(straddle, rho, np.where(h <= -radius, 0.0, radius)).astype(
        np.result_type(radius, h), copy=False
    )
    return new_dx, new_dy, new_dz, new_r


def apply_self_shadow_rules_inplace(dx, dy, dz, radius, h, nx, ny, nz, scratch, masks) -> int:
    """:func:`apply_self_shadow_rules` over a whole block, in place (the runtime's fast path).

    Parameters
    ----------
    dx, dy, dz, radius : ndarray, shape (...)
        ``P - p`` and radii; overwritten with the replacement spheres.
    h : ndarray, shape (...)
        ``(P - p) . N`` (read only).
    nx, ny, nz : ndarray
        Normal components broadcasting against the pairs.
    scratch : sequence of 5 ndarrays, shape (...)
        Float work arrays.
    masks : sequence of 2 bool ndarrays, shape (...)
        Boolean work arrays.

    Returns
    -------
    int
        Number of pairs that straddled the tangent plane.

    Notes
    -----
    Same rules and blend as :func:`apply_self_shadow_rules`; one pass per
    operation over all pairs, no gathers, which is cheaper than the subset form
    once a sizeable fraction of the pairs straddles the plane (receivers on the
    blocker itself).  No masks: with ``hc = clip(h, -r, r)`` the blend formula
    itself leaves spheres in front unaltered (``hc = r`` gives ``rho = r`` and
    no shift), gives radius 0 behind (``hc = -r``; the centre is kept), and
    ``alpha`` is 0 for ``p`` inside ``S`` (``D < d`` there), so one formula
    covers every case.
    """
    s1, s2, s3, s4, s5 = scratch
    not_behind, straddle = masks
    np.abs(h, out=s1)
    np.less(s1, radius, out=straddle)
    n_straddle = int(np.count_nonzero(straddle))
    np.negative(radius, out=s1)
    np.greater(h, s1, out=not_behind)
    np.maximum(h, s1, out=s2)
    np.minimum(s2, radius, out=s2)  # hc = clip(h, -r, r)
    np.multiply(dx, dx, out=s3)
    np.multiply(dy, dy, out=s4)
    s3 += s4
    np.multiply(dz, dz, out=s4)
    s3 += s4  # d^2
    np.multiply(h, h, out=s4)
    s3 -= s4
    np.maximum(s3, 0.0, out=s3)
    np.sqrt(s3, out=s3)  # D: distance from p to q1 along the plane
    np.multiply(radius, radius, out=s1)
    np.multiply(s2, s2, out=s4)
    s1 -= s4  # >= 0: |hc| <= r
    np.sqrt(s1, out=s1)  # d: radius of S ∩ T_p (0 unless straddling)
    s3 -= s1
    np.maximum(s1, np.finfo(s1.dtype).tiny, out=s1)
    with np.errstate(over="ignore"):  # d = 0: alpha -> inf, clipped to 1 next
        s3 /= s1
    np.clip(s3, 0.0, 1.0, out=s3)  # alpha
    np.maximum(s2, 0.0, out=s4)  # inside-rule radius max(hc, 0)
    np.add(s2, radius, out=s5)
    s5 *= 0.5
    s5 -= s4
    s5 *= s3
    s5 += s4  # rho = (1 - alpha) max(hc, 0) + alpha (hc + r) / 2
    np.subtract(s5, s2, out=s2)  # the centre moves by (rho - hc) N
    s2 *= not_behind  # removed spheres (radius 0) keep their centre
    radius[...] = s5
    for comp, n in ((dx, nx), (dy, ny), (dz, nz)):
        np.multiply(s2, n, out=s1)
        comp += s1
    return n_straddle
