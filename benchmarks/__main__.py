"""Run every benchmark: ``python -m benchmarks [--quick] [-k NAME ...]`` (``make bench``).

Discovers ``benchmarks/bench_*.py`` next to this file, imports each and calls its
``main()`` with ``sys.argv`` set to ``[module, *passed-through options]`` (so a
module parses ``--quick`` itself with argparse).  One failing benchmark does not
stop the others; the exit status is 1 if any failed.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent


def discover(names: list[str] | None = None) -> list[Path]:
    """Benchmark modules, sorted; ``names`` filters by substring of the file name."""
    found = sorted(HERE.glob("bench_*.py"))
    if names:
        found = [p for p in found if any(n in p.stem for n in names)]
    return found


def run_module(path: Path, passthrough: list[str]) -> bool:
    """Import ``path`` and run its ``main()``; True on success."""
    spec = importlib.util.spec_from_file_location(f"benchmarks.{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    saved = sys.argv
    sys.argv = [str(path), *passthrough]
    try:
        spec.loader.exec_module(module)
        module.main()
    except SystemExit as exc:  # argparse or an explicit exit inside main()
        return exc.code in (0, None)
    except Exception:
        traceback.print_exc()
        return False
    finally:
        sys.argv = saved
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="small sizes, for a smoke run")
    parser.add_argument("-k", dest="names", action="append", metavar="NAME",
                        help="only benchmarks whose file name contains NAME (repeatable)")
    args, rest = parser.parse_known_args(argv)
    passthrough = (["--quick"] if args.quick else []) + rest
    modules = discover(args.names)
    if not modules:
        print("no benchmarks found", file=sys.stderr)
        return 1
    failed = []
    for path in modules:
        print(f"\n## {path.stem}{' (quick)' if args.quick else ''}\n", flush=True)
        start = time.perf_counter()
        if not run_module(path, passthrough):
            failed.append(path.stem)
        print(f"\n_{path.stem}: {time.perf_counter() - start:.1f} s_", flush=True)
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
