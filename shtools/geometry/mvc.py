"""Mean value coordinates for closed triangle meshes (Ju, Schaefer, Warren 2005).

For a point ``x`` and a closed triangle mesh, the coordinates ``lambda (V,)``
satisfy ``sum_v lambda_v = 1`` and ``sum_v lambda_v p_v = x`` (linear precision),
so any linear function of the vertices is reproduced exactly at ``x``.  They are
computed per triangle with the numerically robust formulation of Ju et al.
(2005, Figure 7), vectorised over (point, triangle) pairs in chunks:

- a point on a vertex gets that vertex's indicator;
- a point on a triangle (``pi - h < eps``) gets that triangle's barycentric
  coordinates ``sin(theta_i) d_{i-1} d_{i+1}`` (normalised);
- a point in a triangle's plane but outside it skips that triangle.

libigl's ``mvc`` covers 2-D polygons only, hence this module.  For an open mesh
the formula still gives weights but loses linear precision;
:func:`is_closed_surface` tells the caller (``bind_spheres`` corrects the rest
residual and falls back when the weights degenerate).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["is_closed_surface", "mean_value_coordinates"]

#: Relative tolerance (of the mesh bounding-box diagonal) for "on a vertex", and
#: absolute angular tolerance for "on a triangle" / "in a triangle's plane".
VERTEX_EPS = 1e-10
ANGLE_EPS = 1e-9
#: (point, triangle) pairs processed per chunk, bounding temporary memory
#: (~40 arrays of this many doubles).
PAIRS_PER_CHUNK = 1 << 17


def is_closed_surface(vertices, faces) -> bool:
    """Whether the mesh is a closed, consistently oriented surface.

    Vertices at identical positions (UV seams, per-face copies in glTF) are
    welded first; then every undirected edge must be used exactly twice, once in
    each direction.

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
    faces : array_like of int, shape (F, 3)
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if faces.size == 0:
        return False
    _, weld = np.unique(vertices, axis=0, return_inverse=True)
    f = weld.reshape(-1)[faces]
    f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = directed[:, 0] * (f.max() + 1) + directed[:, 1]
    rev = directed[:, 1] * (f.max() + 1) + directed[:, 0]
    uniq, counts = np.unique(key, return_counts=True)
    if np.any(counts != 1):
        return False
    return bool(np.all(np.isin(rev, uniq)))


def _chunk_weights(x, tri, eps_vertex):
    """Unnormalised MVC weights for points ``x (P,3)`` and triangles ``tri (F,3,3)``.

    Returns
    -------
    w : ndarray, shape (P, F, 3)
    on_triangle : ndarray of bool, shape (P, F)
    """
    diff = tri[None, :, :, :] - x[:, None, None, :]  # (P, F, 3, 3): p_i - x
    d = np.sqrt(np.einsum("pfij,pfij->pfi", diff, diff))  # (P, F, 3)
    u = diff / np.maximum(d, eps_vertex)[..., None]
    u_next = np.roll(u, -1, axis=2)
    u_prev = np.roll(u, 1, axis=2)
    # angle at x opposite vertex i; atan2 of chord and anti-chord stays accurate
    # near pi, where Ju et al.'s 2*arcsin(l/2) loses half the digits
    chord = np.linalg.norm(u_next - u_prev, axis=3)
    antichord = np.linalg.norm(u_next + u_prev, axis=3)
    theta = 2.0 * np.arctan2(chord, antichord)
    h = 0.5 * theta.sum(axis=2)  # (P, F)
    on_triangle = np.pi - h < ANGLE_EPS
    sin_t = np.sin(theta)
    sin_next = np.roll(sin_t, -1, axis=2)
    sin_prev = np.roll(sin_t, 1, axis=2)
    d_next = np.roll(d, -1, axis=2)
    d_prev = np.roll(d, 1, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = (2.0 * np.sin(h)[..., None] * np.sin(h[..., None] - theta)
             / (sin_next * sin_prev)) - 1.0
        det = np.einsum("pfi,pfi->pf", u[:, :, 0], np.cross(u[:, :, 1], u[:, :, 2]))
        s = np.sign(det)[..., None] * np.sqrt(np.maximum(1.0 - c * c, 0.0))
        skip = np.any(np.abs(s) <= ANGLE_EPS, axis=2) | on_triangle
        c_next = np.roll(c, -1, axis=2)
        c_prev = np.roll(c, 1, axis=2)
        theta_next = np.roll(theta, -1, axis=2)
        theta_prev = np.roll(theta, 1, axis=2)
        s_prev = np.roll(s, 1, axis=2)
        w = (theta - c_next * theta_prev - c_prev * theta_next) / (d * sin_next * s_prev)
    w[skip] = 0.0
    # a point on a triangle: its barycentric coordinates replace everything else
    bary = sin_t * d_prev * d_next
    w = np.where(on_triangle[..., None], bary, w)
    return w, on_triangle


def mean_value_coordinates(points, vertices, faces, *, pairs_per_chunk=PAIRS_PER_CHUNK):
    """Mean value coordinates of points with respect to a closed triangle mesh.

    Parameters
    ----------
    points : array_like, shape (P, 3)
    vertices : array_like, shape (V, 3)
    faces : array_like of int, shape (F, 3)
        Consistently oriented (either orientation gives the same coordinates).
    pairs_per_chunk : int
        Memory bound: (point, triangle) pairs evaluated at once.

    Returns
    -------
    ndarray, shape (P, V)
        Rows sum to 1 where defined.  Rows whose raw weights sum to 0 (possible
        only for open meshes) are NaN; the caller decides the fallback.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    n_points, n_verts, n_faces = points.shape[0], vertices.shape[0], faces.shape[0]
    scale = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) or 1.0
    eps_vertex = VERTEX_EPS * scale
    tri = vertices[faces]  # (F, 3, 3)
    # corner k of face f scatters into vertex faces[f, k]
    scatter = sp.csr_matrix(
        (np.ones(3 * n_faces), (np.arange(3 * n_faces), faces.reshape(-1))),
        shape=(3 * n_faces, n_verts),
    )
    out = np.zeros((n_points, n_verts))
    step = max(1, pairs_per_chunk // max(n_faces, 1))
    for start in range(0, n_points, step):
        x = points[start:start + step]
        w, on_triangle = _chunk_weights(x, tri, eps_vertex)
        # points on a triangle keep only that triangle's (first such) weights
        hit = on_triangle.any(axis=1)
        if np.any(hit):
            first = np.argmax(on_triangle, axis=1)
            keep = np.zeros_like(on_triangle)
            keep[np.flatnonzero(hit), first[hit]] = True
            w[hit] = np.where(keep[hit][..., None], w[hit], 0.0)
        out[start:start + step] = (scatter.T @ w.reshape(x.shape[0], -1).T).T
    # points on a vertex: that vertex's indicator
    nearest_d2 = np.full(n_points, np.inf)
    nearest = np.zeros(n_points, dtype=np.int64)
    vstep = max(1, pairs_per_chunk // max(n_verts, 1))
    for start in range(0, n_points, vstep):
        dist2 = np.sum((points[start:start + vstep, None, :] - vertices[None]) ** 2, axis=2)
        nearest[start:start + vstep] = np.argmin(dist2, axis=1)
        nearest_d2[start:start + vstep] = dist2.min(axis=1)
    on_vertex = nearest_d2 <= eps_vertex ** 2
    out[on_vertex] = 0.0
    out[np.flatnonzero(on_vertex), nearest[on_vertex]] = 1.0
    total = out.sum(axis=1, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(total != 0, out / total, np.nan)
    return out
