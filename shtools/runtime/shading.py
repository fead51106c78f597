r"""Shading of white Lambertian receivers (SHEXP Sec. 7, docs/conventions.md "Light and radiance").

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
from shtools.runtime.fast_exp import QuadratureProducts, row_matmul
from shtools.sh import band_of, basis, cap_zh_cos, clamped_cosine_zh, product_matrix, window

#: Rec. 709 luminance weights of linear RGB.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def desaturate_negative(radiance) -> np.ndarray:
    """Bring negative channels to 0 while keeping each colour's luminance (de-ringing).

    Truncated SH rings: under a strong, coloured light (a sun) the order-n
    product can dip below zero in one channel while the others stay positive,
    e.g. ``(-0.014, 0.000, 0.035)`` -- a saturated blue blotch.  Clamping per
    channel would keep that hue; instead each colour is desaturated toward its
    luminance ``Y`` just enough that its smallest channel is 0, and colours with
    ``Y <= 0`` become black.  Colours without a negative channel are unchanged.

    Parameters
    ----------
    radiance : array_like, shape (..., 3)
        Linear RGB.

    Returns
    -------
    ndarray, shape (..., 3) float64
        Non-negative linear RGB.
    """
    rgb = np.asarray(radiance, dtype=np.float64)
    # channel by channel: several times faster than a reduction over the short last axis
    negative = np.minimum(np.minimum(rgb[..., 0], rgb[..., 1]), rgb[..., 2]) < 0.0
    if not negative.any():
        return rgb
    out = rgb.copy()
    # only the colours with a negative channel change (few: ringing is rare)
    sub = rgb[negative]
    lum = sub @ LUMINANCE
    low = sub.min(axis=-1)
    # c' = Y + s (c - Y) with s = Y / (Y - min c) puts the smallest channel at 0
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.clip(lum / (lum - low), 0.0, 1.0)
    fixed = lum[:, None] + s[:, None] * (sub - lum[:, None])
    out[negative] = np.where(lum[:, None] > 0.0, np.maximum(fixed, 0.0), 0.0)
    return out


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
    r"""Tabulated form: :math:`\mathbf L_H(N)\cdot\mathbf g`.

    :math:`\mathbf L_H = \mathbf L * \mathbf H(N)` is cosine-weighted incident radiance.

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
    return lit_transfer_radiance(lit_transfer(transfer, env_matrices), visibility)


def lit_transfer(transfer, env_matrices) -> np.ndarray:
    r""":math:`\mathbf L_H(N) = \mathbf L * \mathbf H(N)` per vertex and colour.

    Parameters
    ----------
    transfer : ndarray, shape (V, n*n)
    env_matrices : ndarray, shape (3, n*n, n*n)

    Returns
    -------
    ndarray, shape (V, 3, n*n)
        The table a static receiver keeps while the light does not change.
    """
    n_c, size = env_matrices.shape[0], env_matrices.shape[1]
    # all colours with one matrix product: (V, n*n) @ (n*n, 3*n*n); M_L is symmetric;
    # in blocks, so that a cache refreshing whole blocks gets the bytes of all rows
    mats = np.concatenate(list(env_matrices), axis=1).astype(transfer.dtype, copy=False)
    return row_matmul(transfer, mats).reshape(-1, n_c, size)


def lit_transfer_radiance(l_h, visibility) -> np.ndarray:
    """``L_H (V, 3, n*n)`` dotted with ``visibility (V, n*n)``: radiance ``(V, 3)``."""
    return np.einsum("vcs,vs->vc", l_h, visibility).astype(np.float64)


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


#: Vertices per block of the sphere-light term: its scratch (about 0.5 KB a
#: vertex) then stays in a core's L2 cache.  Measured on 20k moving receivers and
#: two lights, one BLAS thread: 2.9 ms at 2,048, 8.5 ms at 8,192.  A multiple of
#: :data:`~shtools.runtime.fast_exp.PRODUCT_BLOCK_ROWS` (a cache refreshing whole
#: blocks of rows then gets the bytes of a fresh call).
LIGHT_CHUNK = 2048


def sphere_light_terms(light: SphereLight, points, order: int
                       ) -> tuple[np.ndarray, np.ndarray]:
    """What a light's term needs of the receivers' positions alone (kept for static rows).

    Returns
    -------
    zh : ndarray, shape (V, n) float32
        Zonal coefficients of the light's radiance cap (:func:`_sphere_light_zonal`).
    y : ndarray, shape (V, n*n) float32
        The SH basis at the direction to the light.
    """
    zh, axis = _sphere_light_zonal(light, points, order)
    return zh, np.ascontiguousarray(basis(axis, order))  # rows are read in blocks


def sphere_light_transfer(lights, points, transfer, order: int, win, terms=None
                          ) -> np.ndarray:
    """The spherical lights' lit transfer, shape ``(V, 3, n*n)`` float32.

    :math:`\\sum_k \\mathbf c_k\\,(\\mathbf H * \\mathbf L_k)`: dotted with the
    windowed visibility it gives their radiance.

    The triple product is symmetric, :math:`(\\mathbf H * \\mathbf g)\\cdot\\mathbf L =
    \\mathbf g\\cdot(\\mathbf H * \\mathbf L)` (both are :math:`\\int H g L` for order-``n``
    vectors), so a light's term is a per-row table like :math:`\\mathbf L_H` that a
    static receiver keeps while the light holds still.  ``H * L_k`` is an exact
    quadrature product of ``H`` with the light's rotated, windowed zonal radiance.

    Parameters
    ----------
    lights : sequence of SphereLight
    points : ndarray, shape (V, 3)
    transfer : ndarray, shape (V, n*n) float32
        ``H(N)`` (or ``H(N) * g_p``).
    order : int
    win : ndarray, shape (n*n,)
        Window factors of the lighting.
    terms : sequence of (zh, y), optional
        :func:`sphere_light_terms` of each light at ``points`` (a cache; the
        same values as computed here).

    Returns
    -------
    ndarray, shape (V, 3, n*n) float32
    """
    ops = QuadratureProducts(order, np.float32)
    size = order * order
    degrees = np.arange(order)
    scale = np.sqrt(4.0 * np.pi / (2.0 * degrees + 1.0))
    # zonal (V', n) -> windowed per-coefficient factors (V', n*n) as one small product
    band = band_of(order)
    expand = np.zeros((order, size), np.float32)
    expand[band, np.arange(size)] = (scale * win[degrees * degrees + degrees])[band]
    # sum_k c_k (outer) lit_k as one product: (V', K n*n) @ (K n*n, 3 n*n), blocks c_k[c] I
    mix = np.kron(np.stack([light.color for light in lights]), np.eye(size)).astype(np.float32)
    n_v = transfer.shape[0]
    out = np.empty((n_v, 3, size), np.float32)
    if terms is None:  # for all rows at once: per call, the basis costs more than per row
        terms = [sphere_light_terms(light, points, order) for light in lights]
    for start in range(0, n_v, LIGHT_CHUNK):
        stop = min(n_v, start + LIGHT_CHUNK)
        lits = np.empty((stop - start, len(lights) * size), np.float32)
        # one class (order 4): H's values at the nodes are shared by the lights
        h_vals = row_matmul(transfer[start:stop], ops.recon[0]) if len(ops.classes) == 1 else None
        for k, (zh_all, y_all) in enumerate(terms):
            zh, y = zh_all[start:stop], y_all[start:stop]
            # the light's windowed radiance (V', n*n)
            rotated = row_matmul(zh, expand)
            rotated *= y
            lit = lits[:, k * size:(k + 1) * size]
            if h_vals is None:
                lit[...] = ops.product(transfer[start:stop], rotated)
            else:  # in blocks from the first row: a cache refreshing whole blocks (row_matmul)
                vals = row_matmul(rotated, ops.recon[0])
                vals *= h_vals
                row_matmul(vals, ops.proj[0], out=lit)
        row_matmul(lits, mix, out=out[start:stop].reshape(stop - start, 3 * size))
    return out


def _sphere_light_zonal(light: SphereLight, points, order: int):
    r"""Zonal coefficients ``(V, n)`` of a light's radiance cap and its axis ``(V, 3)``.

    float32: the cap indicator's coefficients are
    :math:`\sqrt{4\pi}\,\delta_{l0} - g_l` with :func:`shtools.sh.cap_zh_cos`'s
    closed form in :math:`\cos\theta = \sqrt{1 - R^2/D^2}` (no arcsin).  A receiver
    inside the light sees it over the whole sphere.
    """
    delta = light.position[None, :].astype(np.float32) - np.asarray(points, dtype=np.float32)
    dist2 = np.einsum("vi,vi->v", delta, delta)
    inside = dist2 <= np.float32(light.radius) ** 2
    inv = 1.0 / np.sqrt(np.maximum(dist2, np.float32(1e-30)))
    axis = delta * inv[:, None]
    axis[inside] = (0.0, 0.0, 1.0)  # any axis: the cap is the whole sphere
    sin2 = np.minimum(np.float32(light.radius) ** 2 * inv * inv, 1.0)
    cos_t = np.where(inside, np.float32(-1.0), np.sqrt(1.0 - sin2))
    zh = -cap_zh_cos(cos_t, order)  # the indicator is 1 minus the cap's visibility
    zh[:, 0] += np.float32(math.sqrt(4.0 * math.pi))
    return zh, axis


def sphere_light_unshadowed(light: SphereLight, points, normals) -> np.ndarray:
    r"""Unshadowed radiance per unit colour of a spherical light, closed form, shape ``(V,)``.

    :math:`E/\pi` with :math:`E = \int_{cap} \max(0, N\cdot s)\,ds` the cosine-weighted
    solid angle of the light's cap: :math:`\pi\sin^2\sigma\cos\theta` while the whole
    cap is above the horizon (:math:`\cos\theta > \sin\sigma`), and the exact
    horizon-clipped form factor of a sphere (Snyder 1996, as written in Lagarde & de
    Rousiers 2014, "Moving Frostbite to PBR", eq. 15 listing) otherwise.  The
    small-light paths (occlusion camera, ray tracing) multiply it by the visible
    fraction; it is not SH-truncated.

    Parameters
    ----------
    light : SphereLight
    points, normals : array_like, shape (V, 3)

    Returns
    -------
    ndarray, shape (V,) float64
        1 for a receiver inside the light (the whole hemisphere at unit radiance).
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    delta = light.position[None, :] - p
    dist = np.linalg.norm(delta, axis=1)
    inside = dist <= light.radius
    safe = np.where(inside, 1.0, dist)
    cos_t = np.clip(np.einsum("ij,ij->i", nrm, delta) / safe, -1.0, 1.0)
    sin2 = np.minimum((light.radius / safe) ** 2, 1.0)
    full = cos_t * cos_t > sin2
    e = np.pi * sin2 * np.maximum(cos_t, 0.0)
    part = ~full & ~inside
    if part.any():
        ct, s2 = cos_t[part], sin2[part]
        st = np.sqrt(np.maximum(1.0 - ct * ct, 1e-300))
        x = np.sqrt(np.maximum(1.0 / s2 - 1.0, 0.0))
        y = np.clip(-x * ct / st, -1.0, 1.0)
        sty = st * np.sqrt(np.maximum(1.0 - y * y, 0.0))
        with np.errstate(divide="ignore"):
            e[part] = (ct * np.arccos(y) - x * sty) * s2 + np.arctan2(sty, x)
    e = np.where(inside, np.pi, np.maximum(e, 0.0))
    return e / np.pi


def shade(visibility, points, normals, env_sh=None, sphere_lights=(), *, order: int,
          window_kind: str | None = "cosine", window_h: float | None = None,
          local_visibility=None, form: str = "tabulated", transfer=None,
          env_transfer=None, light_terms=None, lit_rows=None) -> np.ndarray:
    """Outgoing radiance of white Lambertian receivers, shape ``(V, 3)``.

    Parameters
    ----------
    visibility : array_like, shape (V, n*n)
        Visibility ``g`` per vertex.
    points, normals : array_like, shape (V, 3)
        Receiver positions (for spherical lights) and unit normals.
    env_sh : array_like, shape (n'*n', 3) or (V, n'*n', 3), optional
        RGB environment radiance, shared or per vertex (mid-range lighting,
        :func:`shtools.runtime.scaling.midrange_lighting`); truncated or
        zero-padded to order ``n``.
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
    env_transfer : ndarray, shape (V, 3, n*n), optional
        Precomputed :func:`lit_transfer` of ``transfer`` and the windowed
        environment (:func:`environment_matrices`); the tabulated form then
        costs one dot product per vertex and colour.
    light_terms : sequence of (zh, y), optional
        Precomputed :func:`sphere_light_terms` of each sphere light (a cache).
    lit_rows : ndarray, shape (V, 3, n*n), optional
        Precomputed lit transfer of the shared environment and the sphere lights
        together, :func:`lit_transfer` plus :func:`sphere_light_transfer` (a
        cache): the radiance is then one dot product per vertex and colour, and
        ``env_sh``, ``sphere_lights`` and the transfer are not read.

    Returns
    -------
    ndarray, shape (V, 3) float64
    """
    size = order * order
    g = np.asarray(visibility, dtype=np.float32)[:, :size]
    win = band_window(order, window_kind, window_h)
    g_w = g * win.astype(np.float32)
    if lit_rows is not None:
        return lit_transfer_radiance(lit_rows, g_w)
    if transfer is None:
        transfer = cosine_transfer(normals, order)
    transfer = np.asarray(transfer, dtype=np.float32)
    if local_visibility is not None:
        local = np.asarray(local_visibility, dtype=np.float32)[:, :size]
        transfer = QuadratureProducts(order, np.float32).product(transfer, local)
    shared = env_sh is not None and np.ndim(env_sh) == 2
    if env_transfer is None and shared and form == "tabulated":
        env_transfer = lit_transfer(transfer, environment_matrices(env_sh, order, window_kind,
                                                                   window_h))
    lit = env_transfer
    if sphere_lights:
        lights = sphere_light_transfer(sphere_lights, np.asarray(points), transfer, order,
                                       win, light_terms)
        lit = lights if lit is None else lit + lights
    out = np.zeros((g.shape[0], 3)) if lit is None else lit_transfer_radiance(lit, g_w)
    if env_transfer is None and env_sh is not None:
        if shared:  # on the fly
            out += on_the_fly_radiance(transfer, environment_matrices(
                env_sh, order, window_kind, window_h), g_w)
        else:  # per vertex (mid-range lighting)
            out += per_vertex_environment_radiance(transfer, env_sh, g_w, win)
    return out


def shading_matrix(points, normals, env_sh=None, sphere_lights=(), *, order: int,
                   window_kind: str | None = "cosine", window_h: float | None = None,
                   transfer=None) -> np.ndarray:
    r"""The linear map of :func:`shade` in the visibility: ``K`` with ``shade(g) = K g``.

    :func:`shade` is linear in ``g`` (de-ringing, outside it, is not), so for
    receivers whose position, normal and lights stay fixed a new visibility
    costs one small product.  Every term is ``g_w`` dotted with a vector of
    the vertex: the environment's lit transfer :math:`\mathbf L_H(N)`
    (:func:`lit_transfer`); for a spherical light and a per-vertex environment,
    the dot of the shadowed transfer :math:`\mathbf H * \mathbf g_w` with a
    radiance vector :math:`\mathbf w`, which is :math:`\mathbf g_w\cdot(\mathbf
    H * \mathbf w)` because the exact triple product :math:`\int y_i y_j y_k`
    is symmetric in its three indices (SHEXP Sec. 3; the product runs on the
    same exact quadrature as :func:`shade`'s).  The window of ``g_w`` is folded
    into ``K``.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
    env_sh : array_like, shape (n'*n', 3) or (V, n'*n', 3), optional
        As :func:`shade`.
    sphere_lights : sequence of SphereLight
    order : int
    window_kind, window_h
        As :func:`shade`.
    transfer : ndarray, shape (V, n*n), optional
        :func:`cosine_transfer` of ``normals`` (a cache).

    Returns
    -------
    ndarray, shape (V, 3, n*n) float32
        ``K[v] @ g[v]`` is ``shade(g, ...)[v]`` before de-ringing, to float32
        rounding.
    """
    size = order * order
    win = band_window(order, window_kind, window_h)
    win32 = win.astype(np.float32)
    transfer = np.asarray(cosine_transfer(normals, order) if transfer is None else transfer,
                          dtype=np.float32)
    K = np.zeros((transfer.shape[0], 3, size), np.float32)
    if env_sh is not None and np.ndim(env_sh) == 3:  # per vertex: (H * g_w) . (win L_v)
        ops = QuadratureProducts(order, np.float32)
        env = np.asarray(env_sh, dtype=np.float32)
        env_n = np.zeros((env.shape[0], size, 3), np.float32)
        env_n[:, :min(size, env.shape[1])] = env[:, :size]
        for c in range(3):
            K[:, c] = ops.product(transfer, env_n[:, :, c] * win32)
    elif env_sh is not None:
        K += lit_transfer(transfer, environment_matrices(env_sh, order, window_kind, window_h))
    if sphere_lights:  # the lights' lit transfer, as shade() dots it with g_w
        K += sphere_light_transfer(sphere_lights, np.asarray(points), transfer, order, win)
    K *= win32
    return K


def per_vertex_environment_radiance(transfer, env_sh, visibility, win) -> np.ndarray:
    """Radiance under a per-vertex environment: ``(H(N) * g) . L_v``, shape ``(V, 3)``.

    Parameters
    ----------
    transfer : ndarray, shape (V, n*n)
        ``H(N)`` (or ``H(N) * g_p``).
    env_sh : array_like, shape (V, n'*n', 3)
        RGB radiance per vertex; truncated or zero-padded to order ``n``.
    visibility : ndarray, shape (V, n*n)
        Windowed visibility.
    win : ndarray, shape (n*n,)
        Window factors of the lighting.
    """
    size = transfer.shape[1]
    order = round(math.sqrt(size))
    env = np.asarray(env_sh, dtype=np.float32)
    env_n = np.zeros((env.shape[0], size, env.shape[2]), np.float32)
    env_n[:, :min(size, env.shape[1])] = env[:, :size]
    shadowed = QuadratureProducts(order, np.float32).product(
        np.asarray(transfer, np.float32), np.asarray(visibility, np.float32))
    return np.einsum("vs,vsc->vc", shadowed * win.astype(np.float32), env_n).astype(np.float64)


def environment_matrices(env_sh, order: int, window_kind: str | None = "cosine",
                         window_h: float | None = None) -> np.ndarray:
    """float32 product matrices of the windowed RGB environment, ``(3, n*n, n*n)``.

    ``env_sh (n'*n', 3)`` is truncated or zero-padded to order ``n``.
    """
    size = order * order
    env = np.asarray(env_sh, dtype=np.float64)
    env_n = np.zeros((size, 3))
    k = min(size, env.shape[0])
    env_n[:k] = env[:k]
    win = band_window(order, window_kind, window_h)
    return light_matrices(env_n * win[:, None]).astype(np.float32)
