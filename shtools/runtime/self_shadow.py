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
