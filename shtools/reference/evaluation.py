"""Method comparison behind ``shtools eval`` (the paper's Figures 7 and 9 as a table).

A *method spec* is a name with an optional ``@N`` accumulation order:
``auto`` (the runtime's defaults), an exp method of the log-space runtime
(``hyb``, ``ps*``, ``ps``, ``ol``, ``exact``, ``volterra``), or ``product``
(product-space accumulation, the baseline).  ``hyb@4`` accumulates at order
4, ``product@6`` multiplies at order 6; both are truncated to the shading order.
Without ``@N`` every method uses the same accumulation order (the runtime's
default, or ``--acc-order``), so baselines are compared at equal order.

Every method is shaded identically (:meth:`shtools.runtime.ShadowRuntime.shade`)
and compared with ray tracing of the real meshes and of the sphere set (after
the self-shadow rules), by relative RMSE of per-vertex radiance.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shtools.errors import InputError
from shtools.reference.metrics import relative_rmse
from shtools.reference.product_space import product_space_visibility
from shtools.reference.raytrace import (
    DEFAULT_DIRECTIONS,
    raytrace_visibility,
    sphere_union_visibility,
)
from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker
from shtools.runtime.hierarchy import leaf_spheres
from shtools.runtime.settings import RUNTIME_EXP_METHODS

METHOD_NAMES = (*RUNTIME_EXP_METHODS, "product")


@dataclass
class EvalInputs:
    """One evaluation scene: receivers, blockers, their meshes and the lights.

    Attributes
    ----------
    name : str
    vertices, normals : ndarray, shape (V, 3)
    groups : ndarray of int, shape (V,), or None
        Object id per receiver vertex (clusters never span two objects).
    blockers : list of SphereBlocker
    meshes : list of trimesh.Trimesh
        The blockers' real meshes (ray-traced reference).
    env : ndarray, shape (n*n, 3) or None
    lights : list of SphereLight
    settings : dict
        The scene's runtime settings (``order``, ``acc_order``, ``window``, ...).
    tables : dict or None
        Log tables the scene names.
    """

    name: str
    vertices: np.ndarray
    normals: np.ndarray
    groups: np.ndarray | None
    blockers: list
    meshes: list
    env: np.ndarray | None
    lights: list
    settings: dict
    tables: dict | None = None


def eval_settings(inputs: EvalInputs, *, order: int | None = None,
                  acc_order: int | None = None, window: bool = True,
                  hierarchy: bool = True) -> ShadowSettings:
    """The runtime settings of an evaluation: the scene's, overridden by the caller's.

    One process (the method times compare with single-process references).
    """
    base = inputs.settings
    kwargs = {"order": base.get("order", order or 4)}
    for key in ("window_h", "theta_max", "theta_min", "vertices_per_cluster"):
        if base.get(key) is not None:
            kwargs[key] = base[key]
    kwargs["window"] = base.get("window", "cosine") if window else None
    kwargs["hierarchy"] = base.get("hierarchy", True) if hierarchy else False
    if acc_order is not None:
        kwargs["acc_order"] = acc_order
    elif base.get("acc_order") is not None:
        kwargs["acc_order"] = base["acc_order"]
    if kwargs.get("acc_order") is not None and kwargs["acc_order"] < kwargs["order"]:
        raise InputError(f"--acc-order {kwargs['acc_order']} is below the order {kwargs['order']}")
    return ShadowSettings(processes=1, **kwargs)


def mesh_eval_inputs(mesh_path, spheres_path, tree_path=None, light_path=None, *,
                     grid: int = 64, gap: float = 0.0, order: int = 4) -> EvalInputs:
    """The built-in evaluation scene: the mesh over a ground grid touching its lowest point.

    Parameters
    ----------
    mesh_path, spheres_path : path-like
        The blocker mesh and its sphere set (spheres asset).
    tree_path : path-like, optional
        A tree asset over the set (enables the hierarchy).
    light_path : path-like, optional
        Environment light asset (default: a procedural sky).
    grid : int
        Ground receivers per side.
    gap : float
        Gap between ground and mesh, as a fraction of the mesh height.
    order : int
        Shading SH order.
    """
    from shtools.data_formats.spheres import read_spheres
    from shtools.geometry.mesh import load_mesh
    from shtools.reference.scenes import mesh_scene

    mesh = load_mesh(mesh_path)
    sph = read_spheres(spheres_path)
    tree = None
    if tree_path is not None:
        from shtools.data_formats.tree import read_tree

        t = read_tree(tree_path)
        if int((t.leaf >= 0).sum()) != len(sph.radii):
            raise InputError(f"the tree has {int((t.leaf >= 0).sum())} leaves but the sphere "
                             f"set has {len(sph.radii)} spheres; rebuild it from this set",
                             tree_path)
        tree = (t.parent, t.leaf)
    env = None
    if light_path is not None:
        from shtools.data_formats.light import read_light

        env, _ = read_light(light_path)
    sc = mesh_scene(mesh, sph.centers, sph.radii, grid=grid, order=order, tree=tree,
                    env_sh=env, gap=gap)
    return EvalInputs(Path(mesh_path).name, sc.vertices, sc.normals, None,
                      [SphereBlocker(sc.centers, sc.radii, tree=tree)], sc.meshes, sc.env_sh,
                      [], {"order": order, "hierarchy": tree is not None})




@dataclass
class MethodResult:
    """One row of the comparison."""

    method: str
    rmse_mesh: float
    rmse_spheres: float
    seconds: float
    radiance: np.ndarray


def parse_methods(text: str) -> list[tuple[str, str, int | None]]:
    """``"hyb,ps*@6,product"`` -> ``[(label, name, acc_order or None), ...]``."""
    out = []
    for item in (t.strip() for t in text.split(",")):
        if not item:
            continue
        name, _, acc = item.partition("@")
        name = name.lower()
        if name not in METHOD_NAMES:
            raise InputError(f"unknown method {name!r}; use one of {', '.join(METHOD_NAMES)} "
                             "(optionally with @N for the accumulation order)")
        acc_order = None
        if acc:
            if not acc.isdigit() or not 1 <= int(acc) <= 10:
                raise InputError(f"bad accumulation order in {item!r}; write e.g. hyb@6")
            acc_order = int(acc)
        out.append((item, name, acc_order))
    if not out:
        raise InputError("no methods given; e.g. --methods hyb,ps*,product")
    return out


def evaluate(vertices, normals, blockers: list[SphereBlocker], meshes, env_sh, lights,
             settings: ShadowSettings, methods: str, *, clusters=None,
             tables: dict | None = None, n_dirs: int = DEFAULT_DIRECTIONS) -> dict:
    """Run the methods and the two ray-traced references on one frame.

    Parameters
    ----------
    vertices, normals : ndarray, shape (V, 3)
    blockers : list of SphereBlocker
    meshes : list of trimesh.Trimesh
        Actual blocker geometry.
    env_sh : ndarray, shape (n*n, 3) or None
    lights : list of SphereLight
    settings : ShadowSettings
        Base settings (order, window, hierarchy, ...); methods override the exp
        method and accumulation order.
    methods : str
        Comma-separated method specs (see the module docstring).
    clusters : ReceiverClusters, optional
    tables : dict, optional
        Log tables (used when their order matches a method's accumulation order).
    n_dirs : int
        Ray-tracing directions per vertex.

    Returns
    -------
    dict
        ``references``: {"mesh": seconds, "spheres": (rmse vs mesh, seconds)},
        ``results``: list of :class:`MethodResult`, and the radiance arrays of the
        references (``mesh_radiance``, ``spheres_radiance``).
    """
    specs = parse_methods(methods)
    order = settings.order
    shader = ShadowRuntime(dataclasses.replace(settings, acc_order=order, exp_method="ol"))

    def shade(g):
        return shader.shade(g, vertices, normals, env_sh, lights)

    t0 = time.perf_counter()
    g_mesh = raytrace_visibility(vertices, normals, meshes, order, n_dirs)
    t_mesh = time.perf_counter() - t0
    centers, radii = leaf_spheres(blockers)
    t0 = time.perf_counter()
    g_sph = sphere_union_visibility(vertices, normals, centers, radii, order, n_dirs)
    t_sph = time.perf_counter() - t0
    r_mesh, r_sph = shade(g_mesh), shade(g_sph)
    results = []
    for label, name, acc in specs:
        if name == "product":
            t0 = time.perf_counter()
            # without @N: the runtime's accumulation order, like the SHEXP rows
            g = product_space_visibility(vertices, normals, (centers, radii), order,
                                         acc if acc is not None else
                                         settings.resolved_acc_order())
            seconds = time.perf_counter() - t0
        else:
            s = dataclasses.replace(settings, exp_method=name,
                                    acc_order=acc if acc is not None else settings.acc_order)
            acc_order = s.resolved_acc_order()
            use_tables = tables if tables is not None and np.asarray(
                tables["log_zh"]).shape[-1] == acc_order else None
            rt = ShadowRuntime(s, tables=use_tables)
            rt.visibility(vertices, normals, blockers, clusters)  # warm-up (tables, buffers)
            t0 = time.perf_counter()
            g = rt.visibility(vertices, normals, blockers, clusters)
            seconds = time.perf_counter() - t0
        rad = shade(g)
        results.append(MethodResult(label, relative_rmse(rad, r_mesh), relative_rmse(rad, r_sph),
                                    seconds, rad))
    return {
        "references": {"mesh_seconds": t_mesh, "spheres_seconds": t_sph,
                       "spheres_rmse_mesh": relative_rmse(r_sph, r_mesh)},
        "results": results,
        "mesh_radiance": r_mesh,
        "spheres_radiance": r_sph,
    }
