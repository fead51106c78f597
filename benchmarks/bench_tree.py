"""Sphere trees, runtime refit and skin binding: speed and quality.

Tables:

1. tree build time and branching for 64-512 leaves (clumpy random sphere sets);
2. runtime refit per frame for ~250 leaves (with and without the centre
   refinement steps), and the refit radii relative to the optimal bound of the
   same children;
3. for the skinned models in ../shared/data/skinned (Fox, CesiumMan): sphere
   fit (variational, or k-means with --quick), bind time, posed-vertex coverage
   over every animation, truncation error of 4 bones per sphere, tree refit over
   the animation.

Run: ``.venv/bin/python benchmarks/bench_tree.py [--quick]``.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from shtools.geometry.bounding import minimal_enclosing_sphere
from shtools.geometry.sphere_tree import build_tree, check_tree, tree_statistics
from shtools.runtime.spheres import plan_refit, refit_tree

DATA = Path(os.environ.get("SHTOOLS_SHARED_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))


def clumpy_spheres(n, seed=0):
    rng = np.random.default_rng(seed)
    blobs = rng.normal(size=(max(2, n // 20), 3)) * 3
    centers = blobs[rng.integers(len(blobs), size=n)] + rng.normal(size=(n, 3)) * 0.6
    return centers, rng.uniform(0.05, 0.5, size=n)


def timed(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def optimal_ratio(parent, leaf, centers, radii):
    """Refit radius / minimal bound of the same (refit) children, per inner node."""
    ratios = []
    for node in np.flatnonzero(leaf < 0):
        kids = np.flatnonzero(parent == node)
        _, r = minimal_enclosing_sphere(centers[kids], radii[kids])
        ratios.append(radii[node] / r)
    return np.asarray(ratios)


def table_build(sizes):
    print("\n### Tree build (bottom-up Lloyd, branching 4)\n")
    print("| leaves | nodes | levels | avg branching | max branching | build s | "
          "max child excess |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for n in sizes:
        centers, radii = clumpy_spheres(n)
        seconds, tree = timed(lambda c=centers, r=radii: build_tree(c, r), 1)
        s = tree_statistics(tree)
        print(f"| {n} | {s['nodes']} | {s['levels']} | {s['average_branching']:.2f} | "
              f"{s['max_branching']} | {seconds:.3f} | {check_tree(tree):.1e} |")


def table_refit(n, repeat):
    print(f"\n### Runtime refit per frame ({n} leaves, numpy, best of {repeat})\n")
    print("| refine steps | µs / frame | mean r / optimal | max r / optimal | "
          "max child excess |")
    print("|---:|---:|---:|---:|---:|")
    centers, radii = clumpy_spheres(n, 1)
    tree = build_tree(centers, radii)
    rng = np.random.default_rng(2)
    moved = centers + rng.normal(size=centers.shape) * 0.3
    plan = plan_refit(tree.parent, tree.leaf)
    for steps in (0, 2, 4):
        seconds, (c, r) = timed(
            lambda s=steps: refit_tree(tree.parent, tree.leaf, moved, radii, plan=plan,
                                       refine_steps=s), repeat)
        ratio = optimal_ratio(tree.parent, tree.leaf, c, r)
        tree_m = type(tree)(c, r, tree.parent, tree.leaf)
        print(f"| {steps} | {seconds * 1e6:.0f} | {ratio.mean():.4f} | {ratio.max():.4f} | "
              f"{check_tree(tree_m):.1e} |")
    seconds, _ = timed(lambda: refit_tree(tree.parent, tree.leaf, moved, radii), repeat)
    print(f"\n(without a precomputed plan, cache lookup included: {seconds * 1e6:.0f} µs)")


def table_skinned(quick):
    models = [DATA / "skinned" / f for f in ("Fox.glb", "CesiumMan.glb")]
    models = [m for m in models if m.is_file()]
    if not models:
        print(f"\n(skinned models not found under {DATA / 'skinned'}; table 3 skipped)")
        return
    import trimesh

    from shtools.geometry.binding import (
        bind_spheres,
        covering_radii,
        posed_coverage,
        truncation_error,
    )
    from shtools.geometry.mesh import validate_mesh
    from shtools.geometry.skin import load_skinned_gltf
    from shtools.geometry.sphere_fit import fit_spheres

    method = "kmeans" if quick else "variational"
    n_spheres = 32 if quick else 64
    frames = 8 if quick else 24
    print(f"\n### Skinned models: {n_spheres} spheres ({method} fit on the rest mesh), "
          f"4 bones per sphere, {frames} frames per animation\n")
    print("| model | V | joints | fit s | bind s | rest cov. | posed cov. | worst frame | "
          "max gap / mean r | trunc. err / mean r | refit µs | refit r / optimal | "
          "covered: r growth mean/max | covered: cov. between frames |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for path in models:
        model = load_skinned_gltf(path)
        mesh = validate_mesh(trimesh.Trimesh(model.rest_vertices, model.faces, process=True))
        t = time.perf_counter()
        fitted = fit_spheres(mesh, n_spheres, method=method, seed=0)
        fit_s = time.perf_counter() - t
        bind_s, binding = timed(lambda f=fitted, m=model: bind_spheres(f.centers, m), 1)
        cov = posed_coverage(binding, fitted.radii, model, frames=frames)
        mean_r = float(fitted.radii.mean())
        errs, ratios = [], []
        tree = build_tree(fitted.centers, fitted.radii)
        plan = plan_refit(tree.parent, tree.leaf)
        refit_s = np.inf
        for a in range(len(model.animations)):
            for time_s in np.linspace(0, model.duration(a), frames):
                mats = model.joint_matrices(float(time_s), a)
                errs.append(truncation_error(fitted.centers, model, binding, mats).max())
                posed = binding.pose(mats)
                s, (c, r) = timed(lambda p=posed, t=tree, f=fitted, pl=plan: refit_tree(
                    t.parent, t.leaf, p, f.radii, plan=pl), 3)
                refit_s = min(refit_s, s)
                ratios.append(optimal_ratio(tree.parent, tree.leaf, c, r).mean())
        grown = covering_radii(binding, fitted.radii, model, frames=frames)
        growth = grown / fitted.radii
        # evaluated at 2*frames-1 times: the inflation frames plus every midpoint
        cov_grown = posed_coverage(binding, grown, model, frames=2 * frames - 1)
        print(f"| {path.stem} | {model.rest_vertices.shape[0]} | {model.joint_count} | "
              f"{fit_s:.1f} | {bind_s:.3f} | {cov['rest_vertex_coverage']:.3f} | "
              f"{cov['posed_vertex_coverage']:.3f} | {cov['worst_frame_coverage']:.3f} | "
              f"{cov['max_uncovered_distance'] / mean_r:.2f} | {max(errs) / mean_r:.3f} | "
              f"{refit_s * 1e6:.0f} | {np.mean(ratios):.4f} | "
              f"{growth.mean():.3f} / {growth.max():.3f} | "
              f"{cov_grown['posed_vertex_coverage']:.4f} |")
    print("\nrest cov. / posed cov.: fraction of skinned vertices inside some sphere at the "
          "bind pose / over all sampled frames; max gap: farthest uncovered vertex from the "
          "nearest sphere surface; trunc. err: largest distance between 4-bone and all-bone "
          "posed centres; covered: radii grown by `bind --cover-animations` "
          "(covering_radii) at the sampled frames, coverage checked at those and the "
          "midpoints between them.")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, fast fit")
    args = parser.parse_args(argv)
    sizes = (64, 256) if args.quick else (64, 128, 256, 512)
    print("# bench_tree: sphere trees, refit, skin binding")
    table_build(sizes)
    table_refit(250, 20 if args.quick else 200)
    table_skinned(args.quick)


if __name__ == "__main__":
    main()
