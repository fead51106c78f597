"""Accuracy on real meshes: `shtools eval`'s table for each shared mesh.

Each mesh of ``../shared/data/meshes`` (when present) is fitted with the
variational sphere set (``N = 48``) and stands on a ground grid under the
procedural sky (``shtools eval``'s built-in form).  Per method the
table gives the relative RMSE of per-vertex radiance against ray tracing of the
real mesh and of the sphere set (the paper's Figure 7 split: sphere
approximation, truncation, log space) and the time of one visibility pass.
Without the data directory the benchmark runs the procedural capsule character.

``python benchmarks/bench_eval.py [--quick]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "meshes"
MESHES = {"bunny": "stanford-bunny.obj", "spot": "spot.obj", "cow": "cow.obj",
          "teapot": "teapot.obj"}
#: default runtime, the order-4 methods of the paper, product space, and a higher
#: accumulation order (the truncation part of the error)
METHODS = "auto,hyb@4,product@4,product@6,auto@8"
SPHERES = 48


def _meshes(quick: bool):
    from shtools.geometry.mesh import load_mesh

    found = {name: DATA / file for name, file in MESHES.items() if (DATA / file).exists()}
    if quick:
        found = dict(list(found.items())[:1])
    if found:
        return {name: load_mesh(path) for name, path in found.items()}
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "_sphere_test_meshes", REPO / "tests" / "geometry" / "conftest.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {"character (procedural)": module.make_character()}


def run(quick: bool) -> list[dict]:
    from shtools.geometry.sphere_fit import fit_spheres
    from shtools.reference.evaluation import evaluate
    from shtools.reference.scenes import mesh_scene
    from shtools.runtime import ShadowSettings, SphereBlocker

    rows = []
    for name, mesh in _meshes(quick).items():
        t0 = time.perf_counter()
        fit = fit_spheres(mesh, SPHERES if not quick else 16, seed=0)
        fit_s = time.perf_counter() - t0
        sc = mesh_scene(mesh, fit.centers, fit.radii, grid=32 if quick else 64, order=4)
        out = evaluate(sc.vertices, sc.normals, [SphereBlocker(sc.centers, sc.radii)],
                       sc.meshes, sc.env_sh, [], ShadowSettings(order=4, hierarchy=False,
                                                                processes=1),
                       METHODS, n_dirs=800 if quick else 2000)
        ref = out["references"]
        for res in out["results"]:
            rows.append({"mesh": name, "spheres": len(fit.radii), "E": fit.outside_volume_ratio,
                         "method": res.method, "vs mesh": res.rmse_mesh,
                         "vs spheres": res.rmse_spheres, "ms": 1e3 * res.seconds,
                         "spheres vs mesh": ref["spheres_rmse_mesh"], "fit s": fit_s})
    return rows


def _markdown(rows: list[dict]) -> str:
    keys = list(rows[0])
    out = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        out.append("| " + " | ".join(f"{r[k]:.4g}" if isinstance(r[k], float) else str(r[k])
                                     for k in keys) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one mesh, coarse grid")
    args = parser.parse_args(argv)
    rows = run(args.quick)
    print("\n### Eval on real meshes: relative RMSE of radiance (order 4, procedural sky, "
          "no hierarchy; target <= 3 % vs spheres, <= 8 % vs mesh at default settings)\n")
    print(_markdown(rows))
    worst = max(r["vs spheres"] for r in rows if r["method"] == "auto")
    print(f"\nDefault method, worst mesh: {100 * worst:.1f} % vs the sphere set")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
