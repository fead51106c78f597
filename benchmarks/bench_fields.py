"""Adaptive shadow fields: sizes, sampling speed, accuracy, a Tamura-like scene.

Parts (``--part``, default all):

* ``sizes`` -- Tamura's Tables 1-2: per-shell R_c and bytes, fixed vs adaptive at
  thresholds 0.02 / 0.01 / 0.005, for the teapot, a long object (``human_man.obj``
  with its long axis across and along the pole axis) and a thin box, in the
  32-shell and the 16-shell conventions (spec 2.3).  Target: >= 60 % smaller
  than fixed at 0.01, 32-shell convention.
* ``speed`` -- rays/s of the field sampler next to raw embreex OCCLUDED rays/s on
  the same rays in the same run (CPU and wall); wall time of a default
  ``shtools field sample teapot.obj``.  Targets: >= 50 % of raw; <= 60 s.
* ``accuracy`` -- the teapot (open) and spot (closed) over a ground grid under an
  HDR probe: radiance relative RMSE of field shading against ray tracing of the
  real mesh, split into convention+quadrature / interpolation / reduction /
  quantization; log-space vs visibility interpolation.  Target <= 3 %.
* ``scene`` -- a bowling-like scene, 15 rigid field objects over a ~40k-vertex
  receiver: frame time in log and product space, one process and the default
  processes.  Target <= 100 ms per frame in log space (10x Tamura's 1-3 fps CPU).

Needs ``../shared/data`` (meshes, probes) for the real-mesh parts; ``--quick``
shrinks everything for a smoke run.

``python benchmarks/bench_fields.py [--quick] [--part sizes,speed,accuracy,scene]``
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
THRESHOLDS = (0.02, 0.01, 0.005)
#: Tamura Table 1 (L rows) and Table 2, for the side-by-side tables
PAPER_RC = {"teapot": [8] + [64] * 8 + [32] * 3 + [16] * 4,
            "statue": [64] * 8 + [32] + [16] * 4 + [8] * 3,
            "plane": [64] * 11 + [32] + [16] * 4}
PAPER_MB = {"teapot": (2.0, 0.59), "statue": (2.0, 0.55), "plane": (2.0, 0.75)}


def machine() -> str:
    load = os.getloadavg()
    return (f"{os.cpu_count()} cores, load average {load[0]:.1f} / {load[1]:.1f} / "
            f"{load[2]:.1f} (1/5/15 min)")


def _meshes(quick: bool) -> dict:
    import trimesh

    from shtools.geometry.mesh import load_mesh

    out = {}
    if (DATA / "meshes" / "teapot.obj").exists():
        out["teapot"] = load_mesh(DATA / "meshes" / "teapot.obj")
        if not quick:
            man = load_mesh(DATA / "meshes" / "human_man.obj")
            out["human (long axis across the pole, standing Y-up)"] = man
            lying = man.copy()
            lying.apply_transform(trimesh.transformations.rotation_matrix(
                math.pi / 2, [1, 0, 0]))  # long axis y -> z, the shells' pole axis
            out["human (long axis along the pole)"] = lying
    out["thin box 2 x 0.1 x 1.2"] = trimesh.creation.box(extents=(2.0, 0.1, 1.2))
    return out


_SAMPLED: dict = {}


def sampled(name, mesh, params):
    """Full-resolution shells of a mesh, sampled once per run."""
    from shtools.fields import sample_shells

    key = (name, params.shells, params.resolution, params.map_size, params.order)
    if key not in _SAMPLED:
        c0 = time.process_time()
        w0 = time.perf_counter()
        s = sample_shells(mesh, params)
        _SAMPLED[key] = (s, time.process_time() - c0, time.perf_counter() - w0)
    return _SAMPLED[key]


def _params(quick: bool, **kw):
    from shtools.fields import FieldParameters

    base = dict(shells=32, resolution=64, map_size=64, order=4)
    if quick:
        base.update(resolution=32, map_size=32)
    base.update(kw)
    return FieldParameters(**base)


# ----------------------------------------------------------------------------- sizes
def part_sizes(quick: bool) -> None:
    from shtools.fields import build_field

    print(f"\n## Sizes (Tamura Tables 1-2); {machine()}\n")
    rows = []
    for name, mesh in _meshes(quick).items():
        params = _params(quick)
        s, _cpu, _wall = sampled(name, mesh, params)
        R0 = params.resolution
        n2 = params.order ** 2
        for tau in THRESHOLDS:
            fld, _ = build_field(s, _params(quick, threshold=tau), mesh=mesh)
            rc = [int(r) for r in fld.resolution]
            b32 = sum(r * r for r in rc) * n2
            b16 = sum(r * r for r in rc[:16]) * n2
            f32 = 32 * R0 * R0 * n2
            f16 = 16 * R0 * R0 * n2
            rows.append((name, tau, rc, b32, f32, b16, f16, float(fld.reduction_error.max())))
    print("| object | tau | R_c per shell (increasing radius) | 32 shells: bytes (fixed) | "
          "reduction | 16-shell convention: bytes (fixed) | reduction | max cumulative "
          "eq.1 error |")
    print("|---|---|---|---|---|---|---|---|")
    for name, tau, rc, b32, f32, b16, f16, err in rows:
        print(f"| {name} | {tau} | {_runs(rc)} | {b32:,} ({f32:,}) | {100 * (1 - b32 / f32):.1f} % "
              f"| {b16:,} ({f16:,}) | {100 * (1 - b16 / f16):.1f} % | {err:.4f} |")
    print("\nTamura (order 4, 8 bits, tau 0.01; Table 1 prints 16 shells, Table 2 'fixed' is "
          "32 shells):\n")
    print("| object | R_c (Table 1) | adaptive bytes of the 16 printed shells | vs 32-shell "
          "fixed 2,097,152 B | vs 16-shell fixed 1,048,576 B | Table 2 (MB) |")
    print("|---|---|---|---|---|---|")
    for name, rc in PAPER_RC.items():
        b = sum(r * r for r in rc) * 16
        print(f"| {name} | {_runs(rc)} | {b:,} | {100 * (1 - b / 2097152):.1f} % | "
              f"{100 * (1 - b / 1048576):.1f} % | {PAPER_MB[name][0]} -> {PAPER_MB[name][1]} |")


def _runs(rc) -> str:
    out, k = [], 0
    while k < len(rc):
        j = k
        while j < len(rc) and rc[j] == rc[k]:
            j += 1
        out.append(f"{rc[k]}x{j - k}" if j - k > 1 else str(rc[k]))
        k = j
    return ", ".join(out)


# ----------------------------------------------------------------------------- speed
def part_speed(quick: bool) -> None:
    from shtools.fields.sampling import (
        bounding_sphere,
        cone_mask,
        direction_map,
        grid_directions,
        object_visibility,
        shell_radii,
    )
    from shtools.geometry.raycast import RayCaster

    meshes = _meshes(True)
    name = "teapot" if "teapot" in meshes else next(iter(meshes))
    mesh = meshes[name]
    print(f"\n## Sampling speed ({name}); {machine()}\n")
    center, vr = bounding_sphere(mesh.vertices)
    caster = RayCaster(mesh.vertices, mesh.faces)
    R = 32 if quick else 64
    dirs, _ = direction_map(32 if quick else 64)
    pts_dir = grid_directions(R).reshape(-1, 3)
    print("| shells | rays | sampler Mrays/s CPU (wall) | raw embreex Mrays/s CPU (wall) | "
          "ratio CPU (wall) |")
    print("|---|---|---|---|---|")
    tot = np.zeros(4)
    rays_all = 0
    for c in range(0, 32, 4 if quick else 2):
        r = shell_radii(vr, 32)[c]
        pts = center + r * pts_dir
        stats = {"rays": 0}
        c0, w0 = time.process_time(), time.perf_counter()
        object_visibility(caster, center, vr, pts, dirs, stats=stats)
        c1, w1 = time.process_time() - c0, time.perf_counter() - w0
        # the same rays, prepared in Embree's frame outside the timing
        mask = cone_mask(pts, center, vr, dirs)
        vi, qi = np.nonzero(mask)
        o = caster.embree_points(pts)[vi]
        d = dirs[qi].astype(np.float32)
        c0, w0 = time.process_time(), time.perf_counter()
        caster._scene.run(o, d, query="OCCLUDED")
        c2, w2 = time.process_time() - c0, time.perf_counter() - w0
        n = stats["rays"]
        assert n == vi.size
        tot += (c1, w1, c2, w2)
        rays_all += n
        if c % 8 == 0:
            print(f"| {c} | {n:,} | {n / c1 / 1e6:.2f} ({n / w1 / 1e6:.2f}) | "
                  f"{n / c2 / 1e6:.2f} ({n / w2 / 1e6:.2f}) | {c2 / c1:.2f} ({w2 / w1:.2f}) |")
    c1, w1, c2, w2 = tot
    print(f"| all tested | {rays_all:,} | {rays_all / c1 / 1e6:.2f} ({rays_all / w1 / 1e6:.2f}) | "
          f"{rays_all / c2 / 1e6:.2f} ({rays_all / w2 / 1e6:.2f}) | **{c2 / c1:.2f}** "
          f"({w2 / w1:.2f}) |")
    if quick or name != "teapot":
        return
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "teapot.field.h5"
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
        load0 = machine()
        c0 = os.times()
        w0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "shtools.cli.main", "field", "sample",
                               str(DATA / "meshes" / "teapot.obj"), "-o", str(out), "--json"],
                              capture_output=True, text=True, env=env)
        wall = time.perf_counter() - w0
        c1 = os.times()
    cpu = (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
    import json

    if done.returncode != 0:
        print(f"\n`shtools field sample teapot.obj` failed: {done.stderr.strip()}")
        return
    summary = json.loads(done.stdout)
    print(f"\nDefault `shtools field sample teapot.obj` (32 shells, R 64, 64x64 map, order 4, "
          f"O_v included): **{wall:.1f} s wall**, {cpu:.1f} s CPU (stage times "
          f"{summary.get('seconds')}; "
          f"{summary.get('rays', 0):,} rays of {summary.get('rays_without_cull', 0):,} without "
          f"the cone cull); before: {load0}; after: {machine()}")


# ----------------------------------------------------------------------------- accuracy
def _shade_all(rt, vis, sc):
    return rt.shade(np.asarray(vis, dtype=np.float32), sc.vertices, sc.normals, sc.env_sh)


def _float_table(s, grids, res):
    """A FieldTable over float grids (no quantization) for the error split."""
    from shtools.data_formats.field import ShadowField
    from shtools.runtime import FieldTable

    C = len(grids)
    n2 = grids[0].shape[-1]
    zeros = np.zeros((C, n2), np.float32)
    ones = np.ones((C, n2), np.float32)
    fld = ShadowField(center=s.center, bounding_radius=s.bounding_radius, shell_radii=s.radii,
                      resolution=np.asarray(res), ocv=[g.astype(np.float32) for g in grids],
                      offset=zeros, step=ones, log_ocv=[g.astype(np.float32) for g in grids],
                      log_offset=zeros, log_step=ones, order=math.isqrt(n2))
    return FieldTable(fld)


def part_accuracy(quick: bool) -> None:
    import trimesh

    from shtools.fields import build_field
    from shtools.fields.reduction import reduce_shell
    from shtools.fields.sampling import direction_map, sample_ocvs
    from shtools.geometry.mesh import load_mesh
    from shtools.geometry.raycast import RayCaster
    from shtools.lighting.environment import project_environment
    from shtools.reference import raytrace_visibility
    from shtools.reference.metrics import relative_rmse
    from shtools.reference.scenes import mesh_scene
    from shtools.runtime import FieldBlocker, ShadowRuntime, ShadowSettings
    from shtools.sh import exp as sh_exp

    print(f"\n## Accuracy vs ray tracing of the real mesh; {machine()}\n")
    meshes = {}
    if (DATA / "meshes" / "teapot.obj").exists():
        meshes["teapot (open)"] = load_mesh(DATA / "meshes" / "teapot.obj")
        if not quick:
            meshes["spot (closed)"] = load_mesh(DATA / "meshes" / "spot.obj")
    else:
        meshes["box (closed)"] = trimesh.creation.box(extents=(1.0, 0.6, 0.8))
    probe = DATA / "probes" / "grace.hdr"
    env = project_environment(probe, 4)[0] if probe.exists() else None
    grid = 24 if quick else 64
    n_dirs = 1000 if quick else 4000
    print(f"Ground grid {grid}x{grid} touching the mesh's lowest point, probe "
          f"{probe.name if env is not None else 'procedural sky'}, order 4, cosine window; "
          f"reference: {n_dirs} ray-traced directions per vertex, projected to order 4 "
          "(directions below the tangent plane count as visible).\n")
    print("Split: each column is the relative RMSE of radiance between consecutive stages "
          "(exact OCV at the receiver vs the reference: the hemisphere convention and the map "
          "quadrature; full-resolution float field vs exact OCV: interpolation; adaptive float "
          "vs full: reduction; the 8-bit asset vs adaptive float: quantization; log space vs "
          "the asset's visibility: log/exp round trip + log quantization).\n")
    print("| mesh | **total, log space (default)** | total, visibility (product space) | "
          "convention + quadrature | interpolation | reduction | quantization | log/exp |")
    print("|---|---|---|---|---|---|---|---|")
    for name, mesh in meshes.items():
        params = _params(quick)
        s, _, _ = sampled(name.split()[0], mesh, params)
        sc = mesh_scene(mesh, np.zeros((0, 3)), np.zeros(0), grid=grid, order=4, env_sh=env)
        with ShadowRuntime(ShadowSettings(order=4, processes=1)) as rt:
            g_ref = raytrace_visibility(sc.vertices, sc.normals, [mesh], 4, n_dirs=n_dirs)
            r_ref = _shade_all(rt, g_ref, sc)
            caster = RayCaster(mesh.vertices, mesh.faces)
            dirs, w = direction_map(params.map_size)
            g_exact = sample_ocvs(caster, s.center, s.bounding_radius, sc.vertices, dirs, w, 4)
            full = _float_table(s, list(s.grids), [params.resolution] * len(s.grids))
            reduced = [reduce_shell(g, 0.01, 8) for g in s.grids]
            red = _float_table(s, [r.grid for r in reduced], [r.resolution for r in reduced])
            fld, _ = build_field(s, params, mesh=mesh)
            asset = FieldBlocker(fld)

            def rr(g, ref=None, rt=rt, sc=sc, r_ref=r_ref):
                return relative_rmse(_shade_all(rt, g, sc),
                                     r_ref if ref is None else _shade_all(rt, ref, sc))

            g_full = FieldBlocker(full).world_vectors(sc.vertices)
            g_red = FieldBlocker(red).world_vectors(sc.vertices)
            g_q = asset.world_vectors(sc.vertices)
            g_log = rt.visibility(sc.vertices, sc.normals, [asset])  # log space, the default
            print(f"| {name} | **{rr(g_log):.4f}** | {rr(g_q):.4f} | {rr(g_exact):.4f} | "
                  f"{rr(g_full, g_exact):.4f} | {rr(g_red, g_full):.4f} | "
                  f"{rr(g_q, g_red):.4f} | {rr(g_log, g_q):.4f} |")
            # which interpolation is more accurate: of visibilities or of logs (same grids)
            pts = _between(s, 400)
            g_pts = sample_ocvs(caster, s.center, s.bounding_radius, pts, dirs, w, 4)
            from shtools.fields import l1_error, log_ocvs

            log_tab = _float_table(s, [log_ocvs(r.grid) for r in reduced],
                                   [r.resolution for r in reduced])
            e_vis = l1_error(FieldBlocker(red).world_vectors(pts), g_pts)
            e_log = l1_error(sh_exp(FieldBlocker(log_tab).world_vectors(pts, "log")
                                    .astype(np.float64), "ps*"), g_pts)
            _ACC_NOTES.append(f"{name}: eq.(1) error at 400 random points 1.0-2.0 V_r "
                              f"against the exact OCV (same map), reduced float field: "
                              f"interpolating visibilities mean {e_vis.mean():.4f} / max "
                              f"{e_vis.max():.4f}; exp of interpolated logs mean "
                              f"{e_log.mean():.4f} / max {e_log.max():.4f}")
    for note in _ACC_NOTES:
        print(f"\n* {note}")


_ACC_NOTES: list = []


def _between(s, count):
    rng = np.random.default_rng(0)
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return s.center + d * (s.bounding_radius * rng.uniform(1.0, 2.0, count))[:, None]


# ----------------------------------------------------------------------------- scene
def _pin():
    import trimesh

    # a bowling pin profile (radius, height), revolved: closed, ~0.38 tall
    prof = np.array([[0.0, 0.0], [0.03, 0.0], [0.055, 0.08], [0.06, 0.13], [0.04, 0.21],
                     [0.022, 0.26], [0.028, 0.31], [0.032, 0.35], [0.02, 0.375], [0.0, 0.38]])
    return trimesh.creation.revolve(prof, sections=24)


def part_scene(quick: bool) -> None:
    import trimesh

    from shtools.fields import FieldParameters, sample_field
    from shtools.reference.scenes import ground_grid, sky_light
    from shtools.runtime import FieldBlocker, FieldTable, ShadowRuntime, ShadowSettings

    print(f"\n## Tamura-like scene (bowling: 10 pins, 2 balls, 3 crates); {machine()}\n")
    params = FieldParameters() if not quick else FieldParameters(resolution=32, map_size=32)
    shapes = {"pin": _pin(), "ball": trimesh.creation.icosphere(3, radius=0.11),
              "crate": trimesh.creation.box(extents=(0.3, 0.25, 0.3))}
    tables = {}
    sizes = 0
    for k, mesh in shapes.items():
        t0 = time.perf_counter()
        fld, _ = sample_field(mesh, params)
        tables[k] = FieldTable(fld)
        sizes += fld.stored_bytes()
        print(f"* {k}: R_c {_runs(fld.resolution.tolist())}, {fld.stored_bytes():,} B, sampled "
              f"in {time.perf_counter() - t0:.1f} s")
    side = 100 if quick else 201
    v, nrm = ground_grid(side, (0.0, -1.0), 1.6)  # a 3.2 x 3.2 lane end, y = 0
    print(f"\n{len(v):,} receiver vertices, 15 objects, field data {sizes:,} B "
          "(three shared fields)\n")
    pins = [(x, z) for row in range(4) for x, z in
            [((k - row / 2) * 0.3, -1.8 + row * 0.26) for k in range(row + 1)]]
    rng = np.random.default_rng(0)
    env = sky_light(4)

    def frame(t):
        out = []
        for k, (x, z) in enumerate(pins):
            R = trimesh.transformations.rotation_matrix(0.3 * t + k, [0, 1, 0])
            R[:3, 3] = [x, 0.0, z]
            out.append(FieldBlocker.from_matrix(tables["pin"], R))
        for k in range(2):
            M = trimesh.transformations.rotation_matrix(t + k, [1, 0, 0])
            M[:3, 3] = [-0.4 + 0.8 * k, 0.11, 0.2 - 0.5 * t]
            out.append(FieldBlocker.from_matrix(tables["ball"], M))
        for k in range(3):
            M = trimesh.transformations.rotation_matrix(rng.uniform(0, 6), [0, 1, 0])
            M[:3, 3] = [-1.2 + 1.2 * k, 0.125, -0.3 + 0.2 * k]
            out.append(FieldBlocker.from_matrix(tables["crate"], M))
        return out

    frames = 3 if quick else 6
    print("| combination | accumulation order | processes | frame wall (ms), median | "
          "visibility+exp wall (ms) | shading (ms) | frame CPU of the calling process (ms) | "
          "vs Tamura CPU 1-3 fps (333-1000 ms), wall |")
    print("|---|---|---|---|---|---|---|---|")
    for space, acc, processes in (("log", None, 1), ("log", None, None), ("log", 4, 1),
                                  ("log", 4, None), ("product", None, 1),
                                  ("product", None, None), ("product", 4, 1)):
        if True:
            st = ShadowSettings(order=4, field_space=space, processes=processes, acc_order=acc)
            with ShadowRuntime(st) as rt:
                g = rt.visibility(v, nrm, frame(0.0))  # warm-up: workers, tables
                rt.shade(g, v, nrm, env)
                walls, vis_t, sh_t, cpus = [], [], [], []
                for f in range(frames):
                    blockers = frame(0.1 * (f + 1))
                    c0 = time.process_time()
                    w0 = time.perf_counter()
                    g = rt.visibility(v, nrm, blockers)
                    w1 = time.perf_counter()
                    rt.shade(g, v, nrm, env)
                    w2 = time.perf_counter()
                    walls.append(w2 - w0)
                    cpus.append(time.process_time() - c0)
                    vis_t.append(w1 - w0)
                    sh_t.append(w2 - w1)
                used = rt.last_stats.get("processes", 1)
                acc_used = rt.acc_order
            ms = 1000 * float(np.median(walls))
            print(f"| {space} | {acc_used} | {used} | **{ms:.0f}** | "
                  f"{1000 * np.median(vis_t):.0f} | {1000 * np.median(sh_t):.0f} | "
                  f"{1000 * np.median(cpus):.0f} | {333 / ms:.1f}-{1000 / ms:.1f}x |")
    print(f"\nafter: {machine()}")


PARTS = {"sizes": part_sizes, "speed": part_speed, "accuracy": part_accuracy,
         "scene": part_scene}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--part", default=",".join(PARTS))
    args = parser.parse_args()
    print("# bench_fields" + (" (quick)" if args.quick else ""))
    for part in args.part.split(","):
        PARTS[part.strip()](args.quick)


if __name__ == "__main__":
    main()
