"""``shtools spheres``: fit bounding sphere sets, import/export ``.sph``, trees, binding.

``fit``, ``import`` and ``export`` live here; ``tree`` and ``bind`` come from
:mod:`shtools.cli.spheres_tree`.  Commands are thin: parse, call
:mod:`shtools.geometry`, write one asset, report.
"""

from __future__ import annotations

from pathlib import Path

import click

from shtools.cli._common import (
    InputPath,
    errors_name,
    json_option,
    option_type,
    output_option,
    progress,
    report,
    scheduler_options,
)
from shtools.geometry.fit_methods import DEFAULT_ROUNDS, FIT_METHODS


@click.group()
def spheres():
    """Sphere-set blockers: fit spheres to a mesh, build trees, bind to skins."""


@spheres.command("fit")
@click.argument("mesh_paths", metavar="MESH...", nargs=-1, required=True,
                type=InputPath())
@click.option("-n", "--count", "count", type=option_type("count"), required=True,
              help="Number of spheres N (>= 1).")
@click.option("-o", "--output", required=True, type=click.Path(writable=True),
              help="Output file (written atomically); with several meshes, an existing "
                   "folder that gets one MESH_STEM.spheres.h5 per mesh.")
@click.option("--method", type=click.Choice(FIT_METHODS),
              default="variational", show_default=True,
              help="variational (Wang et al. 2006, minimal outside volume) or a baseline.")
@click.option("--seed", type=option_type("seed"), default=0, show_default=True,
              help="Seed of sampling and initialisation (same seed -> identical asset).")
@click.option("--thickness", type=option_type("thickness"), default=None,
              help="Fit a shell of this thickness around the surface (for flat/open sheets).")
@click.option("--iterations", type=option_type("iterations"), default=None,
              help="Round budget of the variational fit, counted in rounds at N spheres "
                   "(from N = 64 the coarse stages spend part of it in cheaper rounds); "
                   "a short budget shortens the finishing passes too (quick previews) "
                   f"[default: {DEFAULT_ROUNDS}].")
@click.option("--restarts", type=option_type("restarts"), default=1, show_default=True,
              help="Independent starts (seeds SEED, SEED+1, ...); the lowest E is kept.  "
                   "The fit is a non-convex search: a few starts buy a few percent of E.")
@scheduler_options("meshes (several MESH)")
@json_option
def fit(mesh_paths, count, output, method, seed, thickness, iterations, restarts,
        scheduler, workers, as_json):
    """Fit N spheres bounding the solid of MESH with minimal outside volume.

    Writes a 'spheres' asset with centers, radii and outside_volume_ratio
    E = sum_i V(S_i - T) / V(T), the E of the final line (the progress shows the
    search's objective instead: E on sample points, before the spheres are grown to
    hold the whole surface).  Several meshes (`meshes/*.obj -o out/`) are
    fitted as independent tasks on the local cores or a Dask cluster, one
    asset per mesh in the folder OUTPUT (docs/scale-out.md).
    """
    from shtools.cli._outputs import guard_outputs
    from shtools.geometry.assets import batch_outputs, fit_many, fit_to_file

    if len(mesh_paths) > 1 or Path(output).is_dir():
        outputs = batch_outputs(mesh_paths, output)
        guard_outputs({f"-o ({o.name})": o for o in outputs}, mesh_paths)
        pool: dict = {}
        rows = []
        with progress(total=len(mesh_paths), desc="fit", unit="mesh") as bar:
            for row in fit_many(mesh_paths, output, count, method=method, seed=seed,
                                thickness=thickness, iterations=iterations,
                                restarts=restarts, scheduler=scheduler,
                                workers=workers, pool_summary=pool):
                rows.append(row)
                bar.update(1)
        report({"fits": rows, "pool": pool}, as_json,
               "\n".join(f"wrote {r['output']}: {r['spheres']} spheres ({method}), "
                         f"E = {r['outside_volume_ratio']:.4f}" for r in rows))
        return
    mesh_path = mesh_paths[0]
    guard_outputs({"-o": output}, [mesh_path])
    result = fit_to_file(mesh_path, count, output, method=method, seed=seed,
                         thickness=thickness, iterations=iterations, restarts=restarts,
                         progress=progress)
    summary = {
        "output": output,
        "spheres": len(result),
        "method": method,
        "outside_volume_ratio": result.outside_volume_ratio,
        "coverage": result.coverage,
        "seconds": round(result.info.get("seconds", 0.0), 3),
        "volume": result.info.get("volume"),
        **{k: v for k, v in result.info.items()
           if k in ("iterations", "teleports_tried", "teleports_accepted", "points")},
    }
    report(summary, as_json,
           f"wrote {output}: {len(result)} spheres ({method}), "
           f"E = {result.outside_volume_ratio:.4f}, coverage {result.coverage:.3f}")


@spheres.command("import")
@click.argument("sph_path", metavar="FILE.sph", type=InputPath())
@output_option
@click.option("--level", type=option_type("level"), default=None,
              help="Tree level to import (0 = root); default the deepest non-empty level.")
@click.option("--mesh", "mesh_path", type=InputPath(), default=None,
              help="Mesh the spheres bound: used to compute outside_volume_ratio.")
@json_option
@errors_name("sph_path")
def import_cmd(sph_path, output, level, mesh_path, as_json):
    """Convert a spheretree .sph file into a 'spheres' asset."""
    from shtools.cli._outputs import guard_outputs
    from shtools.data_formats.spheres import write_spheres
    from shtools.geometry.sph_format import read_sph

    guard_outputs({"-o": output}, [sph_path, mesh_path])
    result = read_sph(sph_path, level=level)
    inputs = {"sph": sph_path}
    if mesh_path is not None:
        from shtools.geometry.mesh import load_mesh
        from shtools.geometry.outside_volume import OutsideVolume

        mesh = load_mesh(mesh_path)
        result.outside_volume_ratio = OutsideVolume(mesh).outside_volume_ratio(
            result.centers, result.radii)
        inputs["mesh"] = mesh_path
    write_spheres(output, result, inputs=inputs,
                  parameters={"level": result.info.get("level"), "source": "sph"})
    summary = {"output": output, "spheres": len(result), "level": result.info.get("level"),
               "outside_volume_ratio": result.outside_volume_ratio}
    report(summary, as_json, f"wrote {output}: {len(result)} spheres from level "
                             f"{result.info.get('level')} of {sph_path}")


@spheres.command("export")
@click.argument("spheres_path", metavar="SPHERES", type=InputPath())
@output_option
@json_option
@errors_name("spheres_path")
def export_cmd(spheres_path, output, as_json):
    """Write a 'spheres' asset as a two-level spheretree .sph file."""
    from shtools.cli._outputs import guard_outputs
    from shtools.data_formats.spheres import read_spheres
    from shtools.geometry.sph_format import write_sph

    guard_outputs({"-o": output}, [spheres_path])
    result = read_spheres(spheres_path)
    write_sph(output, result)
    report({"output": output, "spheres": len(result)}, as_json,
           f"wrote {output}: {len(result)} spheres")


@spheres.command("preview")
@click.argument("mesh_path", metavar="MESH", type=InputPath())
@click.argument("spheres_path", metavar="SPHERES", type=InputPath())
@output_option
@click.option("--size", nargs=2, type=option_type("size"), default=(480, 360),
              show_default=True, metavar="W H",
              help="Size of each of the two PNG panels (at most 8192 x 8192 pixels in all).")
@click.option("--elevation", type=option_type("elevation"), default=20.0, show_default=True,
              help="Camera elevation, degrees.")
@click.option("--azimuth", type=option_type("azimuth"), default=35.0, show_default=True,
              help="Camera azimuth of the left panel, degrees (the right one is +90).")
@json_option
def preview(mesh_path, spheres_path, output, size, elevation, azimuth, as_json):
    """Show the spheres of SPHERES (a spheres, tree or bound asset) over MESH.

    .png: two views, the mesh grey and each sphere half-transparent in its own
    colour.  .glb: the mesh and one node per sphere, for a DCC viewport.
    """
    from pathlib import Path

    from shtools.cli._outputs import guard_outputs
    from shtools.errors import InputError
    from shtools.export.spheres import render_spheres_png, write_spheres_glb
    from shtools.geometry.mesh import load_mesh

    guard_outputs({"-o": output}, [mesh_path, spheres_path])
    suffix = Path(output).suffix.lower()
    if suffix not in (".png", ".glb"):
        raise InputError(f"unsupported output format '{suffix or '(none)'}'; use .png or .glb",
                         output)
    centers, radii = _blocker_spheres(spheres_path)
    mesh = load_mesh(mesh_path)
    if suffix == ".png":
        from shtools.export.png import save_png

        save_png(render_spheres_png(mesh, centers, radii, width=size[0], height=size[1],
                                    elevation=elevation, azimuth=azimuth), output)
    else:
        write_spheres_glb(output, mesh, centers, radii, mesh_name=Path(mesh_path).stem)
    report({"output": output, "spheres": len(radii), "mesh_vertices": len(mesh.vertices)},
           as_json, f"wrote {output}: {len(radii)} spheres over {mesh_path}")


def _blocker_spheres(path):
    """Centres (N, 3) and radii (N,) of a spheres asset, a tree's leaves or a bound set."""
    import numpy as np

    from shtools.data_formats import read_asset
    from shtools.errors import InputError

    asset = read_asset(path)
    d = asset.data
    if asset.kind in ("spheres", "bound"):
        return np.asarray(d["centers"], float), np.asarray(d["radii"], float)
    if asset.kind == "tree":
        leaves = np.flatnonzero(d["leaf"] >= 0)
        return np.asarray(d["centers"][leaves], float), np.asarray(d["radii"][leaves], float)
    raise InputError(f"is a '{asset.kind}' asset; give a spheres, tree or bound asset", path)


# the tree engineer's commands (shtools/cli/spheres_tree.py)
from shtools.cli.spheres_tree import bind, tree  # noqa: E402

spheres.add_command(tree)
spheres.add_command(bind)
