r"""The soft shadow occlusion camera (SSOC; Mo, Popescu, Wyman): small spherical lights.

Per light and frame, on the CPU in vectorised NumPy (Mo et al., cited in
``docs/references.md``; what is marked *derived* below fills gaps in the paper):

1. **silhouettes** from face orientation relative to the light centre
   (:mod:`shtools.runtime.silhouettes`; adjacency built once per topology);
2. a **shadow map** per face of the light camera (:mod:`shtools.runtime.light_camera`;
   a cube map with a guard band by default) -- eye-space depth ``z`` along
   the face axis, z-buffered by :func:`shtools.runtime.raster.depth_buffer`;
3. the **SSOC**: silhouettes extruded along their image-space normals into
   quads of width ``w`` (perpendicular to the view direction) and rasterised
   into an OUTER map (outside the hard shadow) and an INNER map (inside it);
   every texel keeps the 6-tuple of its *nearest* silhouette edge (overlaps
   resolved by the distance to the silhouette): nearest point ``e`` (2), edge
   normal ``n`` (2, pointing away from the occluder), ``z_near`` and ``z_far``;
4. **receivers**: the visible fraction ``S`` of the light per receiver.

Geometry (*derived*; the paper's Fig. 5 pseudo-code is missing).  For a
silhouette at depth :math:`z_n`, a receiver at depth :math:`p_z` and a light
of radius :math:`r_L`, the penumbra is the band of half-width

.. math::  d_{max}(p_z) = f\,r_L\,\bigl(1/z_n - 1/\min(p_z, z_f)\bigr)_+ \, g

(pixels) about the hard-shadow boundary -- the DDOC's 1/z-linear form with
:math:`d_f = f r_L (1/z_n - 1/z_f)`, which is why ``d_f`` is not stored; ``g``
(:func:`~shtools.runtime.ssoc_maps.obliquity`, 1 on the face's axis) is the
pinhole image's stretch of an angle across the edge away from the axis.  With
:math:`s = (u - e)\cdot n` the signed image distance of the receiver's
projection from the edge, the SSOC squeezes the band ``[-d_max, d_max]`` into
its visible half: distortion :math:`d = (d_{max} - s)/2` and (Eq. 1)
:math:`S = 1 - d/d_{max}`, mapped to the exact disk-segment fraction
:math:`\tfrac12 + (\sin^{-1}\tau + \tau\sqrt{1-\tau^2})/\pi`, :math:`\tau = s/d_{max}`
(``falloff="disk"``, the default: the visible part of a disk light behind a
straight edge) or smoothed by :math:`3t^2 - 2t^3` (``falloff="smoothstep"``, as
in the paper).

Boundary rules (Sec. 3.2.2): no record -> plain shadow map; :math:`s \le -d_{max}`
-> umbra (0); :math:`s \ge d_{max}` or :math:`d_{max} = 0` -> the edge does not
shadow this receiver ("too far": lit if visible, umbra if hidden); after the
first distortion the point is tested against the shadow map again and a point
still hidden is fully shadowed (the cow's light leak, Fig. 6).  Overlapping
penumbrae (Sec. 3.2.3): the record at the distorted position is read; if it
belongs to another edge (normals differ, ``n.n' < cos_same``) with an
overlapping ``[z_near, z_far]``, the *original* receiver's intensity against that
edge multiplies ``S`` (``overlap="product"``, the paper) -- up to ``max_steps``
lookups.  By default (``overlap="union"``, beyond the paper; the spec's Sec. 7.2)
each edge met hides a half-plane of the light disk and ``S`` is the part of the
disk outside all of them (:func:`_union_fraction`): light that passes two edges is
not counted as blocked twice.  The 4-tap filter
(Sec. 5): ``S`` is evaluated with the records and shadow-map depths of the 4
texels around the receiver's projection and blended bilinearly.

Depth bias (stated form, "rather large", Sec. 4):
:math:`b(\delta) = \epsilon z + (1.5 + \delta)\,(z/f)\,\min(\tan\theta, 10)` where
``θ`` is the angle between the receiver normal and the direction to the light
and ``δ`` the distance in pixels between the receiver's projection and the
texel tested: the depth change of the receiver's own plane over ``1.5 + δ``
texels (the 4 taps reach 1 texel, distorted lookups ``δ``) plus a relative
``ε`` (default 2e-3) for rasterisation round-off -- so a distorted lookup does
not find the receiver's own tilted surface in front of itself (Fig. 9).

Choices the paper leaves open (recorded here; the maps are made in
:mod:`~shtools.runtime.ssoc_maps`): quads are rasterised per sub-segment of at
most ``SEGMENT_PX`` pixels (a long edge's bounding box would be the whole
image); ``z_far`` is the shadow-map depth outside the edge at each
texel's nearest point (the deepest of 1.5, 3 and 6 px; the receivers' far
depth where nothing is behind); the quad width uses the edge's smaller
``z_near`` and the deepest of those ``z_far`` at its ends and middle, clamped
to the guard band; the post-distortion test looks at least 1.5 px outside the edge (a point
closer than that would find the edge's own rasterised pixels); silhouette
corners get round caps (``corners="caps"``, default; the paper's bare quads
leave wedge gaps at the convex corners of tessellated contours, as
``tests/runtime/test_ssoc.py`` shows); silhouette points that are no depth
discontinuity of the shadow map -- covered by a nearer surface, or the backward
pieces of a contour folding on itself in the image -- get no record
(``drop_covered``, default; :func:`~shtools.runtime.ssoc_maps.distortion_maps`).

This module is numpy-only and lives in the runtime (rasterisation is a NumPy
z-buffer, so no ray tracer is needed; the paper's method is raster-based): a
pipeline embedding :mod:`shtools.runtime` gets the small-light path too.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from shtools.blend import smoothstep
from shtools.errors import InputError
from shtools.runtime.light_camera import LightCamera, fit_light_camera
from shtools.runtime.raster import depth_buffer
from shtools.runtime.silhouettes import EdgeAdjacency, edge_adjacency, silhouette_edges
from shtools.runtime.ssoc_maps import (
    OUTSIDE_PX,
    DistortionMap,
    distortion_maps,
    obliquity,
    sample_map,
)

#: Valid map resolutions (pixels per face side).
RESOLUTION_RANGE = (16, 8192)
#: Near plane of every face, relative to the scene's extent.
NEAR_REL = 1e-6

FALLOFFS = ("smoothstep", "disk")
OVERLAPS = ("union", "product")
#: Points of the light disk (unit radius) that :func:`_union_fraction` counts: a Fibonacci
#: spiral, equal area per point, so ``1/DISK_POINTS`` of the light per point.
DISK_POINTS = 256
CAMERAS = ("cube", "frustum", "auto")
CORNERS = ("quads", "caps")


@dataclass
class SSOCSettings:
    """Parameters of the occlusion camera (one place for every default).

    Attributes
    ----------
    resolution : int
        Pixels per side of each light-camera face (16..8192).
    camera : {"cube", "frustum", "auto"}
        Light camera (:mod:`shtools.runtime.light_camera`).
    guard : float
        Guard band of the faces (fraction of the 90° half-tangent).
    max_steps : int
        Distortion-map lookups per tap (1 = the paper's naive approach, Fig. 5;
        2-3 = Sec. 3.2.3).
    falloff : {"disk", "smoothstep"}
        The exact disk-segment fraction (default), or the paper's Bernstein smoothstep.
    filter : bool
        The paper's 4-tap bilinear blend (False: nearest texel).
    visibility_check : bool
        Fully shadow points still hidden after distortion (Fig. 6).
    bias_rel : float
        ``ε`` of the depth bias (relative to depth).
    cos_same : float
        Two records with ``n.n' >= cos_same`` belong to the same region (Sec. 4).
    max_width : float or None
        Widest quad in pixels (default: the guard band, ``guard * f``).
    corners : {"quads", "caps"}
        ``"quads"``: the paper's quads, which leave wedge-shaped gaps at convex
        silhouette corners (zig-zag contours of tessellated curved occluders);
        ``"caps"``: capsules (quads plus round caps at the endpoints, records
        there point radially from the corner) -- beyond the paper.
    overlap : {"union", "product"}
        How the edges met in successive lookups combine (Sec. 3.2.3): ``"product"``
        multiplies their visible fractions (the paper); ``"union"`` (default)
        counts the part of the light disk outside every edge's shadow, each edge
        blocking a half-plane of the disk -- exact for two straight edges of
        separate occluders or of a concave corner, and ``min`` of the fractions
        for nested edges, where the product is too dark.
    drop_covered : bool
        Do not record silhouette points that are no depth discontinuity in the
        shadow map (hidden behind a nearer surface, or a contour's backward
        piece whose normal points into the occluder;
        :func:`shtools.runtime.ssoc_maps.distortion_maps`).
    """

    resolution: int = 1024
    camera: str = "cube"
    guard: float = 0.125
    max_steps: int = 3
    falloff: str = "disk"
    filter: bool = True
    visibility_check: bool = True
    bias_rel: float = 2e-3
    cos_same: float = 0.9
    max_width: float | None = None
    corners: str = "caps"
    overlap: str = "union"
    drop_covered: bool = True

    def __post_init__(self):
        lo, hi = RESOLUTION_RANGE
        if (isinstance(self.resolution, bool) or not isinstance(self.resolution, int | np.integer)
                or not lo <= self.resolution <= hi):
            raise InputError(f"SSOC map resolution must be an integer in {lo}..{hi}, "
                             f"got {self.resolution!r}")
        if self.camera not in CAMERAS:
            raise InputError(f"SSOC camera must be one of {', '.join(CAMERAS)}, "
                             f"got {self.camera!r}")
        if self.falloff not in FALLOFFS:
            raise InputError(f"SSOC falloff must be one of {', '.join(FALLOFFS)}, "
                             f"got {self.falloff!r}")
        if self.overlap not in OVERLAPS:
            raise InputError(f"SSOC overlap must be one of {', '.join(OVERLAPS)}, "
                             f"got {self.overlap!r}")
        if self.corners not in CORNERS:
            raise InputError(f"SSOC corners must be one of {', '.join(CORNERS)}, "
                             f"got {self.corners!r}")
        if not 1 <= int(self.max_steps) <= 8:
            raise InputError(f"SSOC max_steps must be in 1..8, got {self.max_steps!r}")
        if not 0.0 < self.guard <= 1.0:
            raise InputError(f"SSOC guard band must be in (0, 1], got {self.guard!r}")
        if not self.bias_rel >= 0:
            raise InputError(f"SSOC bias_rel must be >= 0, got {self.bias_rel!r}")


@dataclass
class FaceMaps:
    """Shadow map and the two distortion maps of one light-camera face."""

    depth: np.ndarray  # (R*R,) eye-space depth, inf where empty
    outer: DistortionMap
    inner: DistortionMap


@dataclass
class SSOCStats:
    """CPU seconds (process time) per stage of the last frame (the paper's Table 1 columns)."""

    silhouettes: float = 0.0
    shadow_map: float = 0.0
    ssoc: float = 0.0
    receivers: float = 0.0
    n_silhouettes: int = 0
    camera: str = ""
    faces: int = 0


class OcclusionCamera:
    """The SSOC of a set of occluder meshes with fixed topology.

    Parameters
    ----------
    faces : sequence of array_like of int, shape (F_i, 3)
        Triangles of every occluder mesh (their adjacency is built here, once).
    settings : SSOCSettings, optional

    Examples
    --------
    >>> oc = OcclusionCamera([faces])                                  # doctest: +SKIP
    >>> S = oc.visible_fraction([vertices], center, radius, pts, nrm)  # doctest: +SKIP
    """

    def __init__(self, faces, settings: SSOCSettings | None = None):
        self.settings = settings or SSOCSettings()
        self.faces = [np.asarray(f, dtype=np.int64).reshape(-1, 3) for f in faces]
        self.adjacency: list[EdgeAdjacency] = [edge_adjacency(f) for f in self.faces]
        #: Stage times of the last call (:class:`SSOCStats`).
        self.last_stats = SSOCStats()
        #: Shadow and distortion maps of the last call, by cube face (for inspection).
        self.maps: dict[int, FaceMaps] = {}
        #: Receivers of the last call whose lookups met a silhouette record, ``(V,)`` bool:
        #: inside a penumbra band of the maps, whatever ``S`` came out (a scene's hybrid
        #: traces the ones called umbra too, :mod:`shtools.scene.light_shadows`).
        self.last_near_silhouette = np.zeros(0, dtype=bool)
        self._camera: LightCamera | None = None

    # ------------------------------------------------------------------ public
    def visible_fraction(self, vertices, center, radius: float, points, normals) -> np.ndarray:
        """Fraction ``S`` of the spherical light visible from each receiver, shape ``(V,)``.

        Parameters
        ----------
        vertices : sequence of array_like, shape (V_i, 3)
            Posed vertices of each occluder mesh (same order as the faces).
        center : array_like, shape (3,)
            Light centre.
        radius : float
            Light radius (> 0).
        points, normals : array_like, shape (V, 3)
            Receivers and their unit normals (the normal only sets the bias).

        Raises
        ------
        InputError
            ``radius <= 0`` or not finite, the light centre inside an occluder,
            mismatched meshes.
        """
        st = self.settings
        c = np.asarray(center, dtype=np.float64).reshape(3)
        r = float(radius)
        if not (np.isfinite(r) and r > 0) or not np.isfinite(c).all():
            raise InputError(f"SSOC light needs a finite centre and a radius > 0, got radius {r!r}")
        verts = [np.asarray(v, dtype=np.float64).reshape(-1, 3) for v in vertices]
        if len(verts) != len(self.faces):
            raise InputError(f"SSOC got {len(verts)} vertex arrays for {len(self.faces)} meshes")
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        for k, (v, f) in enumerate(zip(verts, self.faces, strict=True)):
            if len(f) and winding_number(v, f, c) > 0.75:
                raise InputError(f"the light centre is inside occluder mesh {k}; "
                                 "move the light out of the object")
        stats = SSOCStats()
        t0 = time.process_time()
        tris, sil = self._silhouettes(verts, c)
        stats.silhouettes = time.process_time() - t0
        stats.n_silhouettes = len(sil[0])
        cam = fit_light_camera(c, pts, mode=st.camera, resolution=st.resolution, guard=st.guard)
        self._camera = cam
        stats.camera = cam.mode
        face_of = cam.assign(pts)
        out = np.ones(len(pts))
        near_sil = np.zeros(len(pts), dtype=bool)
        scale = max(float(np.ptp(np.concatenate([pts, tris.reshape(-1, 3)]), axis=0).max())
                    if len(tris) else 1.0, 1e-12)
        near = NEAR_REL * scale
        self.maps = {}
        for k in np.unique(face_of):
            idx = np.flatnonzero(face_of == k)
            t1 = time.process_time()
            depth = _shadow_map(cam, int(k), tris, near)
            t2 = time.process_time()
            z_recv = float(cam.to_camera(int(k), pts[idx])[:, 2].max())
            outer, inner = distortion_maps(cam, int(k), sil, depth, r, near, z_recv, st)
            t3 = time.process_time()
            maps = FaceMaps(depth.reshape(-1), outer, inner)
            self.maps[int(k)] = maps
            out[idx], near_sil[idx] = _receivers(cam, int(k), maps, pts[idx], nrm[idx], r, st)
            t4 = time.process_time()
            stats.shadow_map += t2 - t1
            stats.ssoc += t3 - t2
            stats.receivers += t4 - t3
            stats.faces += 1
        self.last_stats = stats
        self.last_near_silhouette = near_sil
        return out

    @property
    def camera(self) -> LightCamera | None:
        """The light camera of the last call (its ``mode`` records cube or frustum)."""
        return self._camera

    # ------------------------------------------------------------------ stages
    def _silhouettes(self, verts, c):
        """All triangles ``(F, 3, 3)`` and the silhouettes ``(a (K,3), b (K,3), side (K,3))``."""
        tris, a, b, side = [], [], [], []
        for v, f, adj in zip(verts, self.faces, self.adjacency, strict=True):
            if not len(f):
                continue
            tris.append(v[f])
            edges, opp = silhouette_edges(adj, v, f, c)
            a.append(v[edges[:, 0]])
            b.append(v[edges[:, 1]])
            side.append(v[opp])
        if not tris:
            z = np.zeros((0, 3))
            return np.zeros((0, 3, 3)), (z, z, z)
        return np.concatenate(tris), (np.concatenate(a), np.concatenate(b),
                                      np.concatenate(side))


def visible_fraction(meshes, center, radius: float, points, normals,
                     settings: SSOCSettings | None = None) -> np.ndarray:
    """One-shot :meth:`OcclusionCamera.visible_fraction`.

    ``meshes`` is a list of ``(vertices (n, 3), faces (m, 3))``.

    Returns
    -------
    ndarray, shape (V,)
    """
    meshes = list(meshes)
    oc = OcclusionCamera([f for _, f in meshes], settings)
    return oc.visible_fraction([v for v, _ in meshes], center, radius, points, normals)


def winding_number(vertices, faces, point) -> float:
    """Generalised winding number of a triangle mesh at ``point`` (1 inside, 0 outside).

    Van Oosterom-Strackee solid angles summed over the triangles, divided by 4π;
    an open sheet gives at most ±1/2, a closed outward-oriented mesh 1 inside.
    """
    v = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)] - np.asarray(
        point, dtype=np.float64)
    a, b, c = v[:, 0], v[:, 1], v[:, 2]
    la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc + np.einsum("ij,ij->i", b, c) * la
           + np.einsum("ij,ij->i", c, a) * lb)
    return float(2.0 * np.arctan2(det, den).sum() / (4.0 * np.pi))


# ---------------------------------------------------------------------- shadow map
def _clip_near(cam_tris: np.ndarray, near: float) -> np.ndarray:
    """Clip camera-space triangles ``(F, 3, 3)`` to ``z >= near`` (0, 1 or 2 triangles each)."""
    behind = cam_tris[..., 2] < near
    nb = behind.sum(axis=1)
    keep = [cam_tris[nb == 0]]
    rows = np.arange(cam_tris.shape[0])

    def cut(p, q):  # point on segment p->q at z = near
        t = (near - p[:, 2]) / (q[:, 2] - p[:, 2])
        return p + t[:, None] * (q - p)

    one = rows[nb == 1]
    if one.size:  # roll so the vertex behind is first: A behind, B, C in front
        k = np.argmax(behind[one], axis=1)
        A, B, C = (cam_tris[one, (k + j) % 3] for j in range(3))
        ab, ac = cut(A, B), cut(A, C)
        keep += [np.stack([ab, B, C], axis=1), np.stack([ab, C, ac], axis=1)]
    two = rows[nb == 2]
    if two.size:  # roll so the vertex in front is first
        k = np.argmin(behind[two], axis=1)
        A, B, C = (cam_tris[two, (k + j) % 3] for j in range(3))
        keep.append(np.stack([A, cut(A, B), cut(A, C)], axis=1))
    return np.concatenate(keep)


def _shadow_map(cam: LightCamera, face: int, tris: np.ndarray, near: float) -> np.ndarray:
    """Eye-space depth ``(R, R)`` of the nearest occluder per texel of one face."""
    R = cam.resolution
    if not len(tris):
        return np.full((R, R), np.inf)
    ct = _clip_near(cam.to_camera(face, tris), near)
    sx, sy = cam.to_pixels(ct)
    return depth_buffer(sx, sy, ct[..., 2], R, R)


# ---------------------------------------------------------------------- receivers
def _falloff(t: np.ndarray, kind: str) -> np.ndarray:
    """Intensity from the linear Eq. 1 value ``t = 1 - d/d_max`` in [0, 1]."""
    t = np.clip(t, 0.0, 1.0)
    if kind == "disk":
        tau = 2.0 * t - 1.0
        return 0.5 + (np.arcsin(tau) + tau * np.sqrt(np.maximum(1.0 - tau * tau, 0.0))) / np.pi
    return smoothstep(t)


def _receivers(cam: LightCamera, face: int, maps: FaceMaps, pts, nrm, radius: float,
               st: SSOCSettings) -> tuple[np.ndarray, np.ndarray]:
    """SSOC intensity of receivers assigned to ``face``, shape ``(V,)``, and whether any
    tap met a silhouette record, ``(V,)`` bool."""
    R, f = cam.resolution, cam.focal
    q = cam.to_camera(face, pts)
    z = q[:, 2]
    ux, uy = cam.to_pixels(q)
    # slope of the receiver's own plane seen from the light: depth change per texel
    to_light = cam.center - pts
    dist = np.linalg.norm(to_light, axis=1)
    cos_t = np.einsum("ij,ij->i", nrm, to_light) / np.maximum(dist, 1e-300)
    tan_t = np.sqrt(np.maximum(1.0 - cos_t ** 2, 0.0)) / np.maximum(np.abs(cos_t), 0.1)
    slope = (z / f) * np.minimum(tan_t, 10.0)
    if st.filter:
        i0 = np.floor(ux - 0.5).astype(np.int64)
        j0 = np.floor(uy - 0.5).astype(np.int64)
        fx, fy = ux - 0.5 - i0, uy - 0.5 - j0
        taps = [(i0, j0, (1 - fx) * (1 - fy)), (i0 + 1, j0, fx * (1 - fy)),
                (i0, j0 + 1, (1 - fx) * fy), (i0 + 1, j0 + 1, fx * fy)]
    else:
        taps = [(np.floor(ux).astype(np.int64), np.floor(uy).astype(np.int64),
                 np.ones(len(z)))]
    out = np.zeros(len(z))
    near = np.zeros(len(z), dtype=bool)
    for ti, tj, w in taps:
        tid = np.clip(tj, 0, R - 1) * R + np.clip(ti, 0, R - 1)
        S, recorded = _intensity(maps, tid, ux, uy, z, slope, radius, f, R, st)
        out += w * S
        near |= recorded
    return out, near


def _intensity(maps: FaceMaps, tid, ux, uy, z, slope, radius, f, R, st
               ) -> tuple[np.ndarray, np.ndarray]:
    """One tap: the per-fragment SSOC rules (module docstring) at texels ``tid``; ``S`` and
    whether the tap met a record."""
    eps = st.bias_rel * z
    hidden = z > maps.depth[tid] + eps + 1.5 * slope
    S = np.where(hidden, 0.0, 1.0)
    rec = np.where(hidden, maps.inner.edge[tid], maps.outer.edge[tid])
    act = np.flatnonzero(rec >= 0)
    if not act.size:
        return S, rec >= 0
    # records of the active receivers: (edge, e, n, zn, zf) from INNER or OUTER
    h = hidden[act]
    t = tid[act]

    def fetch(texel, inner_mask):
        r_in, r_out = maps.inner, maps.outer
        pick = lambda a, b: np.where(inner_mask[:, None] if a.ndim == 2 else inner_mask,  # noqa: E731
                                     a[texel], b[texel])
        return (pick(r_in.edge, r_out.edge), pick(r_in.e, r_out.e), pick(r_in.n, r_out.n),
                pick(r_in.z_near, r_out.z_near), pick(r_in.z_far, r_out.z_far))

    edge, e, n, zn, zf = fetch(t, h)
    zz, ux_, uy_, sl, ep = z[act], ux[act], uy[act], slope[act], eps[act]
    s_val = np.ones(act.size)
    px, py = ux_.copy(), uy_.copy()
    seen = [edge]
    alive = np.ones(act.size, dtype=bool)
    union = st.overlap == "union"
    taus, normals = [], []  # per lookup (union): tau = s/d_max of the edge, nan if none
    for step in range(int(st.max_steps)):
        dmax = (f * radius * np.maximum(1.0 / zn - 1.0 / np.minimum(zz, zf), 0.0)
                * obliquity(ux_ - 0.5 * R, uy_ - 0.5 * R, n[:, 0], n[:, 1], f))
        s = (ux_ - e[:, 0]) * n[:, 0] + (uy_ - e[:, 1]) * n[:, 1]
        pos_d = dmax > 0
        umbra = alive & pos_d & (s <= -dmax)
        pen = alive & pos_d & (s < dmax) & ~umbra
        if union:
            with np.errstate(divide="ignore", invalid="ignore"):
                tau = np.where(pos_d, np.clip(s / dmax, -1.0, 1.0), 1.0)
            taus.append(np.where(alive, tau, np.nan))
            normals.append(n)
            if step > 0:  # an edge met later blocks its half-plane of the disk, no more
                umbra = np.zeros_like(umbra)
        if step == 0:
            # the edge does not shadow this receiver: plain shadow map for hidden points
            irrelevant = alive & ~pen & ~umbra & h
            s_val[irrelevant] = 0.0
            alive &= ~irrelevant
        s_val[umbra] = 0.0
        alive &= ~umbra
        d = np.where(pen, (dmax - s) / 2.0, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            lin = np.where(pen, 1.0 - d / dmax, 1.0)
        if step == 0 or not union:
            s_val = np.where(pen, s_val * _falloff(lin, st.falloff), s_val)
        px = px + d * n[:, 0]
        py = py + d * n[:, 1]
        if step == 0 and st.visibility_check:
            # test at least OUTSIDE_PX outside the edge (closer finds the edge's own pixels)
            extra = np.maximum(0.0, OUTSIDE_PX - (s + d))
            tx, ty = px + extra * n[:, 0], py + extra * n[:, 1]
            moved = d + extra
            still = pen & (zz > sample_map(maps.depth, R, tx, ty) + ep + (1.5 + moved) * sl)
            s_val[still] = 0.0
            alive &= ~still
        if step + 1 == int(st.max_steps):
            break
        # the record at the distorted position: another overlapping penumbra? (Sec. 3.2.3)
        moved = np.hypot(px - ux_, py - uy_)
        nt = (np.clip(np.floor(py), 0, R - 1).astype(np.int64) * R
              + np.clip(np.floor(px), 0, R - 1).astype(np.int64))
        h2 = zz > maps.depth[nt] + ep + (1.5 + moved) * sl
        edge2, e2, n2, zn2, zf2 = fetch(nt, h2)
        new = alive & pen & (edge2 >= 0)
        for old in seen:
            new &= edge2 != old
        new &= (n2[:, 0] * n[:, 0] + n2[:, 1] * n[:, 1]) < st.cos_same
        new &= (zn2 <= zf) & (zn <= zf2)  # overlapping [z_near, z_far] ranges
        if not new.any():
            break
        alive &= new
        edge = np.where(new, edge2, edge)
        e = np.where(new[:, None], e2, e)
        n = np.where(new[:, None], n2, n)
        zn, zf = np.where(new, zn2, zn), np.where(new, zf2, zf)
        seen.append(edge)
    if union and len(taus) > 1:
        multi = np.flatnonzero(~np.isnan(taus[1]) & (s_val > 0))
        s_val[multi] = _union_fraction([t[multi] for t in taus], [m[multi] for m in normals])
    S[act] = s_val
    return S, rec >= 0


def _disk_points() -> np.ndarray:
    """``DISK_POINTS`` points of the unit disk, equal area each (Fibonacci spiral), ``(M, 2)``."""
    i = np.arange(DISK_POINTS) + 0.5
    rho, phi = np.sqrt(i / DISK_POINTS), i * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([rho * np.cos(phi), rho * np.sin(phi)], axis=1)


_DISK = _disk_points()


def _union_fraction(taus, normals) -> np.ndarray:
    """Visible fraction of the light behind several straight edges, shape ``(k,)``.

    The light disk seen from the receiver, scaled to unit radius: a light point ``y``
    is hidden by an edge of normal ``n`` and ``tau = s/d_max`` where ``y.n >= tau`` (one
    edge alone leaves the disk-segment fraction, the ``"disk"`` falloff).  Every point of
    :data:`_DISK` hidden by any edge counts as hidden; ``taus[j]`` is nan where the
    ``j``-th lookup found no edge.
    """
    hidden = np.zeros((len(taus[0]), len(_DISK)), dtype=bool)
    for tau, n in zip(taus, normals, strict=True):
        ok = ~np.isnan(tau)
        hidden |= ok[:, None] & (n @ _DISK.T >= np.where(ok, tau, 1.0)[:, None])
    return 1.0 - hidden.mean(axis=1)
