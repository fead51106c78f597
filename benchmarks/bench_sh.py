"""SH algebra throughput: basis, products, every exp method.

Measured side by side in one run:

* ``shtools.sh.basis`` at order 4 in float32 and float64 (directions/s) next to
  sphericart's ``SphericalHarmonics`` (same directions; target: at least 1/3
  of sphericart).  Directions are the vertex normals of a real mesh from
  ``../shared/data`` when present, random otherwise.
* SH product and square on 65,536 vectors at orders 4 and 6: the default
  kernel (exact quadrature factorisation of Γ), the generated sparse kernel,
  and a dense contraction over Γ (``np.einsum`` over the dense tensor); target:
  the sparse product at order 4 at least 5x faster than the dense one.
* Every exp method on 65,536 log-visibility vectors (sums of 3–25 cap logs
  from the circle tables, as the runtime builds them) at orders 4 and 6.

Figures are the best of a few repetitions (wall clock).  ``--quick`` uses
4,096 vectors and one repetition.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # runnable as a script too
import unrolled_kernel  # noqa: F401  (registers the "unrolled" product kernel)

import shtools.sh as sh
from shtools.sh._kernels import run_product
from shtools.sh.tables import build_log_tables

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "meshes" / "armadillo.obj"
BATCH = 65_536
QUICK_BATCH = 4_096
BASIS_DIRECTIONS = 1_000_000


def best_rate(fn, items: int, repeats: int) -> float:
    """Items per second of the fastest of ``repeats`` calls (after one warm-up call)."""
    fn()
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return items / best


def directions(count: int, rng) -> tuple[np.ndarray, str]:
    """Unit directions: a real mesh's vertex normals (tiled) or random ones."""
    if DATA.exists():
        import trimesh

        mesh = trimesh.load(DATA, process=False, force="mesh")
        normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
        reps = -(-count // len(normals))
        return np.tile(normals, (reps, 1))[:count], f"{DATA.name} vertex normals"
    d = rng.normal(size=(count, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True), "random directions"


def log_vectors(order: int, count: int, rng) -> np.ndarray:
    """Sums of 3–25 cap logs (radius 0.05–0.6 rad) from the circle tables, ``(count, n*n)``."""
    tables = build_log_tables(order)
    most = 25
    theta = rng.uniform(0.05, 0.6, size=(count, most))
    t = np.clip(np.searchsorted(tables["theta"], theta), 0, len(tables["theta"]) - 1)
    axes = rng.normal(size=(count, most, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    present = np.arange(most) < rng.integers(3, most + 1, size=count)[:, None]
    logs = tables["log_zh"][t][..., sh.band_of(order)] * sh.basis(axes, order)
    return np.where(present[..., None], logs, 0.0).sum(axis=1)


def bench_basis(repeats: int, quick: bool, rng) -> None:
    count = BASIS_DIRECTIONS // (10 if quick else 1)
    dirs, source = directions(count, rng)
    try:
        import sphericart
    except ImportError:  # optional benchmark dependency
        sphericart = None
    print(f"\n### basis, order 4, {count:,} directions ({source})\n")
    print("| dtype | shtools (dir/s) | shtools + C-order copy (dir/s) | sphericart (dir/s) "
          "| shtools / sphericart | target |")
    print("|---|---:|---:|---:|---:|---|")
    for dtype in (np.float32, np.float64):
        d = dirs.astype(dtype)
        ours = best_rate(lambda d=d: sh.basis(d, 4), count, repeats)
        ours_c = best_rate(lambda d=d: np.ascontiguousarray(sh.basis(d, 4)), count, repeats)
        if sphericart is not None:
            calc = sphericart.SphericalHarmonics(3)
            theirs = best_rate(lambda d=d, c=calc: c.compute(d), count, repeats)
            ratio = f"{ours / theirs:.2f}"
            theirs_s = f"{theirs:.3g}"
        else:
            theirs_s, ratio = "not installed", "-"
        print(f"| {np.dtype(dtype).name} | {ours:.3g} | {ours_c:.3g} | {theirs_s} | {ratio} "
              "| >= 0.33 |")


def bench_products(batch: int, repeats: int, rng) -> None:
    print(f"\n### SH product, {batch:,} vectors (vectors/s)\n")
    print("| order | dtype | product (default, CP) | product (sparse kernel) | square (CP) "
          "| square (sparse) | dense einsum over Γ | sparse / dense | CP / dense |")
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for order in (4, 6):
        size = order * order
        dense = sh.triple_tensor(order).todense()
        for dtype in (np.float64, np.float32):
            f = rng.normal(size=(batch, size)).astype(dtype)
            g = rng.normal(size=(batch, size)).astype(dtype)
            d = dense.astype(dtype)
            cp = best_rate(lambda f=f, g=g: sh.product(f, g), batch, repeats)
            sparse = best_rate(lambda f=f, g=g, o=order: run_product(f, g, o, o, "unrolled"),
                               batch, repeats)
            sq = best_rate(lambda f=f: sh.square(f), batch, repeats)
            sq_sparse = best_rate(lambda f=f, o=order: run_product(f, None, o, o, "unrolled"),
                                  batch, repeats)
            dense_rate = best_rate(
                lambda f=f, g=g, d=d: np.einsum("ijk,bj,bk->bi", d, f, g, optimize=True),
                batch, repeats)
            print(f"| {order} | {np.dtype(dtype).name} | {cp:.3g} | {sparse:.3g} | {sq:.3g} "
                  f"| {sq_sparse:.3g} | {dense_rate:.3g} | {sparse / dense_rate:.1f}x "
                  f"| {cp / dense_rate:.1f}x |")


def bench_exp(batch: int, repeats: int, rng) -> None:
    print(f"\n### SH exp, {batch:,} log-visibility vectors (vectors/s)\n")
    runs = [("hyb", {}), ("hyb", {"acc_order": "n+2"}), ("ps*", {"degree": 2}),
            ("ps", {"degree": 8}), ("ol", {}), ("exact", {}), ("volterra", {})]
    print("| order | " + " | ".join(_label(m, kw) for m, kw in runs) + " | hyb float32 |")
    print("|---:|" + "---:|" * (len(runs) + 1))
    for order in (4, 6):
        f = log_vectors(order, batch, rng)
        sh.exp(f[:8], "hyb")  # build and cache the OL tables outside the timing
        cells = []
        for method, kw in runs:
            opts = {k: (order + 2 if v == "n+2" else v) for k, v in kw.items()}
            reps = 1 if method in ("exact", "volterra") else repeats
            cells.append(best_rate(lambda m=method, o=opts, f=f: sh.exp(f, m, **o), batch, reps))
        f32 = f.astype(np.float32)
        cells.append(best_rate(lambda f32=f32: sh.exp(f32, "hyb"), batch, repeats))
        print(f"| {order} | " + " | ".join(f"{c:.3g}" for c in cells) + " |")


def _label(method: str, kw: dict) -> str:
    extra = ", ".join(f"{k}={v}" for k, v in kw.items())
    return f"{method}" + (f" ({extra})" if extra else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="4,096 vectors, one repetition")
    args, _ = parser.parse_known_args()
    rng = np.random.default_rng(0)
    batch = QUICK_BATCH if args.quick else BATCH
    repeats = 1 if args.quick else 3
    bench_basis(repeats, args.quick, rng)
    bench_products(batch, repeats, rng)
    bench_exp(batch, repeats, rng)


if __name__ == "__main__":
    main()
