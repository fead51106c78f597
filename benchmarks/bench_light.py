"""``shtools light project`` speed: load + exact per-pixel projection of real HDR probes.

Uses the lat-long probes in ../shared/data/probes when present (else a procedural
1024x512 sky), at SH orders 4, 8 and 16.  ``--quick`` runs order 4 only.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

PROBES = Path(__file__).resolve().parents[2] / "shared" / "data" / "probes"
ORDERS = (4, 8, 16)
REPEATS = 3


def _images():
    from shtools.lighting import load_hdr_image

    paths = sorted(PROBES.glob("*.hdr")) if PROBES.is_dir() else []
    if paths:
        for path in paths:
            start = time.perf_counter()
            image = load_hdr_image(path)
            yield path.name, image, time.perf_counter() - start
    else:
        from shtools.lighting import latlong_directions

        d = latlong_directions(512, 1024)
        sky = (1.0 + 3.0 * np.clip(d[..., 1], 0, None))[..., None] * np.array([0.6, 0.7, 1.0])
        yield "procedural sky", sky.astype(np.float32), 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    args, _ = parser.parse_known_args()
    from shtools.lighting import project_latlong

    orders = ORDERS[:1] if args.quick else ORDERS
    print("| image | size | load (ms) | order | project (ms, best of 3) | Mpixel/s |")
    print("|---|---|---:|---:|---:|---:|")
    for name, image, load_seconds in _images():
        height, width = image.shape[:2]
        for order in orders:
            best = np.inf
            for _ in range(1 if args.quick else REPEATS):
                start = time.perf_counter()
                project_latlong(image, order)
                best = min(best, time.perf_counter() - start)
            print(f"| {name} | {width}x{height} | {load_seconds * 1e3:.1f} | {order} "
                  f"| {best * 1e3:.1f} | {width * height / best / 1e6:.1f} |", flush=True)


if __name__ == "__main__":
    main()
