"""The SSOC's distortion maps of one light-camera face: OUTER and INNER silhouette records.

Silhouette edges are extruded along their image-space normals into quads (or round
caps at corners) and rasterised; every texel keeps the 6-tuple of its nearest edge
(Mo et al., "The Soft Shadow Occlusion Camera", Sec. 3.2).  The choices
the paper leaves open are listed in :mod:`shtools.runtime.ssoc`, which reads these
maps per receiver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.runtime.light_camera import LightCamera
from shtools.runtime.raster import FRAGMENT_BUDGET

#: Longest sub-segment of a silhouette rasterised as one quad (pixels).
SEGMENT_PX = 8.0
#: Offset (pixels) outside an edge where z_far and the post-distortion test look.
OUTSIDE_PX = 1.5
#: Relative depth by which a nearer surface must cover a silhouette point to drop its record.
COVERED_REL = 1e-3


@dataclass
class DistortionMap:
    """One SSOC map (INNER or OUTER) of one face: the 6-tuple per texel.

    Attributes
    ----------
    edge : ndarray of int32, shape (R*R,)
        Silhouette edge id of the record (-1: empty texel).
    e : ndarray, shape (R*R, 2)
        Nearest point on the silhouette (pixels).
    n : ndarray, shape (R*R, 2)
        Unit edge normal (pixels), pointing away from the occluder.
    z_near, z_far : ndarray, shape (R*R,)
    dist : ndarray, shape (R*R,)
        Distance to the silhouette (the overlap test's depth).
    """

    edge: np.ndarray
    e: np.ndarray
    n: np.ndarray
    z_near: np.ndarray
    z_far: np.ndarray
    dist: np.ndarray

    @classmethod
    def empty(cls, size: int) -> DistortionMap:
        return cls(np.full(size, -1, np.int32), np.zeros((size, 2)), np.zeros((size, 2)),
                   np.zeros(size), np.full(size, np.inf), np.full(size, np.inf))


def sample_map(depth: np.ndarray, R: int, x, y) -> np.ndarray:
    """Nearest-texel lookup of a flat ``(R*R,)`` map at pixel coordinates (clamped)."""
    i = np.clip(np.floor(x).astype(np.int64), 0, R - 1)
    j = np.clip(np.floor(y).astype(np.int64), 0, R - 1)
    return depth[j * R + i]


def obliquity(x, y, nx, ny, f):
    """Pixels per unit of angle across an edge at ``(x, y)``, relative to the image centre.

    A pinhole image stretches angles away from its axis: a step of angle
    ``dθ`` along the unit image direction ``(nx, ny)`` at ``u = (x, y)``
    (pixels from the principal point) spans ``(f dθ / cos φ) / sqrt(1 - (n.û)² sin² φ)``
    pixels, ``φ`` the angle off the axis.  The ``1 / cos φ`` cancels against
    depth being measured along the axis (``z = D cos φ``) in the penumbra's
    half-width, which leaves this factor
    ``sqrt((f² + |u|²) / (f² + |u|² - (n.u)²))`` (1 on the axis; wider penumbrae
    in pixels across edges seen obliquely, as at the borders of a cube face).
    """
    uu = f * f + x * x + y * y
    nu = x * nx + y * ny
    return np.sqrt(uu / np.maximum(uu - nu * nu, 1e-12 * uu))


def _clip_segments(x0, y0, x1, y1, lo, hi):
    """Liang-Barsky: parameter range ``[t0, t1]`` of segments inside the square ``[lo, hi]^2``."""
    t0 = np.zeros_like(x0)
    t1 = np.ones_like(x0)
    dx, dy = x1 - x0, y1 - y0
    for p, q in ((-dx, x0 - lo), (dx, hi - x0), (-dy, y0 - lo), (dy, hi - y0)):
        with np.errstate(divide="ignore", invalid="ignore"):
            r = q / p
        par = p == 0
        t0 = np.where(~par & (p < 0), np.maximum(t0, r), t0)
        t1 = np.where(~par & (p > 0), np.minimum(t1, r), t1)
        t1 = np.where(par & (q < 0), -1.0, t1)  # parallel and outside
    return t0, t1


def distortion_maps(cam: LightCamera, face: int, sil, depth: np.ndarray, radius: float,
                    near: float, z_recv: float, st
                    ) -> tuple[DistortionMap, DistortionMap]:
    """OUTER and INNER maps of one face from the silhouettes ``sil = (a, b, side)``.

    ``z_recv`` is the receivers' far bound: ``z_far`` where nothing is behind an edge;
    ``st`` the light's :class:`~shtools.runtime.ssoc.SSOCSettings`.
    """
    R = cam.resolution
    f = cam.focal
    flat = depth.reshape(-1)
    outer, inner = DistortionMap.empty(R * R), DistortionMap.empty(R * R)
    a_w, b_w, side_w = sil
    if not len(a_w):
        return outer, inner
    w_max = st.max_width if st.max_width is not None else st.guard * f
    near_max = _max_3x3(depth.reshape(R, R)).reshape(-1) if st.drop_covered else None
    a, b, side = (cam.to_camera(face, x) for x in (a_w, b_w, side_w))
    # occluder side from the plane through the light centre and the edge: its trace in
    # the image is the projected edge, and sign(m . p) is the side for any p with z > 0
    m = np.cross(a, b)
    s3 = np.sign(np.einsum("ij,ij->i", m, side))
    # clip to z >= near (both ends behind: drop)
    za, zb = a[:, 2], b[:, 2]
    keep = ((za >= near) | (zb >= near)) & (s3 != 0)
    a, b, m, s3 = a[keep], b[keep], m[keep], s3[keep]
    edge_id = np.flatnonzero(keep).astype(np.int32)
    za, zb = a[:, 2], b[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = np.where(za < near, (near - za) / (zb - za), 0.0)
        tb = np.where(zb < near, (near - za) / (zb - za), 1.0)
    a, b = a + ta[:, None] * (b - a), a + tb[:, None] * (b - a)
    ax, ay = cam.to_pixels(a)
    bx, by = cam.to_pixels(b)
    za, zb = a[:, 2], b[:, 2]
    nx, ny = -s3 * m[:, 0], -s3 * m[:, 1]
    nl = np.hypot(nx, ny)
    ok = nl > 0
    # clip the 2-D segments to the image grown by the widest quad
    t0, t1 = _clip_segments(ax, ay, bx, by, -w_max, R + w_max)
    ok &= t1 > t0
    sel = np.flatnonzero(ok)
    ax, ay, bx, by, za, zb = (x[sel] for x in (ax, ay, bx, by, za, zb))
    nx, ny = nx[sel] / nl[sel], ny[sel] / nl[sel]
    t0, t1, edge_id = t0[sel], t1[sel], edge_id[sel]
    # per-edge width: the smallest z_near against the deepest z_far at its ends and middle
    ex, ey = bx - ax, by - ay
    inv_za, inv_zb = 1.0 / za, 1.0 / zb
    inv_zn = np.maximum(inv_za + t0 * (inv_zb - inv_za), inv_za + t1 * (inv_zb - inv_za))
    zf = np.zeros(len(sel))
    for t in (0.0, 0.5, 1.0):
        tt = t0 + t * (t1 - t0)
        zn_t = 1.0 / (inv_za + tt * (inv_zb - inv_za))
        zf = np.maximum(zf, _z_far(flat, R, ax + tt * ex, ay + tt * ey, nx, ny, zn_t, z_recv))
    stretch = np.ones(len(sel))
    for t in (0.0, 1.0):  # the obliquity is largest at an end of the clipped edge
        tt = t0 + t * (t1 - t0)
        stretch = np.maximum(stretch, obliquity(ax + tt * ex - 0.5 * R, ay + tt * ey - 0.5 * R,
                                                nx, ny, f))
    width = np.minimum(f * radius * np.maximum(inv_zn - 1.0 / zf, 0.0) * stretch, w_max)
    live = width > 0
    # split each clipped edge into sub-segments of at most SEGMENT_PX pixels
    length = np.hypot(ex, ey) * (t1 - t0)
    pieces = np.where(live, np.maximum(1, np.ceil(length / SEGMENT_PX)), 0).astype(np.int64)
    seg = np.repeat(np.arange(len(sel)), pieces)
    j = np.arange(seg.size) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    p_lo = t0[seg] + (t1 - t0)[seg] * j / pieces[seg]
    p_hi = t0[seg] + (t1 - t0)[seg] * (j + 1) / pieces[seg]
    if st.corners == "caps":  # the end pieces also own the round caps beyond the ends
        p_lo = np.where(j == 0, -np.inf, p_lo)
        p_hi = np.where(j == pieces[seg] - 1, np.inf, p_hi)
    # bounding box of the piece grown by its width on both sides
    wx = width[seg]
    q_lo = np.maximum(p_lo, t0[seg])
    q_hi = np.minimum(p_hi, t1[seg])
    xs = np.stack([ax[seg] + q_lo * ex[seg], ax[seg] + q_hi * ex[seg]], axis=1)
    ys = np.stack([ay[seg] + q_lo * ey[seg], ay[seg] + q_hi * ey[seg]], axis=1)
    x_lo = np.clip(np.floor(xs.min(1) - wx), 0, R).astype(np.int64)
    x_hi = np.clip(np.ceil(xs.max(1) + wx), 0, R).astype(np.int64)
    y_lo = np.clip(np.floor(ys.min(1) - wx), 0, R).astype(np.int64)
    y_hi = np.clip(np.ceil(ys.max(1) + wx), 0, R).astype(np.int64)
    bw, bh = x_hi - x_lo, y_hi - y_lo
    counts = np.where((bw > 0) & (bh > 0), bw * bh, 0)
    csum = np.cumsum(counts)
    start = 0
    while start < seg.size:
        base = csum[start - 1] if start else 0
        stop = max(int(np.searchsorted(csum, base + FRAGMENT_BUDGET, side="right")), start + 1)
        pc = np.arange(start, stop)
        start = stop
        cnt = counts[pc]
        if not cnt.sum():
            continue
        pf = np.repeat(pc, cnt)
        local = np.arange(pf.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        py, px = np.divmod(local, bw[pf])
        px += x_lo[pf]
        py += y_lo[pf]
        s_ = seg[pf]
        cx, cy = px + 0.5 - ax[s_], py + 0.5 - ay[s_]
        el2 = ex[s_] ** 2 + ey[s_] ** 2
        t = (cx * ex[s_] + cy * ey[s_]) / el2
        sd = cx * nx[s_] + cy * ny[s_]  # signed distance to the line, + outside
        tc = np.clip(t, t0[s_], t1[s_])  # nearest point of the (clipped) edge
        gx, gy = cx - tc * ex[s_], cy - tc * ey[s_]  # from the nearest point to the texel
        dist = np.hypot(gx, gy)
        inside = (t >= p_lo[pf]) & (t <= p_hi[pf]) & (dist <= width[s_])
        if not inside.any():
            continue
        pf, s_, px, py, tc, sd, gx, gy, dist = (
            x[inside] for x in (pf, s_, px, py, tc, sd, gx, gy, dist))
        exx, eyy = ax[s_] + tc * ex[s_], ay[s_] + tc * ey[s_]
        rnx, rny = nx[s_], ny[s_]
        cap = (np.abs(dist - np.abs(sd)) > 1e-9) & (dist > 0)  # beyond an end: radial normal
        sgn = np.where(sd >= 0, 1.0, -1.0)
        rnx = np.where(cap, sgn * gx / np.where(cap, dist, 1.0), rnx)
        rny = np.where(cap, sgn * gy / np.where(cap, dist, 1.0), rny)
        zn = 1.0 / (inv_za[s_] + tc * (inv_zb[s_] - inv_za[s_]))
        rec = (py * R + px, dist, edge_id[s_], exx, eyy, rnx, rny, zn)
        out_side = sd >= 0
        if near_max is not None:
            keep = _uncovered(flat, near_max, R, exx, eyy, rnx, rny, zn)
            rec, out_side = tuple(x[keep] for x in rec), out_side[keep]
        _splat(outer, tuple(x[out_side] for x in rec))
        _splat(inner, tuple(x[~out_side] for x in rec))
    for dm in (outer, inner):  # z_far of the winning records only
        full = np.flatnonzero(dm.edge >= 0)
        dm.z_far[full] = _z_far(flat, R, dm.e[full, 0], dm.e[full, 1], dm.n[full, 0],
                                dm.n[full, 1], dm.z_near[full], z_recv)
    return outer, inner


def _max_3x3(d: np.ndarray) -> np.ndarray:
    """Largest depth of each texel's 3 x 3 neighbourhood, shape ``(R, R)`` (edges repeated)."""
    R0, R1 = d.shape
    pad = np.pad(d, 1, mode="edge")
    out = d.copy()
    for di in range(3):
        for dj in range(3):
            np.maximum(out, pad[di:di + R0, dj:dj + R1], out=out)
    return out


def _uncovered(flat, near_max, R, ex, ey, nx, ny, zn) -> np.ndarray:
    """Records whose silhouette point is a depth discontinuity in the shadow map, ``(k,)`` bool.

    Silhouettes are found on the mesh, not in the image, so some of them cannot bound
    the shadow: a fold of the far layer of an occluder hidden behind its near layer (no
    texel within 1 px of the point ``e`` is as deep as the edge: ``near_max < z_near``),
    and the backward pieces of a tessellated contour that folds on itself in the image,
    whose normal points into the occluder (the texel ``OUTSIDE_PX`` along the normal is
    nearer than the edge).  Their quads would win texels as the nearest silhouette over
    the true outline a few pixels away, and the receivers behind would read umbra
    (or fail the post-distortion test).  Both tests allow ``COVERED_REL`` of the depth.
    """
    lim = zn * (1.0 - COVERED_REL)
    return ((sample_map(near_max, R, ex, ey) >= lim)
            & (sample_map(flat, R, ex + OUTSIDE_PX * nx, ey + OUTSIDE_PX * ny) >= lim))


def _z_far(flat, R, ex, ey, nx, ny, zn, z_recv) -> np.ndarray:
    """Depth behind a silhouette: the deepest shadow-map sample 1.5, 3 and 6 px outside it.

    Samples that still land on the occluder itself (depth within 0.1 % of
    ``z_near``; a zig-zag contour's normal can point across its own outline) do
    not count; where nothing is found the receivers' far bound ``z_recv`` is used.
    """
    zf = np.full(len(zn), -np.inf)
    for k in (OUTSIDE_PX, 2 * OUTSIDE_PX, 4 * OUTSIDE_PX):
        z = sample_map(flat, R, ex + k * nx, ey + k * ny)
        zf = np.where(z > zn * 1.001, np.maximum(zf, z), zf)
    zf = np.where(np.isfinite(zf), zf, z_recv)
    return np.maximum(np.minimum(zf, z_recv), zn)


def _splat(dm: DistortionMap, rec) -> None:
    """Write fragments into a map, keeping per texel the nearest silhouette (Sec. 3.2.1 step 5).

    ``rec = (texel, distance, edge, ex, ey, nx, ny, z_near)``; ``z_far`` is filled
    in afterwards for the winners.
    """
    pid, dist = rec[0], rec[1]
    if not pid.size:
        return
    best = dm.dist.copy()
    np.minimum.at(best, pid, dist)
    win = (dist == best[pid]) & (dist < dm.dist[pid])  # ties: any of the equals
    pid = pid[win]
    dm.dist[pid] = rec[1][win]
    dm.edge[pid] = rec[2][win]
    dm.e[pid, 0], dm.e[pid, 1] = rec[3][win], rec[4][win]
    dm.n[pid, 0], dm.n[pid, 1] = rec[5][win], rec[6][win]
    dm.z_near[pid] = rec[7][win]
