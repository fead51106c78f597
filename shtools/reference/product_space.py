"""Product-space accumulation (Zhou et al. 2005), the baseline SHEXP must beat.

Every blocker sphere's cap visibility vector (closed form,
:func:`shtools.sh.cap`) is multiplied into the running visibility with the
truncated SH product (eq. 6), left to right in the order the spheres are given,
after the same self-shadow rules as the runtime (Sec. 6.2).  Accumulating at a
higher order ``acc_order`` and truncating afterwards reduces the truncation
error after each product (Fig. 7e).
"""

from __future__ import annotations

import numpy as np

from shtools.runtime.blockers import SphereBlocker
from shtools.runtime.hierarchy import leaf_spheres
from shtools.runtime.self_shadow import apply_self_shadow_rules
from shtools.sh import cap, product

#: Elements of the per-batch (vertices x spheres x n_acc^2) cap array (bounds memory).
_BATCH_ELEMENTS = 1 << 22


def blocker_spheres(blockers) -> tuple[np.ndarray, np.ndarray]:
    """Leaf spheres from a list of :class:`SphereBlocker` or a ``(centers, radii)`` pair."""
    if isinstance(blockers, tuple) and len(blockers) == 2 and not isinstance(
        blockers[0], SphereBlocker
    ):
        return np.asarray(blockers[0], dtype=np.float64), np.asarray(blockers[1], dtype=np.float64)
    return leaf_spheres(list(blockers))


def cap_vectors(points, normals, centers, radii, order: int, *, self_shadow: bool = True,
                dtype=np.float64) -> np.ndarray:
    """Visibility vectors of every (vertex, sphere) pair after the self-shadow rules.

    Returns
    -------
    ndarray, shape (V, S, n*n)
    """
    p = np.asarray(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    delta = centers[None, :, :] - p[:, None, :]
    r = np.broadcast_to(radii[None, :], delta.shape[:2])
    if self_shadow:
        dx, dy, dz, r = apply_self_shadow_rules(
            delta[..., 0], delta[..., 1], delta[..., 2], r,
            nrm[:, None, 0], nrm[:, None, 1], nrm[:, None, 2])
        delta = np.stack([dx, dy, dz], axis=-1)
    d = np.linalg.norm(delta, axis=-1)
    axis = delta / np.maximum(d, 1e-300)[..., None]
    theta = np.arcsin(np.clip(r / np.maximum(d, 1e-300), 0.0, 1.0))
    theta = np.where(r > 0, theta, 0.0)
    return cap(theta, axis, order).astype(dtype, copy=False)


def product_space_visibility(vertices, normals, blockers, order: int, acc_order: int | None = None,
                             *, self_shadow: bool = True, dtype=np.float64,
                             kernel: str = "cp") -> np.ndarray:
    """Visibility by sequential truncated SH products of the blockers' cap vectors.

    Parameters
    ----------
    vertices, normals : array_like, shape (V, 3)
        Receivers and unit normals.
    blockers : list of SphereBlocker or (centers (S,3), radii (S,))
        All leaf spheres are used (no hierarchy).
    order : int
        Output order ``n``.
    acc_order : int, optional
        Order of the products (``>= n``); truncated to ``n`` at the end.
    self_shadow : bool
        Apply the Sec. 6.2 rules (as the runtime does).
    dtype : numpy dtype
        float64 (reference) or float32 (speed comparisons).
    kernel : str
        Product evaluation (:func:`shtools.sh.product`): ``"cp"``, quadrature
        factors of Γ (default, fastest here), ``"sparse"``, the sparse
        triple-product contraction, or a registered kernel (the benchmarks'
        generated ``"unrolled"`` one, as product-space methods classically use).

    Returns
    -------
    ndarray, shape (V, n*n)
    """
    n_acc = order if acc_order is None else int(acc_order)
    centers, radii = blocker_spheres(blockers)
    p = np.asarray(vertices, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    out = np.zeros((p.shape[0], order * order), dtype=dtype)
    if centers.shape[0] == 0:
        out[:, 0] = np.sqrt(4.0 * np.pi)
        return out
    step = max(1, _BATCH_ELEMENTS // (centers.shape[0] * n_acc * n_acc))
    for s in range(0, p.shape[0], step):
        caps = cap_vectors(p[s : s + step], nrm[s : s + step], centers, radii, n_acc,
                           self_shadow=self_shadow, dtype=dtype)
        g = caps[:, 0].copy()
        for i in range(1, caps.shape[1]):
            g = product(g, caps[:, i], n_acc, kernel=kernel)
        out[s : s + step] = g[:, : order * order]
    return out
