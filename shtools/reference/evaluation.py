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

:func:`error_split` splits a method's error per receiver object into where it
comes from: the **sphere approximation** (sphere union vs real mesh,
both ray traced), **SHEXP** (the method vs the sphere union it approximates),
**truncation** (order-``n`` windowed shading of the real visibility vs the
exact integral of the binary visibility against the same windowed order-``n``
environment, environment only) and **ringing** (the norm of the negative radiance the
method leaves, relative to the reference).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shtools.errors import InputError
from shtools.reference.metrics import relative_rmse
from shtools.reference.product_space import product_space_visibility
from shtools.reference.raytrace import (
    DEFAULT_DIRECTIONS,
    sphere_union_visibility,
)
from shtools.runtime import (
    FieldBlocker,
    ShadowRuntime,
    ShadowSettings,
    SphereBlocker,
    field_product_visibility,
)
from shtools.runtime.hierarchy import leaf_spheres
from shtools.runtime.settings import EXP_CHOICES

METHOD_NAMES = (*EXP_CHOICES, "product")


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
    #: name of each receiver group (``groups`` indexes it; one "ground" when None)
    receiver_names: list = field(default_factory=lambda: ["ground"])
    #: exact self-shadowing of rigid objects (runtime SelfVisibility), for the methods
    self_visibility: list = field(default_factory=list)
    #: each receiver group's triangles (indices into its own vertices), for the look
    #: measures (:mod:`shtools.reference.look`); None: not measured
    faces: list | None = None
    #: receiver group of each blocker mesh (-1: a blocker that does not receive), so a
    #: receiver's error near blockers leaves out its own
    blocker_groups: list | None = None


def eval_settings(inputs: EvalInputs, *, order: int | None = None,
                  acc_order: int | None = None, window: bool = True,
                  hierarchy: bool = True, field_space: str | None = None) -> ShadowSettings:
    """The runtime settings of an evaluation: the scene's, overridden by the caller's.

    One process (the method times compare with single-process references).
    """
    base = inputs.settings
    kwargs = {"order": base.get("order", order or 4)}
    for key in ("window_h", "theta_max", "theta_min", "vertices_per_cluster", "cluster_blend",
                "deringing"):
        if base.get(key) is not None:
            kwargs[key] = base[key]
    kwargs["window"] = base.get("window", "cosine") if window else None
    kwargs["hierarchy"] = base.get("hierarchy", True) if hierarchy else False
    kwargs["field_space"] = field_space or base.get("field_space")
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
                      [], {"order": order, "hierarchy": tree is not None},
                      faces=[grid_faces(grid)], blocker_groups=[-1])




@dataclass
class MethodResult:
    """One row of the comparison."""

    method: str
    rmse_mesh: float
    rmse_spheres: float | None  # None without sphere blockers
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
             tables: dict | None = None, n_dirs: int = DEFAULT_DIRECTIONS,
             self_visibility=(), groups=None, faces=None, blocker_groups=None) -> dict:
    """Run the methods and the two ray-traced references on one frame.

    Parameters
    ----------
    vertices, normals : ndarray, shape (V, 3)
    blockers : list of SphereBlocker or FieldBlocker
        Shadow fields combine as ``settings.field_space`` says (runtime
        methods) or by products (``product``); the sphere-set reference is
        only computed when there are sphere blockers.
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
    self_visibility : sequence of SelfVisibility
        Exact self-shadowing of rigid objects, used by the runtime methods.
    groups : ndarray of int, shape (V,), optional
        Receiver object of each vertex, for the per-receiver :func:`error_split`
        (default: one receiver).
    faces : list of ndarray (F_k, 3), optional
        Each receiver group's triangles (indices into its own vertices): adds the
        first method's :func:`look_split` per receiver.
    blocker_groups : list of int, optional
        Receiver group of each mesh in ``meshes`` (-1 for none).

    Returns
    -------
    dict
        ``references``: {"mesh": seconds, "spheres": (rmse vs mesh, seconds)},
        ``results``: list of :class:`MethodResult`, the radiance arrays of the
        references (``mesh_radiance``, ``spheres_radiance``), ``split``: the
        first method's :func:`error_split` per receiver, and ``look``: its
        :func:`look_split` (empty without ``faces``).
    """
    specs = parse_methods(methods)
    order = settings.order
    # references shaded raw (their negative lobes are part of order-n shading);
    # methods with the settings' de-ringing
    plain = dataclasses.replace(settings, acc_order=order, exp_method="ol")
    ref_shader = ShadowRuntime(dataclasses.replace(plain, deringing="none"))
    shader = ShadowRuntime(plain)

    def shade(g, runtime=shader):
        return runtime.shade(g, vertices, normals, env_sh, lights)

    t0 = time.perf_counter()
    g_mesh, binary, dirs, weights = _raytrace_binary(vertices, normals, meshes, order, n_dirs)
    t_mesh = time.perf_counter() - t0
    spheres = [b for b in blockers if isinstance(b, SphereBlocker)]
    fields = [b for b in blockers if isinstance(b, FieldBlocker)]
    centers, radii = leaf_spheres(spheres) if spheres else (np.zeros((0, 3)), np.zeros(0))
    t0 = time.perf_counter()
    g_sph = sphere_union_visibility(vertices, normals, centers, radii, order, n_dirs) \
        if spheres else None
    t_sph = time.perf_counter() - t0
    r_mesh = shade(g_mesh, ref_shader)
    r_sph = shade(g_sph, ref_shader) if g_sph is not None else None
    results = []
    for label, name, acc in specs:
        if name == "product":
            t0 = time.perf_counter()
            # without @N: the runtime's accumulation order, like the SHEXP rows
            acc_p = acc if acc is not None else settings.resolved_acc_order()
            g = None
            if spheres or not fields:
                g = product_space_visibility(vertices, normals, (centers, radii), order, acc_p)
            if fields:
                g = field_product_visibility(vertices, normals, fields, order, acc_p, base=g)
            seconds = time.perf_counter() - t0
        else:
            s = dataclasses.replace(settings, exp_method=name,
                                    acc_order=acc if acc is not None else settings.acc_order)
            acc_order = s.resolved_acc_order()
            use_tables = tables if tables is not None and np.asarray(
                tables["log_zh"]).shape[-1] == acc_order else None
            rt = ShadowRuntime(s, tables=use_tables)
            sv = () if acc_order != settings.resolved_acc_order() else self_visibility
            rt.visibility(vertices, normals, blockers, clusters,
                          self_visibility=sv)  # warm-up (tables, buffers)
            t0 = time.perf_counter()
            g = rt.visibility(vertices, normals, blockers, clusters, self_visibility=sv)
            seconds = time.perf_counter() - t0
        rad = shade(g)
        results.append(MethodResult(label, relative_rmse(rad, r_mesh),
                                    relative_rmse(rad, r_sph) if r_sph is not None else None,
                                    seconds, rad))
    exact = None
    if env_sh is not None:
        env_only = ref_shader.shade(g_mesh, vertices, normals, env_sh)
        exact = (env_only, _exact_environment(binary, dirs, weights, normals, env_sh, settings))
    groups = np.zeros(len(vertices), dtype=np.int64) if groups is None else np.asarray(groups)
    return {
        "references": {"mesh_seconds": t_mesh, "spheres_seconds": t_sph,
                       "spheres_rmse_mesh": relative_rmse(r_sph, r_mesh)
                       if r_sph is not None else None},
        "results": results,
        "mesh_radiance": r_mesh,
        "spheres_radiance": r_sph,
        "split": error_split(results[0].radiance, r_mesh, r_sph, groups, exact),
        "look": [] if faces is None else look_split(
            results[0].radiance, r_mesh, shade(_unblocked(len(vertices), order), ref_shader),
            groups, faces, vertices, meshes, blocker_groups),
    }


def _unblocked(n_vertices: int, order: int) -> np.ndarray:
    g = np.zeros((n_vertices, order * order))
    g[:, 0] = np.sqrt(4.0 * np.pi)
    return g


def look_split(radiance, mesh_radiance, unshadowed, groups, faces, vertices, meshes,
               blocker_groups=None) -> list[dict]:
    """:func:`shtools.reference.look.look_metrics` per receiver group.

    Parameters
    ----------
    radiance, mesh_radiance, unshadowed : ndarray, shape (V, 3)
        The method, the ray-traced real meshes, and no blocker at all.
    groups : ndarray of int, shape (V,)
    faces : list of ndarray (F_k, 3)
        Group ``k``'s triangles, indices into its own vertices (in order).
    vertices : ndarray, shape (V, 3)
    meshes : list of trimesh.Trimesh
        The blockers (their bounding spheres for the near-blocker error).
    blocker_groups : list of int, optional
        Receiver group of each mesh (-1 for none): a receiver's own mesh is left out.

    Returns
    -------
    list of dict
        Per group: ``group`` and the measures of :func:`look_metrics`.
    """
    from shtools.reference.look import bounding_sphere, look_metrics

    spheres = [bounding_sphere(m.vertices) for m in meshes]
    owners = [-1] * len(spheres) if blocker_groups is None else list(blocker_groups)
    rows = []
    for g in np.unique(groups):
        m = groups == g
        others = [s for s, k in zip(spheres, owners, strict=True) if k != g]
        rows.append({"group": int(g), **look_metrics(
            radiance[m], mesh_radiance[m], unshadowed[m], faces[int(g)], points=vertices[m],
            blocker_spheres=others)})
    return rows


def error_split(radiance, mesh_radiance, spheres_radiance, groups, exact=None) -> list[dict]:
    """Where a method's error comes from, per receiver group (relative RMSEs).

    Parameters
    ----------
    radiance : ndarray, shape (V, 3)
        The method's radiance.
    mesh_radiance, spheres_radiance : ndarray, shape (V, 3)
        Ray-traced references of the real meshes and of the sphere union
        (with the self-shadow rules), shaded raw at order ``n``;
        ``spheres_radiance`` is None without sphere blockers.
    groups : ndarray of int, shape (V,)
        Receiver group of each vertex.
    exact : tuple of ndarray (V, 3), optional
        ``(order-n environment-only radiance of the real visibility, exact
        integral of the binary visibility against the same environment)``.

    Returns
    -------
    list of dict
        Per group: ``group``, ``vertices``, ``total`` (vs mesh),
        ``sphere_approximation`` (spheres vs mesh), ``shexp`` (method vs
        spheres), ``truncation`` (None without ``exact``), ``ringing``
        (``||min(radiance, 0)|| / ||mesh||``) and ``negative_vertices``.
    """
    rows = []
    for g in np.unique(groups):
        m = groups == g
        ref = mesh_radiance[m]
        norm = float(np.linalg.norm(ref)) or 1.0
        rows.append({
            "group": int(g), "vertices": int(m.sum()),
            "total": relative_rmse(radiance[m], ref),
            # without sphere blockers (shadow fields only) there is no sphere reference
            "sphere_approximation": (None if spheres_radiance is None
                                     else relative_rmse(spheres_radiance[m], ref)),
            "shexp": (None if spheres_radiance is None
                      else relative_rmse(radiance[m], spheres_radiance[m])),
            "truncation": (None if exact is None
                           else relative_rmse(exact[0][m], exact[1][m])),
            "ringing": float(np.linalg.norm(np.minimum(radiance[m], 0.0))) / norm,
            "negative_vertices": int((radiance[m].min(axis=1) < 0).sum()),
        })
    return rows


def grid_faces(n: int) -> np.ndarray:
    """Triangles ``(2 (n-1)^2, 3)`` of an ``n x n`` receiver grid stored row by row
    (:func:`shtools.reference.scenes.ground_grid`)."""
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    return np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                           np.stack([a, c, d], -1).reshape(-1, 3)])


def _raytrace_binary(vertices, normals, meshes, order, n_dirs):
    """Ray-traced binary visibility ``(V, Q)`` on the reference's rule, and its projection."""
    from shtools.geometry.raycast import RayCaster
    from shtools.geometry.visibility import RAY_OFFSET, direction_quadrature
    from shtools.sh import project

    dirs, w = direction_quadrature(n_dirs)
    p = np.asarray(vertices, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    if not meshes:
        vis = np.ones((p.shape[0], dirs.shape[0]), dtype=bool)
    else:
        caster = RayCaster.from_meshes(list(meshes))
        vis = caster.visibility(p, dirs, normals=nrm, offset=RAY_OFFSET * caster.diagonal)
    g = project(vis.astype(np.float64), dirs, w, order)
    return g, vis, dirs, w


def _exact_environment(binary, dirs, weights, normals, env_sh, settings) -> np.ndarray:
    """``(1/pi) sum_q w_q L(s_q) V(s_q) max(0, N.s_q)``: no truncation of V or H, ``(V, 3)``.

    ``L`` is the order-n environment with the settings' window, as shaded.
    """
    from shtools.runtime.shading import band_window
    from shtools.sh import basis

    order = settings.order
    env = np.zeros((order * order, 3))
    e = np.asarray(env_sh, dtype=np.float64)[: order * order]
    env[: e.shape[0]] = e
    env *= band_window(order, settings.resolved_window(), settings.window_h)[:, None]
    radiance_dirs = basis(dirs, order) @ env  # (Q, 3)
    cos = np.maximum(np.asarray(normals, dtype=np.float64) @ dirs.T, 0.0)  # (V, Q)
    return ((binary * cos) * weights[None, :]) @ radiance_dirs / np.pi


def field_eval_inputs(mesh_path, field_path, light_path=None, *, grid: int = 64,
                      gap: float = 0.0, order: int | None = None) -> EvalInputs:
    """The built-in evaluation scene with a shadow-field blocker (no sphere set).

    Parameters are those of :func:`mesh_eval_inputs`, with ``field_path`` (a
    ``field`` asset of the mesh) instead of the sphere set; ``order`` must be the
    field's when given.
    """
    from shtools.data_formats.field import read_field
    from shtools.geometry.mesh import load_mesh
    from shtools.reference.scenes import mesh_scene
    from shtools.runtime import FieldBlocker

    mesh = load_mesh(mesh_path)
    fld = read_field(field_path)
    if order is not None and order != fld.order:
        raise InputError(f"the field is SH order {fld.order} but --order is {order}; resample "
                         f"it with `shtools field sample --order {order}`", field_path)
    env = None
    if light_path is not None:
        from shtools.data_formats.light import read_light

        env, _ = read_light(light_path)
    sc = mesh_scene(mesh, np.zeros((0, 3)), np.zeros(0), grid=grid, order=fld.order,
                    env_sh=env, gap=gap)
    return EvalInputs(Path(mesh_path).name, sc.vertices, sc.normals, None,
                      [FieldBlocker(fld)], sc.meshes, sc.env_sh, [],
                      {"order": fld.order, "hierarchy": False},
                      faces=[grid_faces(grid)], blocker_groups=[-1])
