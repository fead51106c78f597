r"""Shading of white Lambertian receivers (SHEXP Sec. 7, DESIGN.md "Radiance").

Outgoing radiance of an albedo-1 diffuse receiver with unit normal ``N`` under
distant lighting ``L`` and visibility ``g`` is the triple product

.. math::

    R = (\mathbf H(N), \mathbf L, \mathbf g)
      = \tfrac1\pi\int L(s)\,V(s)\max(0, N\cdot s)\,ds,
    \qquad \mathbf H(N) = \tfrac1\pi\int \max(s\cdot N, 0)\,\mathbf y(s)\,ds .

Two equivalent evaluations (Sec. 7):

* **tabulated** — :math:`\mathbf L_H(N) = \mathbf L * \mathbf H(N)` per normal,
  dotted with ``g`` (for fixed lighting; the paper keeps ``L_H`` in a cube map,
  here it is one small matrix product per normal, which is exact);
* **on the fly** — :math:`(\mathbf M_L \mathbf g)\cdot\mathbf H(N)` with the
  light's product matrix, for lighting that changes every frame.

Static receivers may carry baked local visibility :math:`\mathbf g_p`: they
are shaded with the transfer vector :math:`\mathbf H(N) * \mathbf g_p` in place
of :math:`\mathbf H(N)`.

Spherical lights: a light of radius ``R`` at distance ``D`` subtends a cap of
angular radius :math:`\sin^{-1}(R/D)` about the direction to it; its radiance
is the colour times the cap's indicator, whose zonal coefficients are
:math:`\sqrt{4\pi}\,\delta_{l0} - g_l(\theta)` (one minus the cap visibility of
:func:`shtools.sh.cap_zh`), rotated to the light direction per vertex (eq. 34
rule) and shaded through the same visibility.

Windowing (Sec. 7): lighting and visibility are both multiplied per band by the
window (cosine, :math:`h = 2n` by default); ``H`` is not.
"""

from __future__ import annotations

import math

import numpy as np

from shtools.runtime.blockers import SphereLight
from shtools.runtime.fast_exp import QuadratureProducts
from shtools.sh import band_of, basis, cap_zh, clamped_cosine_zh, product_matrix, window


def band_window(order: int, kind: str | None, h: float | None) -> np.ndarray:
    """Window factors expanded to coefficients, shape ``(n*n,)``."""
    return window(order, kind, h)[band_of(order)]


def zonal_to_sh32(zh, axis) -> np.ndarray:
    """float32 :func:`shtools.sh.zonal_to_sh`.

    ``zh (..., n)`` zonal coefficients about ``+z`` and ``axis (..., 3)`` give
    ``(..., n*n)``.
    """
    zh = np.asarray(zh, dtype=np.float64)
    order = zh.shape[-1]
    scale = np.sqrt(4.0 * np.pi / (2.0 * np.arange(order) + 1.0))
    y = basis(np.asarray(axis, dtype=np.float32), order)
    return y * (zh * scale)[..., band_of(order)].astype(np.float32)


def cosine_transfer(normals, order: int) -> np.ndarray:
    """:math:`\\mathbf H(N)` for every normal, shape ``(V, n*n)`` float32 (eq. 9)."""
    return zonal_to_sh32(clamped_cosine_zh(order), normals)


def light_matrices(env_sh) -> np.ndarray:
    """Product matrices :math:`\\mathbf M_L` of an RGB light, shape ``(3, n*n, n*n)``."""
    env = np.asarray(env_sh, dtype=np.float64)
    return product_matrix(env.T)


def tabulated_radiance(transfer, env_matrices, visibility) -> np.ndarray:
    """Tabulated form: :math:`\\mathbf L_H(N)\\cdot\\mathbf g`.

    :math:`\\mathbf L_H = \\mathbf L * \\mathbf H(N)` is cosine-weighted incident radiance.

    Parameters
    ----------
    transfer : ndarray, shape (V, n*n)
        ``H(N)`` (or ``H(N) * g_p`` for baked local visibility).
    env_matrices : ndarray, shape (3, n*n, n*n)
        Product matrices of the (windowed) light.
    visibility : ndarray, shape (V, n*n)
        (Windowed) visibility ``g``.

    Returns
    -------
    ndarray, shape (V, 3)
    """
    n_c, size = env_matrices.shape[0], env_matrices.shape[1]
    # L_H for all colours with one matrix product: (V, n*n) @ (n*n, 3*n*n); M_L symmetric
    l_h = transfer @ np.concatenate(list(env_matrices), axis=1)
    return np.einsum("vcs,vs->vc", l_h.reshape(-1, n_c, size), visibility).astype(np.float64)


def on_the_fly_radiance(transfer, env_matrices, visibility) -> np.ndarray:
    """On-the-fly form :math:`(\\mathbf M_L\\mathbf g)\\cdot\\mathbf H(N)`.

    Same shapes as :func:`tabulated_radiance`.
    """
    n_c, size = env_matrices.shape[0], env_matrices.shape[1]
    lit = (visibility @ np.concatenate(list(env_matrices), axis=1)).reshape(-1, n_c, size)
    return np.einsum("vcs,vs->vc", lit, transfer).astype(np.float64)  # (M_L g) . H(N)


def sphere_light_sh(light: SphereLight, points, order: int) -> np.ndarray:
    """Per-vertex SH radiance (per unit colour) of a spherical light, shape ``(V, n*n)``.

    A receiver inside the light sees it over the whole sphere.
    """
    zh, axis = _sphere_light_zonal(light, points, order)
    return zonal_to_sh32(zh, axis)


def _sphere_light_dot(light: SphereLight, points, order: int, shadowed, win) -> np.ndarray:
    """``sphere_light_sh(...) * win`` dotted with ``shadowed (V, n*n)`` per vertex, ``(V,)``.

    Without forming the light's ``(V, n*n)`` vectors: ``y(axis) * shadowed`` is
    summed per band and weighted by the rotated zonal coefficients.
    """
    zh, axis = _sphere_light_zonal(light, points, order)
    scale = np.sqrt(4.0 * np.pi / (2.0 * np.arange(order) + 1.0))
    per_band = (basis(np.asarray(axis, dtype=np.float32), order) * shadowed) @ _band_sum(order)
    weights = (zh * (scale * win[np.arange(order) ** 2 + np.arange(order)])).astype(np.float32)
    return np.einsum("vl,vl->v", per_band, weights).astype(np.float64)


def _band_sum(order: int) -> np.ndarray:
    """``(n*n, n)`` float32 indicator summing the coefficients of each band."""
    return (band_of(order)[:, None] == np.arange(order)[None, :]).astype(np.float32)


def _sphere_light_zonal(light: SphereLight, points, order: int):
    """Zonal coefficients ``(V, n)`` of a light's radiance cap and its axis ``(V, 3)``."""
    delta = light.position[None, :] - np.asarray(points, dtype=np.float64)
    dist = np.linalg.norm(delta, axis=1)
    axis = delta / np.maximum(dist, 1e-300)[:, None]
    theta = np.where(dist > light.radius,
                     np.arcsin(np.minimum(light.radius / np.maximum(dist, 1e-300), 1.0)),
                     math.pi)
    zh = -cap_zh(theta, order)
    zh[:, 0] += math.sqrt(4.0 * math.pi)
    axis[dist == 0] = (0.0, 0.0, 1.0)  # any axis: the cap is the whole sphere
    return zh, axis


def shade(visibility, points, normals, env_sh=None, sphere_lights=(), *, order: int,
          window_kind: str | None = "cosine", window_h: float | None = None,
          local_visibility=None, form: str = "tabulated", transfer=None) -> np.ndarray:
    """Outgoing radiance of white Lambertian receivers, shape ``(V, 3)``.

    Parameters
    ----------
    visibility : array_like, shape (V, n*n)
        Visibility ``g`` per vertex.
    points, normals : array_like, shape (V, 3)
        Receiver positions (for spherical lights) and unit normals.
    env_sh : array_like, shape (n'*n', 3), optional
        RGB environment radiance; truncated or zero-padded to order ``n``.
    sphere_lights : sequence of SphereLight
    order : int
        Shading order ``n``.
    window_kind, window_h
        Window of lighting and visibility (:func:`shtools.sh.window`).
    local_visibility : array_like, shape (V, n*n), optional
        Baked static visibility ``g_p``; shading uses ``H(N) * g_p``.
    form : {"tabulated", "on_the_fly"}
        Evaluation of the environment term (identical results).
    transfer : ndarray, shape (V, n*n), optional
        Precomputed :func:`cosine_transfer` of ``normals`` (a cache).

    Returns
    -------
    ndarray, shape (V, 3) float64
    """
    size = order * order
    g = np.asarray(visibility, dtype=np.float32)[:, :size]
    win = band_window(order, window_kind, window_h)
    g_w = g * win.astype(np.float32)
    if transfer is None:
        transfer = cosine_transfer(normals, order)
    if local_visibility is not None:
        local = np.asarray(local_visibility, dtype=np.float32)[:, :size]
        transfer = QuadratureProducts(order, np.float32).product(transfer, local)
    out = np.zeros((g.shape[0], 3))
    if env_sh is not None:
        env = np.asarray(env_sh, dtype=np.float64)
        env_n = np.zeros((size, 3))
        k = min(size, env.shape[0])
        env_n[:k] = env[:k]
        mats = light_matrices(env_n * win[:, None]).astype(np.float32)
        fn = tabulated_radiance if form == "tabulated" else on_the_fly_radiance
        out += fn(transfer, mats, g_w)
    if sphere_lights:
        # (H * g) by exact quadrature, dotted with each light's radiance
        shadowed = QuadratureProducts(order, np.float32).product(transfer, g_w)
        for light in sphere_lights:
            lit = _sphere_light_dot(light, points, order, shadowed, win)
            out += lit[:, None] * light.color[None, :]
    return out
