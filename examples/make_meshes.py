"""Generate the example's procedural inputs: meshes (OBJ) and a lat-long HDR sky.

    python make_meshes.py arch -o build/meshes/arch.obj
    python make_meshes.py pillar -o build/meshes/pillar.obj
    python make_meshes.py crate -o build/meshes/crate.obj
    python make_meshes.py sky -o build/sky.hdr

Each call writes one file (atomically), so ``make -j`` can run them in parallel.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import trimesh

from shtools.data_formats import atomic_path
from shtools.scene.primitives import make_primitive


def arch() -> trimesh.Trimesh:
    """Two posts and a lintel (three boxes, overlapping at the joints), 1.6 wide, 1.5 tall."""
    parts = [
        make_primitive("box", {"extents": [0.3, 1.2, 0.3], "center": [-0.65, 0.6, 0.0]}),
        make_primitive("box", {"extents": [0.3, 1.2, 0.3], "center": [0.65, 0.6, 0.0]}),
        make_primitive("box", {"extents": [1.6, 0.3, 0.4], "center": [0.0, 1.35, 0.0]}),
    ]
    return trimesh.util.concatenate([p.mesh for p in parts])


def pillar() -> trimesh.Trimesh:
    """A capsule standing on the ground, 1.7 tall."""
    return make_primitive("capsule", {"radius": 0.25, "length": 1.2, "center": [0, 0.85, 0]}).mesh


def crate() -> trimesh.Trimesh:
    """A closed box crate, 0.6 x 0.5 x 0.6, resting on the ground (a shadow-field blocker)."""
    return make_primitive("box", {"extents": [0.6, 0.5, 0.6], "center": [0, 0.25, 0]}).mesh


MESHES = {"arch": arch, "pillar": pillar, "crate": crate}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=[*MESHES, "sky"])
    parser.add_argument("-o", "--output", required=True)
    args = parser.parse_args(argv)
    if args.what == "sky":
        from pathlib import Path

        from shtools.demo import sky_image, write_hdr

        write_hdr(Path(args.output), sky_image())
        return 0
    mesh = MESHES[args.what]()
    text = mesh.export(file_type="obj", include_normals=False)
    with atomic_path(args.output) as tmp:
        tmp.write_text(text)
    print(f"wrote {args.output}: {len(mesh.vertices)} vertices, {len(mesh.faces)} faces "
          f"(volume {float(np.abs(mesh.volume)):.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
