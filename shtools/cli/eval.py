"""``shtools eval``: compare shadowing methods against ray tracing on one scene.

Two forms:

* ``shtools eval SCENE.toml [--frame F]`` — a bake scene (``shtools.scene``);
* ``shtools eval --mesh MESH --spheres spheres.h5 [--tree tree.h5] [--light light.h5]
  [--grid 64]`` — the blocker mesh over a ground-plane grid touching its lowest
  point, under the light (default: a procedural sky).

Prints per method the relative RMSE of per-vertex radiance against ray tracing
of the real meshes and of the sphere set, and the time (``--json`` for a
machine-readable summary; ``--png`` writes a false-colour comparison image).
"""

from __future__ import annotations

import math
from pathlib import Path

import click
import numpy as np

from shtools.cli._common import json_option, option_type, report, setting_type
from shtools.errors import InputError

DEFAULT_METHODS = "auto,hyb@4,ps*@4,ol@4,product@4,product@6"


@click.command("eval")
@click.argument("scene", required=False, type=click.Path(dir_okay=False))
@click.option("--mesh", type=click.Path(dir_okay=False), help="Blocker mesh (built-in form).")
@click.option("--spheres", "spheres_path", type=click.Path(dir_okay=False),
              help="Sphere set of the mesh (spheres asset).")
@click.option("--tree", "tree_path", type=click.Path(dir_okay=False),
              help="Sphere tree of the set (tree asset); enables the hierarchy.")
@click.option("--light", "light_path", type=click.Path(dir_okay=False),
              help="Environment light asset (default: a procedural sky).")
@click.option("--grid", default=64, show_default=True, type=option_type("grid"),
              help="Ground receivers per side (built-in form).")
@click.option("--gap", default=0.0, show_default=True, type=option_type("gap"),
              help="Gap between ground and mesh, as a fraction of the mesh height.")
@click.option("--frame", default=0, show_default=True, type=option_type("frame"),
              help="Scene frame to evaluate (scene form).")
@click.option("--methods", default=DEFAULT_METHODS, show_default=True,
              help="Comma-separated: auto, hyb, ps*, ps, ol, exact, volterra, product; "
                   "append @N for the accumulation order.")
@click.option("--order", default=None, type=setting_type("order"),
              help="Shading SH order (default 4, or the scene's).")
@click.option("--acc-order", default=None, type=setting_type("acc_order"),
              help="Accumulation order of methods without @N (default: the runtime's).")
@click.option("--no-hierarchy", is_flag=True, help="Accumulate all leaf spheres everywhere.")
@click.option("--no-window", is_flag=True, help="Shade without windowing.")
@click.option("--n-dirs", default=2000, show_default=True, type=option_type("n_dirs"),
              help="Ray-tracing directions per vertex.")
@click.option("--png", "png_path", type=click.Path(dir_okay=False),
              help="Write a false-colour side-by-side comparison image.")
@json_option
def eval_cmd(scene, mesh, spheres_path, tree_path, light_path, grid, gap, frame, methods, order,
             acc_order, no_hierarchy, no_window, n_dirs, png_path, as_json):
    """Compare shadowing methods with ray tracing (relative RMSE of radiance, time)."""
    from shtools.reference.evaluation import evaluate, parse_methods
    from shtools.runtime import ShadowSettings

    parse_methods(methods)  # fail early on a typo
    if png_path is not None:
        from shtools.cli._outputs import guard_outputs

        _check_png_path(png_path)
        guard_outputs({"--png": png_path},
                      [scene, mesh, spheres_path, tree_path, light_path])
    if scene is not None:
        if mesh or spheres_path:
            raise InputError("give either a scene file or --mesh/--spheres, not both", scene)
        data = _scene_inputs(scene, frame, order)
    else:
        if not (mesh and spheres_path):
            raise InputError("give a scene file, or --mesh MESH --spheres spheres.h5")
        data = _builtin_inputs(mesh, spheres_path, tree_path, light_path, grid, gap,
                               order or 4)
    base = data["settings"]
    kwargs = {"order": base.get("order", order or 4)}
    for key in ("window_h", "theta_max", "theta_min", "vertices_per_cluster"):
        if base.get(key) is not None:
            kwargs[key] = base[key]
    kwargs["window"] = None if no_window else base.get("window", "cosine")
    kwargs["hierarchy"] = False if no_hierarchy else base.get("hierarchy", True)
    if acc_order is not None:
        kwargs["acc_order"] = acc_order
    elif base.get("acc_order") is not None:
        kwargs["acc_order"] = base["acc_order"]
    if kwargs.get("acc_order") is not None and kwargs["acc_order"] < kwargs["order"]:
        raise InputError(f"--acc-order {kwargs['acc_order']} is below the order {kwargs['order']}")
    # one process: the times compare methods, and the references run in one too
    settings = ShadowSettings(processes=1, **kwargs)
    clusters = None
    if settings.hierarchy:
        from shtools.runtime.clusters import lloyd_clusters

        clusters = lloyd_clusters(data["vertices"], settings.vertices_per_cluster,
                                  groups=data["groups"])
    out = evaluate(data["vertices"], data["normals"], data["blockers"], data["meshes"],
                   data["env"], data["lights"], settings, methods, clusters=clusters,
                   tables=data.get("tables"), n_dirs=n_dirs)
    refs = out["references"]
    rows = [{"method": r.method, "rmse_vs_mesh": r.rmse_mesh, "rmse_vs_spheres": r.rmse_spheres,
             "seconds": r.seconds} for r in out["results"]]
    summary = {
        "scene": data["name"], "vertices": len(data["vertices"]),
        "spheres": int(sum(b.n_spheres for b in data["blockers"])),
        "order": settings.order, "acc_order_default": settings.resolved_acc_order(),
        "window": settings.resolved_window(), "hierarchy": settings.hierarchy,
        "n_dirs": n_dirs,
        "spheres_vs_mesh_rmse": refs["spheres_rmse_mesh"],
        "raytrace_mesh_seconds": refs["mesh_seconds"],
        "raytrace_spheres_seconds": refs["spheres_seconds"],
        "methods": rows,
    }
    if png_path is not None:
        _write_png(png_path, data["vertices"], out)
        summary["png"] = str(png_path)
    report(summary, as_json, _table(summary))


def _table(summary: dict) -> str:
    lines = [
        f"scene {summary['scene']}: {summary['vertices']} receivers, {summary['spheres']} "
        f"spheres, order {summary['order']} (default accumulation order "
        f"{summary['acc_order_default']}), window {summary['window']}, hierarchy "
        f"{'on' if summary['hierarchy'] else 'off'}, {summary['n_dirs']} ray directions",
        "",
        "| method | rel. RMSE vs mesh | rel. RMSE vs spheres | time (s) |",
        "|---|---|---|---|",
        f"| spheres, ray traced | {summary['spheres_vs_mesh_rmse']:.4f} | 0 | "
        f"{summary['raytrace_spheres_seconds']:.3f} |",
        f"| mesh, ray traced | 0 | - | {summary['raytrace_mesh_seconds']:.3f} |",
    ]
    for r in summary["methods"]:
        lines.append(f"| {r['method']} | {r['rmse_vs_mesh']:.4f} | {r['rmse_vs_spheres']:.4f} | "
                     f"{r['seconds']:.4f} |")
    if "png" in summary:
        lines.append(f"\nwrote {summary['png']}")
    return "\n".join(lines)


def _builtin_inputs(mesh_path, spheres_path, tree_path, light_path, grid, gap, order):
    from shtools.data_formats.spheres import read_spheres
    from shtools.geometry.mesh import load_mesh
    from shtools.reference.scenes import mesh_scene
    from shtools.runtime import SphereBlocker

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
    return {
        "name": Path(mesh_path).name, "vertices": sc.vertices, "normals": sc.normals,
        "groups": None, "blockers": [SphereBlocker(sc.centers, sc.radii, tree=tree)],
        "meshes": sc.meshes, "env": sc.env_sh, "lights": [],
        "settings": {"order": order, "hierarchy": tree is not None},
    }


def _scene_inputs(path, frame, order):
    import trimesh

    try:
        from shtools.scene.bake import pose_frame, prepare_scene
        from shtools.scene.scene import load_scene
    except ImportError as exc:  # pragma: no cover - the scene package ships with shtools
        raise InputError(f"scene files need shtools.scene ({exc})", path) from exc
    scene = load_scene(path)
    st = scene.settings
    if frame >= st.frames:
        raise InputError(f"--frame {frame} is outside the scene's frames 0..{st.frames - 1}",
                         path)
    prepared = prepare_scene(scene)
    state = pose_frame(prepared, frame / st.fps, with_meshes=True)
    if not state.blockers:
        raise InputError("the scene has no blocker objects to evaluate", path)
    meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
    groups = np.concatenate([np.full(len(o.vertices), k)
                             for k, o in enumerate(prepared.receivers)])
    settings = {"order": order or st.order, "acc_order": st.acc_order, "window": st.window,
                "window_h": st.window_h, "theta_max": st.theta_max, "theta_min": st.theta_min,
                "hierarchy": st.hierarchy, "vertices_per_cluster": st.vertices_per_cluster}
    return {
        "name": Path(path).name, "vertices": state.vertices, "normals": state.normals,
        "groups": groups, "blockers": state.blockers, "meshes": meshes,
        "env": prepared.env_sh, "lights": state.lights, "settings": settings,
        "tables": prepared.tables,
    }


def _check_png_path(path):
    if Path(path).suffix.lower() != ".png":
        raise InputError("--png needs a file name ending in .png", path)
    parent = Path(path).parent
    if str(parent) and not parent.is_dir():
        raise InputError("output folder does not exist; create it first", path)


def _write_png(path, vertices, out):
    """Top view (x, z) of references and methods, radiance above and error below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from shtools.data_formats import atomic_path

    def lum(rgb):
        return rgb @ np.array([0.2126, 0.7152, 0.0722])

    panels = [("mesh (ray traced)", out["mesh_radiance"]),
              ("spheres (ray traced)", out["spheres_radiance"])]
    panels += [(r.method, r.radiance) for r in out["results"]]
    ref = lum(out["mesh_radiance"])
    vmax = max(float(np.percentile(lum(p), 99.5)) for _, p in panels) or 1.0
    emax = max(float(np.abs(lum(p) - ref).max()) for _, p in panels) or 1.0
    cols = len(panels)
    size = 2.6
    fig, axes = plt.subplots(2, cols, figsize=(size * cols, 2 * size + 0.6), squeeze=False)
    x, z = vertices[:, 0], vertices[:, 2]
    dot = max(1.0, 4e4 / max(1, len(x)))
    for k, (name, rad) in enumerate(panels):
        ax = axes[0, k]
        ax.scatter(x, z, c=lum(rad), s=dot, marker="s", cmap="inferno", vmin=0, vmax=vmax,
                   linewidths=0)
        ax.set_title(name, fontsize=9)
        err = lum(rad) - ref
        ax2 = axes[1, k]
        ax2.scatter(x, z, c=err, s=dot, marker="s", cmap="coolwarm", vmin=-emax, vmax=emax,
                    linewidths=0)
        rms = math.sqrt(float(np.mean(err**2)) / max(float(np.mean(ref**2)), 1e-300))
        ax2.set_title(f"error vs mesh (rel. RMSE {rms:.3f})", fontsize=8)
        for a in (ax, ax2):
            a.set_aspect("equal")
            a.set_xticks([])
            a.set_yticks([])
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=80)
    plt.close(fig)
