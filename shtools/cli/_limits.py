"""The size limits of the commands: every request is costed from its options before work.

Each command estimates what its options will cost -- bytes of working memory,
rays to cast, pixels to hold -- from the options alone (or with the mesh's
vertex count once it is read), before any long work, and refuses a request
past the stated limit with one line giving the size, the limit and the way
out::

    error: mesh.obj: field sample needs 1,056.0 GiB of memory (256 shells x 4096^2
    samples x 16 SH coefficients x 16 bytes, plus ...), above the limit of 4.0 GiB;
    lower --shells, --resolution, --map or --order, or pass --force to run anyway

``--force`` (:func:`force_option`) goes past the memory and ray limits, as
``bake --force`` does for the bake's size; an estimate that is still too big
for the machine then ends in the one-line "out of memory" error of
:mod:`shtools.cli.main`.  Image sizes have a hard limit (:data:`MAX_PIXELS`,
:class:`ImageSize`).
"""

from __future__ import annotations

import os

import click

from shtools.errors import InputError

#: Working memory a stage may plan without --force: well inside a laptop's RAM, far
#: above what the defaults plan (tests/test_bad_inputs_stages.py checks the field's).
MEMORY_LIMIT = 4 * 2**30
#: Rays a stage may cast without --force: hours of ray casting on a few cores.
RAY_LIMIT = 2 * 10**10
#: Largest image (or contact-sheet tile) in pixels: 8192 x 8192, ~1 GiB of raster
#: buffers (colour, depth, weights at ~16 bytes a pixel).
MAX_PIXELS = 8192 * 8192
#: Raster bytes per pixel of a preview (colour, depth and weights, float32).
PIXEL_BYTES = 16


def force_option(limits: str):
    """``--force`` of a command whose ``limits`` (a phrase for the help) it may exceed."""
    return click.option("--force", is_flag=True,
                        help=f"Run even past the size limits ({limits}).")


def _gib(nbytes: float) -> str:
    return f"{nbytes / 2**30:,.1f} GiB"


def check_memory(what: str, nbytes: float, formula: str, fix: str, *, force: bool = False,
                 path: str | os.PathLike | None = None, limit: float | None = None) -> None:
    """Refuse ``what`` when it plans more than ``limit`` bytes, unless ``force``.

    Parameters
    ----------
    what : str
        The stage, e.g. ``"field sample"``.
    nbytes : float
        Its estimated peak memory in bytes.
    formula : str
        How the estimate was made (the options that set it), shown in brackets.
    fix : str
        The options to lower, e.g. ``"lower --shells/--resolution"``.
    force : bool
        ``--force`` was given: no check.
    path : path-like, optional
        The file the line names (the main input).
    limit : float, optional
        Bytes allowed (default :data:`MEMORY_LIMIT`).

    Raises
    ------
    InputError
        Naming the size, the limit, ``fix`` and ``--force``.
    """
    limit = MEMORY_LIMIT if limit is None else limit
    if force or nbytes <= limit:
        return
    raise InputError(f"{what} needs {_gib(nbytes)} of memory ({formula}), above the limit "
                     f"of {_gib(limit)}; {fix}, or pass --force to run anyway", path)


def check_rays(what: str, rays: float, formula: str, fix: str, *, force: bool = False,
               path: str | os.PathLike | None = None, limit: float | None = None) -> None:
    """Refuse ``what`` when it casts more than ``limit`` rays (default :data:`RAY_LIMIT`),
    unless ``force`` (as :func:`check_memory`)."""
    limit = RAY_LIMIT if limit is None else limit
    if force or rays <= limit:
        return
    raise InputError(f"{what} casts {rays:.3g} rays ({formula}), above the limit of "
                     f"{limit:.3g}; {fix}, or pass --force to run anyway", path)


def asset_bytes(path: str | os.PathLike) -> int:
    """Bytes an asset's datasets take in memory, uncompressed (what its reader loads), from
    the HDF5 metadata alone; 0 when it is not readable HDF5 (its reader then says why)."""
    import h5py

    total = 0
    try:
        with h5py.File(path, "r") as f:
            def add(_, obj):
                nonlocal total
                if isinstance(obj, h5py.Dataset):
                    total += int(obj.size) * obj.dtype.itemsize
            f.visititems(add)
    except (OSError, ValueError):
        return 0
    return total


def check_asset_memory(what: str, path: str | os.PathLike, fix: str, *,
                       force: bool = False, factor: float = 1.0) -> None:
    """Refuse a command that loads the asset ``path`` whole (``factor`` times its datasets,
    :func:`asset_bytes`) past :data:`MEMORY_LIMIT`, unless ``force`` -- before reading a
    byte of its data."""
    nbytes = factor * asset_bytes(path)
    check_memory(what, nbytes, f"{os.path.basename(os.fspath(path))}'s datasets, uncompressed"
                 + (f", x {factor:g}" if factor != 1 else ""), fix, force=force, path=path)


def pixel_problem(width: int, height: int) -> str | None:
    """Why an image of ``width x height`` is refused (past :data:`MAX_PIXELS`), or None."""
    pixels = width * height
    if pixels <= MAX_PIXELS:
        return None
    return (f"{width} x {height} is {pixels:,} pixels ({_gib(pixels * PIXEL_BYTES)} of raster "
            f"buffers), above the limit of {MAX_PIXELS:,} (8192 x 8192); use a smaller image")


class ImageSize(click.Tuple):
    """``--size W H`` of an image: sides of at least 8 pixels and at most :data:`MAX_PIXELS`
    pixels in all, refused while parsing with the size the image would take."""

    name = "image size"

    def __init__(self):
        super().__init__([click.IntRange(8, None), click.IntRange(8, None)])

    def convert(self, value, param, ctx):
        width, height = super().convert(value, param, ctx)
        problem = pixel_problem(width, height)
        if problem:
            self.fail(problem, param, ctx)
        return width, height
