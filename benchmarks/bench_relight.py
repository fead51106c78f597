"""Relighting a stored-visibility bake against re-baking it: the demo scene under a new light.

    python benchmarks/bench_relight.py [--quick]

Bakes the demo (48 frames; ``--quick`` 6) with ``--store-visibility`` under its sky,
then puts it under a warmer sky turned 90 degrees about +Y, side by side:

* a fresh bake of the scene with that light, its set-up included and no set-up
  cache (``bake --no-cache``: the full re-bake a user faces without relighting);
* the same bake with a warm set-up cache (:mod:`shtools.cache`: the first bake
  filled it);
* a relight of the first bake (the scene's lamp kept, through the stored
  visibility, read from the bake: ``--lights`` names the scene it was baked from),
  from Python and as the whole ``shtools relight`` command (a new process: its
  start and imports included, its modules' bytecode compiled beforehand as an
  installed package's is); the command without ``--lights`` (the environment
  alone); and the command with ``--lights`` of a copy of the scene with one more
  comment line (other bytes: the scene is parsed, as for an older bake).

Reports the times, the ratios and how far the radiances differ from a fresh bake that
stores its visibility too (a stored visibility leaves the sky out of the traced
shadows' hand-over, ``shtools.scene.traced_shadows.sky_gain``, so a relight can
reproduce it).

Target: the ``shtools relight`` command >= 20x faster than the cold bake, the same
radiance to 1e-4 relative.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: A warmer sky than the demo's: per-channel gains of its SH.
WARM = np.array([1.25, 0.95, 0.7])
ROTATE_DEG = 90.0
RELIGHT_RUNS = 3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="6 frames, not 48")
    args = parser.parse_args(sys.argv[1:])
    from shtools.cache import SetupCache
    from shtools.data_formats.bake import read_bake
    from shtools.data_formats.light import read_light, write_light
    from shtools.demo import FRAMES, run_demo
    from shtools.scene.bake import bake_to_file
    from shtools.scene.relight import relight
    from shtools.scene.scene import load_scene

    frames = 6 if args.quick else FRAMES
    with tempfile.TemporaryDirectory() as tmp:
        demo = Path(tmp) / "demo"
        run_demo(demo, frames=frames, quiet=True)
        scene = demo / "scene.toml"
        cache = SetupCache(Path(tmp) / "cache")
        bake_to_file(load_scene(scene), demo / "a.h5", store_visibility=True, cache=cache)
        coeffs, attrs = read_light(demo / "sky.h5")
        write_light(demo / "warm.h5", coeffs * WARM, source="inline",
                    parameters={"window": (attrs.get("parameters") or {}).get("window")})
        text = scene.read_text()
        assert 'light = "sky.h5"' in text
        warm = demo / "warm.toml"
        warm.write_text(text.replace('light = "sky.h5"',
                                     f'light = "warm.h5"\nrotate_deg = {ROTATE_DEG}'))

        start = time.perf_counter()
        summary = bake_to_file(load_scene(warm), demo / "b.h5", cache=False)
        bake_s = time.perf_counter() - start
        start = time.perf_counter()
        warm_summary = bake_to_file(load_scene(warm), demo / "c.h5", cache=cache)
        warm_s = time.perf_counter() - start
        runs = []
        for _ in range(RELIGHT_RUNS):  # seconds each: the median of a few, on a shared machine
            start = time.perf_counter()
            relight(demo / "a.h5", demo / "warm.h5", demo / "relit.h5", rotate=ROTATE_DEG,
                    scene=scene)
            runs.append(time.perf_counter() - start)
        relight_s = float(np.median(runs))
        command = [sys.executable, "-m", "shtools.cli.main", "relight", str(demo / "a.h5"),
                   "--light", str(demo / "warm.h5"), "--rotate", str(ROTATE_DEG),
                   "--lights", str(scene), "-o", str(demo / "relit_cli.h5")]
        # bytecode as an installed package has it (pip compiles it), kept out of the tree
        env = dict(os.environ, PYTHONPYCACHEPREFIX=str(Path(tmp) / "pycache"))
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=env)
        cli_runs = []
        for _ in range(RELIGHT_RUNS):
            start = time.perf_counter()
            subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env=env)
            cli_runs.append(time.perf_counter() - start)
        cli_s = float(np.median(cli_runs))
        # the same without --lights: the environment alone, no scene parser imported
        plain = [*command[:command.index("--lights")], "-o", str(demo / "relit_env.h5")]
        env_runs = []
        for _ in range(RELIGHT_RUNS):
            start = time.perf_counter()
            subprocess.run(plain, check=True, stdout=subprocess.DEVNULL, env=env)
            env_runs.append(time.perf_counter() - start)
        env_s = float(np.median(env_runs))
        # the same lamp from a scene of other bytes: parsed (pydantic, every kind)
        copy = demo / "scene_copy.toml"
        copy.write_text(scene.read_text() + "\n# a copy: other bytes, the same lights\n")
        parsed = [*command[:command.index("--lights") + 1], str(copy), "-o",
                  str(demo / "relit_parsed.h5")]
        parsed_runs = []
        for _ in range(RELIGHT_RUNS):
            start = time.perf_counter()
            subprocess.run(parsed, check=True, stdout=subprocess.DEVNULL, env=env)
            parsed_runs.append(time.perf_counter() - start)
        parsed_s = float(np.median(parsed_runs))
        same_parsed = np.array_equal(read_bake(demo / "relit_parsed.h5").radiance,
                                     read_bake(demo / "relit_cli.h5").radiance)
        same_bytes = (demo / "relit_cli.h5").read_bytes() == (demo / "relit.h5").read_bytes()

        # the relight's reference: a fresh bake that stores its visibility too (whose
        # traced hand-over leaves the sky out, as the relit one's does)
        bake_to_file(load_scene(warm), demo / "d.h5", store_visibility=True, cache=cache)
        fresh = read_bake(demo / "d.h5").radiance
        relit = read_bake(demo / "relit.h5").radiance
        top = float(np.max(np.abs(fresh)))
        diff = np.abs(relit - fresh)
        # as the tests: rtol 1e-4, atol 1e-6 of the brightest value (deep shadows near 0)
        outside = int(np.sum(diff > 1e-4 * np.abs(fresh) + 1e-6 * top))
        lit = np.abs(fresh) > 1e-3 * top
        rel = float(np.max(diff[lit] / np.abs(fresh[lit])))
        print(f"## shtools relight vs a fresh bake — demo, {frames} frames x "
              f"{summary['vertices']:,} vertices{', --quick' if args.quick else ''}\n")
        print("| way | seconds | per frame ms |")
        print("|---|---|---|")
        print(f"| bake, no set-up cache (set-up {summary['setup_seconds']:.1f} s included) | "
              f"{bake_s:.2f} | {1000 * bake_s / frames:.1f} |")
        print(f"| bake, warm set-up cache (set-up {warm_summary['setup_seconds']:.1f} s) | "
              f"{warm_s:.2f} | {1000 * warm_s / frames:.1f} |")
        print(f"| bake, its frames' own times summed (over parallel processes: may pass "
              f"the wall time) | {summary['frame_seconds']:.2f} | "
              f"{1000 * summary['frame_seconds'] / frames:.1f} |")
        print(f"| relight() from Python (read, shade, write; median of {RELIGHT_RUNS}: "
              f"{min(runs):.2f}-{max(runs):.2f} s) | {relight_s:.2f} | "
              f"{1000 * relight_s / frames:.1f} |")
        print(f"| `shtools relight` command (process start and imports too; median of "
              f"{RELIGHT_RUNS}: {min(cli_runs):.2f}-{max(cli_runs):.2f} s) | {cli_s:.2f} | "
              f"{1000 * cli_s / frames:.1f} |")
        print(f"| `shtools relight` command without `--lights` (the environment only; "
              f"median of {RELIGHT_RUNS}: {min(env_runs):.2f}-"
              f"{max(env_runs):.2f} s) | {env_s:.2f} | {1000 * env_s / frames:.1f} |")
        print(f"| `shtools relight` command, the lamp from a copy of the scene (parsed; "
              f"median of {RELIGHT_RUNS}: {min(parsed_runs):.2f}-{max(parsed_runs):.2f} s) "
              f"| {parsed_s:.2f} | {1000 * parsed_s / frames:.1f} |")
        print(f"\nthe `shtools relight` command is {bake_s / cli_s:.1f}x faster than the bake "
              f"without a cache (target >= 20x), {warm_s / cli_s:.1f}x the bake with a warm "
              f"cache; without `--lights` {bake_s / env_s:.1f}x / {warm_s / env_s:.1f}x; "
              f"the lamp parsed {bake_s / parsed_s:.1f}x / {warm_s / parsed_s:.1f}x "
              f"({'the same' if same_parsed else 'NOT the same'} radiance); "
              f"relight() from Python {bake_s / relight_s:.1f}x / "
              f"{warm_s / relight_s:.1f}x; load average "
              f"{os.getloadavg()[0]:.1f} at the end; the command's output "
              f"is {'byte-identical to' if same_bytes else 'NOT the same bytes as'} "
              f"relight()'s; "
              f"max relative radiance difference {rel:.1e} where radiance > 1e-3 of the "
              f"brightest, {outside} of {diff.size:,} values outside rtol 1e-4 "
              f"(atol 1e-6 x brightest; target: 0)")


if __name__ == "__main__":
    main()
