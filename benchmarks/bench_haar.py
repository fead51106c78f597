"""All-frequency (Haar) shadow fields: sizes as Tamura's Table 2 "A" rows.

Per object: 32 shells, R = 64, a 64 x 64 occlusion map per sample in the
nonstandard 2-D Haar basis, the largest 5 % kept (205 coefficients, an 8-bit
value and a uint16 index each), reduced per shell at τ = 0.01 with eq. (1) on
the reconstructed maps (:func:`shtools.fields.haar.haar_shell_sizes`).  Objects:
the teapot and a long object (``human_man.obj``) from ``../shared/data``
(measurement only), or a procedural long box when that is absent.  Target:
>= 40 % smaller than the fixed 32 x 64 x 64 field.

``--part sun``: the teapot (or the long box) over a ground under the Mondello
probe (``../shared/data/probes``; a procedural sun sky when absent), ground
within 2 bounding radii of the object's centre: radiance relative RMSE of the
Haar field (64 x 64 maps, 5 % kept) and of the order-4 SH field of the same
shells, both against ray tracing of the real mesh at 128 x 128 directions per
vertex under the same light; and the per-frame cost of both (lookup + shading
of the ground, one process, same run).  Target: the Haar field clearly better.

The sun part also times, on the same ground, the map-basis shading schemes
(cell-wise, the default, and Ng et al.'s wavelet triple product with the lit
transfer kept or recomputed) next to the SH field, and the product of two
occluders' maps in the Haar domain (Ng's double product) and in the pixel domain.
Sizes are printed as Table 2 does (10^6-byte MB, fixed -> adaptive).

``python benchmarks/bench_haar.py [--quick] [--part sizes,sun]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
# the shared data next to the repository (or next to the folder of its worktrees)
DATA = next((p for p in (REPO.parent / "shared" / "data", REPO.parents[1] / "shared" / "data")
             if p.is_dir()), REPO.parent / "shared" / "data")


def cell_average(image, size: int):
    """A lat-long HDR (Y-up, docs/conventions.md) averaged into the field's ``size x size``
    (theta, phi) cells about **+z**, shape ``(size*size, 3)``: the field frame's +z is
    the world's +y (up), its +y the world's -z."""
    from shtools.lighting.latlong import latlong_directions, pixel_solid_angles

    H, W = image.shape[:2]
    d = latlong_directions(H, W).reshape(-1, 3)
    w = pixel_solid_angles(H, W).reshape(-1)
    fx, fy, fz = d[:, 0], -d[:, 2], d[:, 1]
    row = np.minimum((np.arccos(np.clip(fz, -1, 1)) / np.pi * size).astype(int), size - 1)
    col = np.minimum(((np.arctan2(fy, fx) % (2 * np.pi)) / (2 * np.pi) * size).astype(int),
                     size - 1)
    cell = row * size + col
    acc = np.zeros((size * size, 3))
    np.add.at(acc, cell, image.reshape(-1, 3) * w[:, None])
    from shtools.fields.sampling import direction_map

    return acc / direction_map(size)[1][:, None]


def sun_sky(height: int = 256):
    """A procedural sky (Y-up lat-long): dim blue, a 1-degree sun 40 degrees up."""
    from shtools.lighting.latlong import latlong_directions

    d = latlong_directions(height, 2 * height)
    sun = np.array([0.6, np.sin(np.radians(40)), -0.5])
    sun /= np.linalg.norm(sun)
    img = np.where((d @ sun > np.cos(np.radians(1.0)))[..., None], 4e4, 0.0) + \
        np.where(d[..., 1:2] > 0, np.array([0.3, 0.5, 0.9]), np.array([0.1, 0.08, 0.05]))
    return img.astype(np.float32)


def part_sun(quick: bool):
    import math

    import trimesh

    from shtools.fields import FieldParameters, sample_field
    from shtools.fields.haar import build_haar_field
    from shtools.fields.sampling import direction_map
    from shtools.geometry.raycast import RayCaster
    from shtools.reference import relative_rmse
    from shtools.runtime import FieldBlocker
    from shtools.runtime.haar import haar_radiance
    from shtools.runtime.shading import shade
    from shtools.sh import basis

    if (DATA / "meshes").is_dir():
        from shtools.geometry.mesh import load_mesh

        mesh, name = load_mesh(DATA / "meshes" / "teapot.obj"), "teapot"
    else:
        mesh, name = trimesh.creation.box((4.0, 1.0, 1.0)), "long box"
    mesh = mesh.copy()
    mesh.vertices = np.c_[mesh.vertices[:, 0], -mesh.vertices[:, 2], mesh.vertices[:, 1]]
    probe = DATA / "probes" / "spiaggia_di_mondello_1k.hdr"
    if probe.is_file():
        from shtools.lighting.images import load_hdr_image

        image, light = load_hdr_image(probe), "Mondello"
    else:
        image, light = sun_sky(), "procedural sun"
    shells, res = (8, 16) if quick else (32, 32)
    t0 = time.perf_counter()
    haar, _ = build_haar_field(mesh, shells=shells, resolution=res, map_size=64)
    t_haar = time.perf_counter() - t0
    t0 = time.perf_counter()
    sh, _ = sample_field(mesh, FieldParameters(shells=shells, resolution=res, map_size=64),
                         scheduler="inline")
    t_sh = time.perf_counter() - t0
    center, vr = haar.center, haar.bounding_radius
    z0 = float(mesh.vertices[:, 2].min())
    xs = np.linspace(-2 * vr, 2 * vr, 15 if quick else 41)
    X, Y = np.meshgrid(xs + center[0], xs + center[1])
    keep = np.hypot(X - center[0], Y - center[1]).ravel() <= 2 * vr
    pts = np.c_[X.ravel(), Y.ravel(), np.full(X.size, z0 - 1e-3)][keep]
    nrm = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    # reference: one ray per cell of a 128 x 128 map, the light averaged into those cells
    fine, fw = direction_map(128)
    env_fine = cell_average(image, 128)
    vis = RayCaster(mesh.vertices, mesh.faces).visibility(pts, fine, normals=nrm)
    ref = (vis * np.maximum(nrm @ fine.T, 0) * fw) @ env_fine / math.pi
    dirs, w = direction_map(64)
    env64 = cell_average(image, 64)
    t0 = time.perf_counter()
    got_haar = haar_radiance(haar.visibility_maps(pts), env64, nrm, dirs, w)
    f_haar = time.perf_counter() - t0
    env_sh = (basis(fine, 4) * fw[:, None]).T @ env_fine  # (16, 3), exact for the cell map
    t0 = time.perf_counter()
    blocker = FieldBlocker(sh)
    vis_sh = blocker.world_vectors(pts)
    got_sh = shade(vis_sh, pts, nrm, env_sh, order=4)
    f_sh = time.perf_counter() - t0
    free = np.zeros((len(pts), 16))
    free[:, 0] = math.sqrt(4 * math.pi)
    print(f"\n## {name} under the {light} probe: ground within 2 bounding radii "
          f"({len(pts)} vertices), {shells} shells, R = {res}\n")
    print("| field | radiance error vs ray tracing | build s | frame s (lookup + shade) |")
    print("|---|---|---|---|")
    print(f"| Haar, 64 x 64 maps, 5 % kept | {100 * relative_rmse(got_haar, ref):.1f} % | "
          f"{t_haar:.0f} | {f_haar:.3f} |")
    print(f"| SH order 4 | {100 * relative_rmse(got_sh, ref):.1f} % | {t_sh:.0f} | "
          f"{f_sh:.3f} |")
    unocc = shade(free, pts, nrm, env_sh, order=4)
    ref_free = (np.maximum(nrm @ fine.T, 0) * fw) @ env_fine / math.pi
    print(f"| (unshadowed ground, SH order 4) | {100 * relative_rmse(unocc, ref_free):.1f} % "
          "| | |")
    part_cost(haar, pts, nrm, env64, ref, f_haar, f_sh)


def part_cost(haar, pts, nrm, env64, ref, f_cells_old, f_sh):
    """Per-frame cost of the map-basis shading schemes and of the two products, one process."""
    from shtools.reference import relative_rmse
    from shtools.runtime.haar import haar2, ihaar2
    from shtools.runtime.haar_shading import (
        HaarBlocker,
        TripleShader,
        combined_coefficients,
        combined_maps,
        shade_cells,
    )
    from shtools.runtime.haar_triple import haar_product

    blk = HaarBlocker(haar, np.eye(3), np.zeros(3))
    t0 = time.perf_counter()
    cells = shade_cells(combined_maps([blk], pts), env64, nrm)
    f_cells = time.perf_counter() - t0
    shader = TripleShader(env64)
    t0 = time.perf_counter()
    triple = shader.radiance(combined_coefficients([blk], pts), nrm)
    f_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    shader.radiance(combined_coefficients([blk], pts), nrm)
    f_triple = time.perf_counter() - t0
    t0 = time.perf_counter()
    sparse = shader.radiance_sparse(*blk.sparse_terms(pts), nrm)
    f_sparse = time.perf_counter() - t0
    # a receiver with a different normal at every vertex: the lit transfer every frame
    tilt = nrm + 1e-3 * np.arange(len(nrm))[:, None] * np.array([1.0, 0.0, 0.0])
    tilt /= np.linalg.norm(tilt, axis=1, keepdims=True)
    t0 = time.perf_counter()
    TripleShader(env64).radiance(combined_coefficients([blk], pts), tilt)
    f_distinct = time.perf_counter() - t0
    c = blk.coefficients(pts)
    t0 = time.perf_counter()
    haar_product(c, c)
    f_hprod = time.perf_counter() - t0
    M = c.shape[-1]
    t0 = time.perf_counter()
    haar2(ihaar2(c) * ihaar2(c))
    f_pprod = time.perf_counter() - t0
    t0 = time.perf_counter()
    ihaar2(c).reshape(-1, M * M) * ihaar2(c).reshape(-1, M * M)
    f_pmaps = time.perf_counter() - t0
    print(f"\n### Per-frame cost, {len(pts)} vertices, one process (same run)\n")
    print("| scheme | radiance error vs ray tracing | frame s |")
    print("|---|---|---|")
    print(f"| cell-wise: lookup + maps + cells | {100 * relative_rmse(cells, ref):.1f} % "
          f"| {f_cells:.3f} |")
    print(f"| Ng triple product, dense coefficients, lit transfer kept | "
          f"{100 * relative_rmse(triple, ref):.1f} % | {f_triple:.3f} |")
    print(f"| Ng triple product on the kept coefficients, lit transfer kept | "
          f"{100 * relative_rmse(sparse, ref):.1f} % | {f_sparse:.3f} |")
    print(f"| Ng triple product, first frame (lit transfer of 1 normal) | | {f_first:.3f} |")
    print(f"| Ng triple product, a distinct normal per vertex | | {f_distinct:.3f} |")
    print(f"| SH order-4 field (lookup + shade) | | {f_sh:.3f} |")
    print(f"| (earlier cell-wise path: visibility_maps + haar_radiance) | | {f_cells_old:.3f} |")
    print(f"\ntriple vs cell-wise radiance: {100 * relative_rmse(triple, cells):.2e} % "
          "(the same sum in another order)\n")
    print("| product of two occluders' maps | s |")
    print("|---|---|")
    print(f"| Ng Haar-domain double product (haar_product) | {f_hprod:.3f} |")
    print(f"| pixel domain, back to Haar (haar2(ihaar2 a * ihaar2 b)) | {f_pprod:.3f} |")
    print(f"| pixel domain, maps only (as the cell-wise scheme) | {f_pmaps:.3f} |")


def main(argv=None):
    import trimesh

    from shtools.fields.haar import haar_shell_sizes

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--part", default="sizes,sun")
    args = ap.parse_args(argv)
    if "sun" in args.part.split(","):
        part_sun(args.quick)
    if "sizes" not in args.part.split(","):
        return
    objects = {}
    if (DATA / "meshes").is_dir():
        from shtools.geometry.mesh import load_mesh

        objects["teapot"] = load_mesh(DATA / "meshes" / "teapot.obj")
        objects["human_man (long)"] = load_mesh(DATA / "meshes" / "human_man.obj")
    else:
        objects["long box 4:1:1"] = trimesh.creation.box((4.0, 1.0, 1.0))
    kw = dict(shells=8, resolution=16, map_size=16) if args.quick else {}
    print("| object | R_c per shell | bytes | fixed | fixed MB | adaptive MB | reduction | s |")
    print("|---|---|---|---|---|---|---|---|")
    for name, mesh in objects.items():
        t0 = time.perf_counter()
        out = haar_shell_sizes(mesh, **kw)
        print(f"| {name} | {out['resolution']} | {out['bytes']} | {out['fixed_bytes']} | "
              f"{out['fixed_bytes'] / 1e6:.1f} | {out['bytes'] / 1e6:.1f} | "
              f"{100 * (1 - out['bytes'] / out['fixed_bytes']):.1f} % | "
              f"{time.perf_counter() - t0:.0f} |")


if __name__ == "__main__":
    main()
