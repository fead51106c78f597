"""Runtime benchmarks: battle-scale frame time, accuracy/time of the
accumulation order, log space vs product space, peak memory, the cluster blend's
seams against its cost.

``python -m benchmarks -k runtime`` or ``python benchmarks/bench_runtime.py [--quick]``.
With ``--baseline DIR`` (or ``SHTOOLS_BASELINE=DIR``; DIR a checkout of an earlier
commit, e.g. ``git worktree add /tmp/base 98bedba``) it first times the battle frame
side by side with that checkout and prints the ratio per stage.

Scenes are procedural (capsule-built characters and columns over a ground grid,
sphere sets bounding the capsules exactly), so the figures do not depend on
the data directory.  The columns' spheres and the ground and column receivers are
flagged static (their pairs' log sum is kept between frames), and each character's
receivers rigid with its own spheres (that log sum is kept in the character's frame
and rotated), where the runtime imported has the flags.  Timings are process CPU
time (``time.process_time``), minima over the frames of one run: the machine is
shared by several jobs, and CPU time is what a frame costs on one otherwise idle core.  Run with
``OPENBLAS_NUM_THREADS=1``: on a loaded 2-core machine OpenBLAS threads spin
and multiply the cost of small matrix products many times over.
"""

from __future__ import annotations

import argparse
import inspect
import json
import math
import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # runnable as a script too

from shtools.geometry.sphere_tree import build_tree
from shtools.reference import (
    product_space_visibility,
    relative_rmse,
    sphere_union_visibility,
)
from shtools.reference.scenes import capsule_scene, capsule_spheres, ground_grid, sky_light
from shtools.runtime import (
    ShadowRuntime,
    ShadowSettings,
    SphereBlocker,
    SphereLight,
)
from shtools.runtime.parallel import available_cores

#: Whether the runtime imported keeps static pairs (a baseline checkout may not):
#: the battle scene flags its columns and ground static where it can.
STATIC_FLAGS = "static" in getattr(SphereBlocker, "__dataclass_fields__", {})
#: Whether the runtime imported keeps rigid objects' own pairs in object space: the
#: battle scene flags each character's receivers as moving with its spheres.
RIGID_FLAGS = "rigid_receivers" in inspect.signature(ShadowRuntime.visibility).parameters

#: The runtime's targets: a battle frame, its memory, log space against product space.
FRAME_TARGET_S = 0.150
MEMORY_TARGET_BYTES = 1 << 30
SPEEDUP_TARGETS = {4: 10.0, 6: 20.0}


# -- battle-scale scene ------------------------------------------------------------
def _capsule_mesh(p0, p1, radius, count):
    import trimesh

    axis = np.asarray(p1, float) - np.asarray(p0, float)
    length = float(np.linalg.norm(axis))
    m = trimesh.creation.capsule(height=length, radius=radius, count=[count, count])
    m.apply_transform(trimesh.geometry.align_vectors([0, 0, 1], axis / length))
    m.apply_translation(0.5 * (np.asarray(p0, float) + np.asarray(p1, float)))
    return m


# (p0, p1, radius) of a character's parts at unit scale, standing at the origin
_BODY = [
    ((0.0, 0.95, 0.0), (0.0, 1.55, 0.0), 0.28),    # torso
    ((0.0, 1.85, 0.0), (0.0, 1.9, 0.0), 0.2),      # head
    ((-0.38, 1.5, 0.0), (-0.7, 0.95, 0.15), 0.09),  # arms
    ((0.38, 1.5, 0.0), (0.75, 1.0, 0.2), 0.09),
    ((-0.15, 0.9, 0.0), (-0.18, 0.12, 0.05), 0.12),  # legs
    ((0.15, 0.9, 0.0), (0.2, 0.12, -0.05), 0.12),
    ((0.75, 1.0, 0.2), (1.2, 1.6, 0.5), 0.1),      # club
]


class BattleScene:
    """Two capsule characters and four columns over a ground grid.

    Parameters
    ----------
    grid : int
        Ground receivers per side.
    mesh_count : int
        Capsule tessellation (vertices per part ~ count^2).
    """

    def __init__(self, grid: int = 200, mesh_count: int = 38):
        import trimesh

        self.parts = []  # (mesh, centers, radii, object index)
        self.objects = []  # (scale, base position) of moving characters
        for k, (scale, base) in enumerate([(1.9, (-1.3, 0.0, 0.3)), (1.4, (1.3, 0.0, -0.4))]):
            meshes, cs, rs = [], [], []
            for p0, p1, r in _BODY:
                p0s = np.asarray(p0) * scale
                p1s = np.asarray(p1) * scale
                meshes.append(_capsule_mesh(p0s, p1s, r * scale, mesh_count))
                n = max(2, math.ceil(np.linalg.norm(p1s - p0s) / (0.5 * r * scale)) + 1)
                c, rr = capsule_spheres(p0s, p1s, r * scale, n)
                cs.append(c)
                rs.append(rr)
            mesh = trimesh.util.concatenate(meshes)
            self.parts.append((mesh, np.vstack(cs), np.concatenate(rs), k))
            self.objects.append(np.asarray(base, float))
        # four static columns (static receivers and blockers)
        col_meshes, ccs, crs = [], [], []
        for x, z in [(-2.6, -2.3), (2.5, -2.2), (-2.4, 2.5), (2.7, 2.3)]:
            col_meshes.append(_capsule_mesh((x, 0.0, z), (x, 2.6, z), 0.3, mesh_count))
            c, rr = capsule_spheres((x, 0.0, z), (x, 2.6, z), 0.3, 18)
            ccs.append(c)
            crs.append(rr)
        self.columns = (trimesh.util.concatenate(col_meshes), np.vstack(ccs), np.concatenate(crs))
        self.ground_v, self.ground_n = ground_grid(grid, (0.0, 0.0), 4.0)
        self.trees = [build_tree(c, r) for _, c, r, _ in self.parts]
        self.column_tree = build_tree(self.columns[1], self.columns[2])
        self.env = sky_light(4)
        self.lights = [SphereLight((2.0, 3.5, 2.0), 0.4, (6.0, 5.0, 3.5)),
                       SphereLight((-2.5, 2.5, -1.5), 0.3, (2.0, 3.0, 6.0))]

    @property
    def n_spheres(self) -> int:
        return sum(c.shape[0] for _, c, _, _ in self.parts) + self.columns[1].shape[0]

    def frame(self, t: float):
        """Receivers (V,3), normals (V,3), group ids (V,) and blockers at time ``t``."""
        verts, norms, groups, blockers = [self.ground_v], [self.ground_n], [
            np.zeros(len(self.ground_v), int)], []
        for (mesh, c, r, k), base, tree in zip(self.parts, self.objects, self.trees, strict=True):
            ang = 0.6 * math.sin(1.3 * t + k)
            rot = np.array([[math.cos(ang), 0, math.sin(ang)], [0, 1, 0],
                            [-math.sin(ang), 0, math.cos(ang)]])
            offset = base + np.array([0.4 * math.sin(t + 2 * k), 0.0, 0.3 * math.cos(0.7 * t)])
            verts.append(np.asarray(mesh.vertices) @ rot.T + offset)
            norms.append(np.asarray(mesh.vertex_normals) @ rot.T)
            groups.append(np.full(len(mesh.vertices), k + 1))
            blockers.append(SphereBlocker(c @ rot.T + offset, r, tree=(tree.parent, tree.leaf)))
        cm, cc, cr = self.columns
        verts.append(np.asarray(cm.vertices))
        norms.append(np.asarray(cm.vertex_normals))
        groups.append(np.full(len(cm.vertices), 9))
        blockers.append(SphereBlocker(cc, cr, tree=(self.column_tree.parent,
                                                   self.column_tree.leaf),
                                      **({"static": True} if STATIC_FLAGS else {})))
        return np.vstack(verts), np.vstack(norms), np.concatenate(groups), blockers

    @staticmethod
    def static_kwargs(groups) -> dict:
        """``visibility`` keywords flagging the ground and the columns static and each
        character's receivers rigid with its spheres (blocker ``k`` is group ``k + 1``)."""
        kw = {"static_receivers": np.isin(groups, (0, 9))} if STATIC_FLAGS else {}
        if RIGID_FLAGS:
            kw["rigid_receivers"] = np.where(np.isin(groups, (1, 2)), groups - 1, -1)
        return kw


#: untimed frames before timing a configuration (steady state)
WARMUP_FRAMES = 2
#: untimed frames at the start of the process: its first frames run up to 1.5x
#: slower because glibc maps large temporaries afresh (page faults) until its
#: dynamic mmap threshold has grown past their size; measured here, the first
#: configuration of a process took 172 ms and the same one later 117 ms
#: (``MALLOC_MMAP_THRESHOLD_=268435456`` removes the difference)
PROCESS_WARMUP_FRAMES = 6


class StageClock:
    """CPU seconds of a runtime's accumulation and exp calls in this process, per frame.

    Wraps the runtime's own ``_accumulate`` and ``exponentiate`` (a baseline checkout
    has both), so frames cut into parts report these stages too.
    """

    def __init__(self, rt):
        self.seconds = {"accumulate": 0.0, "exp": 0.0}
        for name, stage in (("_accumulate", "accumulate"), ("exponentiate", "exp")):
            setattr(rt, name, self._timed(getattr(rt, name), stage))

    def _timed(self, fn, stage):
        def timed(*args, **kwargs):
            t0 = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[stage] += time.process_time() - t0
        return timed

    def take(self) -> dict:
        out, self.seconds = self.seconds, {"accumulate": 0.0, "exp": 0.0}
        return out


def battle_frames(scene: BattleScene, settings: ShadowSettings, frames: int):
    """Warm up, then run ``frames`` frames; returns (per-stage minima, stats of the last frame)."""
    rt = ShadowRuntime(settings)
    clock = StageClock(rt)
    v, n, groups, _ = scene.frame(0.0)
    clusters = rt.clusters(v, groups)
    static = scene.static_kwargs(groups)
    best: dict[str, float] = {}
    stats = {}
    # steady state, as in a bake of many frames: the first frames of a fresh runtime
    # pay one-time costs (scratch buffers, lazily built operators, cold caches)
    for i in range(WARMUP_FRAMES):
        v, n, _, blockers = scene.frame(0.1 * i)
        rt.shade(rt.visibility(v, n, blockers, clusters, **static), v, n, scene.env,
                 scene.lights)
        clock.take()
    for i in range(frames):
        v, n, _, blockers = scene.frame(0.1 * i)
        w0 = time.perf_counter()
        t0 = time.process_time()
        g = rt.visibility(v, n, blockers, clusters, **static)
        t1 = time.process_time()
        rt.shade(g, v, n, scene.env, scene.lights)
        t2 = time.process_time()
        wall = time.perf_counter() - w0
        st = rt.last_stats
        # with worker processes, the accumulation and exp of this process only
        sec = dict(st["seconds"], **clock.take(), shade=t2 - t1, frame=t2 - t0, wall=wall)
        for k, val in sec.items():
            best[k] = min(best.get(k, math.inf), val)
        stats = st
    return best, stats, rt


def peak_memory(scene: BattleScene, settings: ShadowSettings) -> int:
    """tracemalloc peak (bytes) of one battle-scale frame (clusters excluded)."""
    rt = ShadowRuntime(settings)
    v, n, groups, blockers = scene.frame(0.3)
    clusters = rt.clusters(v, groups)
    tracemalloc.start()
    tracemalloc.reset_peak()
    g = rt.visibility(v, n, blockers, clusters, **scene.static_kwargs(groups))
    rt.shade(g, v, n, scene.env, scene.lights)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak


# -- tables ------------------------------------------------------------------------
def table_battle(quick: bool) -> list[dict]:
    scene = BattleScene(grid=90 if quick else 200, mesh_count=14 if quick else 38)
    v, _, _, _ = scene.frame(0.0)
    frames = 2 if quick else 5
    rows = []
    cores = available_cores()
    _, _, rt = battle_frames(scene, ShadowSettings(processes=1), PROCESS_WARMUP_FRAMES)
    rt.close()
    # (order, acc order, exp, threads, processes); processes None = the default (one
    # per core); per-stage CPU times are those of the calling process
    configs = [(4, 4, "auto", 1, 1), (4, 5, "auto", 1, 1), (4, 6, "hyb", 1, 1),
               (4, 6, "auto", 1, 1), (4, 6, "auto", 2, 1), (4, 4, "auto", 1, None),
               (4, 6, "auto", 1, None)]
    if quick:
        configs = configs[3:4] + configs[-1:]
    for order, acc, method, threads, processes in configs:
        s = ShadowSettings(order=order, acc_order=acc, exp_method=method, threads=threads,
                           processes=processes)
        best, st, rt = battle_frames(scene, s, frames)
        rt.close()
        rows.append({
            "order": order, "acc_order": acc, "exp": rt.exp_method,
            "threads": threads, "processes": st.get("processes", 1),
            "vertices": len(v), "leaf spheres": scene.n_spheres,
            "clusters": st["clusters"], "spheres/vertex": st["spheres_per_vertex"],
            "cuts ms": 1e3 * best["cuts"],
            # this process's share (StageClock) where worker processes take parts
            "accumulate ms": 1e3 * best["accumulate"],
            "exp ms": 1e3 * best["exp"],
            "shade ms": 1e3 * best["shade"],
            "frame CPU ms": 1e3 * best["frame"],
            "frame wall ms": 1e3 * best["wall"],
            "Mpairs/s (wall)": st["pairs"] / best["wall"] / 1e6,
            # the kernel skips spheres behind every receiver of a 32-vertex tile
            "evaluated pairs %": 100.0 * st.get("pairs_evaluated", st["pairs"])
            / max(1, st["pairs"]),
        })
    mem = peak_memory(scene, ShadowSettings(processes=1))
    return rows, mem, len(v), cores


def table_accuracy(quick: bool) -> list[dict]:
    """Accuracy vs accumulation order on the capsule scene (errors vs sphere-union rays)."""
    sc = capsule_scene(grid=24 if quick else 48)
    gs = sphere_union_visibility(sc.vertices, sc.normals, sc.centers, sc.radii, 4)
    rows = []
    base = None
    for acc in ([4, 6] if quick else [4, 5, 6, 8]):
        for method in ("hyb", "ps*"):
            rt = ShadowRuntime(ShadowSettings(order=4, acc_order=acc, exp_method=method,
                                              processes=1, vertices_per_cluster=100))
            ref = rt.shade(gs, sc.vertices, sc.normals, sc.env_sh)
            blk = [SphereBlocker(sc.centers, sc.radii)]
            rt.visibility(sc.vertices, sc.normals, blk)
            best = math.inf
            for _ in range(3):
                t0 = time.process_time()
                g = rt.visibility(sc.vertices, sc.normals, blk)
                best = min(best, time.process_time() - t0)
            rad = rt.shade(g, sc.vertices, sc.normals, sc.env_sh)
            err_vis = np.median(np.linalg.norm(g - gs, axis=1) / np.linalg.norm(gs, axis=1))
            if base is None:
                base = best
            rows.append({"acc_order": acc, "exp": method,
                         "radiance rel. RMSE": relative_rmse(rad, ref),
                         "visibility median rel. L2": float(err_vis),
                         "time (x acc 4)": best / base})
    return rows


def table_log_vs_product(quick: bool) -> list[dict]:
    """60 spheres, no hierarchy: log-space runtime vs product-space accumulation."""
    # registers the "unrolled" product kernel; imported here, not at the top, so the
    # side-by-side frame child also runs against a baseline checkout's registry
    import unrolled_kernel  # noqa: F401
    rng = np.random.default_rng(0)
    n_spheres = 60
    centers = np.column_stack([rng.uniform(-2, 2, n_spheres), rng.uniform(0.3, 2.0, n_spheres),
                               rng.uniform(-2, 2, n_spheres)])
    radii = rng.uniform(0.08, 0.3, n_spheres)
    grid = 24 if quick else 64
    v, nrm = ground_grid(grid, (0.0, 0.0), 3.0)
    rows = []
    for order in (4, 6):
        # one process, one thread: the product-space reference runs so too
        s = ShadowSettings(order=order, acc_order=order, hierarchy=False, threads=1,
                           processes=1)
        rt = ShadowRuntime(s)
        blk = [SphereBlocker(centers, radii)]
        rt.visibility(v, nrm, blk)
        t_log = math.inf
        for _ in range(3):
            t0 = time.process_time()
            g_log = rt.visibility(v, nrm, blk)
            t_log = min(t_log, time.process_time() - t0)
        # the product with the quadrature (CP) factors of the triple tensor, our
        # fastest, and with the sparse unrolled tensor, as product-space methods
        # evaluate it classically (Snyder 2006 code generation); warm-up first
        t_prod = {}
        for kernel in ("cp", "unrolled"):
            product_space_visibility(v[:4], nrm[:4], (centers, radii), order,
                                     dtype=np.float32, kernel=kernel)
            t_prod[kernel] = math.inf
            for _ in range(2):
                t0 = time.process_time()
                g_prod = product_space_visibility(v, nrm, (centers, radii), order,
                                                  dtype=np.float32, kernel=kernel)
                t_prod[kernel] = min(t_prod[kernel], time.process_time() - t0)
        rows.append({"order": order, "vertices": len(v), "spheres": n_spheres,
                     "exp": rt.exp_method, "log ms": 1e3 * t_log,
                     "product (CP) ms": 1e3 * t_prod["cp"],
                     "speed-up vs CP": t_prod["cp"] / t_log,
                     "product (sparse Γ) ms": 1e3 * t_prod["unrolled"],
                     "speed-up vs sparse Γ": t_prod["unrolled"] / t_log,
                     "target": SPEEDUP_TARGETS[order],
                     "log vs product rel. L2": float(np.linalg.norm(g_log - g_prod)
                                                     / np.linalg.norm(g_prod))})
    return rows


#: ``cluster_blend`` bands the seam table measures (0: the default, no blend).
BLEND_BANDS = (0.0, 0.25, 0.5, 1.0)


def table_cluster_blend(quick: bool) -> list[dict]:
    """The battle ground's seams and cost with the receivers blended over clusters.

    The ground's radiance under the sky, against the flat sum of every leaf at every
    receiver (``hierarchy = False``, which has no clusters and so no seam): the
    smoothness ratio (:func:`shtools.reference.look.smoothness_ratio`, bench_look's
    mesh-graph Laplacian of the luminance) and the relative RMSE, and the
    visibility's CPU (fastest of 3 frames) and pairs.
    """
    from shtools.reference.evaluation import grid_faces
    from shtools.reference.look import smoothness_ratio

    grid = 90 if quick else 200
    scene = BattleScene(grid=grid, mesh_count=14)
    v, n, groups, blockers = scene.frame(0.3)
    faces = grid_faces(grid)

    def ground(**kw):
        with ShadowRuntime(ShadowSettings(order=4, **kw)) as rt:
            clusters = rt.clusters(v, groups)
            cpu = math.inf
            for _ in range(3):
                t0 = time.process_time()
                g = rt.visibility(v, n, blockers, clusters)
                cpu = min(cpu, time.process_time() - t0)
            return rt.shade(g, v, n, scene.env, [])[:grid * grid], cpu, rt.last_stats["pairs"]

    flat, flat_cpu, flat_pairs = ground(hierarchy=False)
    rows = [{"cluster_blend": "flat sum (no hierarchy)", "smoothness vs flat": 1.0,
             "error vs flat %": 0.0, "visibility CPU ms": 1e3 * flat_cpu,
             "pairs": flat_pairs, "CPU vs no blend": math.nan}]
    base_cpu = None
    for band in BLEND_BANDS:
        radiance, cpu, pairs = ground(cluster_blend=band)
        base_cpu = cpu if base_cpu is None else base_cpu
        rows.append({"cluster_blend": f"{band:g}",
                     "smoothness vs flat": smoothness_ratio(radiance, flat, faces),
                     "error vs flat %": 100 * relative_rmse(radiance, flat),
                     "visibility CPU ms": 1e3 * cpu, "pairs": pairs,
                     "CPU vs no blend": cpu / base_cpu})
    rows[0]["CPU vs no blend"] = flat_cpu / base_cpu
    return rows


# -- side by side with a baseline checkout ------------------------------------------
#: the battle frame the side-by-side comparison times: order 4, accumulation order 6,
#: the default exp, one thread, one process
BATTLE_FRAME = {"order": 4, "acc_order": 6, "exp_method": "auto", "threads": 1,
                "processes": 1}
#: receivers (a fixed random subset) scored against ray tracing in the comparison
TRACED_RECEIVERS = 1500


def frame_child(quick: bool, frames: int, save: str | None) -> int:
    """Time the battle frame with whatever ``shtools`` this process imports (the
    comparison runs it once with the working tree and once with ``PYTHONPATH`` at
    a baseline checkout); prints per-stage minima as JSON, saves one frame's
    visibility to ``save``."""
    import shtools

    scene = BattleScene(grid=90 if quick else 200, mesh_count=14 if quick else 38)
    best, _, rt = battle_frames(scene, ShadowSettings(**BATTLE_FRAME),
                                PROCESS_WARMUP_FRAMES + frames)
    if save:
        v, n, groups, blockers = scene.frame(0.35)
        g = rt.visibility(v, n, blockers, rt.clusters(scene.frame(0.0)[0], groups),
                          **scene.static_kwargs(groups))
        np.save(save, g)
    rt.close()
    print(json.dumps({"module": shtools.__file__, **{k: float(x) for k, x in best.items()}}))
    return 0


def _run_child(baseline: str | None, quick: bool, frames: int, save: str) -> dict:
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    if baseline is not None:
        env["PYTHONPATH"] = os.pathsep.join(
            [baseline, *filter(None, [os.environ.get("PYTHONPATH")])])
    args = [sys.executable, str(Path(__file__).resolve()), "--frame-child",
            "--frames", str(frames), "--save", save] + (["--quick"] if quick else [])
    out = subprocess.run(args, env=env, check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def table_versus(baseline: str, quick: bool, rounds: int) -> tuple[list[dict], dict]:
    """The battle frame timed in child processes, this tree and ``baseline``
    alternating (``rounds`` each, minima kept), and their visibilities compared with
    each other and with sphere-union ray tracing."""
    best = {"this tree": {}, "baseline": {}}
    with tempfile.TemporaryDirectory() as tmp:
        paths = {k: os.path.join(tmp, f"{k.replace(' ', '_')}.npy") for k in best}
        for _ in range(rounds):
            for name, root in (("this tree", None), ("baseline", baseline)):
                res = _run_child(root, quick, 2 if quick else 4, paths[name])
                for k, x in res.items():
                    if k != "module":
                        best[name][k] = min(best[name].get(k, math.inf), x)
        g_new, g_old = np.load(paths["this tree"]), np.load(paths["baseline"])
    keys = [k for k in ("cuts", "accumulate", "exp", "shade", "frame")
            if k in best["this tree"] and k in best["baseline"]]
    rows = [{"stage": k, "baseline ms": 1e3 * best["baseline"][k],
             "this tree ms": 1e3 * best["this tree"][k],
             "ratio (baseline / this)": best["baseline"][k] / best["this tree"][k]}
            for k in keys]
    # accuracy: the same frame's visibility, new vs old, and both vs ray tracing
    scene = BattleScene(grid=90 if quick else 200, mesh_count=14 if quick else 38)
    v, n, _, blockers = scene.frame(0.35)
    pick = np.sort(np.random.default_rng(0).choice(len(v), min(len(v), TRACED_RECEIVERS),
                                                   replace=False))
    centers = np.vstack([b.centers for b in blockers])
    radii = np.concatenate([b.radii for b in blockers])
    ref = sphere_union_visibility(v[pick], n[pick], centers, radii, 4)

    def median_err(g):
        return float(np.median(np.linalg.norm(g[pick] - ref, axis=1)
                               / np.linalg.norm(ref, axis=1)))

    acc = {"max |g_this - g_baseline|": float(np.abs(g_new - g_old).max()),
           "max |g_baseline|": float(np.abs(g_old).max()),
           "median rel. L2 vs rays, baseline": median_err(g_old),
           "median rel. L2 vs rays, this tree": median_err(g_new)}
    return rows, acc


def _markdown(rows: list[dict]) -> str:
    keys = list(rows[0])
    out = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        cells = [f"{r[k]:.4g}" if isinstance(r[k], float) else str(r[k]) for k in keys]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small scenes, few frames")
    parser.add_argument("--baseline", metavar="DIR", default=os.environ.get("SHTOOLS_BASELINE"),
                        help="a checkout of the baseline commit: time the battle frame "
                             "side by side with it (child processes, PYTHONPATH=DIR)")
    parser.add_argument("--rounds", type=int, default=2,
                        help="alternating child runs per side with --baseline")
    parser.add_argument("--versus-only", action="store_true",
                        help="with --baseline: only the side-by-side table")
    parser.add_argument("--frame-child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--frames", type=int, default=4, help=argparse.SUPPRESS)
    parser.add_argument("--save", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.frame_child:
        return frame_child(args.quick, args.frames, args.save)
    if args.baseline:
        rows, acc = table_versus(args.baseline, args.quick, args.rounds)
        print(f"\n### Runtime: battle frame side by side with {args.baseline} (CPU of one "
              "process, one BLAS thread, order 4, acc 6; minima over frames and "
              f"{args.rounds} alternating runs each)\n")
        print(_markdown(rows))
        print("\nSame frame, this tree vs baseline and vs sphere-union ray tracing "
              f"({TRACED_RECEIVERS} receivers): "
              + ", ".join(f"{k} = {x:.3g}" for k, x in acc.items()))
        if args.versus_only:
            return 0
    rows, mem, n_v, cores = table_battle(args.quick)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"\n### Runtime: battle-scale frame ({n_v} receivers; target <= "
          f"{1e3 * FRAME_TARGET_S:.0f} ms wall at full scale and default settings; CPU = "
          f"time of the calling process, wall = elapsed; load average {load:.1f}, "
          f"{cores} cores available)\n")
    print(_markdown(rows))
    print(f"\nPeak memory of one frame in one process (tracemalloc): {mem / 2**20:.1f} MiB "
          f"(target <= {MEMORY_TARGET_BYTES / 2**20:.0f} MiB)")
    print("\n### Runtime: accuracy vs accumulation order (capsule scene, n = 4, radiance "
          "vs sphere-union ray tracing)\n")
    print(_markdown(table_accuracy(args.quick)))
    print("\n### Runtime: log space vs product space (60 spheres, no hierarchy)\n")
    print(_markdown(table_log_vs_product(args.quick)))
    print("\n### Runtime: cluster blend, the battle ground's seams against its cost "
          "(order 4, default settings but `cluster_blend`; one process)\n")
    print(_markdown(table_cluster_blend(args.quick)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
