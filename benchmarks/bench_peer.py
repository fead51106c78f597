"""The default bake against the brute-force ray tracer a user would write instead.

The **peer** bakes a frame the obvious way, honestly: one spherical Fibonacci set of
``2N`` world directions shared by every vertex (:func:`fibonacci_directions`); at
each receiver only the ~N directions above its tangent plane are cast
(:meth:`shtools.geometry.raycast.RayCaster.visibility`), at all posed blocker meshes
in one Embree scene built this frame (the bake's per-frame caster,
:func:`shtools.scene.transfer.posed_caster`); the projection is one matrix product,
``g = proj(1) - blocked @ (Y w)`` with ``w = 4 pi / 2N``; and the visibility is
shaded exactly like the bake's (:func:`shtools.scene.shadows.shade_frame`: the same
environment, lights, window and deringing).

Both are scored by the project's ray tracer of the posed real meshes
(:func:`shtools.reference.raytrace_visibility`, 3,200 directions, shaded the same
way) on every ground vertex (receiver-only objects) and on a random subset of the
objects' vertices: the relative RMSE of the radiance on the ground ("shadowed-ground
error") and on the objects, and the ground's **roughness** -- the RMS difference
between a vertex's radiance and the mean of its mesh neighbours', relative to the
RMS radiance -- divided by the reference's (1: as smooth as the truth; ray noise
raises it).  CPU per frame is ``time.process_time`` (every thread of this process)
of one frame, posing included, the smaller of two evaluations after a warm-up: the
peer's at the scored pose; the default's at the scored pose and half a frame after
it, after a first frame half a frame before it (each timed pose new to it, as in a
bake of many frames; "first frame" is that first one, which also traces the still
objects' shadows a bake keeps for all its frames).  The default bake runs in this
process (``processes = 1``) with one BLAS thread.  The last column is the peer's CPU
per frame over the default's, and "equal error" the fewest rays whose ground error is
at most the default's.

Scenes (``../shared/data``, never committed): ``bunny`` (35k vertices) on a 4 x 4
ground under Uffizi, ``dragon+armadillo`` (102k receivers) under Grace, and the
``make demo`` scene at frame 12 (procedural, built in ``build/bench_peer/demo``).
The set-up (sphere fits ``{ fit = N }``, exact self-transfers) goes through the
set-up cache (``docs/cache.md``): only the first run pays it.

``python benchmarks/bench_peer.py [--quick] [--scene NAME] [--rays 32,64,...]``
(quick: the demo scene alone, 32 and 128 rays, a 1,000-vertex object subset).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from shtools.geometry.visibility import GOLDEN_ANGLE

if __package__:  # run by ``python -m benchmarks``
    from benchmarks.bench_fidelity import placement
else:  # run as a script: its folder is sys.path[0]
    from bench_fidelity import placement

REPO = Path(__file__).resolve().parents[1]
#: real meshes and probes (``SHTOOLS_SHARED_DATA`` overrides, as for the tests)
DATA = Path(os.environ.get("SHTOOLS_SHARED_DATA", REPO.parent / "shared" / "data"))
BUILD = REPO / "build" / "bench_peer"
#: Directions of the reference ray tracer.
REFERENCE_DIRECTIONS = 3200
#: Ray counts N of the peer (its direction set holds 2N).
RAYS = (32, 64, 128, 256)
QUICK_RAYS = (32, 128)
#: Object vertices the reference traces (a random subset; every ground vertex is traced).
SUBSET = 4000
DEMO_FRAME = 12


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` unit directions ``(n, 3)`` of the spherical Fibonacci set (equal areas)."""
    k = np.arange(n, dtype=np.float64)
    y = 1.0 - (2.0 * k + 1.0) / n
    r = np.sqrt(np.maximum(0.0, 1.0 - y * y))
    phi = k * GOLDEN_ANGLE
    return np.stack([r * np.cos(phi), y, r * np.sin(phi)], axis=1)


class Peer:
    """The brute-force baker at ``n_rays`` rays per vertex (a set of ``2 n_rays``)."""

    def __init__(self, n_rays: int, order: int):
        from shtools.sh import basis

        self.dirs = fibonacci_directions(2 * n_rays)
        w = 4.0 * math.pi / len(self.dirs)
        self.yw = (basis(self.dirs, order) * w).astype(np.float32)  # (2N, n*n)
        self.one = np.zeros(order * order, dtype=np.float32)
        self.one[0] = math.sqrt(4.0 * math.pi)  # the projection of V = 1

    def visibility(self, state) -> np.ndarray:
        """SH visibility ``(V, n*n)`` of a posed frame (``state`` with blocker meshes)."""
        from shtools.reference.raytrace import RAY_OFFSET
        from shtools.scene.transfer import posed_caster

        if not state.blocker_meshes:
            return np.broadcast_to(self.one, (len(state.vertices), len(self.one))).copy()
        offsets = np.cumsum([0] + [len(v) for v, _ in state.blocker_meshes])
        caster = posed_caster(np.concatenate([v for v, _ in state.blocker_meshes]),
                              np.concatenate([f + offsets[i]
                                              for i, (_, f) in enumerate(state.blocker_meshes)]))
        # below the tangent plane nothing is cast (visible, the reference's convention)
        vis = caster.visibility(state.vertices, self.dirs, normals=state.normals,
                                offset=RAY_OFFSET * caster.diagonal)
        return self.one - (~vis).astype(np.float32) @ self.yw


def _object(name: str, mesh: str, spheres: int, height: float, x: float, z: float,
            yaw: float) -> str:
    path = DATA / "meshes" / mesh
    return (f'[[objects]]\nname = "{name}"\nmesh = "{path}"\nrole = "both"\n'
            f'blocker = {{ fit = {spheres}, method = "kmeans" }}\n'
            + placement(path, height, x, z, yaw))


def _real_scene(name: str, probe: str, ground: tuple[float, int], objects: str) -> Path:
    size, subdivisions = ground
    text = (f'[settings]\norder = 4\nframes = 1\n\n[environment]\nimage = '
            f'"{DATA / "probes" / probe}"\n\n[[objects]]\nname = "ground"\nprimitive = '
            f'{{ type = "plane", size = [{size}, {size}], subdivisions = {subdivisions} }}\n'
            f'role = "receiver"\n\n' + objects)
    path = BUILD / f"{name.replace('+', '_')}.toml"
    path.write_text(text)
    return path


def scenes(quick: bool, only=None) -> dict[str, tuple[Path, int]]:
    """name -> (scene file, frame)."""
    BUILD.mkdir(parents=True, exist_ok=True)
    out = {}

    def wanted(name):
        return (not only or name in only) and (not quick or name == "demo")

    if wanted("demo"):
        demo = BUILD / "demo"
        if not (demo / "scene.toml").exists():
            from shtools.demo import run_demo

            run_demo(demo, quiet=True)
        out["demo"] = (demo / "scene.toml", DEMO_FRAME)
    if wanted("bunny") and DATA.is_dir():
        out["bunny"] = (_real_scene("bunny", "uffizi.hdr", (4.0, 64), _object(
            "bunny", "stanford-bunny.obj", 48, 1.0, 0.0, 0.0, 0.0)), 0)
    if wanted("dragon+armadillo") and DATA.is_dir():
        out["dragon+armadillo"] = (_real_scene(
            "dragon+armadillo", "grace.hdr", (5.0, 96),
            _object("dragon", "dragon.obj", 64, 1.1, -0.9, 0.0, 20.0)
            + _object("armadillo", "armadillo.obj", 64, 1.4, 0.9, 0.2, -30.0)), 0)
    return out


def _timed(fn):
    """(result, CPU seconds of one call)."""
    start = time.process_time()
    result = fn()
    return result, time.process_time() - start


def _cpu(fn, repeats: int = 2):
    """(result, smallest CPU seconds of ``repeats`` calls after one warm-up call)."""
    result = fn()
    best = math.inf
    for _ in range(repeats):
        result, seconds = _timed(fn)
        best = min(best, seconds)
    return result, best


def _roughness(radiance: np.ndarray, neighbours) -> float:
    """RMS of (radiance - mean of its neighbours'), over the RMS radiance."""
    rows, cols, counts = neighbours
    mean = np.zeros_like(radiance)
    np.add.at(mean, rows, radiance[cols])
    mean /= counts[:, None]
    return float(np.sqrt(np.mean((radiance - mean) ** 2) / np.mean(radiance ** 2)))


def _ground_neighbours(prepared) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rows of the receiver-only vertices and their mesh edges (local to those rows)."""
    rows, edges, start, base = [], [], 0, 0
    for o in prepared.receivers:
        n = len(o.vertices)
        if not o.spec.blocks:
            f = o.faces
            e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
            e = np.unique(np.sort(e, axis=1), axis=0) + base
            edges.append(e)
            rows.append(np.arange(start, start + n))
            base += n
        start += n
    e = np.concatenate(edges)
    a = np.concatenate([e[:, 0], e[:, 1]])
    b = np.concatenate([e[:, 1], e[:, 0]])
    counts = np.bincount(a, minlength=base).astype(np.float64)
    return np.concatenate(rows), a, b, np.maximum(counts, 1.0)


def evaluate(name: str, path: Path, frame: int, rays, subset: int) -> list[dict]:
    from shtools.reference import raytrace_visibility, relative_rmse
    from shtools.scene.bake import FrameBaker, bake_clusters
    from shtools.scene.pose import pose_frame
    from shtools.scene.prepare import prepare_scene
    from shtools.scene.scene import load_scene
    from shtools.scene.shadows import shade_frame

    scene = load_scene(path)
    start = time.perf_counter()
    prepared = prepare_scene(scene)
    setup = time.perf_counter() - start
    t = float(scene.frame_times(range(frame, frame + 1))[0])
    order = scene.settings.order
    baker = FrameBaker(prepared, "default", bake_clusters(prepared, "default", 0.0),
                       processes=1)
    rows_g, a, b, counts = _ground_neighbours(prepared)
    neighbours = (a, b, counts)
    # the reference: every ground vertex, a random subset of the objects' vertices
    state = pose_frame(prepared, t, with_meshes=True, trace=False)
    is_ground = np.zeros(len(state.vertices), dtype=bool)
    is_ground[rows_g] = True
    rng = np.random.default_rng(0)
    objects = np.flatnonzero(~is_ground)
    rows_o = np.sort(rng.choice(objects, min(subset, len(objects)), replace=False))
    ref_rows = np.concatenate([rows_g, rows_o])
    import trimesh

    meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
    sub = dataclasses.replace(state, vertices=state.vertices[ref_rows],
                              normals=state.normals[ref_rows])
    ref_vis = raytrace_visibility(sub.vertices, sub.normals, meshes, order,
                                  n_dirs=REFERENCE_DIRECTIONS)
    with FrameBaker(prepared, "raytrace", processes=1) as ref_baker:
        ref = shade_frame(ref_baker.run, sub, ref_vis)
    ref_g, ref_o = ref[:len(rows_g)], ref[len(rows_g):]
    rough_ref = _roughness(ref_g, neighbours)

    def score(radiance, cpu, label, n_rays=None):
        return {"scene": name, "receivers": len(state.vertices), "method": label,
                "rays": n_rays, "cpu_ms": 1e3 * cpu,
                "ground_error": relative_rmse(radiance[rows_g], ref_g),
                "object_error": relative_rmse(radiance[rows_o], ref_o) if len(rows_o) else
                float("nan"),
                "smoothness": _roughness(radiance[rows_g], neighbours) / rough_ref,
                "setup_s": setup}

    out = []
    with baker:
        # the default's first frame pays what a bake computes once (the traces of still
        # objects, kept for the frames after it); each timed frame is then a pose it has
        # not seen: a repeated pose would find a moving object's trace kept and time
        # nothing.  The peer keeps nothing between frames.
        dt = 0.5 / scene.settings.fps
        _, first = _timed(lambda: baker.frame(frame, t - dt))
        result, cpu = _timed(lambda: baker.frame(frame, t))
        cpu = min(cpu, _timed(lambda: baker.frame(frame, t + dt))[1])
        out.append(score(np.asarray(result.radiance, dtype=np.float64), cpu, "default"))
        out[-1]["first_ms"] = 1e3 * first
        for n_rays in rays:
            peer = Peer(n_rays, order)

            def peer_frame(peer=peer):
                s = pose_frame(prepared, t, with_meshes=True, trace=False)
                return shade_frame(baker.run, s, peer.visibility(s))

            radiance, cpu = _cpu(peer_frame)
            out.append(score(np.asarray(radiance, dtype=np.float64), cpu, "peer", n_rays))
    base = out[0]
    for row in out:
        row["cpu_vs_default"] = row["cpu_ms"] / base["cpu_ms"]
    return out


def _markdown(rows: list[dict]) -> str:
    lines = ["| scene (receivers) | method | rays | CPU / frame | first frame | ground error "
             "| object error | smoothness | CPU vs default |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        first = f"{r['first_ms']:.0f} ms" if "first_ms" in r else "-"
        lines.append(f"| {r['scene']} ({r['receivers']:,}) | {r['method']} | "
                     f"{r['rays'] or '-'} | {r['cpu_ms']:.0f} ms | {first} | "
                     f"{100 * r['ground_error']:.2f} % | {100 * r['object_error']:.2f} % | "
                     f"{r['smoothness']:.2f} | {r['cpu_vs_default']:.2f}x |")
    return "\n".join(lines)


def equal_error(rows: list[dict]) -> str:
    """Per scene: the fewest peer rays at or below the default's ground error."""
    out = []
    for name in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == name]
        default = mine[0]
        ok = [r for r in mine[1:] if r["ground_error"] <= default["ground_error"]]
        if ok:
            r = min(ok, key=lambda r: r["rays"])
            out.append(f"{name}: peer at equal ground error = {r['rays']} rays, "
                       f"{r['cpu_ms']:.0f} ms = {r['cpu_vs_default']:.1f}x the default's "
                       f"{default['cpu_ms']:.0f} ms (set-up {default['setup_s']:.1f} s)")
        else:
            worst = mine[-1]
            out.append(f"{name}: no peer ray count reaches the default's ground error "
                       f"({100 * default['ground_error']:.2f} %); at {worst['rays']} rays "
                       f"{100 * worst['ground_error']:.2f} %, {worst['cpu_vs_default']:.1f}x")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="the demo scene only, 32 and 128 rays, a small object subset")
    parser.add_argument("--scene", action="append", choices=("demo", "bunny",
                                                             "dragon+armadillo"))
    parser.add_argument("--rays", default=None, help="comma-separated ray counts N")
    args = parser.parse_args(argv)
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from threadpoolctl import threadpool_limits

    rays = tuple(int(x) for x in args.rays.split(",")) if args.rays else (
        QUICK_RAYS if args.quick else RAYS)
    subset = 1000 if args.quick else SUBSET
    rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        for name, (path, frame) in scenes(args.quick, args.scene).items():
            print(f"[bench_peer] {name}", file=sys.stderr, flush=True)
            rows.extend(evaluate(name, path, frame, rays, subset))
    print(_markdown(rows))
    print()
    print(equal_error(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
