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

from shtools.scene.scene import Keyframe, LightKey, ObjectSpec, Pose, SphereLightSpec


# --------------------------------------------------------------------------- quaternions
def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def slerp(q0: np.ndarray, q1: np.ndarray, u: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions along the shortest arc."""
    q0 = np.asarray(q0, dtype=float)
    q1 = np.asarray(q1, dtype=float)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:  # q and -q are the same rotation; take the short way round
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly parallel: lerp is exact to rounding and avoids 0/0
        q = q0 + u * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    return (np.sin((1 - u) * theta) * q0 + np.sin(u * theta) * q1) / np.sin(theta)


def pose_matrix(pose: Pose) -> np.ndarray:
    """Homogeneous matrix (4, 4) of ``T * R * S``."""
    m = np.eye(4)
    m[:3, :3] = quaternion_to_matrix(pose.quaternion) * pose.scale[None, :]
    m[:3, 3] = pose.translate
    return m


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
        from shtools.errors import InputError

        self.model = model
        if isinstance(animation, str):
            if animation not in model.animations:
                raise InputError(
                    f"no animation named '{animation}' (has: {', '.join(model.animations)})")
            animation = model.animations.index(animation)
        if not 0 <= animation < len(model.animations):
            raise InputError(f"animation index {animation} out of range (the model has "
                             f"{len(model.animations)})")
        self.animation = int(animation)
        self.speed, self.offset = float(speed), float(offset)
        self.duration = float(model.duration(self.animation))

    def clip_time(self, t: float) -> float:
        ct = self.offset + self.speed * t
        return ct % self.duration if self.duration > 0 else 0.0

    def joint_matrices(self, t: float) -> np.ndarray:
        """Skinning matrices (J, 4, 4) at scene time ``t``."""
        return self.model.joint_matrices(self.clip_time(t), self.animation)
