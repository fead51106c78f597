"""Scale-out benchmark: a many-frame bake of the 65k-vertex battle scene, frames as tasks.

    python benchmarks/bench_scaleout.py [--quick] [--frames N]

Rows, measured side by side in one run (issue 14): the bake in this process
(``--workers 1``: frames one after the other, one process per frame), the
default forked local workers, a Dask ``LocalCluster`` of 1 and 2 workers, and
a simulated larger cluster (8 Dask workers on this machine's cores; BLAS
pinned to one thread) that must run at the speed of the cores actually there,
not slower.  For each: wall time of the frame loop (set-up excluded: scene
preparation is the same for all rows and reported once), per-frame wall time,
speed-up over the in-process row and its fraction of the ideal
``min(workers, cores)``, the cluster's start-up (its own column, not in the
wall time), and per-task overhead (wall x workers / frames minus
the in-process frame time, as a fraction of a frame).  Every output is
compared byte for byte with the in-process bake.

Targets (issue 14): >= 85 % of linear speed-up on 2 cores, per-task overhead
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


def _bake(scene_path: Path, out: Path, prepared, **kwargs) -> tuple[float, dict]:
    from shtools.scene.bake import bake_scene
    from shtools.scene.scene import load_scene

    scene = load_scene(scene_path)
    pool: dict = {}
    start = time.perf_counter()
    for _ in bake_scene(scene, output=out, prepared=prepared, pool_summary=pool, **kwargs):
        pass
    return time.perf_counter() - start, pool


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="12 frames, fewer rows")
    parser.add_argument("--frames", type=int, default=None, help="frames (default 48)")
    args = parser.parse_args()
    frames = args.frames or (12 if args.quick else 48)

    from bench_bake import battle_scene

    from shtools.scene.bake import prepare_scene
    from shtools.scene.scene import load_scene
    from shtools.tasks import default_workers

    cores = default_workers()
    try:
        import distributed  # noqa: F401

        have_dask = True
    except ImportError:
        have_dask = False
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        scene_path = battle_scene(tmp, frames)
        start = time.perf_counter()
        prepared = prepare_scene(load_scene(scene_path))
        setup = time.perf_counter() - start
        print(f"scene: {prepared.n_vertices} receiver vertices, {frames} frames; "
              f"preparation {setup:.2f} s (once, not in the rows); {cores} cores; "
              f"load average {os.getloadavg()[0]:.2f} at start")
        rows = [("in-process (--workers 1)", dict(scheduler="inline", processes=1), 1),
                ("local workers (default)", dict(workers=cores), cores)]
        if have_dask:
            rows += [("Dask LocalCluster, 1 worker", dict(scheduler="local", workers=1), 1),
                     ("Dask LocalCluster, 2 workers", dict(scheduler="local", workers=2), 2)]
            if not args.quick:
                rows.append(("Dask LocalCluster, 8 workers (simulated)",
                             dict(scheduler="local", workers=8), 8))
        print(f"{'configuration':42s} {'wall s':>8s} {'ms/frame':>9s} {'speed-up':>9s} "
              f"{'of ideal':>9s} {'overhead':>9s} {'start s':>8s} {'same bytes':>10s} {'load':>6s}")
        base_out = tmp / "row0.h5"
        base_frame = None
        for k, (name, kwargs, n_workers) in enumerate(rows):
            out = tmp / f"row{k}.h5"
            wall, pool = _bake(scene_path, out, prepared, **kwargs)
            startup = pool.get("startup_seconds", 0.0)
            wall -= startup  # cluster start-up, reported in its own column
            per_frame = wall / frames
            if base_frame is None:
                base_frame = per_frame
            ideal = min(n_workers, cores)
            speedup = base_frame / per_frame
            # Busy worker time per frame beyond the in-process frame, as a fraction.
            overhead = (wall * ideal / frames - base_frame) / base_frame
            same = filecmp.cmp(out, base_out, shallow=False)
            print(f"{name:42s} {wall:8.2f} {1e3 * per_frame:9.1f} {speedup:8.2f}x "
                  f"{100 * speedup / ideal:8.0f}% {100 * overhead:8.1f}% {startup:8.2f} "
                  f"{same!s:>10s} "
                  f"{os.getloadavg()[0]:6.2f}")


if __name__ == "__main__":
    main()
