"""Regenerate the golden bake ON PURPOSE (after an intended change of results).

    .venv/bin/python tests/golden/regenerate.py      # or: make golden

Writes ``post_spheres.h5`` (a hand-placed sphere set bounding the scene's
1.2 x 0.4 x 0.4 post: three spheres of radius sqrt(0.2^2 + 0.2^2 + 0.2^2) on its
axis, each bounding a 0.4-cube slab), ``golden.h5`` (the bake of
``scene.toml`` with the default method) and ``provenance.json`` (the commit and
the NumPy / h5py / Python versions that made them, so a later mismatch can be
traced to a code or a library change).  Review the change with
``shtools diff NEW OLD`` before committing the new files.
"""

from __future__ import annotations

import json
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def write_post_spheres(path: Path) -> None:
    from shtools.data_formats.spheres import write_spheres
    from shtools.geometry.sphere_set import SphereSet

    centers = np.array([[0.0, -0.4, 0.0], [0.0, 0.0, 0.0], [0.0, 0.4, 0.0]])
    radii = np.full(3, np.sqrt(3 * 0.2 ** 2))  # circumradius of each 0.4 cube slab
    write_spheres(path, SphereSet(centers, radii, method="hand-placed"))


def provenance() -> dict:
    """Commit (with a ``-dirty`` mark for uncommitted changes) and library versions."""
    import h5py

    def git(*args):
        try:
            return subprocess.run(["git", *args], cwd=HERE, capture_output=True, text=True,
                                  check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return None

    commit = git("rev-parse", "HEAD")
    if commit and git("status", "--porcelain", "--untracked-files=no"):
        commit += "-dirty"
    return {"commit": commit, "numpy": np.__version__, "h5py": h5py.__version__,
            "hdf5": h5py.version.hdf5_version, "python": platform.python_version(),
            "machine": platform.machine()}


def main() -> int:
    from shtools.scene.bake import bake_to_file
    from shtools.scene.scene import load_scene

    made_by = provenance()  # before writing: the files it rewrites are not "changes"
    write_post_spheres(HERE / "post_spheres.h5")
    summary = bake_to_file(load_scene(HERE / "scene.toml"), HERE / "golden.h5")
    (HERE / "provenance.json").write_text(json.dumps(made_by, indent=2) + "\n")
    print(f"wrote {HERE / 'golden.h5'}: {summary['frames']} frames x {summary['vertices']} "
          "vertices")
    return 0


if __name__ == "__main__":
    sys.exit(main())
