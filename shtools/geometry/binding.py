"""Binding sphere centres to a skin (SHEXP section 6.2, "Animation").

Each sphere centre ``x`` gets mean value coordinates ``lambda (V,)`` on the
rest (bind-space) mesh, so ``x = sum_v lambda_v v_v``.  Skinning every vertex
and applying the same coordinates gives the posed centre

    P' = sum_v lambda_v sum_j w_vj M_j [v_v, 1] = sum_j M_j q_j,
    q_j = sum_v lambda_v w_vj [v_v, 1]          (homogeneous, per bone),

so premultiplying the MVC by the vertex bone weights turns many vertices into a
few bones.  ``beta_j = q_j[3]`` sums to 1 over the bones.

Truncation to K bones: the K bones of largest ``|beta_j|`` are kept and the
dropped vectors' sum ``D = sum_{d dropped} q_d`` is folded into them with
shares ``alpha_k = |beta_k| / sum_kept |beta|``.  The kept vectors still sum to
``[x, 1]``, so the rest pose (all ``M = I``) and any common rigid (indeed
affine) motion of all bones are reproduced exactly.  For a general pose the
error against the untruncated binding is

    e = sum_{d dropped} (M_d - M_bar) q_d,    M_bar = sum_k alpha_k M_k,

i.e. at most ``sum_d ||M_d - M_bar|| ||q_d||``: it vanishes when the dropped
bones move like the kept ones' blend and grows with their relative motion
times their weight.  ``dropped_weight`` records ``sum_d |beta_d| / sum |beta|``
per sphere; :func:`truncation_error` measures ``e`` for given poses.

Open rest meshes: MVC lose linear precision, so ``sum lambda_v v_v != x``.  The
residual ``x - sum lambda_v v_v`` is added to the kept bones with the same
shares ``alpha`` (exact at rest and under rigid motion again) and reported as
``rest_residual``.  Where the raw MVC weights degenerate (their sum vanishes,
possible only for open meshes) the centre is bound with inverse-distance
weights of its nearest vertices instead (``fallback``).  For best results close
the mesh first (e.g. fill holes) so that MVC are exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from shtools.errors import InputError
from shtools.geometry.fit_methods import SPHERE_SPACES
from shtools.geometry.mvc import is_closed_surface, mean_value_coordinates
from shtools.runtime.spheres import pose_bound_spheres

__all__ = ["SphereBinding", "animation_poses", "bind_spheres", "covering_radii",
           "posed_coverage", "spheres_to_bind_space", "truncation_error"]

#: raw MVC weight sums below this fraction of the summed magnitudes mean the
#: coordinates are numerically meaningless (open meshes only)
DEGENERATE_WEIGHT_SUM = 1e-6
#: vertices used by the inverse-distance fallback
FALLBACK_NEIGHBOURS = 8
#: (vertex, sphere) distances evaluated at once in coverage computations
COVER_CHUNK = 1 << 20


@dataclass
class SphereBinding:
    """Per-sphere bones and homogeneous bone vectors.

    Attributes
    ----------
    bone_index : ndarray of int32, shape (N, K)
    bone_vectors : ndarray, shape (N, K, 4)
        Posed centre ``sum_k (M[bone_index[:, k]] @ bone_vectors[:, k])[:3]``.
    dropped_weight : ndarray, shape (N,)
        ``sum |beta|`` over dropped bones / over all bones.
    rest_residual : ndarray, shape (N,)
        ``|x - sum_v lambda_v v_v|`` before correction (0 up to rounding on closed
        meshes).
    fallback : ndarray of bool, shape (N,)
        Centres bound by inverse-distance weights because MVC degenerated.
    mesh_closed : bool
    joint_count : int
    """

    bone_index: np.ndarray
    bone_vectors: np.ndarray
    dropped_weight: np.ndarray
    rest_residual: np.ndarray
    fallback: np.ndarray
    mesh_closed: bool
    joint_count: int

    def pose(self, joint_matrices) -> np.ndarray:
        """Posed centres for skinning matrices ``(..., J, 4, 4)`` -> ``(..., N, 3)``."""
        return pose_bound_spheres(self.bone_index, self.bone_vectors, joint_matrices)


def _covered(points, centers, radii, tol) -> float:
    """Fraction of points inside at least one sphere."""
    rows = max(1, COVER_CHUNK // max(len(radii), 1))
    inside = [
        ((np.linalg.norm(points[s:s + rows, None] - centers[None], axis=2) - radii).min(1)
         <= tol)
        for s in range(0, points.shape[0], rows)
    ]
    return float(np.concatenate(inside).mean())


def spheres_to_bind_space(centers, radii, model, space: str = "auto"):
    """Express a sphere set in the rig's bind space (where binding happens).

    A sphere set fitted to the glTF as a scene (``shtools spheres fit RIG.glb``,
    i.e. ``trimesh.load``) lives in scene space, ``model.mesh_transform @ bind``;
    one fitted to ``model.rest_vertices`` lives in bind space.  For CesiumMan the
    two differ by a Z-up to Y-up rotation.

    Parameters
    ----------
    centers : array_like, shape (N, 3)
    radii : array_like, shape (N,)
    model : SkinnedModel
    space : {"auto", "bind", "scene"}
        ``"auto"`` picks the space in which the spheres cover more rest vertices.

    Returns
    -------
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
        Scaled by the transform's mean scale when it has one.
    space : str
        The space the input was taken to be in.

    Raises
    ------
    InputError
        For an unknown ``space``, or when ``"auto"`` finds the spheres cover
        fewer than half of the rest vertices in either space.
    """

    if space not in SPHERE_SPACES:
        raise InputError(f"unknown sphere space '{space}'; use auto, bind or scene")
    centers = np.asarray(centers, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    transform = np.asarray(getattr(model, "mesh_transform", np.eye(4)), dtype=np.float64)
    inverse = np.linalg.inv(transform)
    scale = abs(np.linalg.det(inverse[:3, :3])) ** (1.0 / 3.0)
    to_bind = (centers @ inverse[:3, :3].T + inverse[:3, 3], radii * scale)
    if space == "bind" or (space == "auto" and np.allclose(transform, np.eye(4))):
        return centers, radii, "bind"
    if space == "scene":
        return (*to_bind, "scene")
    rest = np.asarray(model.rest_vertices, dtype=np.float64)
    tol = 1e-6 * (float(np.linalg.norm(np.ptp(rest, axis=0))) or 1.0)
    in_bind = _covered(rest, centers, radii, tol)
    in_scene = _covered(rest, *to_bind, tol)
    if max(in_bind, in_scene) < 0.5:
        raise InputError(
            f"the spheres cover only {max(in_bind, in_scene):.0%} of the rig's rest vertices "
            "(bind or scene space); fit them to this rig's mesh", getattr(model, "path", None))
    return (centers, radii, "bind") if in_bind >= in_scene else (*to_bind, "scene")


def _bone_weight_matrix(model) -> sp.csr_matrix:
    """Vertex-by-joint weights, ``(V, J)`` sparse, rows sum to 1."""
    n_verts, width = model.joints.shape
    rows = np.repeat(np.arange(n_verts), width)
    return sp.csr_matrix(
        (model.weights.reshape(-1), (rows, model.joints.reshape(-1))),
        shape=(n_verts, model.joint_count),
    )


def _inverse_distance(points, vertices, k) -> np.ndarray:
    """Shepard weights over each point's ``k`` nearest vertices, ``(P, V)``."""
    from scipy.spatial import cKDTree

    k = min(k, vertices.shape[0])
    dist, idx = cKDTree(vertices).query(points, k=k)
    dist, idx = dist.reshape(len(points), k), idx.reshape(len(points), k)
    w = 1.0 / np.maximum(dist, 1e-300) ** 2
    out = np.zeros((len(points), vertices.shape[0]))
    np.put_along_axis(out, idx, w / w.sum(axis=1, keepdims=True), axis=1)
    return out


def bind_spheres(centers, model, bones_per_sphere: int = 4) -> SphereBinding:
    """Bind sphere centres to a skinned model's bones.

    Parameters
    ----------
    centers : array_like, shape (N, 3)
        Sphere centres in the model's bind space (that of ``model.rest_vertices``).
    model : SkinnedModel
        From :func:`shtools.geometry.skin.load_skinned_gltf` (or any object with
        ``rest_vertices (V,3)``, ``faces (F,3)``, ``joints (V,W)``,
        ``weights (V,W)``, ``joint_count``).
    bones_per_sphere : int
        K, bones kept per sphere (capped at the joint count).

    Returns
    -------
    SphereBinding
    """
    x = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    verts = np.asarray(model.rest_vertices, dtype=np.float64)
    n_joints = int(model.joint_count)
    k = max(1, min(int(bones_per_sphere), n_joints))
    closed = is_closed_surface(verts, model.faces)

    lam = mean_value_coordinates(x, verts, model.faces)
    fallback = ~np.all(np.isfinite(lam), axis=1)
    if not closed:
        # degenerate rows: the signed weights nearly cancel
        magnitude = np.abs(lam).sum(axis=1)
        fallback |= ~(magnitude < 1.0 / DEGENERATE_WEIGHT_SUM)
    if np.any(fallback):
        lam[fallback] = _inverse_distance(x[fallback], verts, FALLBACK_NEIGHBOURS)

    weights = _bone_weight_matrix(model)  # (V, J)
    beta = np.asarray((weights.T @ lam.T).T)  # (N, J)
    q = np.stack([np.asarray((weights.T @ (lam * verts[:, a]).T).T) for a in range(3)],
                 axis=-1)  # (N, J, 3)
    full = np.concatenate([q, beta[..., None]], axis=-1)  # (N, J, 4)
    residual = x - q.sum(axis=1)

    order = np.argsort(-np.abs(beta), axis=1, kind="stable")
    keep = np.sort(order[:, :k], axis=1)
    kept = np.take_along_axis(full, keep[..., None], axis=1)  # (N, K, 4)
    dropped = full.sum(axis=1) - kept.sum(axis=1)  # (N, 4)
    magnitude = np.abs(np.take_along_axis(beta, keep, axis=1))
    total = magnitude.sum(axis=1, keepdims=True)
    share = np.where(total > 0, magnitude / np.where(total > 0, total, 1.0), 1.0 / k)
    correction = dropped.copy()
    correction[:, :3] += residual
    bone_vectors = kept + share[..., None] * correction[:, None, :]
    abs_beta = np.abs(beta).sum(axis=1)
    dropped_weight = np.where(abs_beta > 0, 1.0 - total[:, 0] / np.where(abs_beta > 0,
                                                                          abs_beta, 1.0), 0.0)
    return SphereBinding(
        bone_index=keep.astype(np.int32),
        bone_vectors=bone_vectors,
        dropped_weight=np.clip(dropped_weight, 0.0, 1.0),
        rest_residual=np.linalg.norm(residual, axis=1),
        fallback=fallback,
        mesh_closed=closed,
        joint_count=n_joints,
    )


def truncation_error(centers, model, binding: SphereBinding, joint_matrices) -> np.ndarray:
    """Distance between truncated and untruncated posed centres.

    Parameters
    ----------
    centers : array_like, shape (N, 3)
    model : SkinnedModel
    binding : SphereBinding
    joint_matrices : array_like, shape (..., J, 4, 4)

    Returns
    -------
    ndarray, shape (..., N)
    """
    full = bind_spheres(centers, model, bones_per_sphere=model.joint_count)
    return np.linalg.norm(full.pose(joint_matrices) - binding.pose(joint_matrices), axis=-1)


def animation_poses(model, frames: int = 16) -> list[np.ndarray]:
    """Skinning matrices at ``frames`` evenly spaced times of every animation.

    Returns
    -------
    list of ndarray, each (J, 4, 4)
        The bind pose (identity matrices) when the model has no animation.
    """
    poses = [model.joint_matrices(float(t), a)
             for a in range(len(model.animations))
             for t in np.linspace(0.0, model.duration(a), max(int(frames), 1))]
    return poses or [np.tile(np.eye(4), (model.joint_count, 1, 1))]


def covering_radii(binding: SphereBinding, radii, model, frames: int = 16) -> np.ndarray:
    """Radii grown so the posed spheres cover every skinned vertex over the animations.

    SHEXP keeps the rest radii, which bound the skinned mesh only "assuming
    typical articulated motion".  This optional step measures instead: for every
    vertex ``v`` and sphere ``i`` let ``D(v, i)`` be the largest distance between
    the skinned vertex and the posed centre over the sampled frames (``frames``
    per animation, the rest pose included).  Each vertex is given to the sphere
    needing the least growth, ``argmin_i D(v, i) - r_i``, and each radius grows
    to the largest ``D`` of its vertices (never shrinks).  Every vertex is then
    inside a sphere at every sampled frame; between frames the motion is smooth
    and the benchmark measures the (small) remainder.

    Parameters
    ----------
    binding : SphereBinding
    radii : array_like, shape (N,)
        Rest radii.
    model : SkinnedModel
    frames : int

    Returns
    -------
    ndarray, shape (N,)
        ``>= radii``.
    """
    radii = np.asarray(radii, dtype=np.float64)
    n_verts = np.asarray(model.rest_vertices).shape[0]
    rows = max(1, COVER_CHUNK // max(len(radii), 1))  # vertices per (V, N) block
    farthest = np.zeros((n_verts, len(radii)))
    poses = [np.tile(np.eye(4), (model.joint_count, 1, 1)), *animation_poses(model, frames)]
    for mats in poses:
        verts, posed = model.skin(mats), binding.pose(mats)
        for s in range(0, n_verts, rows):
            dist = np.linalg.norm(verts[s:s + rows, None] - posed[None], axis=2)
            np.maximum(farthest[s:s + rows], dist, out=farthest[s:s + rows])
    owner = np.argmin(farthest - radii, axis=1)
    grown = radii.copy()
    np.maximum.at(grown, owner, farthest[np.arange(n_verts), owner])
    return grown


def posed_coverage(binding: SphereBinding, radii, model, frames: int = 16) -> dict:
    """How well the posed spheres (radii kept) cover the skinned vertices.

    Samples ``frames`` evenly spaced times of every animation (the rest pose
    when there is none) and counts skinned vertices inside at least one posed
    sphere.

    Returns
    -------
    dict
        ``posed_vertex_coverage`` (fraction over all sampled frames),
        ``worst_frame_coverage``, ``rest_vertex_coverage`` (identity matrices),
        ``max_uncovered_distance`` (largest distance of a vertex outside every
        sphere to the nearest sphere surface, in model units), ``frames``.
    """
    radii = np.asarray(radii, dtype=np.float64)
    poses = animation_poses(model, frames)
    identity = np.tile(np.eye(4), (model.joint_count, 1, 1))

    rows = max(1, COVER_CHUNK // max(len(radii), 1))

    def gap(joint_matrices):
        verts = model.skin(joint_matrices)
        centers = binding.pose(joint_matrices)
        return np.concatenate([
            (np.linalg.norm(verts[s:s + rows, None] - centers[None], axis=2) - radii).min(1)
            for s in range(0, verts.shape[0], rows)])

    scale = float(np.linalg.norm(np.ptp(model.rest_vertices, axis=0))) or 1.0
    tol = 1e-9 * scale  # rounding of the skinning products
    gaps = [gap(m) for m in poses]
    per_frame = np.array([np.mean(g <= tol) for g in gaps])
    worst = max(float(np.max(g)) for g in gaps)
    return {
        "posed_vertex_coverage": float(per_frame.mean()),
        "worst_frame_coverage": float(per_frame.min()),
        "rest_vertex_coverage": float(np.mean(gap(identity) <= tol)),
        "max_uncovered_distance": max(worst, 0.0),
        "frames": len(poses),
    }


@dataclass
class BoundSphereSet:
    """A sphere set bound to a rig (:func:`bind_sphere_set`), ready for a ``bound`` asset.

    Attributes
    ----------
    centers : ndarray, shape (N, 3)
        Centres in the rig's bind space.
    radii : ndarray, shape (N,)
        Radii used at runtime (grown when covering the animations).
    fit_radii : ndarray, shape (N,)
        The radii of the input set.
    binding : SphereBinding
    space : str
        Space the input set was in (``"bind"`` or ``"scene"``).
    bones_per_sphere : int
        Bones kept per sphere (at most the rig's joint count).
    coverage : dict
        :func:`posed_coverage` over the checked frames (empty if none).
    """

    centers: np.ndarray
    radii: np.ndarray
    fit_radii: np.ndarray
    binding: SphereBinding
    space: str
    bones_per_sphere: int
    coverage: dict

    def summary(self, model) -> dict:
        """Counts and worst cases of the binding (the CLI's ``--json`` fields)."""
        b = self.binding
        return {
            "spheres": int(self.centers.shape[0]),
            "joints": int(model.inverse_bind.shape[0]),
            "bones_per_sphere": int(self.bones_per_sphere),
            "sphere_space": self.space,
            "mesh_closed": bool(b.mesh_closed),
            "mvc_fallback_spheres": int(b.fallback.sum()),
            "max_dropped_weight": float(b.dropped_weight.max(initial=0.0)),
            "max_rest_residual": float(b.rest_residual.max(initial=0.0)),
            "animations": list(model.animations),
            "max_radius_growth": float(np.max(self.radii
                                              / np.maximum(self.fit_radii, 1e-300))),
            **self.coverage,
        }


def bind_sphere_set(centers, radii, model, *, bones_per_sphere: int = 4,
                    space: str = "auto", cover_animations: bool = False,
                    check_frames: int = 16, spheres_path=None,
                    rig_path=None) -> BoundSphereSet:
    """Bind a fitted sphere set to a skinned model (what ``shtools spheres bind`` does).

    The set is brought to bind space (:func:`spheres_to_bind_space`), bound
    (:func:`bind_spheres`), its radii optionally grown to keep covering the
    rest vertices over the animations (:func:`covering_radii`), and its posed
    coverage measured at ``check_frames`` frames per animation (0: skip).
    ``spheres_path`` and ``rig_path`` only name the inputs in errors.

    Raises
    ------
    InputError
        The spheres cover neither space, ``cover_animations`` without an
        animation, or non-finite weights.
    """
    try:
        centers, radii, space = spheres_to_bind_space(centers, radii, model, space)
    except InputError as exc:
        raise InputError(exc.message, spheres_path) from None
    if cover_animations and not model.animations:
        raise InputError("--cover-animations needs an animation but the rig has none; "
                         "drop the flag or export a clip", rig_path)
    bones_per_sphere = min(bones_per_sphere, model.joint_count)
    binding = bind_spheres(centers, model, bones_per_sphere=bones_per_sphere)
    if not np.all(np.isfinite(binding.bone_vectors)):
        raise InputError("binding produced non-finite weights; check the rest mesh", rig_path)
    fit_radii = radii
    if cover_animations:
        radii = covering_radii(binding, fit_radii, model, frames=max(check_frames, 16))
    coverage = posed_coverage(binding, radii, model, frames=check_frames) if check_frames \
        else {}
    return BoundSphereSet(centers, radii, fit_radii, binding, space, bones_per_sphere,
                          coverage)
