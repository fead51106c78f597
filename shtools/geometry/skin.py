"""Skinned, animated glTF models: joints, animation sampling, linear blend skinning.

:func:`load_skinned_gltf` reads a ``.glb``/``.gltf`` (via pygltflib) into a
:class:`SkinnedModel`: the triangles of every primitive of the skinned mesh
node(s), the rest (bind-space) vertex positions, up to 4·s joint influences
per vertex (``JOINTS_n``/``WEIGHTS_n``), the skin's inverse bind matrices, the
node hierarchy with its rest TRS, and every animation's translation / rotation /
scale channels.

Conventions (glTF 2.0 specification, "Skins" and "Animations"):

- The skinning matrix of joint ``j`` is ``G_j @ IBM_j`` where ``G_j`` is the
  joint node's global (world) transform at the sampled time and ``IBM_j`` its
  inverse bind matrix.  Skinned vertices ``sum_j w_j (G_j IBM_j) v`` are in world
  space; the transform of the node holding the mesh is ignored, as the spec
  requires.  The scene frame is glTF's: Y up.
- Sampling clamps time to each sampler's key range.  LINEAR interpolates
  translation/scale linearly and rotation by quaternion slerp (shortest arc);
  STEP holds the previous key; CUBICSPLINE evaluates the Hermite spline with the
  stored in/out tangents scaled by the key interval (rotations renormalised).
- Quaternions are ``(x, y, z, w)``; matrices act on column vectors.
"""

from __future__ import annotations

import base64
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shtools.errors import InputError
from shtools.geometry.transforms import (
    decompose_trs,
    quaternion_matrix,
    slerp,
    trs_matrix,
)

__all__ = ["SkinnedModel", "load_skinned_gltf"]

_COMPONENT_DTYPES = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_TRIANGLES = 4


@dataclass
class _Channel:
    node: int
    path: str  # "translation" | "rotation" | "scale"
    times: np.ndarray  # (T,)
    values: np.ndarray  # (T, C) or (3T, C) for CUBICSPLINE
    interpolation: str

    def sample(self, t: float) -> np.ndarray:
        times = self.times
        n = times.shape[0]
        cubic = self.interpolation == "CUBICSPLINE"
        key = self.values[1::3] if cubic else self.values
        if n == 1 or t <= times[0]:
            return key[0].copy()
        if t >= times[-1]:
            return key[-1].copy()
        i = int(np.searchsorted(times, t, side="right")) - 1
        i = min(max(i, 0), n - 2)
        dt = float(times[i + 1] - times[i])
        u = (t - times[i]) / dt if dt > 0 else 0.0
        if self.interpolation == "STEP":
            return key[i].copy()
        if cubic:
            out_tangent = self.values[3 * i + 2]
            in_tangent = self.values[3 * (i + 1)]
            u2, u3 = u * u, u * u * u
            value = ((2 * u3 - 3 * u2 + 1) * key[i] + (u3 - 2 * u2 + u) * dt * out_tangent
                     + (-2 * u3 + 3 * u2) * key[i + 1] + (u3 - u2) * dt * in_tangent)
            if self.path == "rotation":
                value = value / np.linalg.norm(value)
            return value
        if self.path == "rotation":
            return slerp(key[i], key[i + 1], u)
        return (1 - u) * key[i] + u * key[i + 1]


@dataclass
class SkinnedModel:
    """A skinned mesh with its skeleton and animations.

    Attributes
    ----------
    rest_vertices : ndarray, shape (V, 3)
        Bind-space positions (the ``POSITION`` data the skin deforms).
    faces : ndarray of int64, shape (F, 3)
    joints : ndarray of int64, shape (V, 4*s)
        Indices into the skin's joint list.
    weights : ndarray, shape (V, 4*s)
        Rows sum to 1.
    inverse_bind : ndarray, shape (J, 4, 4)
    animations : list of str
        Animation names (``"animation<i>"`` when unnamed).
    normals : ndarray, shape (V, 3) or None
        Bind-space normals when the file has them.
    joint_nodes : ndarray of int, shape (J,)
        glTF node index of each joint.
    joint_names : list of str
    mesh_transform : ndarray, shape (4, 4)
        Rest global transform of the skinned mesh node: where viewers and
        ``trimesh.load`` put the unskinned mesh ("scene space" =
        ``mesh_transform @ bind space``).  Skinning ignores it (glTF spec).
    primitives : list of (mesh, primitive, start, count)
        Where the vertices come from: glTF mesh and primitive indices and the
        range ``start:start+count`` of ``rest_vertices`` each one fills, in order.
    path : str
    """

    rest_vertices: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray
    inverse_bind: np.ndarray
    animations: list[str]
    normals: np.ndarray | None = None
    joint_nodes: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    joint_names: list[str] = field(default_factory=list)
    mesh_transform: np.ndarray = field(default_factory=lambda: np.eye(4))
    primitives: list[tuple[int, int, int, int]] = field(default_factory=list)
    path: str = ""
    _node_parent: np.ndarray = field(default=None, repr=False)
    _node_order: np.ndarray = field(default=None, repr=False)
    _rest_local: np.ndarray = field(default=None, repr=False)  # (Nn, 4, 4) or TRS
    _rest_trs: list = field(default=None, repr=False)  # per node (t, r, s) or None (matrix)
    _channels: list = field(default=None, repr=False)  # per animation: list[_Channel]

    @property
    def joint_count(self) -> int:
        """Number of joints ``J`` of the skin."""
        return int(self.inverse_bind.shape[0])

    def _animation_index(self, animation) -> int:
        if not self.animations:
            raise InputError("has no animation; export the rig with an animation clip "
                             "or use its rest pose", self.path)
        if isinstance(animation, str):
            if animation not in self.animations:
                raise InputError(f"has no animation named '{animation}' (has: "
                                 f"{', '.join(self.animations)})", self.path)
            return self.animations.index(animation)
        index = int(animation)
        if not 0 <= index < len(self.animations):
            raise InputError(f"animation {index} does not exist (has "
                             f"{len(self.animations)})", self.path)
        return index

    def duration(self, animation=0) -> float:
        """Length in seconds of an animation (its last key time).

        Parameters
        ----------
        animation : int or str
            Index or name.
        """
        channels = self._channels[self._animation_index(animation)]
        return float(max((c.times[-1] for c in channels), default=0.0))

    def _global_transforms(self, local: np.ndarray) -> np.ndarray:
        world = np.empty_like(local)
        for node in self._node_order:
            p = self._node_parent[node]
            world[node] = local[node] if p < 0 else world[p] @ local[node]
        return world

    def node_transforms(self, time: float | None = None, animation=0) -> np.ndarray:
        """Global (world) transforms of every node, shape ``(Nn, 4, 4)``.

        ``time=None`` gives the rest pose (node transforms without animation).
        """
        local = self._rest_local.copy()
        if time is not None:
            channels = self._channels[self._animation_index(animation)]
            trs = {}
            for ch in channels:
                if ch.node not in trs:
                    rest = self._rest_trs[ch.node]
                    if rest is None:
                        rest = decompose_trs(self._rest_local[ch.node])
                    trs[ch.node] = {"translation": rest[0], "rotation": rest[1],
                                    "scale": rest[2]}
                trs[ch.node][ch.path] = ch.sample(float(time))
            if trs:  # every animated node's T @ R @ S at once (one batched rotation)
                nodes = list(trs)
                parts = {k: np.array([trs[n][k] for n in nodes], dtype=np.float64)
                         for k in ("translation", "rotation", "scale")}
                m = np.zeros((len(nodes), 4, 4))
                m[:, :3, :3] = quaternion_matrix(parts["rotation"]) * parts["scale"][:, None, :]
                m[:, :3, 3] = parts["translation"]
                m[:, 3, 3] = 1.0
                local[nodes] = m
        return self._global_transforms(local)

    def joint_matrices(self, time: float, animation=0) -> np.ndarray:
        """Skinning matrices (world x inverse bind) at ``time`` seconds.

        Parameters
        ----------
        time : float
            Clamped to the animation's key range.
        animation : int or str

        Returns
        -------
        ndarray, shape (J, 4, 4)

        Raises
        ------
        InputError
            If the model has no such animation.
        """
        world = self.node_transforms(time, animation)
        return world[self.joint_nodes] @ self.inverse_bind

    def rest_joint_matrices(self) -> np.ndarray:
        """Skinning matrices of the node hierarchy's rest pose, shape ``(J, 4, 4)``."""
        return self.node_transforms(None)[self.joint_nodes] @ self.inverse_bind

    def skin(self, joint_matrices) -> np.ndarray:
        """Linear blend skinning of the rest vertices.

        Parameters
        ----------
        joint_matrices : array_like, shape (J, 4, 4)

        Returns
        -------
        ndarray, shape (V, 3)
            ``sum_k w_vk (M[j_vk] @ [v, 1])[:3]``.
        """
        blend = self._blend(joint_matrices)
        return np.einsum("vij,vj->vi", blend[:, :3, :3], self.rest_vertices) + blend[:, :3, 3]

    def skin_normals(self, joint_matrices, normals=None) -> np.ndarray:
        """Skinned unit normals (inverse transpose of each vertex's blended matrix).

        Parameters
        ----------
        joint_matrices : array_like, shape (J, 4, 4)
        normals : array_like, shape (V, 3), optional
            Bind-space normals; the file's when omitted.

        Returns
        -------
        ndarray, shape (V, 3)
        """
        normals = self.normals if normals is None else np.asarray(normals, dtype=np.float64)
        if normals is None:
            raise InputError("has no vertex normals; compute them from the skinned faces",
                             self.path)
        linear = self._blend(joint_matrices)[:, :3, :3]
        out = np.einsum("vji,vj->vi", np.linalg.inv(linear), normals)
        return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)

    def blend_matrices(self, joint_matrices) -> np.ndarray:
        """Each vertex's blended skinning matrix ``sum_k w_vk M[j_vk]``, shape ``(V, 4, 4)``."""
        return self._blend(joint_matrices)

    def _blend(self, joint_matrices) -> np.ndarray:
        mats = np.asarray(joint_matrices, dtype=np.float64)
        if mats.shape != (self.joint_count, 4, 4):
            raise ValueError(f"joint_matrices must have shape ({self.joint_count}, 4, 4)")
        return np.einsum("vk,vkij->vij", self.weights, mats[self.joints])


class _Buffers:
    """Bytes of a glTF's buffers (GLB binary chunk, data URIs, external files)."""

    def __init__(self, gltf, path: Path):
        self.gltf = gltf
        self.path = path
        self.cache: dict[int, bytes] = {}

    def get(self, index: int) -> bytes:
        if index in self.cache:
            return self.cache[index]
        buffer = self.gltf.buffers[index]
        uri = buffer.uri
        if uri is None:
            data = self.gltf.binary_blob()
            if data is None:
                raise InputError("a buffer has no data (empty GLB binary chunk)", self.path)
        elif uri.startswith("data:"):
            data = base64.b64decode(uri.split(",", 1)[1])
        else:
            file = self.path.parent / uri
            if not file.is_file():
                raise InputError(f"buffer file '{uri}' is missing next to the glTF", self.path)
            data = file.read_bytes()
        self.cache[index] = bytes(data)
        return self.cache[index]


def _read_accessor(gltf, buffers: _Buffers, index: int) -> np.ndarray:
    """An accessor's data as float64 or int64, shape ``(count, components)``."""
    acc = gltf.accessors[index]
    dtype = np.dtype(_COMPONENT_DTYPES[acc.componentType]).newbyteorder("<")
    width = _TYPE_SIZES[acc.type]
    count = acc.count
    if acc.bufferView is None:
        out = np.zeros((count, width), dtype=dtype)
    else:
        view = gltf.bufferViews[acc.bufferView]
        data = buffers.get(view.buffer)
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        elem = dtype.itemsize * width
        stride = view.byteStride or elem
        end = start + stride * (count - 1) + elem
        if count and end > len(data):
            raise InputError(f"accessor {index} reads past the end of its buffer; "
                             "the file is truncated", buffers.path)
        raw = np.frombuffer(data, dtype=np.uint8, count=max(end - start, 0), offset=start)
        rows = np.lib.stride_tricks.as_strided(
            raw, shape=(count, elem), strides=(stride, 1), writeable=False
        )
        out = np.ascontiguousarray(rows).view(dtype).reshape(count, width).copy()
    sparse = getattr(acc, "sparse", None)
    if sparse is not None and sparse.count:
        idx_view = gltf.bufferViews[sparse.indices.bufferView]
        val_view = gltf.bufferViews[sparse.values.bufferView]
        idx_dtype = np.dtype(_COMPONENT_DTYPES[sparse.indices.componentType]).newbyteorder("<")
        idx = np.frombuffer(
            buffers.get(idx_view.buffer), dtype=idx_dtype, count=sparse.count,
            offset=(idx_view.byteOffset or 0) + (sparse.indices.byteOffset or 0),
        )
        vals = np.frombuffer(
            buffers.get(val_view.buffer), dtype=dtype, count=sparse.count * width,
            offset=(val_view.byteOffset or 0) + (sparse.values.byteOffset or 0),
        ).reshape(sparse.count, width)
        out[idx.astype(np.int64)] = vals
    if dtype.kind == "f":
        return out.astype(np.float64)
    if acc.normalized:
        top = float(np.iinfo(dtype).max)
        return np.maximum(out.astype(np.float64) / top, -1.0)
    return out.astype(np.int64)


def _node_local(node) -> tuple[np.ndarray, tuple | None]:
    if node.matrix is not None:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T, None
    t = np.asarray(node.translation if node.translation is not None else [0, 0, 0], float)
    r = np.asarray(node.rotation if node.rotation is not None else [0, 0, 0, 1], float)
    s = np.asarray(node.scale if node.scale is not None else [1, 1, 1], float)
    return trs_matrix(t, r, s), (t, r, s)


def load_skinned_gltf(path: str | os.PathLike) -> SkinnedModel:
    """Load a skinned (and usually animated) glTF 2.0 model.

    Parameters
    ----------
    path : path-like
        ``.glb`` or ``.gltf``.

    Returns
    -------
    SkinnedModel

    Raises
    ------
    InputError
        Missing or unreadable file, no skin, no skinned triangle mesh, missing
        ``JOINTS_0``/``WEIGHTS_0``, joint indices out of range, non-finite data.
    """
    import pygltflib

    path = Path(path)
    if not path.is_file():
        raise InputError("file not found; check the path", path)
    if path.suffix.lower() not in (".glb", ".gltf"):
        raise InputError("unsupported rig format; give a glTF 2.0 file (.glb or .gltf)", path)
    try:
        gltf = pygltflib.GLTF2().load(str(path))
    except Exception as exc:  # pygltflib raises many types on malformed files
        raise InputError(f"not a readable glTF file ({type(exc).__name__}); re-export it",
                         path) from None
    if gltf is None:
        raise InputError("not a readable glTF file; re-export it", path)
    if not gltf.skins:
        raise InputError("has no skin (not a rigged model); export the mesh with its "
                         "armature/skin", path)
    skinned_nodes = [i for i, n in enumerate(gltf.nodes) if n.mesh is not None
                     and n.skin is not None]
    if not skinned_nodes:
        raise InputError("has a skin but no mesh node uses it; export the skinned mesh", path)
    skin_index = gltf.nodes[skinned_nodes[0]].skin
    skinned_nodes = [i for i in skinned_nodes if gltf.nodes[i].skin == skin_index]
    skin = gltf.skins[skin_index]
    buffers = _Buffers(gltf, path)
    n_joints = len(skin.joints)
    if skin.inverseBindMatrices is not None:
        ibm = _read_accessor(gltf, buffers, skin.inverseBindMatrices)
        inverse_bind = ibm.reshape(-1, 4, 4).transpose(0, 2, 1).copy()  # column-major
        if inverse_bind.shape[0] != n_joints:
            raise InputError("inverseBindMatrices count differs from the joint count", path)
    else:
        inverse_bind = np.tile(np.eye(4), (n_joints, 1, 1))

    vertices, faces, joints, weights, normals, sources = [], [], [], [], [], []
    offset = 0
    for node_index in skinned_nodes:
        mesh_index = gltf.nodes[node_index].mesh
        for prim_index, prim in enumerate(gltf.meshes[mesh_index].primitives):
            mode = _TRIANGLES if prim.mode is None else prim.mode
            if mode != _TRIANGLES or prim.attributes.POSITION is None:
                continue
            pos = _read_accessor(gltf, buffers, prim.attributes.POSITION)
            if prim.attributes.JOINTS_0 is None or prim.attributes.WEIGHTS_0 is None:
                raise InputError("a skinned primitive has no JOINTS_0/WEIGHTS_0; re-export "
                                 "with skin weights", path)
            j_sets = [_read_accessor(gltf, buffers, prim.attributes.JOINTS_0)]
            w_sets = [_read_accessor(gltf, buffers, prim.attributes.WEIGHTS_0)]
            if getattr(prim.attributes, "JOINTS_1", None) is not None:
                j_sets.append(_read_accessor(gltf, buffers, prim.attributes.JOINTS_1))
                w_sets.append(_read_accessor(gltf, buffers, prim.attributes.WEIGHTS_1))
            if prim.indices is not None:
                idx = _read_accessor(gltf, buffers, prim.indices).reshape(-1)
            else:
                idx = np.arange(pos.shape[0])
            if idx.size % 3 or (idx.size and (idx.min() < 0 or idx.max() >= pos.shape[0])):
                raise InputError("triangle indices are malformed; re-export the mesh", path)
            nrm = (_read_accessor(gltf, buffers, prim.attributes.NORMAL)
                   if prim.attributes.NORMAL is not None else None)
            vertices.append(pos)
            faces.append(idx.reshape(-1, 3) + offset)
            joints.append(np.concatenate(j_sets, axis=1))
            weights.append(np.concatenate(w_sets, axis=1))
            normals.append(nrm)
            sources.append((int(mesh_index), prim_index, offset, int(pos.shape[0])))
            offset += pos.shape[0]
    if not vertices:
        raise InputError("the skinned mesh has no triangle primitives", path)
    width = max(j.shape[1] for j in joints)
    joints = np.concatenate([np.pad(j, ((0, 0), (0, width - j.shape[1]))) for j in joints])
    weights = np.concatenate([np.pad(w, ((0, 0), (0, width - w.shape[1]))) for w in weights])
    rest = np.concatenate(vertices)
    normals = None if any(n is None for n in normals) else np.concatenate(normals)
    if not np.all(np.isfinite(rest)) or not np.all(np.isfinite(weights)):
        raise InputError("vertex positions or weights contain NaN/inf", path)
    if joints.min() < 0 or joints.max() >= n_joints:
        raise InputError(f"JOINTS_0 refers to joints outside the skin's {n_joints}", path)
    total = weights.sum(axis=1, keepdims=True)
    if np.any(total <= 0):
        raise InputError("some vertices have all-zero skin weights; repaint the weights", path)
    weights = weights / total

    n_nodes = len(gltf.nodes)
    parent = np.full(n_nodes, -1, dtype=np.int64)
    for i, node in enumerate(gltf.nodes):
        for c in node.children or []:
            parent[c] = i
    order, frontier = [], list(np.flatnonzero(parent < 0))
    while frontier:  # breadth-first: every parent before its children
        order.extend(frontier)
        frontier = [c for n in frontier for c in (gltf.nodes[n].children or [])]
    if len(order) != n_nodes:
        raise InputError("the node hierarchy has a cycle", path)
    rest_local = np.empty((n_nodes, 4, 4))
    rest_trs = []
    for i, node in enumerate(gltf.nodes):
        rest_local[i], trs = _node_local(node)
        rest_trs.append(trs)

    names, channels = [], []
    for a, anim in enumerate(gltf.animations or []):
        names.append(anim.name or f"animation{a}")
        chans = []
        for ch in anim.channels:
            if ch.target.node is None or ch.target.path not in ("translation", "rotation",
                                                                 "scale"):
                continue  # morph-target weights do not move joints
            sampler = anim.samplers[ch.sampler]
            times = _read_accessor(gltf, buffers, sampler.input).reshape(-1)
            values = _read_accessor(gltf, buffers, sampler.output)
            interp = sampler.interpolation or "LINEAR"
            expected = 3 * times.size if interp == "CUBICSPLINE" else times.size
            if values.shape[0] != expected or np.any(np.diff(times) < 0):
                raise InputError(f"animation '{names[-1]}' has a malformed sampler", path)
            chans.append(_Channel(ch.target.node, ch.target.path, times, values, interp))
        channels.append(chans)

    model = SkinnedModel(
        rest_vertices=rest,
        faces=np.concatenate(faces).astype(np.int64),
        joints=joints.astype(np.int64),
        weights=weights,
        inverse_bind=inverse_bind,
        animations=names,
        normals=normals,
        joint_nodes=np.asarray(skin.joints, dtype=np.int64),
        joint_names=[gltf.nodes[j].name or f"joint{k}" for k, j in enumerate(skin.joints)],
        primitives=sources,
        path=str(path),
        _node_parent=parent,
        _node_order=np.asarray(order, dtype=np.int64),
        _rest_local=rest_local,
        _rest_trs=rest_trs,
        _channels=channels,
    )
    model.mesh_transform = model.node_transforms(None)[skinned_nodes[0]]
    return model
