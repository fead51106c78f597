"""All-frequency (Haar) shadow fields: sizes as Tamura's Table 2 "A" rows.

Per object: 32 shells, R = 64, a 64 x 64 occlusion map per sample in the
nonstandard 2-D Haar basis, the largest 5 % kept (205 coefficients, an 8-bit
value and a uint16 index each), reduced per shell at τ = 0.01 with eq. (1) on
the reconstructed maps (:func:`shtools.fields.haar.haar_shell_sizes`).  Objects:
the teapot and a long object (``human_man.obj``) from ``../shared/data``
(measurement only), and a procedural long box when that is absent.  Target:
>= 40 % smaller than the fixed 32 x 64 x 64 field.  (Shading of Haar fields is
not implemented.)

``python benchmarks/bench_haar.py [--quick]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# the shared data next to the repository (or next to the folder of its worktrees)
DATA = next((p for p in (REPO.parent / "shared" / "data", REPO.parents[1] / "shared" / "data")
             if p.is_dir()), REPO.parent / "shared" / "data")


def main(argv=None):
    import trimesh

    from shtools.fields.haar import haar_shell_sizes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    objects = {}
    if (DATA / "meshes").is_dir():
        from shtools.geometry.mesh import load_mesh

        objects["teapot"] = load_mesh(DATA / "meshes" / "teapot.obj")
        objects["human_man (long)"] = load_mesh(DATA / "meshes" / "human_man.obj")
    objects["long box 4:1:1"] = trimesh.creation.box((4.0, 1.0, 1.0))
    kw = dict(shells=8, resolution=16, map_size=16) if args.quick else {}
    print("| object | R_c per shell | bytes | fixed | reduction | s |")
    print("|---|---|---|---|---|---|")
    for name, mesh in objects.items():
        t0 = time.perf_counter()
        out = haar_shell_sizes(mesh, **kw)
        print(f"| {name} | {out['resolution']} | {out['bytes']} | {out['fixed_bytes']} | "
              f"{100 * (1 - out['bytes'] / out['fixed_bytes']):.1f} % | "
              f"{time.perf_counter() - t0:.0f} |")


if __name__ == "__main__":
    main()
