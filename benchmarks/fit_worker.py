"""Run one sphere fit in this process and print its spheres and timings as JSON.

``python benchmarks/fit_worker.py MESH N [--seed S] [--code DIR]``: used by
``bench_spheres.py --baseline DIR``, which runs it with ``--code DIR`` so
that another checkout's fit (e.g. the previous release) is timed the same way,
in a fresh single-threaded process, and its spheres are scored by the current
evaluators.  Prints ``{"centers", "radii", "wall", "cpu", "E", "coverage"}``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mesh")
    parser.add_argument("n", type=int)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--code", default=None,
                        help="import shtools from this checkout instead of the installed one")
    args = parser.parse_args(argv)
    if args.code:
        # an editable install's meta-path finder outranks PYTHONPATH: drop it
        sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in repr(f)]
        sys.path.insert(0, os.path.abspath(args.code))
    from shtools.geometry.mesh import load_mesh
    from shtools.geometry.sphere_fit import fit_spheres

    mesh = load_mesh(args.mesh)
    wall, cpu = time.perf_counter(), time.process_time()
    result = fit_spheres(mesh, args.n, seed=args.seed)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    print(json.dumps({"centers": result.centers.tolist(), "radii": result.radii.tolist(),
                      "wall": wall, "cpu": cpu, "E": result.outside_volume_ratio,
                      "coverage": result.coverage, "load": os.getloadavg()[0],
                      "code": sys.modules["shtools"].__file__}))


if __name__ == "__main__":
    main()
