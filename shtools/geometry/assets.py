"""Geometry stages that write one asset each: fit a sphere set, build its tree.

What ``shtools spheres fit`` / ``shtools spheres tree`` run, callable from Python
(the demo and pipelines do): compute, then write the asset atomically with its
inputs and parameters recorded, so the same call gives the same bytes.
"""

from __future__ import annotations

import os
from collections.abc import Callable

import numpy as np

from shtools.errors import InputError


def fit_to_file(mesh_path: str | os.PathLike, count: int, output: str | os.PathLike, *,
                method: str = "variational", seed: int = 0, thickness: float | None = None,
                iterations: int | None = None, restarts: int = 1,
                progress: Callable[[int, float], None] | None = None):
    """Fit ``count`` spheres to the mesh file and write a ``spheres`` asset.

    Parameters are those of :func:`shtools.geometry.sphere_fit.fit_spheres`
    (``iterations`` is its ``max_iterations``); ``progress(iteration, energy)``
    is called as the fit goes.

    Returns
    -------
    SphereSet
    """
    from shtools.data_formats.spheres import write_spheres
    from shtools.geometry.mesh import load_mesh
    from shtools.geometry.sphere_fit import fit_spheres

    if count < 1:
        raise InputError(f"-n must be >= 1 (got {count})")
    if thickness is not None and not thickness > 0:
        raise InputError(f"--thickness must be > 0 (got {thickness})")
    mesh = load_mesh(mesh_path)
    result = fit_spheres(mesh, count, method=method, seed=seed, thickness=thickness,
                         max_iterations=iterations, path=mesh_path, progress=progress,
                         restarts=restarts)
    parameters = {"n": count, "method": method, "seed": seed, "thickness": thickness,
                  "iterations": iterations, "restarts": restarts}
    write_spheres(output, result, inputs={"mesh": mesh_path}, parameters=parameters)
    return result


def read_sphere_set(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``(N, 3)`` and radii ``(N,)`` of a ``spheres`` asset (validated)."""
    from shtools.data_formats import read_asset

    asset = read_asset(path, "spheres")
    return (np.asarray(asset["centers"], dtype=np.float64),
            np.asarray(asset["radii"], dtype=np.float64))


def tree_to_file(spheres_path: str | os.PathLike, output: str | os.PathLike, *,
                 branching: int = 4, seed: int = 0):
    """Build the sphere tree of a ``spheres`` asset and write a ``tree`` asset.

    Returns
    -------
    SphereTree
        As from :func:`shtools.geometry.sphere_tree.build_tree`.
    """
    from shtools.data_formats.tree import write_tree
    from shtools.geometry.sphere_tree import build_tree

    centers, radii = read_sphere_set(spheres_path)
    result = build_tree(centers, radii, branching=branching, seed=seed)
    write_tree(output, result, inputs={"spheres": spheres_path},
               parameters={"branching": branching, "seed": seed})
    return result
