"""A procedural skinned glTF for tests: a two-bone tube that bends at its middle.

Joint 0 sits at the origin, joint 1 (its child) at (0, 1, 0).  The tube runs
along +Y from 0 to 2; vertices below y = 0.8 follow joint 0 only, above 1.2
joint 1 only, with a linear blend in between.  The one animation rotates joint
1 about +Z from 0 to ``bend_degrees`` at t = 1 s and back to 0 at t = 2 s.
"""

from __future__ import annotations

import numpy as np
import pygltflib

RADIUS = 0.2
LENGTH = 2.0


def tube(rings: int = 16, sections: int = 16):
    """Closed tube vertices (V, 3) and faces (F, 3), axis along +Y from 0 to LENGTH."""
    y = np.linspace(0.0, LENGTH, rings + 1)
    phi = 2 * np.pi * np.arange(sections) / sections
    yy, pp = np.meshgrid(y, phi, indexing="ij")
    side = np.stack([RADIUS * np.cos(pp), yy, -RADIUS * np.sin(pp)], -1).reshape(-1, 3)
    idx = np.arange(len(side)).reshape(rings + 1, sections)
    a, b = idx[:-1], np.roll(idx[:-1], -1, axis=1)
    c, d = np.roll(idx[1:], -1, axis=1), idx[1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    bottom, top = len(side), len(side) + 1
    verts = np.concatenate([side, [[0, 0, 0], [0, LENGTH, 0]]])
    k = np.arange(sections)
    caps = np.concatenate([
        np.stack([np.full(sections, bottom), idx[0, (k + 1) % sections], idx[0, k]], 1),
        np.stack([np.full(sections, top), idx[-1, k], idx[-1, (k + 1) % sections]], 1),
    ])
    return verts, np.concatenate([faces, caps])


def bone_weights(y: np.ndarray) -> np.ndarray:
    """Weight of joint 1 at height y: 0 below 0.8, 1 above 1.2, linear between."""
    return np.clip((y - 0.8) / 0.4, 0.0, 1.0)


def write_bending_tube(path, bend_degrees: float = 90.0, *, with_skin=True,
                       with_animation=True) -> None:
    """Write the rig as a .glb (optionally without skin or animation, for error tests)."""
    verts, faces = tube()
    w1 = bone_weights(verts[:, 1])
    joints = np.tile(np.array([0, 1, 0, 0], np.uint16), (len(verts), 1))
    weights = np.stack([1 - w1, w1, 0 * w1, 0 * w1], 1).astype(np.float32)
    inv_bind = np.stack([np.eye(4), np.eye(4)]).astype(np.float32)
    inv_bind[1, 1, 3] = -1.0  # joint 1 sits at y = 1
    half = np.radians(bend_degrees) / 2
    times = np.array([0.0, 1.0, 2.0], np.float32)
    rots = np.array([[0, 0, 0, 1], [0, 0, np.sin(half), np.cos(half)], [0, 0, 0, 1]],
                    np.float32)
    arrays = [
        (verts.astype(np.float32), "VEC3", pygltflib.FLOAT, 34962),
        (faces.astype(np.uint32).reshape(-1), "SCALAR", pygltflib.UNSIGNED_INT, 34963),
        (joints, "VEC4", pygltflib.UNSIGNED_SHORT, 34962),
        (weights, "VEC4", pygltflib.FLOAT, 34962),
        # inverse bind matrices are column-major in glTF
        (np.transpose(inv_bind, (0, 2, 1)).reshape(2, 16), "MAT4", pygltflib.FLOAT, None),
        (times, "SCALAR", pygltflib.FLOAT, None),
        (rots, "VEC4", pygltflib.FLOAT, None),
    ]
    blob, views, accessors = bytearray(), [], []
    for k, (arr, kind, ctype, target) in enumerate(arrays):
        data = np.ascontiguousarray(arr).tobytes()
        views.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data),
                                          target=target))
        blob += data + b"\0" * (-len(data) % 4)
        acc = pygltflib.Accessor(bufferView=k, componentType=ctype, count=len(arr), type=kind)
        if k == 0:
            acc.min, acc.max = arr.min(0).tolist(), arr.max(0).tolist()
        if k == 5:
            acc.min, acc.max = [float(arr.min())], [float(arr.max())]
        accessors.append(acc)
    nodes = [
        pygltflib.Node(name="root_joint", children=[1]),
        pygltflib.Node(name="tip_joint", translation=[0.0, 1.0, 0.0]),
        pygltflib.Node(name="tube", mesh=0, skin=0 if with_skin else None),
    ]
    attrs = pygltflib.Attributes(POSITION=0)
    if with_skin:
        attrs.JOINTS_0, attrs.WEIGHTS_0 = 2, 3
    gltf = pygltflib.GLTF2(
        scene=0,
        scenes=[pygltflib.Scene(nodes=[0, 2])],
        nodes=nodes,
        meshes=[pygltflib.Mesh(primitives=[pygltflib.Primitive(attributes=attrs, indices=1)])],
        skins=[pygltflib.Skin(joints=[0, 1], inverseBindMatrices=4)] if with_skin else [],
        animations=[pygltflib.Animation(
            name="bend",
            samplers=[pygltflib.AnimationSampler(input=5, output=6, interpolation="LINEAR")],
            channels=[pygltflib.AnimationChannel(
                sampler=0, target=pygltflib.AnimationChannelTarget(node=1, path="rotation"))],
        )] if with_animation else [],
        accessors=accessors,
        bufferViews=views,
        buffers=[pygltflib.Buffer(byteLength=len(blob))],
    )
    gltf.set_binary_blob(bytes(blob))
    gltf.save_binary(str(path))


#: A sky of order 3 for the tube scenes: a constant plus some of bands 1 and 2.
SKY = """
[environment]
coeffs = [[1.0, 1.0, 1.0], [0, 0.6, 0], [0, 0.5, 0], [0, 0, 0],
          [0, 0, 0], [0, 0, 0], [0, 0.2, 0], [0, 0, 0], [0, 0, 0]]
"""
#: Vertices of the tube scenes' ground plane (listed first among the receivers).
GROUND_VERTICES = 21 * 21


def ground_scene_head(settings: str = "", *, size: float = 4.0, subdivisions: int = 24,
                      frames: int = 2, fps: float | None = 2) -> str:
    """Scene text up to a receiver-only ground plane: order 3, ``frames`` frames at
    ``fps`` (``None``: the scene default), a sky brighter above (bands 0 and 1),
    ``settings`` more ``[settings]`` lines; the tests append their objects."""
    timing = f"frames = {frames}\n" + ("" if fps is None else f"fps = {fps:g}\n")
    return f"""
[settings]
order = 3
{timing}{settings}
[environment]
coeffs = [[5.0, 5.0, 5.0], [0.0, 0.0, 0.0], [3.0, 3.0, 3.0], [0.0, 0.0, 0.0],
          [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]

[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [{size:g}, {size:g}], subdivisions = {subdivisions} }}
role = "receiver"
"""


def tube_scene_text(blocker: str, *, settings: str = "frames = 2", environment: str = SKY,
                    tube_keys: str = "") -> str:
    """A scene (TOML) of the rig ``rig.glb`` standing on a 4 x 4 ground plane
    (:data:`GROUND_VERTICES` vertices), order 3 at 1 fps, playing its "bend" clip.

    ``blocker`` is the tube's blocker table, ``settings`` more ``[settings]`` lines,
    ``tube_keys`` more keys of the tube object.
    """
    return f"""
[settings]
order = 3
fps = 1
{settings}
{environment}
[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [4.0, 4.0], subdivisions = 20 }}
role = "receiver"

[[objects]]
name = "tube"
mesh = "rig.glb"
role = "both"
translate = [0.0, 0.05, 0.0]
blocker = {blocker}
skin = {{ animation = "bend" }}
{tube_keys}
"""
