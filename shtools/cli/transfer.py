"""``shtools transfer``: precompute a rigid object's self-visibility (a ``transfer`` asset).

Thin: load the mesh, call :func:`shtools.fields.self_visibility.mesh_transfer`,
write the asset, report.
"""

from __future__ import annotations

import time

import click

from shtools.cli._common import json_option, output_option, progress, report


@click.command("transfer")
@click.argument("mesh_path", metavar="MESH", type=click.Path(dir_okay=False))
@output_option
@click.option("--order", default=6, show_default=True, type=click.IntRange(1, 10),
              help="SH order; the scene's accumulation order (6 for the default shading "
                   "order 4).  A higher order is re-logged at bake time.")
@click.option("--n-dirs", default=3200, show_default=True, type=click.IntRange(16),
              help="Minimum ray directions per vertex (Gauss-Legendre x uniform rule).")
@click.option("--floor", default=0.01, show_default=True, type=click.FloatRange(0.0, 0.5),
              help="Visibility floor of the log (fully blocked directions keep this much).")
@json_option
def transfer(mesh_path, output, order, n_dirs, floor, as_json):
    """Ray-trace MESH's self-visibility on its own vertices, projected to SH.

    The baker uses it in place of the object's own spheres on the object's
    vertices (exact self-shadowing of rigid objects; scene key
    self_visibility = "x.transfer.h5").
    """
    from shtools.cli._outputs import guard_outputs
    from shtools.data_formats.transfer import write_transfer
    from shtools.fields.self_visibility import mesh_transfer
    from shtools.geometry.mesh import load_mesh

    guard_outputs({"-o": output}, [mesh_path])
    mesh = load_mesh(mesh_path)
    start = time.perf_counter()
    bar = progress(total=len(mesh.vertices), desc="transfer", unit="vertices")

    def tick(done, total):  # self_visibility reports (done, total) after each chunk
        bar.update(done - bar.n)

    try:
        g, f, params = mesh_transfer(mesh, order, n_dirs=n_dirs, floor=floor, progress=tick)
    finally:
        bar.close()
    write_transfer(output, mesh.vertices, mesh.vertex_normals, g, f, inputs={"mesh": mesh_path},
                   parameters=params)
    seconds = time.perf_counter() - start
    shadowed = float((g[:, 0] < 0.99 * g[:, 0].max()).mean()) if len(g) else 0.0
    summary = {"output": output, "vertices": len(g), "order": order,
               "n_dirs": params["n_dirs"], "seconds": round(seconds, 3),
               "self_shadowed_fraction": round(shadowed, 4)}
    report(summary, as_json,
           f"wrote {output}: {len(g)} vertices, order {order}, {params['n_dirs']} directions, "
           f"{100 * shadowed:.1f} % of vertices self-shadowed, {seconds:.1f} s")
