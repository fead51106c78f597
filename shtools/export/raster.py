"""A CPU rasteriser in vectorised NumPy: pinhole camera, z-buffer, Gouraud colours.

No GPU or display.  Triangles are expanded into covered pixels by
:func:`shtools.runtime.raster.triangle_fragments` (shared with the runtime's
shadow maps) and resolved per pixel against a z-buffer (``np.minimum.at``; of
equally near fragments the lowest face wins, so the picture does not depend on the
fragments' order).  Vertex colours are interpolated perspective-correctly.
Rendering at ``supersample`` times the size and box filtering down gives
anti-aliased edges.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shtools.runtime.raster import EDGE_EPS, FRAGMENT_BUDGET, triangle_fragments

__all__ = ["EDGE_EPS", "FRAGMENT_BUDGET", "Camera", "fit_camera", "rasterize"]


@dataclass
class Camera:
    """A pinhole camera looking from ``eye`` at ``target`` with +Y up.

    Attributes
    ----------
    eye, target : ndarray, shape (3,)
    fov_y : float
        Vertical field of view, radians.
    """

    eye: np.ndarray
    target: np.ndarray
    fov_y: float = np.radians(35.0)

    def view_matrix(self) -> np.ndarray:
        """World -> camera (3, 4): x right, y up, z forward (depth)."""
        forward = self.target - self.eye
        forward = forward / np.linalg.norm(forward)
        up = np.array([0.0, 1.0, 0.0])
        if abs(np.dot(up, forward)) > 0.999:  # looking straight down: pick another up
            up = np.array([0.0, 0.0, -1.0])
        right = np.cross(forward, up)
        right /= np.linalg.norm(right)
        true_up = np.cross(right, forward)
        rot = np.stack([right, true_up, forward])
        return np.concatenate([rot, (-rot @ self.eye)[:, None]], axis=1)


def fit_camera(
    points: np.ndarray,
    *,
    elevation: float = np.radians(30.0),
    azimuth: float = np.radians(35.0),
    fov_y: float = np.radians(35.0),
    aspect: float = 4 / 3,
    zoom: float = 1.0,
    margin: float = 0.04,
    fixed_distance: float | None = None,
) -> Camera:
    """A camera that frames ``points`` (N, 3), looking down at ``elevation``.

    The camera looks at the centre of the points' bounding box along the given
    direction and backs off just far enough that every point projects inside the
    image (with ``margin`` of the half-size to spare); ``zoom > 1`` moves closer.
    ``azimuth`` turns the camera about +Y (0 looks along -Z).  ``fixed_distance``
    (scene units, optional) places the camera that far from the framed centre
    instead of the fitted distance divided by ``zoom``.
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(pts) > 20000:  # the extent of a subsample frames the same scene
        pts = pts[np.linspace(0, len(pts) - 1, 20000).astype(np.int64)]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    center = (lo + hi) / 2
    direction = np.array([
        np.cos(elevation) * np.sin(azimuth),
        np.sin(elevation),
        np.cos(elevation) * np.cos(azimuth),
    ])
    probe = Camera(center + direction, center, fov_y).view_matrix()[:, :3]
    right, up = probe[0], probe[1]
    tan_y = np.tan(fov_y / 2) * (1 - margin)
    tan_x = np.tan(fov_y / 2) * aspect * (1 - margin)
    target = center
    for _ in range(3):  # fit the distance, then centre the projected extent; repeat
        rel = pts - target
        x, y = rel @ right, rel @ up
        along = rel @ direction  # towards the camera
        # a point at depth (d - along) fits when |x| <= tan_x (d - along), same for y
        distance = float(np.max(along + np.maximum(np.abs(x) / tan_x, np.abs(y) / tan_y)))
        distance = max(distance, 1e-6)
        depth = distance - along
        u, v = x / depth, y / depth
        shift_u = (u.max() + u.min()) / 2 * distance
        shift_v = (v.max() + v.min()) / 2 * distance
        target = target + shift_u * right + shift_v * up
    backoff = distance / zoom if fixed_distance is None else float(fixed_distance)
    return Camera(target + backoff * direction, target, fov_y)


def rasterize(
    vertices: np.ndarray,
    faces: np.ndarray,
    colors: np.ndarray,
    camera: Camera,
    width: int,
    height: int,
    *,
    background: np.ndarray | None = None,
    supersample: int = 2,
) -> np.ndarray:
    """Render a vertex-coloured triangle mesh.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3)
    faces : ndarray, shape (F, 3)
    colors : ndarray, shape (V, C)
        Per-vertex attributes to interpolate (e.g. linear RGB).
    camera : Camera
    width, height : int
        Output size in pixels.
    background : ndarray, shape (height, width, C), optional
        Values where no triangle covers the pixel (default zeros).
    supersample : int
        Render at this factor and box-filter down (anti-aliasing).

    Returns
    -------
    image : ndarray, shape (height, width, C)
        Interpolated attributes, float64.
    coverage : ndarray, shape (height, width)
        Fraction of each pixel covered by geometry.
    """
    s = int(supersample)
    W, H = width * s, height * s
    C = colors.shape[1]
    view = camera.view_matrix()
    cam = vertices @ view[:, :3].T + view[:, 3]
    z = cam[:, 2]
    focal = (H / 2) / np.tan(camera.fov_y / 2)
    near = 1e-4 * max(float(np.abs(z).max()), 1.0)
    zs = np.maximum(z, near)
    sx = W / 2 + focal * cam[:, 0] / zs
    sy = H / 2 - focal * cam[:, 1] / zs
    faces = np.asarray(faces, dtype=np.int64)
    # drop triangles touching the near plane (a fitted camera has none)
    faces = faces[np.all(z[faces] > near, axis=1)]
    zbuf = np.full(W * H, np.inf)
    no_face = np.iinfo(np.int64).max  # above every face index: loses every tie
    win_tri = np.full(W * H, no_face, dtype=np.int64)
    fine = np.zeros((W * H, C))  # the winner's interpolated colour per sub-pixel
    inv_z = 1.0 / z[faces]  # (F, 3) for perspective-correct interpolation

    # the nearest fragment of each pixel wins; of equally near ones, the lowest face
    for frag_tri, px, py, bary in triangle_fragments(sx[faces], sy[faces], W, H,
                                                     budget=FRAGMENT_BUDGET):
        # screen-space barycentrics interpolate 1/z linearly; depth = 1 / that
        iz = np.einsum("ij,ij->i", bary, inv_z[frag_tri])
        depth = 1.0 / iz
        pid = py * W + px
        before = zbuf[pid]
        np.minimum.at(zbuf, pid, depth)
        hit = np.flatnonzero(depth == zbuf[pid])
        pid, frag_tri, bary = pid[hit], frag_tri[hit], bary[hit]
        win_tri[pid[zbuf[pid] < before[hit]]] = no_face  # an earlier batch's winner is hidden
        np.minimum.at(win_tri, pid, frag_tri)
        won = np.flatnonzero(win_tri[pid] == frag_tri)
        pid, frag_tri = pid[won], frag_tri[won]
        # perspective-correct weights: (bary_k / z_k) / sum_k(bary_k / z_k)
        pc = bary[won] * inv_z[frag_tri]
        pc /= (pc[:, 0] + pc[:, 1] + pc[:, 2])[:, None]
        corners = faces[frag_tri]
        fine[pid] = sum(colors[corners[:, k]] * pc[:, k, None] for k in range(3))

    covered = (win_tri != no_face).astype(np.float64)
    # box filter: the sum of the s x s sub-pixel grids (strided views, no reduction)
    fine, covered = fine.reshape(H, W, C), covered.reshape(H, W)
    image = sum(fine[i::s, j::s] for i in range(s) for j in range(s)) / (s * s)
    coverage = sum(covered[i::s, j::s] for i in range(s) for j in range(s)) / (s * s)
    if background is not None:  # the uncovered share of each pixel shows the background
        image += (1.0 - coverage)[..., None] * np.asarray(background, dtype=float)
    return image, coverage
