"""The ``.sph`` sphere-tree text format of spheretree (Bradshaw & O'Sullivan).

Layout, as written by spheretree and read by ShadowSG and shexp-demo::

    LEVELS BRANCHING
    x y z r err        <- node 0 (root), then level 1 (BRANCHING nodes), ...
    ...

Level ``l`` holds ``BRANCHING**l`` lines (a complete tree, breadth first); unused
nodes have ``r <= 0``.  Every line has five numbers: centre, radius and the
construction error (ignored on reading).  A flat sphere set is written as a
two-level tree: the root bounds every sphere, the N spheres form level 1 with
branching factor N.
"""

from __future__ import annotations

import os

import numpy as np

from shtools.data_formats import atomic_path
from shtools.errors import InputError
from shtools.geometry.sphere_set import SphereSet


def read_sph(path: str | os.PathLike, *, level: int | None = None) -> SphereSet:
    """Read the spheres of one level of a ``.sph`` tree (the leaves by default).

    Parameters
    ----------
    path : path-like
    level : int, optional
        Tree level to read (0 = root); default the deepest level that holds a
        sphere with ``r > 0``.

    Returns
    -------
    SphereSet
        ``outside_volume_ratio`` and ``coverage`` are NaN (the file has no mesh).

    Raises
    ------
    InputError
        Missing file, bad header, malformed line, too few lines, no spheres.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise InputError("sphere file not found; check the path", path)
    if not os.path.isfile(path):  # a pipe or device would block the read
        raise InputError("is not a regular file (a folder, pipe or device)", path)
    try:
        with open(path, encoding="utf-8", errors="strict") as fh:
            lines = [ln.split() for ln in fh if ln.strip()]
    except (OSError, UnicodeDecodeError):
        raise InputError("cannot read the file as .sph text", path) from None
    if not lines or len(lines[0]) < 2:
        raise InputError("missing the 'LEVELS BRANCHING' header line of a .sph file", path)
    try:
        levels, branching = int(lines[0][0]), int(lines[0][1])
    except ValueError:
        raise InputError("the header must be two integers 'LEVELS BRANCHING'", path) from None
    if levels < 1 or branching < 1:
        raise InputError(f"invalid header: {levels} levels, branching {branching}", path)
    # a header can promise astronomically many nodes (1e9 levels): stop counting as
    # soon as the promise exceeds the lines the file holds
    available = len(lines) - 1
    sizes, total = [], 0
    for lev in range(levels):
        sizes.append(branching**lev)
        total += sizes[-1]
        if total > available:
            raise InputError(
                f"the header promises {levels} levels of branching {branching} (more than "
                f"{available} nodes) but the file has {available} sphere lines; it is "
                "truncated or the header is wrong", path)
    body = lines[1 : 1 + total]
    try:
        nodes = np.array([[float(t) for t in row[:5]] for row in body], dtype=np.float64)
    except ValueError:
        raise InputError("a sphere line holds something other than numbers", path) from None
    if nodes.shape[1] < 4 or any(len(row) < 4 for row in body):
        raise InputError("every sphere line needs 'x y z r [err]'", path)
    if not np.all(np.isfinite(nodes[:, :4])):
        raise InputError("sphere coordinates contain NaN or inf", path)
    starts = np.cumsum([0, *sizes])
    per_level = [nodes[starts[i] : starts[i + 1], :4] for i in range(levels)]
    if level is None:
        filled = [i for i, lv in enumerate(per_level) if np.any(lv[:, 3] > 0)]
        if not filled:
            raise InputError("the file holds no sphere with a positive radius", path)
        level = filled[-1]
    if not 0 <= level < levels:
        raise InputError(f"level {level} does not exist (the tree has {levels})", path)
    chosen = per_level[level]
    chosen = chosen[chosen[:, 3] > 0]
    if len(chosen) == 0:
        raise InputError(f"level {level} holds no sphere with a positive radius", path)
    return SphereSet(chosen[:, :3], chosen[:, 3], method="import", info={"levels": levels,
                                                                        "branching": branching,
                                                                        "level": level})


def write_sph(path: str | os.PathLike, spheres: SphereSet) -> None:
    """Write a sphere set as a two-level ``.sph`` tree (atomically).

    Parameters
    ----------
    path : path-like
    spheres : SphereSet
        ``centers (N, 3)``, ``radii (N,)``.  The root is a sphere bounding all
        of them; the error column holds each sphere's radius-free placeholder 0.
    """
    from shtools.geometry.bounding import minimal_enclosing_sphere

    centers = np.asarray(spheres.centers, dtype=np.float64)
    radii = np.asarray(spheres.radii, dtype=np.float64)
    root_c, root_r = minimal_enclosing_sphere(centers, radii)
    rows = [f"2 {len(radii)}", _row(root_c, root_r)]
    rows += [_row(c, r) for c, r in zip(centers, radii, strict=True)]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(rows) + "\n", encoding="utf-8")


def _row(c, r) -> str:
    # repr-precision floats so that a write/read round trip is exact
    return f"{float(c[0])!r} {float(c[1])!r} {float(c[2])!r} {float(r)!r} 0"
