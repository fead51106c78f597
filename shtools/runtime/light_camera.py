"""The light camera of the occlusion camera: a cube map with a guard band, or one frustum.

Every face is a pinhole camera at the light centre with a square image of
``resolution`` pixels.  Camera coordinates are ``(x, y, z)`` with ``z`` the
depth along the face's axis; a point projects to pixel coordinates
``px = R/2 + f x/z``, ``py = R/2 + f y/z`` (pixel ``(i, j)`` has its centre at
``(i + 0.5, j + 0.5)``), ``f = R / (2 T)`` where ``T`` is the tangent of the
face's half field of view.

* ``"cube"`` (default): six 90° faces widened by a guard band, ``T = 1 + guard``.
  A receiver belongs to the face of its largest direction component, so it
  projects into the central ``[-1, 1]`` square and everything within
  ``guard * f`` pixels of it -- penumbra quads of silhouettes across the face
  border, distorted lookups -- is still inside the face.  Every receiver is
  covered.
* ``"frustum"``: one face about the mean direction to the receivers, widened
  by the same guard; only valid while every receiver is within 60° of it
  (Mo et al.'s single light frustum).  ``"auto"`` picks it when it fits and the
  cube otherwise.  The chosen mode is recorded in :attr:`LightCamera.mode`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Widest half-angle (tangent) of a fitted frustum: 60°.
FRUSTUM_MAX_TAN = float(np.tan(np.radians(60.0)))

_CUBE_AXES = np.array([
    # rows: right, up, forward (a right-handed frame for each face)
    [[0, 0, -1], [0, 1, 0], [1, 0, 0]],
    [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
    [[1, 0, 0], [0, 0, -1], [0, 1, 0]],
    [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
    [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
    [[-1, 0, 0], [0, 1, 0], [0, 0, -1]],
], dtype=np.float64)


@dataclass
class LightCamera:
    """Pinhole faces at the light centre.

    Attributes
    ----------
    center : ndarray, shape (3,)
    axes : ndarray, shape (K, 3, 3)
        Per face the rows right, up, forward.
    resolution : int
        Pixels per side of every face.
    tan_half : float
        ``T``: tangent of the half field of view of a face (guard included).
    mode : str
        ``"cube"`` or ``"frustum"``.
    """

    center: np.ndarray
    axes: np.ndarray
    resolution: int
    tan_half: float
    mode: str

    @property
    def focal(self) -> float:
        """``f``: pixels per unit of tangent-plane coordinate."""
        return self.resolution / (2.0 * self.tan_half)

    @property
    def n_faces(self) -> int:
        return int(self.axes.shape[0])

    def to_camera(self, face: int, points) -> np.ndarray:
        """Camera coordinates ``(..., 3)`` of world points ``(..., 3)`` in face ``face``."""
        return (np.asarray(points, dtype=np.float64) - self.center) @ self.axes[face].T

    def to_pixels(self, cam) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates of camera-space points with ``z > 0``."""
        half = self.resolution / 2.0
        f = self.focal
        return half + f * cam[..., 0] / cam[..., 2], half + f * cam[..., 1] / cam[..., 2]

    def assign(self, points) -> np.ndarray:
        """Face index of every receiver, shape ``(V,)``."""
        d = np.asarray(points, dtype=np.float64) - self.center
        if self.mode == "frustum":
            return np.zeros(d.shape[0], dtype=np.int64)
        k = np.argmax(np.abs(d), axis=1)
        sign = d[np.arange(d.shape[0]), k] < 0
        return 2 * k + sign


def fit_light_camera(center, points, *, mode: str = "cube", resolution: int = 1024,
                     guard: float = 0.125) -> LightCamera:
    """The light camera for receivers ``points (V, 3)`` seen from ``center (3,)``.

    Parameters
    ----------
    mode : {"cube", "frustum", "auto"}
        See the module docstring; ``"frustum"`` falls back to the cube when the
        receivers do not fit in 60° of one axis.
    resolution : int
        Pixels per side of each face.
    guard : float
        Guard band: the faces' half-field tangent is ``1 + guard`` (cube) or the
        receivers' extent times ``1 + guard`` (frustum).
    """
    c = np.asarray(center, dtype=np.float64).reshape(3)
    if mode in ("frustum", "auto"):
        cam = _fit_frustum(c, np.asarray(points, dtype=np.float64), resolution, guard)
        if cam is not None:
            return cam
    return LightCamera(c, _CUBE_AXES.copy(), int(resolution), 1.0 + guard, "cube")


def _fit_frustum(center, points, resolution, guard) -> LightCamera | None:
    d = points - center
    norm = np.linalg.norm(d, axis=1)
    if np.any(norm <= 0):
        return None
    u = d / norm[:, None]
    axis = u.mean(axis=0)
    if np.linalg.norm(axis) < 1e-6:
        return None
    fwd = axis / np.linalg.norm(axis)
    helper = np.array([0.0, 1.0, 0.0]) if abs(fwd[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    right = np.cross(helper, fwd)
    right /= np.linalg.norm(right)
    up = np.cross(fwd, right)
    axes = np.stack([right, up, fwd])[None]
    cam = d @ axes[0].T
    if np.any(cam[:, 2] <= 0):
        return None
    extent = float(np.max(np.abs(cam[:, :2]) / cam[:, 2:3]))
    if extent > FRUSTUM_MAX_TAN:
        return None
    return LightCamera(center, axes, int(resolution), max(extent, 1e-3) * (1.0 + guard),
                       "frustum")
