"""A skinned character with its baked colours: the source glTF, skin and clips kept.

``shtools export walk.h5 --frame F --rig character=character.glb -o out.glb``
copies ``character.glb`` -- nodes, skin, every animation, materials, textures --
and adds to each skinned triangle primitive

* ``COLOR_0`` (float32 RGB, linear): the display colour of bake frame ``F``
  (:func:`shtools.export.quantity.display_linear`); glTF multiplies it with
  the material's base colour, so with ``--quantity irradiance`` or
  ``visibility`` the rig's own textures stay the albedo;
* ``_RADIANCE`` / ``_IRRADIANCE`` / ``_VISIBILITY``: the raw value of frame F.

With one frame the colours are **static** (that frame's).  With a frame range
(``--frames A:B --rig ...``) they play as in :mod:`shtools.export.animated`:
``COLOR_0`` is the first frame's, each later frame a morph target of the colour
change, and an added animation ``bake`` sets the skinned nodes' ``weights``
one-hot (STEP) at each frame's **scene time** -- with the scene's default skin
timing (``speed = 1``, ``offset = 0``) that is the clip's own time, so playing
the clip and ``bake`` together keeps colours and pose in step (three.js plays
both; a viewer that plays one animation at a time shows one or the other).
The raw attribute is written for a single frame only.  The rig keeps its own
placement; the scene's transform and keyframes of the object are not applied.
Vertex ``i`` of the baked object is vertex ``i`` of the rig's skinned
primitives in the order :func:`shtools.geometry.skin.load_skinned_gltf` reads
them (``SkinnedModel.primitives``), which is how the baker loaded it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pygltflib

from shtools.data_formats import atomic_path
from shtools.data_formats.bake import Bake
from shtools.errors import InputError

_FLOAT, _ARRAY_BUFFER = 5126, 34962


def _check_rig(bake: Bake, name: str, rig_path: Path):
    from shtools.data_formats import sha256_file
    from shtools.geometry.skin import load_skinned_gltf

    if name not in bake.object_names:
        raise InputError(f"--rig {name}=...: no receiver object '{name}' in this bake; it has "
                         f"{', '.join(bake.object_names)}", bake.path)
    if rig_path.suffix.lower() != ".glb":
        raise InputError("--rig needs the binary glTF (.glb) the scene used", rig_path)
    # by content, not by name: a renamed copy of the baked rig is that rig, and an edited
    # file is not, whatever its name (the bake records every input's sha256)
    recorded = bake.attrs.get("inputs") or {}
    if recorded and sha256_file(rig_path) not in recorded.values():
        raise InputError(f"is not the rig this bake used (its hash differs from the sha256 "
                         f"of every input the bake recorded: {', '.join(sorted(recorded))}); "
                         "give the rig the scene used", rig_path)
    model = load_skinned_gltf(rig_path)
    o = bake.object_names.index(name)
    count = int(bake.object_offsets[o + 1] - bake.object_offsets[o])
    if len(model.rest_vertices) != count:
        raise InputError(f"has {len(model.rest_vertices)} skinned vertices but object "
                         f"'{name}' of the bake has {count}; give the rig the scene used",
                         rig_path)
    keys = [(m, p) for m, p, _, _ in model.primitives]
    if len(set(keys)) != len(keys):
        raise InputError("uses one mesh in two skinned nodes; cannot colour it per node",
                         rig_path)
    return model, o


def write_rig_glb(path: str | os.PathLike, bake: Bake, t: int | list[int], name: str,
                  rig_path: str | os.PathLike, *, quantity: str = "radiance",
                  scale: float = 1.0, curve: str = "aces", progress=None) -> dict:
    """Write the rig of object ``name`` with the colours of asset frame(s) ``t``, atomically.

    ``t`` is one asset frame position (static colours) or a list of them (the
    colours animated as morph targets, see the module doc).

    Returns
    -------
    dict
        ``skins``, ``animations`` (names) and ``primitives`` coloured.
    """
    from shtools.export.quantity import display_linear, raw_values

    rig_path = Path(rig_path)
    model, o = _check_rig(bake, name, rig_path)
    lo = int(bake.object_offsets[o])
    gltf = pygltflib.GLTF2().load(str(rig_path))
    if len(gltf.buffers) != 1:
        raise InputError("has several buffers; re-export it as a single-buffer .glb", rig_path)
    blob = bytearray(gltf.binary_blob() or b"")
    blob += b"\0" * (-len(blob) % 4)
    if isinstance(t, list) and len(t) > 1:
        _add_colour_animation(gltf, blob, bake, t, model, lo, rig_path, quantity=quantity,
                              scale=scale, curve=curve, progress=progress)
        return _save(path, gltf, blob, model)
    t = t[0] if isinstance(t, list) else t
    display = display_linear(bake, t, quantity, scale, curve).astype(np.float32)
    raw = raw_values(bake, t, quantity).astype(np.float32)

    def add(arr: np.ndarray) -> int:
        data = np.ascontiguousarray(arr).tobytes()
        gltf.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob),
                                                     byteLength=len(data),
                                                     target=_ARRAY_BUFFER))
        blob.extend(data + b"\0" * (-len(data) % 4))
        gltf.accessors.append(pygltflib.Accessor(
            bufferView=len(gltf.bufferViews) - 1, componentType=_FLOAT, count=len(arr),
            type="VEC3" if arr.ndim == 2 else "SCALAR"))
        return len(gltf.accessors) - 1

    for mesh_index, prim_index, start, count in model.primitives:
        prim = gltf.meshes[mesh_index].primitives[prim_index]
        rows = slice(lo + start, lo + start + count)
        prim.attributes.COLOR_0 = add(display[rows])
        setattr(prim.attributes, f"_{quantity.upper()}", add(raw[rows]))
    return _save(path, gltf, blob, model)


def _save(path, gltf: pygltflib.GLTF2, blob: bytearray, model) -> dict:
    gltf.buffers[0].byteLength = len(blob)
    gltf.set_binary_blob(bytes(blob))
    with atomic_path(path) as tmp:
        gltf.save_binary(str(tmp))
    return {"skins": len(gltf.skins or []), "animations": list(model.animations),
            "primitives": len(model.primitives)}


def _add_colour_animation(gltf: pygltflib.GLTF2, blob: bytearray, bake: Bake,
                          positions: list[int], model, lo: int, rig_path: Path, *,
                          quantity: str, scale: float, curve: str, progress) -> None:
    """Add the frames' colours as one-hot morph targets and a ``bake`` weights animation."""
    from shtools.export.animated import FrameTargets, colour_changes, key_times, one_hot_weights
    from shtools.export.gltf import _Buffer

    meshes = {m for m, _, _, _ in model.primitives}
    for m in sorted(meshes):
        prims = gltf.meshes[m].primitives
        if len(prims) != sum(1 for mm, *_ in model.primitives if mm == m):
            raise InputError(f"mesh {m} mixes skinned and unskinned primitives; the frame "
                             "colours cannot animate it (export one --frame)", rig_path)
        if any(p.targets for p in prims):
            raise InputError(f"mesh {m} already has morph targets; the frame colours cannot "
                             "be added to them (export one --frame)", rig_path)
    buf = _Buffer()  # appends to the rig's own buffer, views and accessors
    buf.blob, buf.views, buf.accessors = blob, gltf.bufferViews, gltf.accessors
    tracks = {(m, p): FrameTargets(buf, count, 3) for m, p, _, count in model.primitives}
    changes = colour_changes(bake, positions, quantity=quantity, scale=scale, curve=curve,
                             progress=progress)
    base = next(changes, None)
    for _t, delta, keep in changes:
        for m, p, start, count in model.primitives:
            rows = slice(lo + start, lo + start + count)
            tracks[m, p].add_colour(delta[rows], keep[rows])
    n_targets = len(positions) - 1
    for m, p, start, count in model.primitives:
        prim = gltf.meshes[m].primitives[p]
        prim.attributes.COLOR_0 = buf.add(base[lo + start:lo + start + count], kind="VEC3",
                                          target=_ARRAY_BUFFER)
        prim.targets = [pygltflib.Attributes(COLOR_0=a) for a in tracks[m, p].resolved()]
    # the keys at the frames' scene times, with the closing key of key_times
    frames = [int(bake.frame_index[t]) for t in positions]
    fps = float(bake.attrs.get("fps", 24.0))
    seconds = key_times(frames, fps) + np.float32(bake.times[positions[0]])
    times = buf.add(seconds, kind="SCALAR", target=None, bounds=True)
    weights = buf.add(one_hot_weights(len(positions)).reshape(-1), kind="SCALAR", target=None)
    samplers, channels = [], []
    for m in sorted(meshes):
        gltf.meshes[m].weights = [0.0] * n_targets
        gltf.meshes[m].extras = {**(gltf.meshes[m].extras or {}),
                                 "targetNames": [f"frame {f}" for f in frames[1:]]}
        for n, node in enumerate(gltf.nodes):
            if node.mesh == m:
                samplers.append(pygltflib.AnimationSampler(input=times, output=weights,
                                                           interpolation="STEP"))
                channels.append(pygltflib.AnimationChannel(
                    sampler=len(samplers) - 1,
                    target=pygltflib.AnimationChannelTarget(node=n, path="weights")))
    gltf.animations = [*(gltf.animations or []),
                       pygltflib.Animation(name="bake", samplers=samplers, channels=channels)]
