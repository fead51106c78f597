"""``shtools transfer``: precompute a rigid object's self-visibility (a ``transfer`` asset).

Thin: load the mesh, call :func:`shtools.geometry.transfer.hemisphere_transfer` (the
estimator a bake traces a rigid object's self-transfer with) or
:func:`~shtools.geometry.transfer.mesh_transfer` (``--estimator product``), write the
asset, report.
"""

from __future__ import annotations

import time

import click

from shtools.cli._common import (
    InputPath,
    errors_name,
    json_option,
    option_type,
    output_option,
    progress,
    report,
)
from shtools.cli._limits import check_memory, check_rays, force_option

#: Bytes per ray direction held for the whole run besides its SH row (direction, weight)
#: and per ray in flight (origin, direction, hit flag and its float copy).
DIRECTION_BYTES, RAY_BYTES = 32, 64


@click.command("transfer")
@click.argument("mesh_path", metavar="MESH", type=InputPath())
@output_option
@click.option("--order", default=6, show_default=True, type=click.IntRange(1, 10),
              help="SH order; the scene's accumulation order (6 for the default shading "
                   "order 4).  A higher order is re-logged at bake time.")
@click.option("--estimator", default="hemisphere", show_default=True,
              type=click.Choice(["hemisphere", "product"]),
              help="hemisphere: rays over each vertex's own hemisphere, 256 first, refined to "
                   "--n-dirs where its shadow boundaries are (what a bake traces without an "
                   "asset); product: a Gauss-Legendre x uniform rule over the whole sphere.")
@click.option("--n-dirs", default=None, type=option_type("transfer_n_dirs"),
              help="Ray directions per vertex: the dense hemisphere set [default 1600], or "
                   "the least nodes of the product rule [default 3200].")
@click.option("--floor", default=0.01, show_default=True, type=option_type("floor"),
              help="Visibility floor of the log (fully blocked directions keep this much).")
@force_option("4 GiB of memory, 2e10 rays")
@json_option
@errors_name("mesh_path")
def transfer(mesh_path, output, order, estimator, n_dirs, floor, force, as_json):
    """Ray-trace MESH's self-visibility on its own vertices, projected to SH.

    The baker uses it in place of the object's own spheres on the object's
    vertices (exact self-shadowing of rigid objects; scene key
    self_visibility = "x.transfer.h5").
    """
    from shtools.cli._outputs import guard_outputs
    from shtools.data_formats.transfer import write_transfer
    from shtools.geometry.mesh import load_mesh
    from shtools.geometry.transfer import (
        FIRST_DIRECTIONS,
        TRANSFER_DIRECTIONS,
        hemisphere_transfer,
        mesh_transfer,
    )
    from shtools.geometry.visibility import DEFAULT_DIRECTIONS

    if n_dirs is None:
        n_dirs = TRANSFER_DIRECTIONS if estimator == "hemisphere" else DEFAULT_DIRECTIONS
    guard_outputs({"-o": output}, [mesh_path])
    mesh = load_mesh(mesh_path)
    # two passes only where the dense set is well beyond the first one's 256 rays (a
    # first pass plus the refined cells could cast more than one pass of a set near 256)
    n_first = FIRST_DIRECTIONS if estimator == "hemisphere" and n_dirs >= 2 * FIRST_DIRECTIONS \
        else None
    _check_cost(len(mesh.vertices), order, n_dirs, n_first, force, mesh_path)
    start = time.perf_counter()
    bar = progress(total=len(mesh.vertices), desc="transfer", unit="vertices")

    def tick(done, total):  # self_visibility reports (done, total) after each chunk
        bar.update(done - bar.n)

    try:
        if estimator == "hemisphere":
            g, f, params = hemisphere_transfer(mesh, order, n_dirs=n_dirs, n_first=n_first,
                                               floor=floor, progress=tick)
        else:
            g, f, params = mesh_transfer(mesh, order, n_dirs=n_dirs, floor=floor, progress=tick)
    finally:
        bar.close()
    write_transfer(output, mesh.vertices, mesh.vertex_normals, g, f, inputs={"mesh": mesh_path},
                   parameters=params)
    seconds = time.perf_counter() - start
    shadowed = float((g[:, 0] < 0.99 * g[:, 0].max()).mean()) if len(g) else 0.0
    summary = {"output": output, "vertices": len(g), "order": order, "estimator": estimator,
               "n_dirs": params["n_dirs"], "seconds": round(seconds, 3),
               "self_shadowed_fraction": round(shadowed, 4)}
    report(summary, as_json,
           f"wrote {output}: {len(g)} vertices, order {order}, {params['n_dirs']} directions "
           f"({estimator}), "
           f"{100 * shadowed:.1f} % of vertices self-shadowed, {seconds:.1f} s")


def _check_cost(n_vertices: int, order: int, n_dirs: int, n_first: int | None, force: bool,
                mesh_path) -> None:
    """Refuse a transfer past the memory or ray limit (:mod:`shtools.cli._limits`).

    Memory: the projection matrix (Q, n*n) and the quadrature, one batch of rays
    (at least one vertex's Q rays, at most all V x Q), the visibility and its log
    (V, n*n), and with a first pass of ``n_first`` rays its cells' table
    (Q, n_first) float64;
    rays: V x Q, plus V x ``n_first``.  Q is at least ``--n-dirs``.
    """
    from shtools.geometry.visibility import RAYS_PER_STEP

    n2 = order * order
    first = n_first or 0
    batch = min(n_vertices * n_dirs, max(RAYS_PER_STEP, n_dirs))
    nbytes = (n_dirs * (n2 * 8 + DIRECTION_BYTES + first * 8) + batch * RAY_BYTES
              + 2 * n_vertices * n2 * 8)
    fix = "lower --n-dirs or --order"
    check_memory("transfer", nbytes, f"{n_dirs} directions x {n2} SH coefficients, "
                 f"{n_vertices} vertices", fix, force=force, path=mesh_path)
    per_vertex = n_dirs + first
    check_rays("transfer", n_vertices * per_vertex,
               f"{n_vertices} vertices x {per_vertex} directions", fix, force=force,
               path=mesh_path)
