"""What each optional extra promises, checked in a venv that holds that extra alone.

``make test-extras`` installs ``shtools[EXTRA]`` by itself into a fresh venv for
every extra listed here and runs ``python -P .ci/extras.py EXTRA`` there: every
module the extra's documentation names (``pyproject.toml``'s comments, README)
must import -- a package of shtools with all its submodules -- and a small call of what
the extra is for must run.  ``python .ci/extras.py --list`` prints the extras
(the Makefile's loop).  A new extra is one more entry in :data:`EXTRAS`.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import tempfile
from pathlib import Path


def _fit_spheres() -> None:
    """``pip install 'shtools[geometry]'`` then ``fit_spheres``: the sphere fit runs."""
    import trimesh

    from shtools.geometry.sphere_fit import fit_spheres

    fit = fit_spheres(trimesh.creation.box(extents=[1.0, 0.5, 0.5]), 2, max_iterations=2)
    assert len(fit.radii) == 2, fit


def _tiny_bake(folder: Path):
    """A one-triangle, two-frame bake asset (the core's writer and reader)."""
    import numpy as np

    from shtools.data_formats.bake import read_bake, write_bake

    path = folder / "baked.h5"
    write_bake(path, vertices=np.eye(3), normals=np.tile([0.0, 1.0, 0.0], (3, 1)),
               faces=np.array([[0, 1, 2]]), radiance=np.full((2, 3, 3), 0.5), sh_order=2,
               frame_index=[0, 1], times=[0.0, 1 / 24], fps=24.0)
    return read_bake(path)


def _png() -> None:
    import numpy as np

    from shtools.export.png import save_png

    with tempfile.TemporaryDirectory() as tmp:
        save_png(np.zeros((4, 4, 3), np.uint8), Path(tmp) / "x.png")


def _cli_help() -> None:
    """``shtools --help`` lists every command (each imported to read its help)."""
    import contextlib
    import io

    from shtools.cli.main import main

    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        try:
            code = main(["--help"])
        except SystemExit as stop:  # click's standalone mode
            code = stop.code
    assert code in (0, None) and "export" in text.getvalue(), (code, text.getvalue())


def _plot() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.figure().savefig(Path(tempfile.mkdtemp()) / "x.png")


def _usd() -> None:
    from shtools.export.usd import write_usd

    with tempfile.TemporaryDirectory() as tmp:
        bake = _tiny_bake(Path(tmp))
        write_usd(Path(tmp) / "x.usda", bake, [0, 1])


def _dask() -> None:
    """An in-process Dask client runs a task (the client ``bake --scheduler`` uses)."""
    from dask.distributed import Client

    with Client(processes=False, n_workers=1, threads_per_worker=1,
                dashboard_address=None) as client:
        assert client.submit(sum, [1, 2]).result() == 3


def _view() -> None:
    """The viewer's colours of a tiny bake (what its page draws) and its command."""
    from shtools.view import BakeView

    with tempfile.TemporaryDirectory() as tmp:
        _tiny_bake(Path(tmp))
        view = BakeView(Path(tmp) / "baked.h5")
        assert len(view.colors(1, "radiance")) == 3 * 3, view.summary()


#: extra -> (modules or packages it makes importable, a call that must run)
EXTRAS = {
    "geometry": (["shtools.geometry", "shtools.reference", "shtools.scene",
                  "shtools.export.gltf", "shtools.export.animated", "shtools.export.rig"],
                 _fit_spheres),
    "image": (["shtools.lighting.images", "shtools.export.png"], _png),
    "cli": (["shtools.cli"], _cli_help),
    "plots": (["matplotlib.pyplot"], _plot),
    "usd": (["shtools.export.usd"], _usd),
    "distributed": (["dask.distributed", "shtools.tasks"], _dask),
    "view": (["shtools.view", "shtools.cli.view"], _view),
}


def _import_all(name: str, failed: list[str]) -> None:
    """Import ``name`` and, for a package, each of its submodules; note each failure."""
    try:
        module = importlib.import_module(name)
    except Exception as exc:  # report every failure, not only the first
        failed.append(f"{name}: {type(exc).__name__}: {exc}")
        return
    if not name.startswith("shtools"):  # another project's package: its own extras
        return
    for sub in pkgutil.iter_modules(getattr(module, "__path__", []), name + "."):
        _import_all(sub.name, failed)


def check(extra: str) -> int:
    """Import every promised module of ``extra`` and run its call; print what failed."""
    names, call = EXTRAS[extra]
    failed: list[str] = []
    for name in names:
        _import_all(name, failed)
    if not failed:
        try:
            call()
        except Exception as exc:
            failed.append(f"{call.__name__}: {type(exc).__name__}: {exc}")
    for line in failed:
        print(f"shtools[{extra}]: {line}", file=sys.stderr)
    print(f"shtools[{extra}] alone: {'FAILED' if failed else 'ok'}")
    return 1 if failed else 0


if __name__ == "__main__":
    if sys.argv[1:] == ["--list"]:
        print(" ".join(EXTRAS))
        sys.exit(0)
    if len(sys.argv) != 2 or sys.argv[1] not in EXTRAS:
        sys.exit(f"usage: {sys.argv[0]} --list | EXTRA (one of {', '.join(EXTRAS)})")
    sys.exit(check(sys.argv[1]))
