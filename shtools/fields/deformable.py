r"""Deformable shadow fields (Wang et al. 2005, Sec. 3.1): one shell, re-sampled per frame.

A deforming object (a skinned character) cannot carry a precomputed shadow
field, so every frame its visibility is sampled at points on **one** sphere,
its bounding sphere (centre ``c``, radius ``r``), and extrapolated to other
distances by SH scaling (:mod:`shtools.runtime.deformable`).

Layout (**derived**: Wang et al. sample 6 x 8 x 8 = 384 points in a cube-map
layout; a polar layout has no face seams and interpolates bilinearly): sample
``(i, j)`` is at polar angle ``theta_i = pi (i + 1/2) / R`` from ``+z`` and
azimuth ``phi_j = 2 pi (j + 1/2) / A``; the default ``R x A = 16 x 24 = 384``
samples matches their count.

At each sample point ``q = c + r w`` only the **inward hemisphere** (directions
with ``s . (c - q) > 0``) is cast: the object lies entirely on the centre's
side of the sphere's tangent plane at ``q``, so the outward hemisphere is
exactly unoccluded.  The occlusion is projected with a hemisphere product rule
(Gauss–Legendre in ``cos`` of the angle from the inward axis, uniform in
azimuth; default 16 x 32 = 512 rays per sample, Wang et al. rasterise 32 x 32
pixels), and the visibility is ``sqrt(4 pi) e0 - O``.  Optionally its SH log
(eigen-inversion) is stored too, so the field joins the SHEXP log accumulation.

One place for the rays: :class:`shtools.geometry.raycast.RayCaster`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from shtools.fields.sampling import bounding_sphere as sampling_bounding_sphere
from shtools.geometry.raycast import RayCaster
from shtools.runtime.deformable import DeformableField, layout_directions
from shtools.sh import basis, check_order, rotation_matrix
from shtools.sh import log as sh_log

#: Default polar layout of the sample points (rings x azimuths): 384 like Wang et al.'s.
DEFAULT_LAYOUT = (16, 24)
#: Default hemisphere rule per sample (cos-nodes x azimuths): 512 rays.
DEFAULT_RAYS = (16, 32)
#: Bounding sphere grown by this fraction so the sample points are strictly outside.
RADIUS_MARGIN = 1e-3


@dataclass(frozen=True)
class HemisphereRule:
    """Product rule on the hemisphere ``z > 0``: directions ``(Q, 3)``, weights ``(Q,)``."""

    directions: np.ndarray
    weights: np.ndarray


def hemisphere_rule(n_cos: int, n_azimuth: int) -> HemisphereRule:
    """Gauss–Legendre in ``z`` on ``(0, 1]`` times the uniform rule in azimuth.

    Weights sum to ``2 pi``; exact for polynomials in ``(x, y, z)`` of degree
    ``< min(2 n_cos, n_azimuth)`` over the hemisphere.
    """
    x, w = np.polynomial.legendre.leggauss(int(n_cos))
    z = 0.5 * (x + 1.0)
    wz = 0.5 * w
    phi = 2.0 * math.pi * (np.arange(n_azimuth) + 0.5) / n_azimuth
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    rr = np.sqrt(1.0 - zz * zz)
    dirs = np.stack([rr * np.cos(pp), rr * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    weights = np.repeat(wz * (2.0 * math.pi / n_azimuth), n_azimuth)
    return HemisphereRule(dirs, weights)


def bounding_sphere(vertices) -> tuple[np.ndarray, float]:
    """Minimal sphere enclosing the posed vertices (grown by :data:`RADIUS_MARGIN`).

    Returns
    -------
    center : ndarray, shape (3,)
    radius : float
    """
    center, radius = sampling_bounding_sphere(vertices)  # the shadow fields' own
    return center, radius * (1.0 + RADIUS_MARGIN)


def _frames(axes: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``(S, 3, 3)`` whose third row is ``axes`` (unit)."""
    helper = np.where(np.abs(axes[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(axes, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(axes, t1)
    return np.stack([t1, t2, axes], axis=1)


@functools.lru_cache(maxsize=8)
def _sampling_plan(layout: tuple, rays: tuple, order: int):
    """What does not change between frames: sample directions ``(S, 3)``, unit
    ray directions ``(S, Q, 3)``, the local projection ``(Q, n*n)`` and the SH
    rotations local -> world ``(S, n*n, n*n)``."""
    w = layout_directions(*layout)
    rule = hemisphere_rule(*rays)
    frames = _frames(-w)  # local z = towards the centre
    dirs = np.einsum("qk,skj->sqj", rule.directions, frames)  # world = frame^T local
    local_projection = basis(rule.directions, order) * rule.weights[:, None]
    to_world = rotation_matrix(np.swapaxes(frames, 1, 2), order)
    for a in (w, dirs, local_projection, to_world):
        a.setflags(write=False)
    return w, dirs, local_projection, to_world


def sample_deformable_field(vertices, faces, order: int, *, layout=DEFAULT_LAYOUT,
                            rays=DEFAULT_RAYS, center=None, radius=None, log: bool = True,
                            log_method: str = "eigen",
                            caster: RayCaster | None = None) -> DeformableField:
    """Sample a posed mesh's visibility on its bounding sphere.

    Parameters
    ----------
    vertices : array_like, shape (P, 3)
        Posed vertex positions (world).
    faces : array_like, shape (F, 3)
    order : int
        SH order of the samples (the accumulation order of the runtime).
    layout : (int, int)
        Rings x azimuths of the polar sample layout.
    rays : (int, int)
        Hemisphere rule per sample (cos-nodes x azimuths).
    center, radius : optional
        Sphere to sample on (default :func:`bounding_sphere` of ``vertices``);
        it must enclose the mesh.
    log : bool
        Also store the SH log of every sample for log-space accumulation.
    log_method : {"eigen", "naive"}
        :func:`shtools.sh.log` method: eigen-inversion (SHEXP eqs. 30–32, as the
        runtime's cap tables) or the quadrature of the clipped pointwise log
        (about 10x cheaper; ``benchmarks/bench_scaling.py`` compares them).
    caster : RayCaster, optional
        A caster already built on this posed mesh.

    Returns
    -------
    DeformableField
        ``visibility (S, n*n)`` (and ``log_visibility``) in the world frame.
    """
    order = check_order(order)
    v = np.asarray(vertices, dtype=np.float64)
    if center is None or radius is None:
        center, radius = bounding_sphere(v)
    center = np.asarray(center, dtype=np.float64)
    caster = RayCaster(v, faces) if caster is None else caster
    w, dirs, local_projection, to_world = _sampling_plan(tuple(layout), tuple(rays), order)
    points = center + float(radius) * w
    s, q = dirs.shape[:2]
    hit = caster.occluded(np.repeat(points, q, axis=0), dirs.reshape(-1, 3)).reshape(s, q)
    # occlusion projected in each sample's frame (one product), then rotated to the world
    occlusion = np.einsum("sij,sj->si", to_world, hit @ local_projection)
    visibility = -occlusion
    visibility[:, 0] += math.sqrt(4.0 * math.pi)  # V = 1 - O
    log_vis = sh_log(visibility, log_method) if log else None
    return DeformableField(center=center, radius=float(radius), layout=tuple(layout),
                           visibility=visibility, log_visibility=log_vis,
                           rays=int(s * q), occluded_fraction=float(hit.mean()))
