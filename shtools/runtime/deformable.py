r"""Deformable shadow fields at run time: look up, rotate, scale (Wang et al. Sec. 3.1).

A :class:`DeformableField` holds an object's visibility sampled this frame on
its bounding sphere (:mod:`shtools.fields.deformable` samples it).  For a
receiver ``p`` with ``w = (p - c)/|p - c|`` and ``k = |p - c| / r``:

1. every sample ``S_s`` is re-expressed once per frame in its own **axis frame**
   (``+z`` from the sample point towards ``c``): ``L_s = D_s S_s``;
2. ``L(w)``: bilinear interpolation of the ``L_s`` on the polar layout (near a
   pole, the pole value is the mean of the nearest ring's world samples seen in
   the receiver's own frame, so the lookup is continuous there);
3. ``S_d = D_p^T M(k) L(w)`` with ``D_p`` the receiver's axis frame (the
   direction from ``p`` towards ``c``) and ``M`` the plain **cone** scaling table
   (:class:`shtools.runtime.scaling.ScalingTable`); ``k < 1`` (receivers inside
   the bounding sphere, the object's own vertices) expands the occluded region:
   self-shadowing.

At a sample's own direction this is ``D_s^T M(k) D_s S_s``, the scaling of the
sample about its axis.  Between samples it interpolates the samples *in their
axis frames* (a shadow centred on the axis stays centred) and costs one SH
rotation per receiver instead of two (:func:`interpolate_samples` is the
world-frame interpolation, for other uses).

In **log space** the same is done to the sample's SH log: scaling is linear,
so the scaled logs of several objects add and join the SHEXP accumulation
with one exp.  Scaling does not commute exactly with the pointwise log after
truncation; ``benchmarks/bench_scaling.py`` measures the difference.

Receivers farther than the table's largest ``k`` (8 bounding radii by default:
the sphere subtends < 7.2 degrees) get no contribution (culled); closer than
its smallest ``k`` the table clamps.

NumPy only (the runtime's import rule).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from shtools.runtime.scaling import ScalingTable


def layout_directions(rings: int, azimuths: int) -> np.ndarray:
    """Unit directions of the polar sample layout, shape ``(rings * azimuths, 3)``.

    Sample ``i * azimuths + j`` is at polar angle ``pi (i + 1/2) / rings`` from
    ``+z`` and azimuth ``2 pi (j + 1/2) / azimuths`` from ``+x`` towards ``+y``.
    """
    theta = math.pi * (np.arange(rings) + 0.5) / rings
    phi = 2.0 * math.pi * (np.arange(azimuths) + 0.5) / azimuths
    tt, pp = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp), np.cos(tt)],
                    axis=-1).reshape(-1, 3)


@dataclass
class DeformableField:
    """One frame's visibility samples of an object on its bounding sphere.

    Attributes
    ----------
    center : ndarray, shape (3,)
    radius : float
    layout : (int, int)
        Rings x azimuths of :func:`layout_directions`.
    visibility : ndarray, shape (S, n*n)
        SH visibility at each sample point (world frame), ``S = rings * azimuths``.
    log_visibility : ndarray, shape (S, n*n) or None
        Its SH log (eigen-inversion), for log-space accumulation.
    rays : int
        Rays cast to sample it.
    occluded_fraction : float
        Share of those rays that hit.
    """

    center: np.ndarray
    radius: float
    layout: tuple
    visibility: np.ndarray
    log_visibility: np.ndarray | None = None
    rays: int = 0
    occluded_fraction: float = 0.0
    #: samples in their axis frames, per kind ("log"/"vis"), made on first lookup
    _local: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def order(self) -> int:
        return math.isqrt(self.visibility.shape[1])


def _bilinear(layout, directions):
    """Cells and weights of the bilinear lookup on the pole-padded polar layout.

    Row ``0`` of the padded grid is the north pole (``theta = 0``), row ``i + 1``
    ring ``i``, row ``rings + 1`` the south pole; the pole is half a ring
    spacing from the first ring.  Returns ``i0, j0, j1 (V,)`` and ``tu, tv (V, 1)``.
    """
    rings, az = int(layout[0]), int(layout[1])
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    theta = np.arccos(np.clip(d[:, 2], -1.0, 1.0))
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * math.pi)
    x = theta * rings / math.pi  # ring i at x = i + 1/2
    u = np.where(x < 0.5, 2.0 * x,
                 np.where(x > rings - 0.5, rings + 1.0 - 2.0 * (rings - x), x + 0.5))
    u = np.clip(u, 0.0, rings + 1.0)
    i0 = np.minimum(np.floor(u).astype(np.intp), rings)
    v = phi * az / (2.0 * math.pi) - 0.5
    j0f = np.floor(v)
    j0 = np.mod(j0f.astype(np.intp), az)
    return i0, j0, np.mod(j0 + 1, az), (u - i0)[:, None], (v - j0f)[:, None]


def _gather(grid, i0, j0, j1, tu, tv):
    """Bilinear combination of the padded grid ``(rings + 2, az, C)``."""
    return ((1 - tu) * ((1 - tv) * grid[i0, j0] + tv * grid[i0, j1])
            + tu * ((1 - tv) * grid[i0 + 1, j0] + tv * grid[i0 + 1, j1]))


def interpolate_samples(samples, layout, directions) -> np.ndarray:
    """Bilinear interpolation of per-sample vectors on the polar layout.

    Parameters
    ----------
    samples : ndarray, shape (S, C)
    layout : (int, int)
        Rings x azimuths.
    directions : array_like, shape (V, 3)
        Unit directions from the centre.

    Returns
    -------
    ndarray, shape (V, C)
    """
    rings, az = int(layout[0]), int(layout[1])
    grid = np.asarray(samples).reshape(rings, az, -1)
    # virtual pole rows (the ring mean) make the lookup continuous across the poles
    grid = np.concatenate([grid[:1].mean(axis=1, keepdims=True).repeat(az, axis=1), grid,
                           grid[-1:].mean(axis=1, keepdims=True).repeat(az, axis=1)])
    return _gather(grid, *_bilinear(layout, directions))


def _local_samples(field: DeformableField, table: ScalingTable, log: bool) -> np.ndarray:
    """The field's samples in their axis frames ``(S, n*n)`` float32 (made once per field).

    Only the table's SH rotations are used, which depend on its order alone, so
    the cache holds for every table of the field's order (any alpha).
    """
    key = "log" if log else "vis"
    if key not in field._local:
        samples = field.log_visibility if log else field.visibility
        local = table.to_axis_frame(samples, -layout_directions(*field.layout))
        field._local[key] = local.astype(np.float32)
    return field._local[key]


def interpolate_local(field: DeformableField, table: ScalingTable, directions, *,
                      log: bool) -> np.ndarray:
    """The field at unit ``directions (V, 3)`` from its centre, in each direction's axis frame.

    Bilinear in the samples' axis frames; the pole rows are the mean of the
    nearest ring's world samples, expressed in the receiver's own frame (so the
    world-frame result is continuous across the poles).

    Parameters
    ----------
    field : DeformableField
    table : ScalingTable
        Of the field's order (its SH rotations give the axis frames).
    directions : array_like, shape (V, 3)
        Unit directions from the field's centre to the receivers.
    log : bool
        The log samples, or the visibility samples.

    Returns
    -------
    ndarray, shape (V, n*n) float32
        (the runtime accumulates logs in float32; half the memory traffic)
    """
    rings, az = field.layout
    world = field.log_visibility if log else field.visibility
    local = _local_samples(field, table, log).reshape(rings, az, -1)
    pad = np.zeros((1, az, local.shape[2]), dtype=np.float32)
    grid = np.concatenate([pad, local, pad])
    i0, j0, j1, tu, tv = _bilinear(field.layout, directions)
    tu, tv = tu.astype(np.float32), tv.astype(np.float32)
    out = _gather(grid, i0, j0, j1, tu, tv)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    for cap, ring, weight in ((i0 == 0, 0, 1 - tu), (i0 == rings, rings - 1, tu)):
        if cap.any():
            mean = world.reshape(rings, az, -1)[ring].mean(axis=0).astype(np.float32)
            pole = table.to_axis_frame(np.broadcast_to(mean, (int(cap.sum()), mean.size)),
                                       -d[cap])
            out[cap] += weight[cap] * pole
    return out


def deformable_visibility(field: DeformableField, table: ScalingTable, points, *,
                          log: bool = False) -> np.ndarray:
    """Scaled field at receivers: visibility (product space) or its log.

    Parameters
    ----------
    field : DeformableField
    table : ScalingTable
        A plain ``cone`` table of the field's order.
    points : array_like, shape (V, 3)
    log : bool
        Scale the log samples (sum the result with other logs, exp once);
        otherwise the visibility samples (multiply with other visibilities).

    Returns
    -------
    ndarray, shape (V, n*n)
        Culled receivers get the unoccluded value (log 0, visibility
        ``sqrt(4 pi) e0``).
    """
    if table.function != "cone":
        raise ValueError(f"deformable fields need a 'cone' scaling table, got "
                         f"'{table.function}'")
    if table.info.get("energy_preserving"):
        raise ValueError("deformable visibility needs a plain (not energy-preserving) table")
    if table.order != field.order:
        raise ValueError(f"scaling table order {table.order} does not match the field's "
                         f"order {field.order}")
    samples = field.log_visibility if log else field.visibility
    if samples is None:
        raise ValueError("the field was sampled without its log (log=False)")
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rel = pts - field.center
    dist = np.linalg.norm(rel, axis=1)
    k = dist / field.radius
    out = np.zeros((pts.shape[0], samples.shape[1]))
    if not log:
        out[:, 0] = math.sqrt(4.0 * math.pi)
    near = np.flatnonzero(k <= table.k_range[1])
    if near.size == 0:
        return out
    w = np.where(dist[near, None] > 0, rel[near] / np.maximum(dist[near, None], 1e-300),
                 [0.0, 0.0, 1.0])
    local = interpolate_local(field, table, w, log=log)
    # axis: from the receiver to the centre
    out[near] = table.from_axis_frame(table.scale(local, k[near]), -w)
    return out


class DeformableBlocker:
    """A :class:`~shtools.runtime.LogBlocker` of one frame's deformable field.

    The runtime evaluates it per part of a frame (in its worker processes too)
    and combines it as ``settings.field_space`` says: its log added to the
    other blockers' before the one exp (``"log"``), or its visibility
    multiplied in after the exp (``"product"``).

    Parameters
    ----------
    field : DeformableField
        Sampled with its log, at the runtime's accumulation order.
    table : ScalingTable
        Plain cone table of the same order.
    """

    def __init__(self, field: DeformableField, table: ScalingTable):
        self.field = field
        self.table = table

    def prepare(self, *, log: bool) -> None:
        """Turn the samples into their axis frames now (before the blocker is pickled
        to worker processes, so they do not each do it)."""
        _local_samples(self.field, self.table, log)

    def log_visibility(self, points, normals, order: int) -> np.ndarray:
        """Scaled log visibility ``(V, order*order)`` (see :func:`deformable_visibility`)."""
        if order != self.field.order:
            raise ValueError(f"the deformable field was sampled at order {self.field.order} "
                             f"but the runtime accumulates at order {order}")
        return deformable_visibility(self.field, self.table, points, log=True)

    def visibility(self, points, normals, order: int) -> np.ndarray:
        """Scaled visibility ``(V, order*order)`` for product-space accumulation."""
        if order != self.field.order:
            raise ValueError(f"the deformable field was sampled at order {self.field.order} "
                             f"but the products run at order {order}")
        return deformable_visibility(self.field, self.table, points, log=False)
