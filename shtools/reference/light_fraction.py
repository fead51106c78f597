r"""Ray-traced visible fraction of a spherical light (the small-light ground truth).

Not an SH projection: an order-4 or order-6 projection cannot hold the narrow
penumbra of a small lamp.  Per receiver ``p`` the light of radius ``r`` at
distance ``D`` subtends the cap of half-angle :math:`\alpha = \sin^{-1}(r/D)`
about the direction to its centre.  The cap is split into ``k x k`` strata of
equal solid angle (uniform in :math:`\cos\theta` and in azimuth about the axis),
one jittered direction per stratum, and an occlusion ray is cast from ``p``
(offset along its normal against self-hits, as in
:mod:`shtools.reference.raytrace`) up to the near surface of the light through
:class:`shtools.geometry.raycast.RayCaster`.  Stratification makes the error
of a smooth-edged penumbra fall faster than the unstratified
:math:`0.5/\sqrt{N}`.

Directions below the receiver's tangent plane (``s . N <= 0``) are not cast and
count as visible -- the convention of :mod:`shtools.reference.raytrace`; they
carry no weight in the radiance.  Returned per receiver:

* ``fraction`` -- :math:`S = \frac{1}{\Omega}\int_{cap} V\,d\omega`;
* ``radiance`` -- per unit light colour, :math:`\frac1\pi\int_{cap} V\max(0, N\cdot s)\,d\omega`
  (the white-Lambertian outgoing radiance of docs/conventions.md "Light and radiance");
* ``unshadowed`` -- the same with ``V = 1``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.errors import InputError
from shtools.geometry.visibility import RAY_OFFSET

#: Default strata per receiver (16 x 16).
DEFAULT_SAMPLES = 256


@dataclass
class LightFraction:
    """Per-receiver results of :func:`light_visible_fraction`, each shape ``(V,)``."""

    fraction: np.ndarray
    radiance: np.ndarray
    unshadowed: np.ndarray


def cap_directions(axis, alpha, n_samples: int, rng: np.random.Generator
                   ) -> np.ndarray:
    """Stratified directions uniform in solid angle inside caps.

    Parameters
    ----------
    axis : ndarray, shape (V, 3)
        Unit cap axes.
    alpha : ndarray, shape (V,)
        Cap half-angles (radians).
    n_samples : int
        Rounded down to a square ``k * k``.
    rng : numpy.random.Generator
        Jitter inside the strata (one pattern shared by all receivers).

    Returns
    -------
    ndarray, shape (V, k*k, 3)
    """
    k = max(1, int(np.sqrt(n_samples)))
    gi, gj = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    ju = (gi.ravel() + rng.random(k * k)) / k
    jv = (gj.ravel() + rng.random(k * k)) / k
    one_minus_cos = 1.0 - np.cos(alpha)
    cos_t = 1.0 - ju[None, :] * one_minus_cos[:, None]  # (V, N)
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    phi = 2.0 * np.pi * jv
    helper = np.where(np.abs(axis[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(helper, axis)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(axis, t)
    return (sin_t[..., None] * (np.cos(phi)[None, :, None] * t[:, None, :]
                                + np.sin(phi)[None, :, None] * b[:, None, :])
            + cos_t[..., None] * axis[:, None, :])


def light_visible_fraction(points, normals, meshes, center, radius: float, *,
                           n_samples: int = DEFAULT_SAMPLES, seed: int = 0,
                           offset: float | None = None, chunk: int = 4096) -> LightFraction:
    """Visible fraction and shadowed radiance of a spherical light, by ray tracing.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers and unit normals.
    meshes : list of (vertices (n, 3), faces (m, 3)) or trimesh.Trimesh, or a RayCaster
        Occluder geometry (include a receiver's own mesh for self-shadowing).
    center : array_like, shape (3,)
    radius : float
        Light radius (> 0).
    n_samples : int
        Strata per receiver (a square number is used, ``k*k <= n_samples``).
    seed : int
        Jitter seed.
    offset : float, optional
        Origin offset along the normal (default ``RAY_OFFSET`` x the diagonal).
    chunk : int
        Receivers per batch (bounds memory).

    Returns
    -------
    LightFraction

    Raises
    ------
    InputError
        ``radius <= 0`` or a receiver inside the light.
    """
    from shtools.geometry.raycast import RayCaster

    r = float(radius)
    if not (np.isfinite(r) and r > 0):
        raise InputError(f"a spherical light needs a radius > 0, got {r!r}")
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(center, dtype=np.float64).reshape(3)
    if isinstance(meshes, RayCaster):
        caster = meshes
    else:
        vs, fs, base = [], [], 0
        for m in meshes:
            v, f = (m.vertices, m.faces) if hasattr(m, "vertices") else m
            vs.append(np.asarray(v, dtype=np.float64))
            fs.append(np.asarray(f, dtype=np.int64) + base)
            base += len(vs[-1])
        caster = RayCaster(np.concatenate(vs), np.concatenate(fs))
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    rng = np.random.default_rng(seed)
    k = max(1, int(np.sqrt(n_samples)))
    # one jitter pattern for every chunk: draw it once, replay it per chunk
    state = rng.bit_generator.state
    frac, rad, free = (np.empty(len(p)) for _ in range(3))
    for s in range(0, len(p), chunk):
        pp, nn = p[s:s + chunk], nrm[s:s + chunk]
        delta = c - pp
        dist = np.linalg.norm(delta, axis=1)
        if np.any(dist <= r):
            raise InputError("a receiver is inside the spherical light; move the light")
        axis = delta / dist[:, None]
        alpha = np.arcsin(r / dist)
        rng.bit_generator.state = state
        dirs = cap_directions(axis, alpha, k * k, rng)  # (v, N, 3)
        cos_n = np.einsum("vnk,vk->vn", dirs, nn)
        front = cos_n > 0
        # distance to the light's near surface along each direction
        b = np.einsum("vnk,vk->vn", dirs, delta)
        t_far = b - np.sqrt(np.maximum(b * b - (dist * dist - r * r)[:, None], 0.0))
        vi, ni = np.nonzero(front)
        vis = np.ones(front.shape, dtype=bool)
        if vi.size:
            origins = pp[vi] + offset * nn[vi]
            blocked = caster.occluded(origins, dirs[vi, ni], t_far=t_far[vi, ni])
            vis[vi[blocked], ni[blocked]] = False
        omega = 2.0 * np.pi * (1.0 - np.cos(alpha))
        w = np.maximum(cos_n, 0.0) * (omega / (k * k) / np.pi)[:, None]
        frac[s:s + chunk] = vis.mean(axis=1)
        rad[s:s + chunk] = (w * vis).sum(axis=1)
        free[s:s + chunk] = w.sum(axis=1)
    return LightFraction(frac, rad, free)
