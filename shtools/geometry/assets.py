"""Geometry stages that write one asset each: fit a sphere set, build its tree.

What ``shtools spheres fit`` / ``shtools spheres tree`` run, callable from Python
(the demo and pipelines do): compute, then write the asset atomically with its
inputs and parameters recorded, so the same call gives the same bytes.
"""

from __future__ import annotations

import os

import numpy as np

from shtools.errors import InputError


def fit_to_file(mesh_path: str | os.PathLike, count: int, output: str | os.PathLike, *,
                method: str = "variational", seed: int = 0, thickness: float | None = None,
                iterations: int | None = None, restarts: int = 1, progress=None):
    """Fit ``count`` spheres to the mesh file and write a ``spheres`` asset.

    Parameters are those of :func:`shtools.geometry.sphere_fit.fit_spheres`
    (``iterations`` is its ``max_iterations``); ``progress`` is a progress
    factory (:mod:`shtools.progress`).

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


def batch_outputs(mesh_paths, out_dir: str | os.PathLike) -> list:
    """Output paths ``OUT_DIR/<mesh stem>.spheres.h5`` of a batch fit, one per mesh.

    Raises
    ------
    InputError
        ``out_dir`` is not an existing folder, or two meshes would write the
        same file (same stem in different folders).
    """
    from pathlib import Path

    if not Path(out_dir).is_dir():
        raise InputError("is not a folder; create it first (a batch fit writes "
                         "<mesh stem>.spheres.h5 files into it)", out_dir)
    outputs = [Path(out_dir) / f"{Path(m).stem}.spheres.h5" for m in mesh_paths]
    seen: dict = {}
    for mesh, out in zip(mesh_paths, outputs, strict=True):
        if out in seen:
            raise InputError(f"{seen[out]} and {mesh} would both write {out.name}; "
                             "fit them in separate runs or rename one", mesh)
        seen[out] = mesh
    return outputs


def _fit_task(options: dict, item: tuple):
    """Task body of :func:`fit_many`: one mesh -> one asset (written by the worker)."""
    mesh_path, output = item
    result = fit_to_file(mesh_path, options["count"], output, method=options["method"],
                         seed=options["seed"], thickness=options["thickness"],
                         iterations=options["iterations"], restarts=options["restarts"])
    return {"mesh": str(mesh_path), "output": str(output), "spheres": len(result),
            "outside_volume_ratio": result.outside_volume_ratio,
            "coverage": result.coverage,
            "seconds": round(result.info.get("seconds", 0.0), 3)}


def fit_many(mesh_paths, out_dir: str | os.PathLike, count: int, *,
             method: str = "variational", seed: int = 0, thickness: float | None = None,
             iterations: int | None = None, restarts: int = 1,
             scheduler: str | None = None, workers: int | None = None,
             pool_summary: dict | None = None):
    """Fit every mesh, one task each, on local cores or a Dask cluster.

    Each task fits one mesh and writes ``OUT_DIR/<stem>.spheres.h5`` atomically
    (:func:`fit_to_file`), so an interrupted batch leaves only complete assets
    and a rerun under ``make`` redoes only what is missing.  The fit is a pure
    function of the mesh and the options (fixed seeds): the assets are the same
    bytes whichever worker made them.  With a remote cluster the mesh paths and
    ``out_dir`` must be on storage the workers share.

    Parameters
    ----------
    mesh_paths : sequence of path-like
    out_dir : path-like
        Existing folder for the assets.
    count, method, seed, thickness, iterations, restarts
        As :func:`fit_to_file`.
    scheduler, workers
        As :func:`shtools.tasks.task_pool`.
    pool_summary : dict, optional
        Filled with the scheduler's per-worker task counts and times.

    Yields
    ------
    dict
        Per mesh, in the order given: ``mesh``, ``output``, ``spheres``,
        ``outside_volume_ratio``, ``coverage``, ``seconds``.
    """

    from shtools.tasks import task_pool

    outputs = batch_outputs(mesh_paths, out_dir)
    options = {"count": count, "method": method, "seed": seed, "thickness": thickness,
               "iterations": iterations, "restarts": restarts}
    with task_pool(scheduler, workers, n_tasks=len(outputs)) as pool:
        yield from pool.map_ordered(_fit_task, list(zip(mesh_paths, outputs, strict=True)),
                                    shared=options, window=pool.workers)
        if pool_summary is not None:
            pool_summary.update(pool.summary())


def read_sphere_set(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Centres ``(N, 3)`` and radii ``(N,)`` of a ``spheres`` asset (validated)."""
    from shtools.data_formats import read_asset

    asset = read_asset(path, "spheres")
    return (np.asarray(asset["centers"], dtype=np.float64),
            np.asarray(asset["radii"], dtype=np.float64))


def tree_to_file(spheres_path: str | os.PathLike, output: str | os.PathLike, *,
                 branching: int = 4, seed: int = 0, progress=None):
    """Build the sphere tree of a ``spheres`` asset and write a ``tree`` asset.

    ``progress`` is a progress factory (:mod:`shtools.progress`).

    Returns
    -------
    SphereTree
        As from :func:`shtools.geometry.sphere_tree.build_tree`.
    """
    from shtools.data_formats.tree import write_tree
    from shtools.geometry.sphere_tree import build_tree

    centers, radii = read_sphere_set(spheres_path)
    result = build_tree(centers, radii, branching=branching, seed=seed, progress=progress)
    write_tree(output, result, inputs={"spheres": spheres_path},
               parameters={"branching": branching, "seed": seed})
    return result
