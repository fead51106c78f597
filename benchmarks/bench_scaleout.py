"""Scale-out benchmark: the 65k-vertex battle scene baked with frames as tasks, and one
frame split into part tasks.

    python benchmarks/bench_scaleout.py [--quick] [--frames N] [--only many|single]

Part 1, many frames: the same bake (``--frames``, default 96 of the
48-200 the issue allows) in this process (``--workers 1``: frames one after the
other, one process per frame), on the default forked local workers, on a Dask
``LocalCluster`` of 1 and 2 workers, and on a simulated larger cluster (8 Dask
workers on this machine's cores; BLAS pinned to one thread) that must run at
the speed of the cores actually there, not slower.  Rows are measured side by
side in one run and every asset is compared byte for byte with the in-process
one.

Columns: ``wall s`` is the frame loop (scene preparation, the same for all
rows, is reported once; the cluster's start-up and the per-worker set-up --
shipping the prepared scene and building each worker's runtime -- are in
their own columns, ``start s`` and ``set-up s``); ``speed-up`` over the
in-process row and its fraction of the ideal ``min(workers, cores)``;
``overhead``, the busy worker time per frame beyond the in-process frame
(``wall x min(workers, cores) / frames``), as a fraction of a frame.

Wall clocks need an idle machine (on a busy one, a row with more processes also
gets a bigger share of the cores from the other users' processes, so its
speed-up can even exceed the ideal).  So that a busy machine still says something,
CPU is counted too, per process, between the first and the last frame (set-up
excluded): ``cpu ms/f`` is the CPU of every process of the row (the caller --
writer, Dask client, scheduler and nannies: ``caller`` -- plus the workers) per
frame, and
``cpu ovh`` its excess over the in-process row's: the part of the per-frame
overhead that is work, whatever the load.  ``task cpu%`` is the task threads'
CPU over their wall time (100 %: no other process took the core).  The load
average is printed beside each row.

Part 2, one large frame split into tasks: the battle scene with a 4x finer
ground (262,144 receivers; the 65k frame with ``--quick``), evaluated in this
process, with the runtime's forked in-frame workers (``--processes 2``), and
with its parts as tasks of a Dask LocalCluster of 2 workers
(``split_frames``); per-frame time over a few frames after the first, and the
bytes compared with the in-process bake.

Targets: >= 85 % of linear speed-up on 2 cores, per-task overhead
<= 5 % of a frame.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _cpu_now() -> tuple[float, dict[int, float]]:
    """CPU seconds of this process and of each live descendant (psutil; else none)."""
    own = time.process_time()
    try:
        import psutil
    except ImportError:
        return own, {}
    kids = {}
    for p in psutil.Process().children(recursive=True):
        try:
            t = p.cpu_times()
            kids[p.pid] = t.user + t.system
        except psutil.Error:
            pass
    return own, kids


def _bake(scene_path: Path, out: Path, prepared, frames: int, **kwargs) -> dict:
    """One row's bake; wall and CPU between the first and the last frame, and the pool."""
    from shtools.scene.bake import bake_scene
    from shtools.scene.scene import load_scene

    scene = load_scene(scene_path)
    pool: dict = {}
    start = time.perf_counter()
    first = last = None
    n = 0
    for _ in bake_scene(scene, output=out, prepared=prepared, pool_summary=pool, **kwargs):
        n += 1
        if n in (1, frames):  # the last one while the workers are alive (the pool closes after)
            now = time.perf_counter(), *_cpu_now()
            first = first or now
            last = now
    wall = time.perf_counter() - start
    steady = max(n - 1, 1)
    client_cpu = last[1] - first[1]
    workers_cpu = sum(c - first[2].get(pid, 0.0) for pid, c in last[2].items())
    return {"wall": wall, "pool": pool,
            "cpu_per_frame": (client_cpu + workers_cpu) / steady,
            "client_cpu_per_frame": client_cpu / steady,
            "steady_wall_per_frame": (last[0] - first[0]) / steady}


def _percent(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f}%"


def _task_cpu_share(pool: dict) -> float | None:
    per = pool.get("per_worker", {}).values()
    wall = sum(w["seconds"] for w in per)
    return sum(w.get("cpu_seconds", 0.0) for w in per) / wall if wall else None


def many_frames(tmp: Path, frames: int, quick: bool, cores: int, have_dask: bool) -> None:
    from bench_bake import battle_scene

    from shtools.scene.bake import prepare_scene
    from shtools.scene.scene import load_scene

    scene_path = battle_scene(tmp, frames)
    start = time.perf_counter()
    prepared = prepare_scene(load_scene(scene_path))
    setup = time.perf_counter() - start
    print(f"== many frames: {prepared.n_vertices} receiver vertices, {frames} frames; "
          f"preparation {setup:.2f} s (once, not in the rows); {cores} cores; "
          f"load average {os.getloadavg()[0]:.2f} at start")
    rows = [("in-process (--workers 1)", dict(scheduler="inline", processes=1), 1),
            ("local workers (default)", dict(workers=cores), cores)]
    if have_dask:
        rows += [("Dask LocalCluster, 1 worker", dict(scheduler="local", workers=1), 1),
                 ("Dask LocalCluster, 2 workers", dict(scheduler="local", workers=2), 2)]
        if not quick:
            rows.append(("Dask LocalCluster, 8 workers (simulated)",
                         dict(scheduler="local", workers=8), 8))
    print(f"{'configuration':41s} {'wall s':>7s} {'ms/frame':>8s} {'speed-up':>8s} "
          f"{'of ideal':>8s} {'overhead':>8s} {'start s':>7s} {'set-up s':>8s} "
          f"{'cpu ms/f':>8s} {'caller':>6s} {'cpu ovh':>7s} {'task cpu%':>9s} {'same':>5s} "
          f"{'load':>5s}")
    base_out = tmp / "row0.h5"
    base_frame = base_cpu = None
    for k, (name, kwargs, n_workers) in enumerate(rows):
        out = tmp / f"row{k}.h5"
        r = _bake(scene_path, out, prepared, frames, **kwargs)
        pool = r["pool"]
        startup = pool.get("startup_seconds", 0.0)
        worker_setup = pool.get("setup_seconds", 0.0)
        wall = r["wall"] - startup - worker_setup  # each in its own column
        per_frame = wall / frames
        if base_frame is None:
            base_frame, base_cpu = per_frame, r["cpu_per_frame"]
        ideal = min(n_workers, cores)
        speedup = base_frame / per_frame
        overhead = (wall * ideal / frames - base_frame) / base_frame
        same = filecmp.cmp(out, base_out, shallow=False)
        print(f"{name:41s} {wall:7.2f} {1e3 * per_frame:8.1f} {speedup:7.2f}x "
              f"{100 * speedup / ideal:7.0f}% {100 * overhead:7.1f}% {startup:7.2f} "
              f"{worker_setup:8.2f} {1e3 * r['cpu_per_frame']:8.1f} "
              f"{1e3 * r['client_cpu_per_frame']:6.1f} "
              f"{100 * (r['cpu_per_frame'] / base_cpu - 1):6.1f}% "
              f"{_percent(_task_cpu_share(pool)):>9s} {same!s:>5s} "
              f"{os.getloadavg()[0]:5.2f}")


def single_frame(tmp: Path, cores: int, have_dask: bool, frames: int = 6,
                 subdivisions: int = 511) -> None:
    from bench_bake import battle_scene

    from shtools.scene.bake import prepare_scene
    from shtools.scene.scene import load_scene

    tmp = tmp / "single"
    tmp.mkdir()
    scene_path = battle_scene(tmp, frames, subdivisions)
    prepared = prepare_scene(load_scene(scene_path))
    print(f"\n== one frame split into parts: {prepared.n_vertices} receiver vertices; each "
          f"row bakes {frames} frames one after the other, time per frame after the first; "
          f"{cores} cores; load average {os.getloadavg()[0]:.2f} at start")
    rows = [("in-process, 1 process", dict(scheduler="inline", processes=1)),
            ("in-process, 2 processes (in-frame)", dict(scheduler="inline", processes=2))]
    if have_dask:
        rows.append(("Dask LocalCluster, 2 workers, parts", dict(scheduler="local", workers=2,
                                                              split_frames=True)))
    print(f"{'configuration':41s} {'ms/frame':>8s} {'speed-up':>8s} {'start s':>7s} "
          f"{'set-up s':>8s} {'cpu ms/f':>8s} {'parts':>6s} {'same':>5s} {'load':>5s}")
    base = None
    for k, (name, kwargs) in enumerate(rows):
        out = tmp / f"row{k}.h5"
        r = _bake(scene_path, out, prepared, frames, **kwargs)
        pool = r["pool"]
        per_frame = r["steady_wall_per_frame"]
        base = base or per_frame
        parts = sum(w["tasks"] for w in pool.get("per_worker", {}).values()) \
            if pool.get("scheduler") == "dask" else 0
        print(f"{name:41s} {1e3 * per_frame:8.1f} {base / per_frame:7.2f}x "
              f"{pool.get('startup_seconds', 0.0):7.2f} {pool.get('setup_seconds', 0.0):8.2f} "
              f"{1e3 * r['cpu_per_frame']:8.1f} {parts:6d} "
              f"{filecmp.cmp(out, tmp / 'row0.h5', shallow=False)!s:>5s} "
              f"{os.getloadavg()[0]:5.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="12 frames, fewer rows")
    parser.add_argument("--frames", type=int, default=None, help="frames (default 96)")
    parser.add_argument("--only", choices=["many", "single"], default=None,
                        help="run one part only")
    args = parser.parse_args()
    frames = args.frames or (12 if args.quick else 96)

    from shtools.tasks import default_workers

    cores = default_workers()
    try:
        import distributed  # noqa: F401

        have_dask = True
    except ImportError:
        have_dask = False
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.only != "single":
            many_frames(tmp, frames, args.quick, cores, have_dask)
        if args.only != "many":
            single_frame(tmp, cores, have_dask, frames=4 if args.quick else 6,
                         subdivisions=255 if args.quick else 511)


if __name__ == "__main__":
    main()
