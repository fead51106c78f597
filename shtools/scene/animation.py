"""Animation: keyframed rigid transforms, parent chains, light keys, skinned meshes.

Rigid keyframes interpolate translation and scale linearly and rotation by
quaternion slerp (shortest arc); before the first key and after the last the
end pose holds, unless the object loops (period = time of the last key).
Skinned objects take their joint matrices from the glTF animation through
:mod:`shtools.geometry.skin` and pose their bound spheres with
:func:`shtools.runtime.spheres.pose_bound_spheres`.
"""

from __future__ import annotations

import numpy as np

from shtools.geometry.transforms import slerp, trs_matrix
from shtools.scene.specs import Keyframe, LightKey, ObjectSpec, Pose, SphereLightSpec

__all__ = [
    "SkinnedMotion",
    "interpolate_pose",
    "light_at",
    "local_matrix",
    "pose_matrix",
    "transform_normals",
    "transform_points",
    "transform_spheres",
    "vertex_normals",
    "world_matrices",
]


def pose_matrix(pose: Pose) -> np.ndarray:
    """Homogeneous matrix (4, 4) of ``T * R * S``."""
    return trs_matrix(pose.translate, pose.quaternion, pose.scale)


# --------------------------------------------------------------------------- keyframes
def _bracket(times: np.ndarray, t: float, loop: bool) -> tuple[int, int, float]:
    """Indices of the keys around ``t`` and the blend factor between them."""
    if loop and len(times) > 1 and times[-1] > times[0]:
        t = times[0] + (t - times[0]) % (times[-1] - times[0])
    if t <= times[0]:
        return 0, 0, 0.0
    if t >= times[-1]:
        return len(times) - 1, len(times) - 1, 0.0
    j = int(np.searchsorted(times, t, side="right"))
    i = j - 1
    return i, j, float((t - times[i]) / (times[j] - times[i]))


def interpolate_pose(keyframes: list[Keyframe], t: float, loop: bool = False) -> Pose:
    """Pose at time ``t`` (seconds): lerp translation/scale, slerp rotation."""
    times = np.array([k.time for k in keyframes])
    i, j, u = _bracket(times, t, loop)
    a, b = keyframes[i].pose, keyframes[j].pose
    if i == j:
        return Pose(a.translate.copy(), a.quaternion.copy(), a.scale.copy())
    return Pose(
        (1 - u) * a.translate + u * b.translate,
        slerp(a.quaternion, b.quaternion, u),
        (1 - u) * a.scale + u * b.scale,
    )


def local_matrix(obj: ObjectSpec, t: float) -> np.ndarray:
    """The object's transform (4, 4) relative to its parent at time ``t``."""
    pose = interpolate_pose(obj.keyframes, t, obj.loop) if obj.keyframes else obj.pose
    return pose_matrix(pose)


def world_matrices(objects: list[ObjectSpec], t: float) -> dict[str, np.ndarray]:
    """World transforms (4, 4) of every object at time ``t``, following parents."""
    by_name = {o.name: o for o in objects}
    out: dict[str, np.ndarray] = {}

    def world(o: ObjectSpec) -> np.ndarray:
        if o.name not in out:
            m = local_matrix(o, t)
            if o.parent is not None:
                m = world(by_name[o.parent]) @ m
            out[o.name] = m
        return out[o.name]

    for o in objects:
        world(o)
    return out


def light_at(light: SphereLightSpec, t: float) -> LightKey:
    """Position, radius and colour of a spherical light at time ``t`` (all lerped)."""
    times = np.array([k.time for k in light.keys])
    i, j, u = _bracket(times, t, light.loop)
    a, b = light.keys[i], light.keys[j]
    return LightKey(
        t,
        (1 - u) * a.position + u * b.position,
        (1 - u) * a.radius + u * b.radius,
        (1 - u) * a.color + u * b.color,
    )


# --------------------------------------------------------------------------- geometry
def transform_points(m: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) transform to points (N, 3)."""
    return points @ m[:3, :3].T + m[:3, 3]


def transform_normals(m: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Transform normals (N, 3) by the inverse transpose of ``m``'s linear part; unit length."""
    n = normals @ np.linalg.inv(m[:3, :3])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def transform_spheres(m: np.ndarray, centers: np.ndarray, radii: np.ndarray):
    """Move spheres by ``m``; radii scale by its largest singular value so they still bound.

    Returns
    -------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
    """
    stretch = float(np.linalg.svd(m[:3, :3], compute_uv=False)[0])
    return transform_points(m, centers), radii * stretch


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals (V, 3) of a triangle mesh (faces (F, 3))."""
    v = vertices[faces]
    fn = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])  # length = 2 * area
    n = np.zeros_like(vertices, dtype=float)
    for k in range(3):
        for c in range(3):
            n[:, c] += np.bincount(faces[:, k], weights=fn[:, c], minlength=len(vertices))
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    fallback = np.array([0.0, 1.0, 0.0])  # isolated vertices: any unit vector
    return np.where(norm > 1e-30, n / np.maximum(norm, 1e-300), fallback)


# --------------------------------------------------------------------------- skinning
class SkinnedMotion:
    """Joint matrices of a skinned glTF model over scene time.

    Parameters
    ----------
    model : shtools.geometry.skin.SkinnedModel
    animation : int or str
        Clip index or name.
    speed, offset : float
        Clip time = ``offset + speed * scene_time``, wrapped to the clip's duration.
    """

    def __init__(self, model, animation=0, speed=1.0, offset=0.0):
        self.model = model
        self.animation = animation
        self.speed, self.offset = float(speed), float(offset)
        # raises InputError naming the file when the clip does not exist
        self.duration = float(model.duration(animation))

    def clip_time(self, t: float) -> float:
        ct = self.offset + self.speed * t
        return ct % self.duration if self.duration > 0 else 0.0

    def joint_matrices(self, t: float) -> np.ndarray:
        """Skinning matrices (J, 4, 4) at scene time ``t``."""
        return self.model.joint_matrices(self.clip_time(t), self.animation)
