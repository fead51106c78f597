"""``shtools eval``: compare shadowing methods against ray tracing on one scene.

Two forms:

* ``shtools eval SCENE.toml [--frame F]`` — a bake scene (``shtools.scene``);
* ``shtools eval --mesh MESH --spheres spheres.h5 [--tree tree.h5] [--light light.h5]
  [--grid 64]`` — the blocker mesh over a ground-plane grid touching its lowest
  point, under the light (default: a procedural sky).

Prints per method the relative RMSE of per-vertex radiance against ray tracing
of the real meshes and of the sphere set, and the time, then per receiver where
the first method's error comes from and what a viewer sees of it
(:mod:`shtools.reference.look`: the smoothness ratio, the error over the shadowed
vertices and near the blockers) (``--json`` for a machine-readable summary;
``--png`` writes a false-colour comparison image).
"""

from __future__ import annotations

from pathlib import Path

import click

from shtools.cli._common import (
    InputPath,
    errors_name,
    json_option,
    option_error,
    option_type,
    report,
    setting_type,
)
from shtools.cli._limits import check_memory, check_rays, force_option
from shtools.errors import InputError

DEFAULT_METHODS = "auto,hyb@4,ps*@4,ol@4,product@4,product@6"
#: Bytes per receiver and ray direction of the ray-traced references: the binary
#: visibility, its float64 copy for the projection, and the sphere set's pass.
REFERENCE_BYTES = 17


@click.command("eval")
@click.argument("scene", required=False, type=InputPath())
@click.option("--mesh", type=InputPath(), help="Blocker mesh (built-in form).")
@click.option("--spheres", "spheres_path", type=InputPath(),
              help="Sphere set of the mesh (spheres asset).")
@click.option("--tree", "tree_path", type=InputPath(),
              help="Sphere tree of the set (tree asset); enables the hierarchy.")
@click.option("--field", "field_path", type=InputPath(),
              help="Shadow field of the mesh (field asset), instead of --spheres.")
@click.option("--field-space", type=click.Choice(["log", "product"]), default=None,
              help="How shadow fields combine in the runtime methods (default: log, or "
                   "the scene's).")
@click.option("--light", "light_path", type=InputPath(),
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
@force_option("4 GiB of memory, 2e10 rays")
@json_option
@errors_name("scene")
def eval_cmd(scene, mesh, spheres_path, tree_path, field_path, field_space, light_path, grid,
             gap, frame, methods, order, acc_order, no_hierarchy, no_window, n_dirs, png_path,
             force, as_json):
    """Compare shadowing methods with ray tracing (relative RMSE of radiance, time)."""
    from shtools.reference.evaluation import (
        eval_settings,
        evaluate,
        field_eval_inputs,
        mesh_eval_inputs,
        parse_methods,
    )

    try:
        parse_methods(methods)  # fail early on a typo
    except InputError as exc:
        raise option_error(f"--methods: {exc.message}") from None
    if png_path is not None:
        from shtools.cli._outputs import guard_outputs

        _check_png_path(png_path)
        guard_outputs({"--png": png_path},
                      [scene, mesh, spheres_path, tree_path, field_path, light_path])
    if scene is not None:
        if mesh or spheres_path or field_path:
            raise InputError("give either a scene file or --mesh/--spheres/--field, not both",
                             scene)
        from shtools.scene.evaluation import scene_eval_inputs

        data = scene_eval_inputs(scene, frame, order)
    else:
        if not mesh or (spheres_path is None) == (field_path is None):
            raise InputError("give a scene file, or --mesh MESH with --spheres spheres.h5 "
                             "or --field x.field.h5")
        if field_path is not None:
            data = field_eval_inputs(mesh, field_path, light_path, grid=grid, gap=gap,
                                     order=order)
        else:
            data = mesh_eval_inputs(mesh, spheres_path, tree_path, light_path, grid=grid,
                                    gap=gap, order=order or 4)
    _check_cost(len(data.vertices), n_dirs, force, scene or mesh)
    settings = eval_settings(data, order=order, acc_order=acc_order, window=not no_window,
                             hierarchy=not no_hierarchy, field_space=field_space)
    clusters = None
    if settings.hierarchy:
        from shtools.runtime.clusters import lloyd_clusters

        clusters = lloyd_clusters(data.vertices, settings.vertices_per_cluster,
                                  groups=data.groups)
    out = evaluate(data.vertices, data.normals, data.blockers, data.meshes, data.env,
                   data.lights, settings, methods, clusters=clusters, tables=data.tables,
                   n_dirs=n_dirs, self_visibility=data.self_visibility, groups=data.groups,
                   faces=data.faces, blocker_groups=data.blocker_groups)
    refs = out["references"]
    rows = [{"method": r.method, "rmse_vs_mesh": r.rmse_mesh, "rmse_vs_spheres": r.rmse_spheres,
             "seconds": r.seconds} for r in out["results"]]
    summary = {
        "scene": data.name, "vertices": len(data.vertices),
        "spheres": int(sum(b.n_spheres for b in data.blockers if hasattr(b, "n_spheres"))),
        "fields": int(sum(not hasattr(b, "n_spheres") for b in data.blockers)),
        "field_space": settings.resolved_field_space("rigid"),
        "order": settings.order, "acc_order_default": settings.resolved_acc_order(),
        "window": settings.resolved_window(), "hierarchy": settings.hierarchy,
        "n_dirs": n_dirs,
        "spheres_vs_mesh_rmse": refs["spheres_rmse_mesh"],
        "raytrace_mesh_seconds": refs["mesh_seconds"],
        "raytrace_spheres_seconds": refs["spheres_seconds"],
        "methods": rows,
        # where the first method's error comes from, per receiver object
        "split_method": rows[0]["method"],
        "split": [dict(r, receiver=data.receiver_names[r["group"]]) for r in out["split"]],
        # what a viewer sees of the first method, per receiver (shtools.reference.look)
        "look": [dict(r, receiver=data.receiver_names[r["group"]]) for r in out["look"]],
    }
    if png_path is not None:
        from shtools.reference.maps import write_comparison_png

        write_comparison_png(png_path, data.vertices, out)
        summary["png"] = str(png_path)
    report(summary, as_json, _table(summary))


def _table(summary: dict) -> str:
    def num(x, fmt="{:.4f}"):
        return "-" if x is None else fmt.format(x)

    lines = [
        f"scene {summary['scene']}: {summary['vertices']} receivers, {summary['spheres']} "
        f"spheres, {summary['fields']} shadow fields ({summary['field_space']} space), "
        f"order {summary['order']} (default accumulation order "
        f"{summary['acc_order_default']}), window {summary['window']}, hierarchy "
        f"{'on' if summary['hierarchy'] else 'off'}, {summary['n_dirs']} ray directions",
        "",
        "| method | rel. RMSE vs mesh | rel. RMSE vs spheres | time (s) |",
        "|---|---|---|---|",
        f"| spheres, ray traced | {num(summary['spheres_vs_mesh_rmse'])} | 0 | "
        f"{summary['raytrace_spheres_seconds']:.3f} |",
        f"| mesh, ray traced | 0 | - | {summary['raytrace_mesh_seconds']:.3f} |",
    ]
    for r in summary["methods"]:
        lines.append(f"| {r['method']} | {r['rmse_vs_mesh']:.4f} | {num(r['rmse_vs_spheres'])} | "
                     f"{r['seconds']:.4f} |")
    lines += [
        "",
        f"error split of {summary['split_method']} per receiver (relative RMSE of radiance):",
        "",
        "| receiver | total vs mesh | sphere approximation | SHEXP (vs spheres) | "
        "truncation (order n) | ringing (negative part) | negative vertices |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in summary["split"]:
        trunc = "-" if r["truncation"] is None else f"{r['truncation']:.4f}"
        lines.append(f"| {r['receiver']} | {r['total']:.4f} | "
                     f"{num(r['sphere_approximation'])} | "
                     f"{num(r['shexp'])} | {trunc} | {r['ringing']:.4f} | "
                     f"{r['negative_vertices']} |")
    if summary["look"]:
        lines += [
            "",
            f"look of {summary['split_method']} per receiver (smoothness: mean |graph Laplacian| "
            "of luminance over the ray tracer's; errors over the vertices the real meshes "
            "darken by > 2 % and within 2 bounding radii of the other blockers):",
            "",
            "| receiver | smoothness ratio | whole | shadowed (vertices) | near blockers "
            "(vertices) |",
            "|---|---|---|---|---|",
        ]
        for r in summary["look"]:
            lines.append(f"| {r['receiver']} | {r['smoothness']:.3f} | {r['error']:.4f} | "
                         f"{num(r['shadowed_error'])} ({r['shadowed_vertices']}) | "
                         f"{num(r['near_error'])} ({r['near_vertices']}) |")
    if "png" in summary:
        lines.append(f"\nwrote {summary['png']}")
    return "\n".join(lines)


def _check_cost(n_receivers: int, n_dirs: int, force: bool, path) -> None:
    """Refuse references past the memory or ray limit (:mod:`shtools.cli._limits`): the
    mesh and the sphere set are each ray traced from every receiver in ``--n-dirs``
    directions."""
    fix = "lower --n-dirs or --grid"
    formula = f"{n_receivers} receivers x {n_dirs} directions"
    check_memory("eval", n_receivers * n_dirs * REFERENCE_BYTES,
                 f"{formula} x {REFERENCE_BYTES} bytes", fix, force=force, path=path)
    check_rays("eval", 2 * n_receivers * n_dirs, f"{formula}, mesh and spheres", fix,
               force=force, path=path)


def _check_png_path(path):
    if Path(path).suffix.lower() != ".png":
        raise InputError("--png needs a file name ending in .png", path)
    parent = Path(path).parent
    if str(parent) and not parent.is_dir():
        raise InputError("output folder does not exist; create it first", path)
