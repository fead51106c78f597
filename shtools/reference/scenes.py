"""Evaluation scenes: a blocker over a ground-plane grid under an environment light.

Used by ``shtools eval`` (built-in form), the accuracy tests and the benchmarks.
Y is up and the ground is a horizontal grid of receiver vertices.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from shtools.sh import project, sphere_quadrature

#: Default sun direction of :func:`sky_light` (normalised).
SKY_SUN = (0.45, 1.0, 0.3)


@dataclass
class EvalScene:
    """Receivers, blockers (meshes and spheres) and lighting of one evaluation.

    Attributes
    ----------
    vertices, normals : ndarray, shape (V, 3)
        Receiver positions and unit normals.
    grid_shape : tuple of int or None
        ``(rows, cols)`` when the receivers are a grid (for images).
    meshes : list of trimesh.Trimesh
        Actual blocker geometry (for the ray-traced reference); built on first
        use when given as a function (``mesh_source``), so scenes used only by
        the runtime need no geometry stack.
    centers, radii : ndarray, shapes (N, 3), (N,)
        Blocker sphere set.
    tree : tuple (parent (M,), leaf (M,)) or None
        Sphere hierarchy (inner spheres are refit by the runtime).
    env_sh : ndarray, shape (n*n, 3)
        RGB environment radiance.
    """

    vertices: np.ndarray
    normals: np.ndarray
    grid_shape: tuple | None
    mesh_source: list | Callable[[], list]
    centers: np.ndarray
    radii: np.ndarray
    tree: tuple | None
    env_sh: np.ndarray
    lights: list = field(default_factory=list)

    @property
    def meshes(self) -> list:
        if callable(self.mesh_source):
            self.mesh_source = self.mesh_source()
        return self.mesh_source


def ground_grid(resolution: int, center_xz, half_size: float, y: float = 0.0):
    """A ``resolution x resolution`` grid of receivers on the plane ``y``, normals +Y.

    Returns
    -------
    vertices : ndarray, shape (R*R, 3)
    normals : ndarray, shape (R*R, 3)
    """
    t = np.linspace(-half_size, half_size, int(resolution))
    xx, zz = np.meshgrid(t + center_xz[0], t + center_xz[1], indexing="ij")
    v = np.stack([xx.ravel(), np.full(xx.size, float(y)), zz.ravel()], axis=1)
    nrm = np.zeros_like(v)
    nrm[:, 1] = 1.0
    return v, nrm


def sky_light(order: int, sun=SKY_SUN, sharpness: float = 8.0) -> np.ndarray:
    """A sky-like RGB environment in SH: bluish ambient plus a warm lobe toward ``sun``.

    ``L(s) = a + b * max(0, s . sun)^sharpness`` per channel, projected by quadrature.

    Returns
    -------
    ndarray, shape (n*n, 3)
    """
    d = np.asarray(sun, dtype=np.float64)
    d = d / np.linalg.norm(d)
    dirs, w = sphere_quadrature(2 * order + 2 * int(np.ceil(sharpness)) + 8)
    lobe = np.maximum(dirs @ d, 0.0) ** sharpness
    ambient = np.array([0.25, 0.3, 0.4])
    sun_rgb = np.array([3.0, 2.7, 2.2])
    values = ambient[:, None] + sun_rgb[:, None] * lobe[None, :]  # (3, Q)
    return project(values, dirs, w, order).T


def capsule_spheres(p0, p1, radius: float, count: int):
    """Spheres along a segment whose union bounds the capsule of ``radius`` about it.

    Spacing ``delta`` between centres needs radius ``sqrt(R^2 + (delta/2)^2)``
    to cover the capsule's cylinder between two centres.
    """
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    t = np.linspace(0.0, 1.0, int(count))
    centers = p0[None, :] + t[:, None] * (p1 - p0)[None, :]
    delta = np.linalg.norm(p1 - p0) / max(1, count - 1)
    radii = np.full(count, np.sqrt(radius**2 + (0.5 * delta) ** 2))
    return centers, radii


def capsule_scene(grid: int = 24, order: int = 4, *, spheres: int = 6, lift: float = 0.35):
    """A tilted capsule and a ball above a ground grid (procedural; for tests).

    Parameters
    ----------
    grid : int
        Receivers per side of the ground grid.
    order : int
        SH order of the environment light.
    spheres : int
        Spheres bounding the capsule.
    lift : float
        Height of the capsule's lowest point above the ground.

    Returns
    -------
    EvalScene
    """
    radius = 0.3
    p0 = np.array([-0.6, lift + radius, -0.2])
    p1 = np.array([0.7, lift + radius + 0.5, 0.3])
    ball_c, ball_r = np.array([0.5, 0.25, -0.8]), 0.25

    def meshes():
        import trimesh

        axis = p1 - p0
        length = float(np.linalg.norm(axis))
        capsule = trimesh.creation.capsule(height=length, radius=radius, count=[24, 24])
        # trimesh's capsule runs along +Z from -length/2 to +length/2
        capsule.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], axis / length))
        capsule.apply_translation(0.5 * (p0 + p1))
        ball = trimesh.creation.icosphere(subdivisions=4, radius=ball_r)
        ball.apply_translation(ball_c)
        return [capsule, ball]

    c_caps, r_caps = capsule_spheres(p0, p1, radius, spheres)
    # the icosphere is inscribed in its sphere: the sphere bounds it
    centers = np.vstack([c_caps, ball_c[None, :]])
    radii = np.concatenate([r_caps, [ball_r]])
    v, nrm = ground_grid(grid, (0.0, 0.0), 2.0)
    return EvalScene(v, nrm, (grid, grid), meshes, centers, radii, None,
                     sky_light(order))


def mesh_scene(mesh, centers, radii, *, grid: int = 64, order: int = 4, tree=None,
               env_sh=None, gap: float = 0.0) -> EvalScene:
    """A blocker mesh over a ground grid: the plane touches the mesh's lowest point.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Blocker geometry (its own coordinates; Y up).
    centers, radii : ndarray
        Its sphere set.
    grid : int
        Receivers per side.
    order : int
        SH order of the default light.
    tree : tuple (parent, leaf), optional
    env_sh : ndarray, shape (n*n, 3), optional
        Lighting (default :func:`sky_light`).
    gap : float
        Distance between the plane and the mesh, as a fraction of the mesh height.

    Returns
    -------
    EvalScene
    """
    lo, hi = mesh.bounds
    size = hi - lo
    y = lo[1] - gap * size[1]
    center_xz = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[2] + hi[2]))
    half = 1.25 * max(size[0], size[2], size[1])
    v, nrm = ground_grid(grid, center_xz, half, y)
    env = sky_light(order) if env_sh is None else np.asarray(env_sh, dtype=np.float64)
    return EvalScene(v, nrm, (grid, grid), [mesh], np.asarray(centers, dtype=np.float64),
                     np.asarray(radii, dtype=np.float64), tree, env)
