"""Bake benchmarks: demo wall time, bake throughput (vertex-frames/s) on the demo and on a
65k-vertex scene, and a skinned real character when ../shared/data is present.

    python benchmarks/bench_bake.py [--quick] [--baseline DIR]

Target: the demo runs in about a minute on this 2-core machine.  With ``--baseline DIR``
(or ``SHTOOLS_BASELINE=DIR``; DIR a checkout of an earlier commit, e.g.
``git worktree add /tmp/base 98bedba``) it first times ``make demo``'s command side by
side with that checkout: ``python -m shtools.demo`` into a fresh folder with an empty
set-up cache (as on a fresh clone), the two trees alternated ``DEMO_ROUNDS`` times.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("SHTOOLS_SHARED_DATA", REPO.parent / "shared" / "data"))


def battle_scene(directory: Path, frames: int, subdivisions: int = 255) -> Path:
    """A 65,536-vertex ground grid under 16 moving balls and 4 columns of 50 spheres each.

    ``subdivisions`` of the ground: 255 gives the 65,536 vertices, 511 a 262,144-vertex
    frame (``bench_scaleout``'s one large frame).

    216 leaf spheres in total (the columns in trees), as in the runtime's battle-scale
    benchmark; balls cross the ground on straight paths.
    """
    from shtools.data_formats.spheres import write_spheres
    from shtools.data_formats.tree import write_tree
    from shtools.geometry.sphere_set import SphereSet
    from shtools.geometry.sphere_tree import build_tree

    rng = np.random.default_rng(0)
    # a column as a helix of 50 overlapping spheres (a twisted pillar), height 2.5
    k = np.arange(50)
    centers = np.stack([0.12 * np.cos(k * 0.7), 0.05 + 0.05 * k, 0.12 * np.sin(k * 0.7)], 1)
    radii = np.full(50, 0.22)
    write_tree(directory / "column_tree.h5", build_tree(centers, radii))
    write_spheres(directory / "column.h5", SphereSet(centers, radii))
    objects = ["""
[[objects]]
name = "ground"
primitive = { type = "plane", size = [16.0, 16.0], subdivisions = SUBDIVISIONS }
role = "receiver"
""".replace("SUBDIVISIONS", str(int(subdivisions)))]
    for c in range(4):
        x, z = rng.uniform(-5, 5, size=2)
        objects.append(f"""
[[objects]]
name = "column{c}"
primitive = {{ type = "cylinder", radius = 0.3, height = 2.5, center = [0, 1.25, 0] }}
role = "blocker"
translate = [{x:.3f}, 0.0, {z:.3f}]
blocker = {{ tree = "column_tree.h5" }}
""")
    duration = max(frames - 1, 1) / 24.0
    for b in range(16):
        start = rng.uniform(-6, 6, size=2)
        end = start + rng.uniform(-2, 2, size=2)
        r = rng.uniform(0.3, 0.6)
        objects.append(f"""
[[objects]]
name = "ball{b}"
primitive = {{ type = "sphere", radius = {r:.3f}, subdivisions = 1 }}
role = "blocker"
[[objects.keyframes]]
time = 0.0
translate = [{start[0]:.3f}, {r + 0.05:.3f}, {start[1]:.3f}]
[[objects.keyframes]]
time = {duration:.4f}
translate = [{end[0]:.3f}, {r + 0.05:.3f}, {end[1]:.3f}]
""")
    sky = ", ".join(["[3.0, 3.0, 3.2]", "[0, 0, 0]", "[2.0, 2.0, 2.0]", "[0.5, 0.4, 0.3]"]
                    + ["[0, 0, 0]"] * 12)
    text = f"""
[settings]
order = 4
frames = {frames}
fps = 24
[environment]
coeffs = [{sky}]
[[lights]]
position = [2.0, 4.0, 1.0]
radius = 0.5
color = [10.0, 9.0, 8.0]
""" + "".join(objects)
    path = directory / "battle.toml"
    path.write_text(text)
    return path


def skinned_scene(directory: Path, frames: int) -> Path | None:
    """The Fox (shared data) walking on a ground grid; spheres fitted on the fly (k-means)."""
    fox = SHARED / "skinned" / "Fox.glb"
    if not fox.is_file():
        return None
    text = f"""
[settings]
order = 4
frames = {frames}
fps = 24
[environment]
coeffs = [[3.0, 3.0, 3.2], [0, 0, 0], [2.0, 2.0, 2.0], [0.5, 0.4, 0.3],
          [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0],
          [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]
[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [300.0, 300.0], subdivisions = 128 }}
role = "receiver"
[[objects]]
name = "fox"
mesh = "{fox}"
role = "both"
blocker = {{ fit = 32, method = "kmeans" }}
skin = {{ animation = "Walk" }}
"""
    path = directory / "fox.toml"
    path.write_text(text)
    return path


def bake_row(name: str, scene_path: Path, out: Path) -> dict:
    from shtools.scene.bake import bake_to_file
    from shtools.scene.scene import load_scene

    summary = bake_to_file(load_scene(scene_path), out)
    frame_ms = 1000 * summary["frame_seconds"] / summary["frames"]
    return {
        "scene": name,
        "vertices": summary["vertices"],
        "frames": summary["frames"],
        "setup s": summary["setup_seconds"],
        "total s": summary["seconds"],
        "ms/frame": frame_ms,
        "vertex-frames/s": summary["vertex_frames_per_second"],
    }


#: Alternated runs of each tree in the side-by-side demo wall time.
DEMO_ROUNDS = 3
#: A demo run taking longer than this (s) is killed and fails the table (a fresh
#: clone's demo takes 12-22 s on this repository's 2-core machines).
DEMO_TIMEOUT_S = 600


def demo_wall(root: Path) -> float:
    """Wall seconds of ``python -m shtools.demo`` run from ``root`` (a checkout), as
    ``make demo`` runs it, into a fresh folder with an empty set-up cache."""
    import subprocess

    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", SHTOOLS_CACHE=str(Path(tmp) / "cache"),
                   PYTHONPATH=os.pathsep.join(filter(None, [str(root),
                                                            os.environ.get("PYTHONPATH")])))
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "shtools.demo", str(Path(tmp) / "out")],
                       cwd=root, env=env, check=True, capture_output=True,
                       timeout=DEMO_TIMEOUT_S)
        return time.perf_counter() - start


def table_demo_versus(baseline: Path) -> str:
    """``make demo``'s wall time, this tree and ``baseline`` alternated (fastest kept)."""
    walls: dict[str, list[float]] = {"this tree": [], "baseline": []}
    for _ in range(DEMO_ROUNDS):
        for name, root in (("this tree", REPO), ("baseline", baseline)):
            walls[name].append(demo_wall(root))
    base, this = min(walls["baseline"]), min(walls["this tree"])
    rows = [{"tree": name, "fastest s": min(w), "runs s": " / ".join(f"{x:.1f}" for x in w)}
            for name, w in walls.items()]
    return (table(rows) + f"\n\nratio (baseline / this tree, fastest runs): "
            f"{base / this:.2f}")


def table(rows: list[dict]) -> str:
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        cells = []
        for k in keys:
            v = r[k]
            cells.append(f"{v:,.1f}" if isinstance(v, float) else str(v))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="few frames, seconds not minutes")
    parser.add_argument("--baseline", metavar="DIR", default=os.environ.get("SHTOOLS_BASELINE"),
                        help="a checkout of the baseline commit: time make demo side by side")
    args = parser.parse_args(sys.argv[1:])
    from shtools.demo import FRAMES, run_demo

    if args.baseline:
        print(f"## make demo's wall time side by side with {args.baseline} (fresh folder, "
              f"empty set-up cache, {DEMO_ROUNDS} alternated runs each)\n")
        print(table_demo_versus(Path(args.baseline).resolve()) + "\n")

    frames = 6 if args.quick else FRAMES
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        start = time.perf_counter()
        timings = run_demo(tmp / "demo", frames=frames, quiet=True)
        demo_wall = time.perf_counter() - start
        print(f"## shtools bake — demo ({frames} frames{', --quick' if args.quick else ''})\n")
        print(table([{"stage": k, "seconds": v} for k, v in timings.items()]))
        print(f"\ndemo wall time: {demo_wall:.1f} s (target: about a minute)\n")
        rows = [bake_row("demo", tmp / "demo" / "scene.toml", tmp / "demo_rebake.h5")]
        battle_frames = 2 if args.quick else 8
        rows.append(bake_row("65k grid + 216 spheres",
                             battle_scene(tmp, battle_frames), tmp / "battle.h5"))
        fox = skinned_scene(tmp, 2 if args.quick else 8)
        if fox is not None:
            rows.append(bake_row("Fox.glb skinned + grid", fox, tmp / "fox.h5"))
        else:
            print(f"(skinned row skipped: {SHARED} not present)\n")
        print("## bake throughput (default method, order 4)\n")
        print(table(rows))
        print(f"\n{math.nan if not rows else rows[1]['ms/frame']:.0f} ms per 65k-vertex frame "
              "(posing + visibility + shading; the runtime's own target "
              "for cuts + accumulate + exp + shade is <= 150 ms)")


if __name__ == "__main__":
    main()
