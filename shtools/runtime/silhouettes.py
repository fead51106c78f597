"""Silhouette edges of triangle meshes as seen from a point (the SSOC's step 1).

The edge-face adjacency depends only on the topology, so it is built once
(:func:`edge_adjacency`) and reused every frame; per frame only the facing
signs of the faces relative to the light centre are computed
(:func:`silhouette_edges`).

Edge kinds:

* **interior** edges (two faces) are silhouettes where one face is front-facing
  and the other back-facing relative to the light centre;
* **boundary** edges of open meshes (one face; the holes of a scanned bunny, the
  rim of a ground plane) are *always* silhouettes: a one-sided sheet is a depth
  discontinuity seen from either side, and the ray-traced reference treats
  triangles as two-sided, so a rim occludes from behind too;
* **non-manifold** edges (three or more faces) are split into one boundary
  edge per incident face (each such face's edge is a discontinuity by itself).

For every silhouette the *occluder side* is recorded as a vertex of an
incident face that is not on the edge: both faces of a contour fold project to
the same side of the edge, so either one names the side the occluder is on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class EdgeAdjacency:
    """Edges of a triangle mesh with their incident faces.

    Attributes
    ----------
    edges : ndarray of int, shape (E, 2)
        Vertex indices of each edge.
    faces : ndarray of int, shape (E, 2)
        Incident faces; ``faces[:, 1]`` is -1 for boundary edges.
    opposite : ndarray of int, shape (E, 2)
        The vertex of each incident face that is not on the edge (-1 where the
        face is absent).
    """

    edges: np.ndarray
    faces: np.ndarray
    opposite: np.ndarray

    @property
    def n_boundary(self) -> int:
        """Number of boundary (one-face) edges, including split non-manifold ones."""
        return int((self.faces[:, 1] < 0).sum())


def edge_adjacency(faces) -> EdgeAdjacency:
    """Edge-face adjacency of a triangle mesh (once per topology).

    Parameters
    ----------
    faces : array_like of int, shape (F, 3)

    Returns
    -------
    EdgeAdjacency
    """
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    n_f = f.shape[0]
    # half-edge k of face i runs f[i, k] -> f[i, k+1]; the opposite vertex is f[i, k+2]
    a = f.reshape(-1)
    b = np.roll(f, -1, axis=1).reshape(-1)
    opp = np.roll(f, -2, axis=1).reshape(-1)
    face_of = np.repeat(np.arange(n_f), 3)
    key = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    key, face_of, opp = key[order], face_of[order], opp[order]
    new = np.ones(len(key), dtype=bool)
    new[1:] = np.any(key[1:] != key[:-1], axis=1)
    group = np.cumsum(new) - 1
    count = np.bincount(group)
    per = count[group]
    first = np.flatnonzero(new)
    # manifold interior edges: exactly two half-edges
    two = first[count == 2]
    edges = [key[two]]
    inc = [np.stack([face_of[two], face_of[two + 1]], axis=1)]
    opps = [np.stack([opp[two], opp[two + 1]], axis=1)]
    # boundary and non-manifold: one record per half-edge
    single = np.flatnonzero(per != 2)
    edges.append(key[single])
    inc.append(np.stack([face_of[single], np.full(len(single), -1)], axis=1))
    opps.append(np.stack([opp[single], np.full(len(single), -1)], axis=1))
    return EdgeAdjacency(np.concatenate(edges), np.concatenate(inc), np.concatenate(opps))


def face_facing(vertices, faces, point) -> np.ndarray:
    """True where a face's front (counter-clockwise) side faces ``point``, shape ``(F,)``."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    p0 = v[f[:, 0]]
    normal = np.cross(v[f[:, 1]] - p0, v[f[:, 2]] - p0)
    return np.einsum("ij,ij->i", normal, np.asarray(point, dtype=np.float64) - p0) > 0


def silhouette_edges(adjacency: EdgeAdjacency, vertices, faces, point
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Silhouette edges of a mesh seen from ``point``.

    Parameters
    ----------
    adjacency : EdgeAdjacency
        From :func:`edge_adjacency` of ``faces``.
    vertices : array_like, shape (V, 3)
        Posed vertices of this frame.
    faces : array_like of int, shape (F, 3)
    point : array_like, shape (3,)
        The light centre.

    Returns
    -------
    edges : ndarray of int, shape (K, 2)
        Vertex indices of the silhouette edges.
    side : ndarray of int, shape (K,)
        A vertex on the occluder side of each edge (see the module docstring).
    """
    front = face_facing(vertices, faces, point)
    f0, f1 = adjacency.faces[:, 0], adjacency.faces[:, 1]
    boundary = f1 < 0
    fr0 = front[f0]
    fr1 = np.where(boundary, fr0, front[np.maximum(f1, 0)])
    sil = boundary | (fr0 != fr1)
    return adjacency.edges[sil], adjacency.opposite[sil, 0]
