"""What a person sees in a bake, measured against a ray-traced reference, per receiver.

Averages over a whole receiver hide the two things a viewer notices first: steps,
rings and ray noise in the shading (which a smooth error field of the same RMSE does
not have), and the error inside the shadows (which a wide unshadowed plane
dilutes).  Three measures, each of one receiver's luminance:

* the **smoothness ratio**: the mesh-graph Laplacian of the luminance (each
  vertex's value minus the mean of its mesh neighbours), its mean absolute value
  on the bake over the same on the reference.  1 is as smooth as the truth; above
  1 the bake has seams, rings or noise the truth does not; below 1 it is blurred.
* the **shadowed-vertex error**: the relative RMSE of radiance over the vertices
  the reference darkens by more than :data:`SHADOW_DARKENING` (luminance below
  ``1 - SHADOW_DARKENING`` times the unshadowed luminance), next to the error over
  the whole receiver.
* the **near-blocker error**: the relative RMSE over the vertices within
  :data:`NEAR_RADII` bounding radii of the centre of any blocker's bounding sphere
  (a blocker's own vertices excluded by the caller: pass only other receivers).
"""

from __future__ import annotations

import numpy as np

from shtools.reference.metrics import relative_rmse

#: Rec. 709 luminance weights of linear RGB.
LUMA = np.array([0.2126, 0.7152, 0.0722])
#: A vertex is shadowed when the reference is this much darker than unshadowed.
SHADOW_DARKENING = 0.02
#: "Near a blocker": within this many bounding radii of its bounding sphere's centre.
NEAR_RADII = 2.0


def luminance(radiance) -> np.ndarray:
    """Luminance ``(V,)`` of linear RGB radiance ``(V, 3)`` (a ``(V,)`` array is returned as is)."""
    x = np.asarray(radiance, dtype=np.float64)
    return x if x.ndim == 1 else x @ LUMA


def mesh_adjacency(faces, n_vertices: int):
    """Vertex adjacency of a triangle mesh, ``(V, V)`` CSR of 0/1 (each edge once per side).

    Parameters
    ----------
    faces : array_like of int, shape (F, 3)
    n_vertices : int
    """
    from scipy import sparse

    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    a = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])
    b = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
    keep = a != b
    adj = sparse.coo_matrix((np.ones(int(keep.sum())), (a[keep], b[keep])),
                            shape=(n_vertices, n_vertices)).tocsr()
    adj.data[:] = 1.0  # an edge shared by two faces counts once
    return adj


def graph_laplacian(values, faces) -> np.ndarray:
    """``x_v`` minus the mean of ``x`` over the mesh neighbours of ``v``, shape ``(V,)``.

    Vertices without neighbours (unreferenced) get 0.

    Parameters
    ----------
    values : array_like, shape (V,)
    faces : array_like of int, shape (F, 3)
    """
    x = np.asarray(values, dtype=np.float64).reshape(-1)
    adj = mesh_adjacency(faces, x.shape[0])
    degree = np.asarray(adj.sum(axis=1)).reshape(-1)
    mean = (adj @ x) / np.maximum(degree, 1.0)
    return np.where(degree > 0, x - mean, 0.0)


def laplacian_energy(values, faces) -> float:
    """Mean ``|x_v - mean of neighbours|`` over the mesh's vertices (of luminance)."""
    return float(np.mean(np.abs(graph_laplacian(luminance(values), faces))))


def smoothness_ratio(values, reference, faces) -> float:
    """:func:`laplacian_energy` of the bake over that of the reference (luminance)."""
    ref = laplacian_energy(reference, faces)
    x = laplacian_energy(values, faces)
    if ref == 0.0:
        return 1.0 if x == 0.0 else float("inf")
    return x / ref


def shadowed(reference, unshadowed, darkening: float = SHADOW_DARKENING) -> np.ndarray:
    """Bool ``(V,)``: the reference's luminance below ``1 - darkening`` times unshadowed."""
    return luminance(reference) < (1.0 - darkening) * luminance(unshadowed)


def near_blockers(points, spheres, radii: float = NEAR_RADII) -> np.ndarray:
    """Bool ``(V,)``: points within ``radii`` bounding radii of any sphere's centre.

    Parameters
    ----------
    points : array_like, shape (V, 3)
    spheres : sequence of (centre (3,), radius)
        Each blocker's bounding sphere.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    near = np.zeros(len(p), dtype=bool)
    for center, radius in spheres:
        near |= np.linalg.norm(p - np.asarray(center, dtype=np.float64), axis=1) <= (
            radii * float(radius))
    return near


def bounding_sphere(vertices) -> tuple[np.ndarray, float]:
    """Centre of the bounding box and the farthest vertex's distance from it."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    center = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return center, float(np.sqrt(((v - center) ** 2).sum(axis=1).max()))


def _masked_rmse(values, reference, mask) -> float | None:
    return relative_rmse(values[mask], reference[mask]) if mask.any() else None


def look_metrics(radiance, reference, unshadowed, faces, *, points=None,
                 blocker_spheres=(), darkening: float = SHADOW_DARKENING,
                 radii: float = NEAR_RADII) -> dict:
    """The module's measures of one receiver.

    Parameters
    ----------
    radiance, reference, unshadowed : array_like, shape (V, 3)
        The bake, the ray-traced reference and the reference without any blocker
        (visibility 1), all shaded the same way.
    faces : array_like of int, shape (F, 3)
        The receiver's triangles (indices into its ``V`` vertices).
    points : array_like, shape (V, 3), optional
        Its vertices (world space), for the near-blocker error.
    blocker_spheres : sequence of (centre, radius)
        Bounding spheres of the blockers other than the receiver itself.

    Returns
    -------
    dict
        ``smoothness`` (ratio), ``error`` (whole receiver), ``shadowed_error`` and
        ``shadowed_vertices``, ``near_error`` and ``near_vertices`` (None errors
        when no vertex qualifies).
    """
    x = np.asarray(radiance, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    dark = shadowed(ref, unshadowed, darkening)
    out = {"smoothness": smoothness_ratio(x, ref, faces), "error": relative_rmse(x, ref),
           "shadowed_error": _masked_rmse(x, ref, dark), "shadowed_vertices": int(dark.sum()),
           "near_error": None, "near_vertices": 0}
    if points is not None and len(blocker_spheres):
        near = near_blockers(points, blocker_spheres, radii)
        out["near_error"] = _masked_rmse(x, ref, near)
        out["near_vertices"] = int(near.sum())
    return out
