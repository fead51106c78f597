"""A skinned character with its baked colours: the source glTF, skin and clips kept.

``shtools export walk.h5 --frame F --rig character=character.glb -o out.glb``
copies ``character.glb`` -- nodes, skin, every animation, materials, textures --
and adds to each skinned triangle primitive

* ``COLOR_0`` (float32 RGB, linear): the display colour of bake frame ``F``
  (:func:`shtools.export.quantity.display_linear`); glTF multiplies it with
  the material's base colour, so with ``--quantity irradiance`` or
  ``visibility`` the rig's own textures stay the albedo;
* ``_RADIANCE`` / ``_IRRADIANCE`` / ``_VISIBILITY``: the raw value of frame F.

The colours are **static** (one frame's): glTF animates the skin and the node
transforms but has no per-frame vertex colours (see docs/scenes.md).  The rig
keeps its own placement; the scene's transform and keyframes of the object are
not applied.  Vertex ``i`` of the baked object is vertex ``i`` of the rig's
skinned primitives in the order :func:`shtools.geometry.skin.load_skinned_gltf`
reads them (``SkinnedModel.primitives``), which is how the baker loaded it.
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


def write_rig_glb(path: str | os.PathLike, bake: Bake, t: int, name: str,
                  rig_path: str | os.PathLike, *, quantity: str = "radiance",
                  scale: float = 1.0, curve: str = "aces") -> dict:
    """Write the rig of object ``name`` with the colours of asset frame ``t``, atomically.

    Returns
    -------
    dict
        ``skins``, ``animations`` (names) and ``primitives`` coloured.
    """
    from shtools.export.quantity import display_linear, raw_values

    rig_path = Path(rig_path)
    model, o = _check_rig(bake, name, rig_path)
    lo = int(bake.object_offsets[o])
    display = display_linear(bake, t, quantity, scale, curve).astype(np.float32)
    raw = raw_values(bake, t, quantity).astype(np.float32)
    gltf = pygltflib.GLTF2().load(str(rig_path))
    if len(gltf.buffers) != 1:
        raise InputError("has several buffers; re-export it as a single-buffer .glb", rig_path)
    blob = bytearray(gltf.binary_blob() or b"")
    blob += b"\0" * (-len(blob) % 4)

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
    gltf.buffers[0].byteLength = len(blob)
    gltf.set_binary_blob(bytes(blob))
    with atomic_path(path) as tmp:
        gltf.save_binary(str(tmp))
    return {"skins": len(gltf.skins or []), "animations": list(model.animations),
            "primitives": len(model.primitives)}
