r"""Shadow-field lookup and combination (Tamura et al. Sec. 5.1; NumPy + h5py only).

A :class:`FieldBlocker` is a rigid object carrying a precomputed shadow field
(:class:`shtools.data_formats.field.ShadowField`, from ``shtools field sample``)
posed by a rotation, a translation and a uniform scale.  For every receiver
point the lookup

1. moves the point into the object's frame, ``p_loc = R^T (p - t) / s``;
2. finds the two shells around ``d = |p_loc - centre|``;
3. interpolates bilinearly on each shell's cell-centred (theta, phi) grid
   (:func:`shell_bilinear`: theta clamps at the poles, phi wraps -- the same
   interpolation the adaptive reduction checks its threshold with), dequantizes
   (``offset + q * step``; bilinear weights sum to 1, so dequantizing after the
   weighted sum is exact);
4. blends the two shells linearly in radius;
5. rotates the SH vector to the world (one SH rotation matrix per object).

Outside the sampled range (the paper is silent; chosen to be continuous):

* **inside the innermost shell** the innermost shell's value is used (clamped);
* **beyond the last shell** the value fades linearly to "unoccluded"
  (``(sqrt(4 pi), 0, ...)``; log 0) over one shell spacing, and is exactly
  unoccluded past ``r_last + spacing`` (at the default 6.4 V_r the bounding
  sphere subtends 9 deg, at most ~2.4 % of cosine-weighted irradiance);
* at the poles the value clamps to the first/last ring of samples (a tiny
  phi-dependence within half a cell of the pole, documented, not blended).

Pairs that are exactly unoccluded are skipped: beyond the fade, and where the
object's bounding sphere lies entirely behind the receiver's tangent plane (the
project's visibility convention counts directions below the plane as visible,
``shtools.reference.raytrace``).  A receiver never looks up its own object's
field (``skip_rows``): its self-shadowing is the per-vertex O_v.

Combination: :func:`field_log_visibility` sums the rotated logs (log space:
one exp for fields, sphere sets and trees together); :func:`field_product_visibility`
multiplies the OCVs with truncated SH products, occluders nearest first
(product space, as the papers do).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shtools.errors import InputError
from shtools.sh import product, rotation_matrix
from shtools.sh.basis import SQRT_4PI

#: Receiver points per lookup pass (bounds the (P, 8, n*n) gather to ~20 MiB).
LOOKUP_CHUNK = 1 << 15

#: Relative tolerance of the uniform-scale check of a pose.
SCALE_TOL = 1e-6


def shell_bilinear(theta, phi, res):
    """Sample indices and weights of the bilinear lookup on a cell-centred shell grid.

    Sample ``(s, t)`` sits at ``theta_s = (s + 1/2) pi / R``, ``phi_t = (t + 1/2) 2 pi / R``.
    theta clamps to the first/last row; phi wraps (Tamura et al.'s duplicated border
    columns, Sec. 5.1).

    Parameters
    ----------
    theta, phi : array_like, shape (P,)
        Polar angle from the pole axis in [0, pi] and azimuth (any real; wrapped).
    res : int or array_like of int, shape (P,)
        Grid resolution ``R`` (per point when shells differ).

    Returns
    -------
    index : ndarray of int64, shape (P, 4)
        Flat sample index ``s * R + t`` of the four corners.
    weight : ndarray, shape (P, 4)
        Bilinear weights (sum to 1), float32 when ``theta`` is float32.
    """
    theta = np.asarray(theta)
    dtype = np.float32 if theta.dtype == np.float32 else np.float64
    R = np.asarray(res, dtype=np.int64)
    Rf = R.astype(dtype)
    u = np.clip(theta.astype(dtype) * (Rf / dtype(math.pi)) - dtype(0.5), 0, Rf - 1)
    s0 = np.floor(u)
    fu = u - s0
    s0 = s0.astype(np.int64)
    s1 = np.minimum(s0 + 1, R - 1)
    v = np.asarray(phi, dtype=dtype) * (Rf / dtype(2 * math.pi)) - dtype(0.5)
    t0f = np.floor(v)
    fv = v - t0f
    t0 = np.mod(t0f.astype(np.int64), R)
    t1 = np.where(t0 + 1 == R, 0, t0 + 1)
    index = np.stack([s0 * R + t0, s0 * R + t1, s1 * R + t0, s1 * R + t1], axis=-1)
    gu, gv = 1 - fu, 1 - fv
    weight = np.stack([gu * gv, gu * fv, fu * gv, fu * fv], axis=-1)
    return index, weight


def grid_angles(res: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell-centred sample angles of a shell, ``theta (R,)`` and ``phi (R,)``."""
    k = np.arange(res) + 0.5
    return k * math.pi / res, k * 2 * math.pi / res


def interpolate_grid(grid, theta, phi) -> np.ndarray:
    """Bilinear lookup (:func:`shell_bilinear`) in one float grid.

    Parameters
    ----------
    grid : array_like, shape (R, R, K)
    theta, phi : array_like, shape (P,)

    Returns
    -------
    ndarray, shape (P, K)
    """
    g = np.asarray(grid)
    R = g.shape[0]
    index, weight = shell_bilinear(theta, phi, R)
    flat = g.reshape(R * R, -1)
    return np.einsum("pk,pkc->pc", weight, flat[index])


def _flatten(shells: list, offset, step, K: int) -> tuple[np.ndarray, np.ndarray]:
    """Every shell's samples, dequantized, in one float32 table ``(sum R_c^2, K)``.

    Dequantizing once at load (not per lookup) is exact: within a shell the
    bilinear weights sum to 1, so interpolating then dequantizing gives the same
    value, and between shells the values must be dequantized first anyway.
    """
    base = np.zeros(len(shells), dtype=np.int64)
    total = 0
    for c, q in enumerate(shells):
        base[c] = total
        total += q.shape[0] * q.shape[1]
    flat = np.empty((total, K), dtype=np.float32)
    off = np.asarray(offset, np.float32)
    st = np.asarray(step, np.float32)
    for c, q in enumerate(shells):
        rows = np.asarray(q).reshape(-1, K).astype(np.float32)
        flat[base[c]:base[c] + rows.shape[0]] = off[c] + rows * st[c]
    return flat, base


class FieldTable:
    """A shadow field laid out for lookups: every shell's samples in one flat table.

    Parameters
    ----------
    fld : ShadowField
        From :func:`shtools.data_formats.field.read_field` or the sampler.

    Attributes
    ----------
    order : int
    center : ndarray, shape (3,)
    radii : ndarray, shape (C,)
    bounding_radius : float
    fade_end : float
        Object-frame distance beyond which the field is exactly unoccluded.
    """

    def __init__(self, fld):
        self.field = fld
        self.order = int(fld.order)
        #: SH vectors per sample (3 for an RGB source radiance field), channel-major
        self.channels = int(getattr(fld, "channels", 1))
        K = self.order ** 2 * self.channels
        self.center = np.asarray(fld.center, dtype=np.float64)
        self.radii = np.asarray(fld.shell_radii, dtype=np.float64)
        self.res = np.asarray(fld.resolution, dtype=np.int64)
        self.bounding_radius = float(fld.bounding_radius)
        C = self.radii.shape[0]
        self.fade = float(self.radii[-1] - self.radii[-2]) if C > 1 else float(self.radii[0])
        self.fade_end = float(self.radii[-1] + self.fade)
        steps = np.diff(self.radii)
        self._step = float(steps[0]) if C > 1 else 1.0
        #: equally spaced shells (the default): the shell index is arithmetic, no search
        self._uniform = C > 1 and bool(np.allclose(steps, self._step, rtol=1e-9, atol=0))
        self._data = {"ocv": _flatten(fld.ocv, fld.offset, fld.step, K)}
        if getattr(fld, "log_ocv", None) is not None:  # radiance fields have no log
            self._data["log"] = _flatten(fld.log_ocv, fld.log_offset, fld.log_step, K)

    def __getstate__(self):
        # worker processes get the lookup tables only, not the stored (quantized) field
        state = dict(self.__dict__)
        state["field"] = None
        return state

    def lookup(self, points, space: str = "ocv") -> np.ndarray:
        """Field value at object-frame points (no rotation), shape ``(P, channels*n*n)`` float32.

        Parameters
        ----------
        points : array_like, shape (P, 3)
            Object-frame positions.
        space : {"ocv", "log"}
            The visibility vectors or their SH logs.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        K = self.order ** 2 * self.channels
        out = np.empty((p.shape[0], K), dtype=np.float32)
        for s in range(0, p.shape[0], LOOKUP_CHUNK):
            out[s:s + LOOKUP_CHUNK] = self._lookup_chunk(p[s:s + LOOKUP_CHUNK], space)
        return out

    def _lookup_chunk(self, p, space):
        flat, base = self._data[space]
        rel = (p - self.center).astype(np.float32)
        d = np.sqrt(np.einsum("pi,pi->p", rel, rel))
        safe = np.where(d > 0, d, np.float32(1))
        theta = np.arccos(np.clip(rel[:, 2] / safe, -1, 1))
        phi = np.arctan2(rel[:, 1], rel[:, 0])
        C = self.radii.shape[0]
        P = p.shape[0]
        if C > 1:
            if self._uniform:  # r_c = r_0 + c dr (the default shells): no search
                x = np.clip((d - np.float32(self.radii[0])) / np.float32(self._step), 0, C - 1)
                c1 = np.minimum(x.astype(np.int64), C - 2)
                w = x - c1
            else:
                d64 = d.astype(np.float64)
                c1 = np.clip(np.searchsorted(self.radii, d64, side="right") - 1, 0, C - 2)
                w = np.clip((d64 - self.radii[c1]) / (self.radii[c1 + 1] - self.radii[c1]),
                            0, 1).astype(np.float32)
            shells = ((c1, 1 - w), (c1 + 1, w))
        else:
            shells = ((np.zeros(P, np.int64), np.ones(P, np.float32)),)
        # the corners of both shells in one gather: (P, 4 * shells) rows and weights
        index = np.empty((P, 4 * len(shells)), dtype=np.int64)
        weight = np.empty((P, 4 * len(shells)), dtype=np.float32)
        # beyond the last shell: fade to unoccluded over one shell spacing
        fade = np.clip((d - np.float32(self.radii[-1])) / np.float32(self.fade), 0, 1)
        keep = 1 - fade
        for k, (c, wc) in enumerate(shells):
            idx, wb = shell_bilinear(theta, phi, self.res[c])
            index[:, 4 * k:4 * k + 4] = idx + base[c][:, None]
            weight[:, 4 * k:4 * k + 4] = wb * (wc * keep)[:, None]
        out = np.einsum("pk,pkc->pc", weight, np.take(flat, index, axis=0))
        if space == "ocv":
            out[:, 0] += fade * np.float32(SQRT_4PI)
        return out


@dataclass
class FieldBlocker:
    """A rigid object with a shadow field, posed for one frame.

    Parameters
    ----------
    table : FieldTable or ShadowField
    rotation : array_like, shape (3, 3)
        Object-to-world rotation (proper).
    translation : array_like, shape (3,)
    scale : float
        Uniform scale (> 0).
    skip_rows : array_like of int, optional
        Receiver rows that belong to this object (never looked up: a surface
        point is inside the field's innermost shells).
    """

    table: Any
    rotation: Any = field(default_factory=lambda: np.eye(3))
    translation: Any = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0
    skip_rows: Any = None

    def __post_init__(self):
        if not isinstance(self.table, FieldTable):
            self.table = FieldTable(self.table)
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        self.translation = np.asarray(self.translation, dtype=np.float64).reshape(3)
        self.scale = float(self.scale)
        R = self.rotation
        if not (np.allclose(R.T @ R, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0):
            raise InputError("a field blocker needs a proper rotation (no mirror, no shear)")
        if not (self.scale > 0 and math.isfinite(self.scale)):
            raise InputError(f"a field blocker needs a scale > 0, got {self.scale!r}")
        if not np.isfinite(self.translation).all():
            raise InputError("a field blocker's translation contains NaN or inf")

    @classmethod
    def from_matrix(cls, table, matrix, skip_rows=None) -> FieldBlocker:
        """Pose from a 4x4 object-to-world matrix; refuses non-uniform scale and shear.

        Raises
        ------
        InputError
            The matrix is not rotation x uniform scale + translation.
        """
        m = np.asarray(matrix, dtype=np.float64)
        a = m[:3, :3]
        scales = np.linalg.norm(a, axis=0)
        s = float(scales.mean())
        if not s > 0 or np.ptp(scales) > SCALE_TOL * s:
            raise InputError("shadow fields need a rigid pose with a uniform scale; got scales "
                             f"{np.round(scales, 6).tolist()} (use a sphere-set blocker for a "
                             "stretched object)")
        R = a / s
        if not np.allclose(R.T @ R, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
            raise InputError("shadow fields need a rigid pose (rotation, uniform scale, "
                             "translation); this transform shears or mirrors")
        return cls(table, R, m[:3, 3], s, skip_rows)

    @property
    def world_center(self) -> np.ndarray:
        """Bounding-sphere centre in the world, shape (3,)."""
        return self.rotation @ self.table.center * self.scale + self.translation

    def local_points(self, points) -> np.ndarray:
        """World points in the object frame, ``R^T (p - t) / s``, shape (P, 3)."""
        return (np.asarray(points, dtype=np.float64) - self.translation) @ self.rotation \
            / self.scale

    def active_rows(self, points, normals) -> np.ndarray:
        """Receiver rows where this object's field is not exactly unoccluded, shape (P',)."""
        rel = self.world_center - np.asarray(points, dtype=np.float64)
        dist = np.sqrt(np.einsum("pi,pi->p", rel, rel))
        active = dist < self.table.fade_end * self.scale
        if normals is not None:
            # the whole bounding sphere behind the tangent plane: visible by convention
            height = np.einsum("pi,pi->p", rel, np.asarray(normals, dtype=np.float64))
            active &= height > -self.table.bounding_radius * self.scale
        if self.skip_rows is not None:
            active[np.asarray(self.skip_rows)] = False
        return np.flatnonzero(active)

    def log_visibility(self, points, normals, order: int) -> np.ndarray:
        """The runtime's log-blocker protocol: this field's SH log at the receivers.

        Parameters
        ----------
        points, normals : ndarray, shape (V, 3)
        order : int
            The accumulation order (``>=`` the field's order; zero above it).

        Returns
        -------
        ndarray, shape (V, order*order) float32
        """
        return field_log_visibility(points, normals, [self], self.table.order, order)

    def world_vectors(self, points, space: str = "ocv") -> np.ndarray:
        """Field value at world points, rotated to the world, shape ``(P, n*n)`` float32."""
        local = self.table.lookup(self.local_points(points), space)
        D = rotation_matrix(self.rotation, self.table.order).astype(np.float32)
        return local @ D.T


def _check_orders(blockers, order: int) -> None:
    for b in blockers:
        if b.table.order != order:
            raise InputError(f"a shadow field has SH order {b.table.order} but the scene "
                             f"shades at order {order}; resample it with "
                             f"`shtools field sample --order {order}`")


def field_log_visibility(points, normals, blockers, order: int, out_order: int | None = None,
                         out=None) -> np.ndarray:
    """Sum of the fields' rotated SH logs per receiver (log space), shape ``(V, m*m)``.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
    blockers : list of FieldBlocker
    order : int
        Shading order ``n``; every field must have it.
    out_order : int, optional
        Order ``m >= n`` of the result (the accumulation order); the fields' logs
        are order ``n`` and zero above.
    out : ndarray, shape (V, m*m), optional
        Added to in place (e.g. the sphere blockers' log sum).

    Returns
    -------
    ndarray, shape (V, m*m) float32
    """
    _check_orders(blockers, order)
    m = order if out_order is None else int(out_order)
    p = np.asarray(points, dtype=np.float64)
    if out is None:
        out = np.zeros((p.shape[0], m * m), dtype=np.float32)
    K = order * order
    acc = np.zeros((p.shape[0], K), dtype=np.float32)  # contiguous: cheaper row updates
    for b in blockers:
        rows = b.active_rows(p, normals)
        if rows.size:
            acc[rows] += b.world_vectors(p[rows], "log")
    out[:, :K] += acc
    return out


def field_product_visibility(points, normals, blockers, order: int,
                             acc_order: int | None = None, base=None) -> np.ndarray:
    """Product of the fields' rotated OCVs per receiver (product space), shape ``(V, n*n)``.

    Occluders are multiplied nearest first (distance from their centre to the
    receivers' centroid; the order matters only through truncation, Fig. 3).

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
    blockers : list of FieldBlocker
    order : int
        Shading order ``n``; every field must have it.
    acc_order : int, optional
        Order of the running product (``>= n``), truncated to ``n`` at the end.
    base : array_like, shape (V, k*k), optional
        Visibility of other blockers to multiply into (e.g. sphere sets).

    Returns
    -------
    ndarray, shape (V, n*n) float64
    """
    _check_orders(blockers, order)
    m = order if acc_order is None else int(acc_order)
    p = np.asarray(points, dtype=np.float64)
    g = np.zeros((p.shape[0], m * m))
    if base is None:
        g[:, 0] = SQRT_4PI
    else:
        b0 = np.asarray(base, dtype=np.float64)
        k = min(b0.shape[1], m * m)
        g[:, :k] = b0[:, :k]
    centroid = p.mean(axis=0) if p.shape[0] else np.zeros(3)
    ordered = sorted(blockers, key=lambda b: float(np.linalg.norm(b.world_center - centroid)))
    K = order * order
    for b in ordered:
        rows = b.active_rows(p, normals)
        if rows.size:
            o = np.zeros((rows.size, m * m))
            o[:, :K] = b.world_vectors(p[rows], "ocv")
            g[rows] = product(g[rows], o, m)
    return np.ascontiguousarray(g[:, :K])
