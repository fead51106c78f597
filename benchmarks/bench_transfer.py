"""The exact self-transfer's estimators: error against a dense reference and CPU per vertex.

On a random subset of each real mesh's vertices (``../shared/data``, never
committed), at the default accumulation order 6:

* **product rule** -- :func:`shtools.geometry.transfer.mesh_transfer`'s
  estimator at :data:`~shtools.geometry.visibility.DEFAULT_DIRECTIONS`
  (3,200 Gauss-Legendre x uniform directions over the sphere, about half of them
  above each vertex's tangent plane and cast);
* **hemisphere** -- N spherical Fibonacci rays over each vertex's own hemisphere,
  every one cast (:func:`~shtools.geometry.transfer.hemisphere_transfer_visibility`);
* **refined** -- :func:`~shtools.geometry.transfer.hemisphere_transfer`'s default:
  the first rays, then the dense set's directions in the cells where they disagree
  with a neighbour (:func:`~shtools.geometry.transfer.refined_transfer_visibility`;
  "rays" is dense / first, the CPU column says what it casts);

both against the product rule at 51,200 directions.  Errors (relative RMSE over
the subset): the order-6 visibility coefficients, the cosine-weighted visibility
(the order-4 Lambertian shading of a white sky, ``g . H(N)``), and the log the
runtime adds (:func:`~shtools.geometry.visibility.self_visibility_log`).  CPU
is ``time.process_time`` per vertex (Embree's threads included).

``python benchmarks/bench_transfer.py [--quick] [--mesh NAME] [--rays 512,1024]``
(quick: the bunny, 400 vertices, 512 and 1024 rays).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: real meshes and probes (``SHTOOLS_SHARED_DATA`` overrides, as for the tests)
DATA = Path(os.environ.get("SHTOOLS_SHARED_DATA", REPO.parent / "shared" / "data"))
MESHES = ("stanford-bunny", "armadillo", "dragon")
RAYS = (512, 800, 1024, 1280, 1600)
ORDER = 6
REFERENCE_DIRECTIONS = 51200
SUBSET = 1000


def _errors(g, truth, shading) -> tuple[float, float, float]:
    from shtools.geometry.visibility import self_visibility_log

    def rel(a, b):
        return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b ** 2)))

    return (rel(g, truth), rel((g[:, :16] * shading).sum(1), (truth[:, :16] * shading).sum(1)),
            rel(self_visibility_log(g), self_visibility_log(truth)))


def evaluate(name: str, rays, subset: int) -> list[dict]:
    from shtools.geometry import visibility as sv
    from shtools.geometry.mesh import load_mesh
    from shtools.runtime.shading import cosine_transfer

    mesh = load_mesh(DATA / "meshes" / f"{name}.obj")
    rng = np.random.default_rng(1)
    rows = np.sort(rng.choice(len(mesh.vertices), min(subset, len(mesh.vertices)),
                              replace=False))
    p = np.asarray(mesh.vertices, dtype=np.float64)[rows]
    n = np.asarray(mesh.vertex_normals, dtype=np.float64)[rows]
    truth = sv.self_visibility(p, n, mesh, ORDER, n_dirs=REFERENCE_DIRECTIONS)
    shading = cosine_transfer(n, 4).astype(np.float64)
    out = []

    def row(label, n_rays, fn):
        start = time.process_time()
        g = fn()
        cpu = time.process_time() - start
        c, s, lg = _errors(g, truth, shading)
        out.append({"mesh": name, "estimator": label, "rays": n_rays, "coeff": c,
                    "shading": s, "log": lg, "us_per_vertex": 1e6 * cpu / len(rows)})

    row("product rule", sv.DEFAULT_DIRECTIONS,
        lambda: sv.self_visibility(p, n, mesh, ORDER, n_dirs=sv.DEFAULT_DIRECTIONS))
    for k in rays:
        row("hemisphere", k, lambda k=k: _hemisphere_rows(mesh, n, rows, k))
    from shtools.geometry.transfer import FIRST_DIRECTIONS, TRANSFER_DIRECTIONS

    row("refined", f"{TRANSFER_DIRECTIONS}/{FIRST_DIRECTIONS}",
        lambda: _hemisphere_rows(mesh, n, rows, TRANSFER_DIRECTIONS, refined=True))
    return out


def _hemisphere_rows(mesh, normals, rows, n_rays: int, refined: bool = False) -> np.ndarray:
    """:func:`hemisphere_transfer`'s visibility at ``rows`` only (same caster and offset),
    in one pass or ``refined`` from the first rays."""
    from shtools.geometry.raycast import RayCaster
    from shtools.geometry.transfer import (
        hemisphere_transfer_visibility,
        refined_transfer_visibility,
    )

    caster = RayCaster(np.asarray(mesh.vertices), np.asarray(mesh.faces), robust=False)
    estimate = refined_transfer_visibility if refined else hemisphere_transfer_visibility
    return estimate(np.asarray(mesh.vertices)[rows], normals, caster, ORDER, n_dirs=n_rays)


def _markdown(rows: list[dict]) -> str:
    lines = ["| mesh | estimator | rays | coefficients | shading | log | CPU / vertex | "
             "vs product rule |", "|---|---|---|---|---|---|---|---|"]
    base = {}
    for r in rows:
        base.setdefault(r["mesh"], r["us_per_vertex"])
        lines.append(f"| {r['mesh']} | {r['estimator']} | {r['rays']} | "
                     f"{100 * r['coeff']:.2f} % | {100 * r['shading']:.2f} % | "
                     f"{100 * r['log']:.2f} % | {r['us_per_vertex']:.0f} us | "
                     f"{r['us_per_vertex'] / base[r['mesh']]:.2f}x |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--mesh", action="append", choices=MESHES)
    parser.add_argument("--rays", default=None, help="comma-separated hemisphere ray counts")
    args = parser.parse_args(argv)
    if not DATA.is_dir():
        print(f"bench_transfer: {DATA} is not present; nothing to measure")
        return 0
    rays = tuple(int(x) for x in args.rays.split(",")) if args.rays else (
        (512, 1024) if args.quick else RAYS)
    meshes = args.mesh or (("stanford-bunny",) if args.quick else MESHES)
    from threadpoolctl import threadpool_limits

    rows = []
    with threadpool_limits(limits=1, user_api="blas"):
        for name in meshes:
            print(f"[bench_transfer] {name}", file=sys.stderr, flush=True)
            rows.extend(evaluate(name, rays, 400 if args.quick else SUBSET))
    print(_markdown(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
