"""``shtools tables log`` wall time for SH orders 4, 6 and 8.

Measures the command as a user runs it (a fresh ``python -m shtools`` process:
interpreter start-up, imports, cold caches), the same command in-process, and
the in-process split into building the tables (warm) and writing the asset.
``--quick`` uses fewer cap radii so it finishes in seconds.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import subprocess
import sys
import tempfile
import time

ORDERS = (4, 6, 8)
SAMPLES = 256
QUICK_SAMPLES = 32


def time_tables_log(order: int, samples: int, directory: str) -> dict:
    """Wall times of ``tables log`` and of its two parts, in seconds."""
    from shtools.cli.main import main as shtools_main
    from shtools.data_formats.tables import write_tables
    from shtools.sh.tables import build_log_tables

    out = os.path.join(directory, f"tables{order}.h5")
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "shtools", "tables", "log", "--order", str(order),
                    "--samples", str(samples), "-o", out], check=True, capture_output=True)
    process_seconds = time.perf_counter() - start
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = shtools_main(["tables", "log", "--order", str(order), "--samples", str(samples),
                             "-o", out])
    cli_seconds = time.perf_counter() - start
    if code != 0:
        raise RuntimeError(f"shtools tables log --order {order} failed with exit {code}")
    start = time.perf_counter()
    built = build_log_tables(order, samples=samples)
    build_seconds = time.perf_counter() - start
    start = time.perf_counter()
    write_tables(os.path.join(directory, "w.h5"), built, order)
    write_seconds = time.perf_counter() - start
    return {"process": process_seconds, "cli": cli_seconds, "build": build_seconds,
            "write": write_seconds, "bytes": os.path.getsize(out), "ol": len(built["ol_norm"])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    args, _ = parser.parse_known_args()
    samples = QUICK_SAMPLES if args.quick else SAMPLES
    print("| order | cap radii | OL samples | `shtools tables log` process (s) "
          "| in-process (s) | build, warm (s) | write (s) | file (KiB) |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as directory:
        for order in ORDERS:
            t = time_tables_log(order, samples, directory)
            print(f"| {order} | {samples} | {t['ol']} | {t['process']:.2f} | {t['cli']:.2f} "
                  f"| {t['build']:.2f} | {t['write']:.3f} | {t['bytes'] / 1024:.0f} |",
                  flush=True)


if __name__ == "__main__":
    main()
