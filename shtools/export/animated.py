"""One animated GLB of a frame range: colours as morph targets, rigid motion as node TRS.

``shtools export baked.h5 --frames A:B[:S] -o shot.glb`` writes one file that
three.js (and so model-viewer) and Babylon.js play:

* one node and one mesh per receiver object, named as in the bake, with the
  unlit material of :mod:`shtools.export.gltf`;
* the mesh's ``COLOR_0`` is the first exported frame's display colour (linear,
  as in the single-frame export), so a viewer that plays nothing shows it;
* exported frame ``k > 0`` is morph target ``k - 1``, whose ``COLOR_0`` holds
  the colour change from the first frame.  One animation, ``bake``, sets the
  node's ``weights`` one-hot (1 on frame k's target, 0 elsewhere) with
  ``STEP`` interpolation: at the frame's time a player shows that frame's
  colours and holds them until the next.  Times are ``(frame - first) / fps``
  seconds, the bake's fps, with a closing key one frame step after the last
  (:func:`key_times`) so that the clip lasts the last frame too;
* each target is stored whichever way is smaller:

  - *dense*: every vertex's change as signed 16-bit normalised integers (glTF
    2.0 allows normalised integer ``COLOR_n`` morph deltas without an
    extension; KHR_mesh_quantization only adds integer positions, normals,
    tangents and UVs), a step of 1/32767, padded to 8 bytes a vertex;
  - *sparse*: a float32 sparse accessor listing only the vertices whose
    colour changed by at least :data:`KEEP_STEP` of an 8-bit step (linear or
    sRGB-encoded, whichever is larger), 12 bytes plus a 2- or 4-byte index
    each.  Its values are float, not integers: three.js's GLTFLoader
    normalised integer sparse values twice before r169 (three.js pull
    request 29330);

  so a decoded colour is within :data:`KEEP_STEP` of an 8-bit step of the
  frame's own.  An object whose colours never change gets no targets at all;
  identical targets share one accessor;
* an object that moves rigidly keeps one mesh in its own frame (centred on its
  first-frame centroid) and gets ``translation`` / ``rotation`` channels (STEP)
  in the same animation; an object that deforms (a skin the bake posed) gets
  float ``POSITION`` and ``NORMAL`` deltas in its targets instead.

The raw quantity (``_RADIANCE`` ...) of the single-frame export is not in the
animated file; ``--sequence`` writes one file per frame with it, and USD
(:mod:`shtools.export.usd`) holds it per frame.

three.js uploads the weights as one uniform per target, so very long ranges
(over a few hundred frames) are better split into several files.
"""

from __future__ import annotations

import hashlib
import os
import warnings

import numpy as np
import pygltflib

from shtools.data_formats.bake import Bake
from shtools.export.gltf import _ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER, _Buffer, save_glb
from shtools.export.quantity import display_linear
from shtools.export.tonemap import srgb_encode

#: A vertex goes into a sparse target when its colour changed by at least this many
#: 8-bit steps (linear or sRGB-encoded); below it the decoded colour stays the first
#: frame's, which is then within this many steps of the frame's own.
KEEP_STEP = 0.25
#: Largest rigid-fit residual, relative to the object's size (float32 positions are
#: good to ~1e-7 of it, so a true rigid motion fits far below this).
RIGID_TOLERANCE = 1e-5
_INT16 = 32767


def rigid_motion(points: np.ndarray):
    """Fit ``points[k] = R_k (points[0] - c_0) + c_k`` for every frame, or None.

    Parameters
    ----------
    points : ndarray, shape (K, V, 3)
        One object's vertices over the exported frames.

    Returns
    -------
    (translations, rotations) : ndarray (K, 3), ndarray (K, 4)
        Centroid ``c_k`` and unit quaternion ``(x, y, z, w)`` of ``R_k``
        (glTF's order), sign-continuous; None when some frame's best rigid
        fit misses a vertex by more than :data:`RIGID_TOLERANCE` of the size.
    """
    from scipy.spatial.transform import Rotation

    points = np.asarray(points, dtype=np.float64)
    centroids = points.mean(axis=1)
    rest = points[0] - centroids[0]
    size = float(np.abs(points).max()) + 1e-12
    quats = np.empty((len(points), 4))
    for k, (frame, c) in enumerate(zip(points, centroids, strict=True)):
        with warnings.catch_warnings():  # a degenerate shape: the residual decides
            warnings.simplefilter("ignore")
            rot, _ = Rotation.align_vectors(frame - c, rest)
        if np.abs(rot.apply(rest) + c - frame).max() > RIGID_TOLERANCE * size:
            return None
        q = rot.as_quat()
        if k and q @ quats[k - 1] < 0:  # the same rotation, continuous for interpolators
            q = -q
        quats[k] = q
    return centroids, quats


def colour_change(display: np.ndarray, base: np.ndarray, base_srgb: np.ndarray):
    """A frame's colour change from the first frame, and the vertices it moves.

    Parameters
    ----------
    display : ndarray, shape (V, 3)
        The frame's display colours, linear [0, 1].
    base, base_srgb : ndarray, shape (V, 3)
        The first frame's (as stored, float32) and their sRGB encoding.

    Returns
    -------
    delta : ndarray, shape (V, 3)
    keep : ndarray of bool, shape (V,)
        Changed by at least :data:`KEEP_STEP` 8-bit steps, linear or sRGB-encoded.
    """
    delta = display - base
    moved = np.maximum(np.abs(delta), np.abs(srgb_encode(display) - base_srgb))
    return delta, moved.max(axis=1) * 255.0 >= KEEP_STEP


def colour_changes(bake: Bake, positions: list[int], *, quantity: str, scale: float,
                   curve: str, progress=None):
    """The first frame's display colours, then each later frame's change from them.

    Parameters
    ----------
    bake : Bake
    positions : list of int
        Frame positions in the bake, the first one the base.
    quantity, scale, curve
        As for :func:`shtools.export.quantity.display_linear`.
    progress : callable, optional
        Progress factory (:mod:`shtools.progress`), one step per frame.

    Yields
    ------
    base : ndarray, shape (V, 3) float32
        First: the first frame's display colours, linear [0, 1].
    t, delta, keep : int, ndarray (V, 3), ndarray of bool (V,)
        Then, for each later position ``t``, :func:`colour_change` from ``base``.
    """
    from shtools.progress import silent

    base = base_srgb = None
    with (progress or silent)(positions, desc="glb", unit="frames") as steps:
        for t in steps:
            display = np.clip(display_linear(bake, t, quantity, scale, curve), 0.0, 1.0)
            if base is None:
                base = display.astype(np.float32)
                base_srgb = srgb_encode(base)
                yield base
                continue
            yield (t, *colour_change(display, base, base_srgb))


def key_times(frames: list[int], fps: float) -> np.ndarray:
    """Key times (seconds, float32) of exported ``frames``: one per frame from 0, plus a
    closing key one frame step after the last.

    The closing key holds the last frame for its own duration: a player's clip
    ends at its last key, so without it a looping playback would show the last
    frame for no time at all.
    """
    frames = np.asarray(frames, np.float64)
    step = frames[-1] - frames[-2] if len(frames) > 1 else 1.0
    return (np.append(frames, frames[-1] + step) - frames[0]).astype(np.float32) / np.float32(
        fps)


def one_hot_weights(n_frames: int) -> np.ndarray:
    """Morph weights ``(n_frames + 1, n_frames - 1)`` of :func:`key_times`' keys: frame 0
    all zeros, frame k one on target k - 1, the closing key as the last frame."""
    weights = np.zeros((n_frames + 1, n_frames - 1), np.float32)
    weights[np.arange(1, n_frames), np.arange(n_frames - 1)] = 1.0
    weights[-1] = weights[-2]
    return weights


class FrameTargets:
    """The morph-target accessors of one attribute of one object, frame by frame."""

    def __init__(self, buf: _Buffer, count: int, width: int, *, bounds: bool = False):
        self.buf, self.count, self.width, self.bounds = buf, count, width, bounds
        self.accessors: list[int | None] = []  # None: no change in that frame
        self._seen: dict[bytes, int] = {}
        self.stats = {"dense": 0, "sparse": 0, "shared": 0, "empty": 0}

    def _shared(self, kind: str, *arrays) -> tuple[bytes, int | None]:
        digest = hashlib.sha256(kind.encode())
        for a in arrays:
            digest.update(np.ascontiguousarray(a).tobytes())
        key = digest.digest()
        return key, self._seen.get(key)

    def add_colour(self, delta: np.ndarray, keep: np.ndarray) -> None:
        """One frame's colour change ``delta`` (V, 3); ``keep`` marks the vertices it moves."""
        rows = np.flatnonzero(keep)
        if len(rows) == 0:
            self.accessors.append(None)
            self.stats["empty"] += 1
            return
        index_bytes = 2 if self.count <= 65535 else 4
        if len(rows) * (12 + index_bytes) < self.count * 8:
            values = delta[rows].astype(np.float32)
            key, hit = self._shared("sparse", rows, values)
            if hit is None:
                hit = self.buf.add_sparse(self.count, rows, values)
                self.stats["sparse"] += 1
        else:
            q = np.clip(np.round(delta * _INT16), -_INT16, _INT16).astype(np.int16)
            key, hit = self._shared("dense", q)
            if hit is None:
                hit = self.buf.add(q, kind="VEC3", target=_ARRAY_BUFFER, normalized=True)
                self.stats["dense"] += 1
        if key in self._seen:
            self.stats["shared"] += 1
        self._seen[key] = hit
        self.accessors.append(hit)

    def add_float(self, delta: np.ndarray) -> None:
        """One frame's float32 change ``delta`` (V, 3), dense (a deforming mesh moves all)."""
        delta = delta.astype(np.float32)
        if not delta.any():
            self.accessors.append(None)
            self.stats["empty"] += 1
            return
        key, hit = self._shared("float", delta)
        if hit is None:
            hit = self.buf.add(delta, kind="VEC3", target=_ARRAY_BUFFER, bounds=self.bounds)
        self._seen[key] = hit
        self.accessors.append(hit)

    @property
    def changes(self) -> bool:
        return any(a is not None for a in self.accessors)

    def resolved(self) -> list[int]:
        """The accessors with one shared all-zero accessor for the frames without change."""
        zero = None
        out = []
        for a in self.accessors:
            if a is None:
                if zero is None:
                    zero = self.buf.add_sparse(self.count, np.zeros(0, np.int64),
                                               np.zeros((0, self.width)), bounds=self.bounds)
                a = zero
            out.append(a)
        return out


def write_animated_glb(path: str | os.PathLike, bake: Bake, positions: list[int], *,
                       quantity: str = "radiance", scale: float = 1.0, curve: str = "aces",
                       progress=None) -> dict:
    """Write asset frames ``positions`` of ``bake`` as one animated GLB, atomically.

    Parameters
    ----------
    path : path-like
    bake : Bake
    positions : list of int
        Asset frame positions (0-based), at least two, in increasing scene order.
    quantity : {"radiance", "irradiance", "visibility"}
        What the display colour shows (:func:`shtools.export.quantity.display_linear`).
    scale : float
        Exposure shared by every frame.
    curve : str
        Tone curve.
    progress : callable, optional
        Progress factory (:mod:`shtools.progress`), one step per frame.

    Returns
    -------
    dict
        ``objects`` (names), ``colour_animated`` / ``moving`` / ``deforming``
        (object names), ``targets`` (counts of dense, sparse, shared and empty
        colour targets) and ``bytes`` of the file.
    """
    frames = [int(bake.frame_index[t]) for t in positions]
    fps = float(bake.attrs.get("fps", 24.0))
    buf = _Buffer()
    objects = []
    for o in range(len(bake.object_names)):
        lo, hi = int(bake.object_offsets[o]), int(bake.object_offsets[o + 1])
        count = hi - lo
        motion = deform = None
        if bake.vertices.ndim == 3:
            pts = bake.vertices[positions, lo:hi]
            if count and np.any(pts != pts[0]):
                motion = rigid_motion(pts)
                deform = motion is None
        objects.append({"lo": lo, "hi": hi, "motion": motion, "deform": bool(deform),
                        "colour": FrameTargets(buf, count, 3),
                        "position": FrameTargets(buf, count, 3, bounds=True),
                        "normal": FrameTargets(buf, count, 3)})

    changes = colour_changes(bake, positions, quantity=quantity, scale=scale, curve=curve,
                             progress=progress)
    base = next(changes, None)
    for t, delta, keep in changes:
        for obj in objects:
            rows = slice(obj["lo"], obj["hi"])
            obj["colour"].add_colour(delta[rows], keep[rows])
            if obj["deform"]:
                for name, frame_values in (("position", bake.frame_vertices),
                                           ("normal", bake.frame_normals)):
                    now = np.asarray(frame_values(t)[rows], dtype=np.float64)
                    obj[name].add_float(now - frame_values(positions[0])[rows])

    nodes, meshes, channels, samplers = [], [], [], []
    n_targets = len(positions) - 1
    times = buf.add(key_times(frames, fps), kind="SCALAR", target=None, bounds=True)
    weights = None
    summary = {"objects": list(bake.object_names), "colour_animated": [], "moving": [],
               "deforming": [], "targets": {"dense": 0, "sparse": 0, "shared": 0, "empty": 0}}
    t0 = positions[0]
    for o, (name, obj) in enumerate(zip(bake.object_names, objects, strict=True)):
        rows = slice(obj["lo"], obj["hi"])
        verts = np.asarray(bake.frame_vertices(t0)[rows], dtype=np.float64)
        normals = np.asarray(bake.frame_normals(t0)[rows], dtype=np.float64)
        node = pygltflib.Node(mesh=o, name=name)
        if obj["motion"] is not None:
            centres, quats = obj["motion"]
            verts = verts - centres[0]
            node.translation = [float(x) for x in centres[0]]
            for path_name, values, kind in (("translation", centres, "VEC3"),
                                            ("rotation", quats, "VEC4")):
                held = np.concatenate([values, values[-1:]])  # the closing key
                samplers.append(pygltflib.AnimationSampler(
                    input=times, interpolation="STEP",
                    output=buf.add(held.astype(np.float32), kind=kind, target=None)))
                channels.append(pygltflib.AnimationChannel(
                    sampler=len(samplers) - 1,
                    target=pygltflib.AnimationChannelTarget(node=o, path=path_name)))
            summary["moving"].append(name)
        attrs = pygltflib.Attributes(
            POSITION=buf.add(verts.astype(np.float32), kind="VEC3", target=_ARRAY_BUFFER,
                             bounds=True),
            NORMAL=buf.add(normals.astype(np.float32), kind="VEC3", target=_ARRAY_BUFFER),
            COLOR_0=buf.add(base[rows], kind="VEC3", target=_ARRAY_BUFFER))
        indices = buf.add(np.asarray(bake.object_faces(o), np.uint32).reshape(-1),
                          kind="SCALAR", target=_ELEMENT_ARRAY_BUFFER, bounds=True)
        primitive = pygltflib.Primitive(attributes=attrs, indices=indices, material=0)
        mesh = pygltflib.Mesh(name=name, primitives=[primitive])
        colour, deform = obj["colour"], obj["deform"]
        for key in summary["targets"]:
            summary["targets"][key] += colour.stats[key]
        if colour.changes or deform:
            # every target carries every morphed attribute: three.js substitutes the
            # base attribute for a missing one, which relative targets would add twice
            per_frame = [{"COLOR_0": a} for a in colour.resolved()]
            if deform:
                for entry, p, n in zip(per_frame, obj["position"].resolved(),
                                       obj["normal"].resolved(), strict=True):
                    entry.update(POSITION=p, NORMAL=n)
                summary["deforming"].append(name)
            primitive.targets = [pygltflib.Attributes(**entry) for entry in per_frame]
            mesh.weights = [0.0] * n_targets
            mesh.extras = {"targetNames": [f"frame {f}" for f in frames[1:]]}
            if weights is None:  # shared by every mesh
                weights = buf.add(one_hot_weights(len(positions)).reshape(-1), kind="SCALAR",
                                  target=None)
            samplers.append(pygltflib.AnimationSampler(input=times, interpolation="STEP",
                                                       output=weights))
            channels.append(pygltflib.AnimationChannel(
                sampler=len(samplers) - 1,
                target=pygltflib.AnimationChannelTarget(node=o, path="weights")))
            if colour.changes:
                summary["colour_animated"].append(name)
        meshes.append(mesh)
        nodes.append(node)
    animations = [pygltflib.Animation(name="bake", samplers=samplers, channels=channels)]
    extras = {"frames": frames, "fps": fps, "quantity": quantity}
    save_glb(path, buf, nodes, meshes, extras, animations if channels else None)
    summary["bytes"] = os.path.getsize(path)
    return summary
