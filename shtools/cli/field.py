"""``shtools field sample``: the adaptive shadow field of a rigid mesh (Tamura et al.).

Thin: validate options, load the mesh, call :func:`shtools.fields.sample_field`,
write one ``field`` asset, report.
"""

from __future__ import annotations

import click

from shtools.cli._common import (
    InputPath,
    checking_options,
    errors_name,
    json_option,
    option_type,
    output_option,
    progress,
    report,
    scheduler_options,
    setting_type,
)
from shtools.cli._limits import force_option


@click.group("field")
def field():
    """Shadow fields of rigid objects (precomputed visibility on concentric shells)."""


@field.command("sample")
@click.argument("mesh_path", metavar="MESH", type=InputPath())
@output_option
@click.option("--shells", default=32, show_default=True, type=option_type("shells"),
              help="Shells C; radius r_c = 0.2 V_r (1 + c), V_r the bounding-sphere radius.")
@click.option("--resolution", default=64, show_default=True,
              type=option_type("field_resolution"), help="Initial samples per shell, R x R.")
@click.option("--map", "map_size", default=64, show_default=True,
              type=option_type("map_size"),
              help="Directions per sample: a MAP x MAP (theta, phi) map, exact cell areas.")
@click.option("--order", default=4, show_default=True, type=setting_type("order"),
              help="SH order n.")
@click.option("--threshold", default=0.01, show_default=True, type=option_type("threshold"),
              help="Eq. (1) error below which a shell's resolution is halved.")
@click.option("--min-resolution", default=8, show_default=True,
              type=option_type("min_resolution"),
              help="Smallest R a shell is reduced to, at most --resolution.")
@click.option("--bits", default=8, show_default=True, type=option_type("bits"),
              help="Quantization bits per coefficient.")
@click.option("--cumulative", is_flag=True,
              help="Check every halving against the initial samples (beyond the paper, "
                   "which compares with the previous level only).")
@click.option("--no-self-visibility", is_flag=True,
              help="Do not store the per-vertex self-visibility O_v (the object's own "
                   "vertices then need a transfer asset or are not self-shadowed).")
@click.option("--self-order", default=None, type=setting_type("acc_order"),
              help="SH order of the stored O_v, at least --order [default: --order; a bake "
                   "uses its first --order only].")
@click.option("--seed", default=0, show_default=True, type=option_type("seed"),
              help="Recorded for reproducibility (sampling is deterministic).")
@click.option("--radiance", "emission", default=None, type=click.Path(dir_okay=False),
              help="EMISSION table (TOML: radiance = [r, g, b], fixture = [meshes]): sample "
                   "the source radiance field of a lamp whose closed emitter is MESH into an "
                   "srf asset, instead of an occlusion field (docs/formats.md).")
@click.option("--error-scale", default="receiver", show_default=True,
              type=click.Choice(["receiver", "peak", "emitter"]),
              help="With --radiance: eq. (1) on the Lambertian radiance the lamp casts, "
                   "relative to the brightest receiver at each shell (receiver), on the "
                   "radiance relative to each shell's largest (peak) or to the emitter's "
                   "radiance (emitter: smaller, less exact).")
@click.option("--basis", default="sh", show_default=True, type=click.Choice(["sh", "haar"]),
              help="haar: an all-frequency field, each sample's MAP x MAP occlusion map in "
                   "the 2-D Haar basis, the largest --keep kept (a haar asset; no O_v).")
@click.option("--keep", default=0.05, show_default=True, type=option_type("keep"),
              help="With --basis haar: fraction of the Haar coefficients kept per sample.")
@scheduler_options("shells")
@force_option("4 GiB of memory, 2e10 rays")
@json_option
@errors_name("mesh_path")
def sample(mesh_path, output, shells, resolution, map_size, order, threshold, min_resolution,
           bits, cumulative, no_self_visibility, self_order, seed, emission, error_scale,
           basis, keep, scheduler, workers, force, as_json):
    """Sample the shadow field of MESH into a field asset.

    Per shell, the object's binary visibility over the direction map at R x R
    points is projected to SH (rays outside the cone of the bounding sphere are
    not cast: they are unoccluded), the shell is reduced while eq. (1) stays
    below --threshold at every initial sample, and the kept samples and their
    SH logs are quantized.  The object's self-visibility O_v on its own vertices
    (--self-order) is stored too: a bake with `blocker = { field = ... }` then
    shadows the object itself with its real mesh, with no other asset.
    """
    from shtools.data_formats.field import write_field
    from shtools.errors import InputError
    from shtools.fields import FieldParameters, sample_field
    from shtools.geometry.mesh import load_mesh

    params = FieldParameters(shells=shells, resolution=resolution, map_size=map_size,
                             order=order, threshold=threshold, min_resolution=min_resolution,
                             bits=bits, cumulative=cumulative, seed=seed,
                             self_order=self_order)
    with checking_options():  # what the types cannot see: --min-resolution, --self-order
        params.validate()
    from shtools.cli._limits import check_memory, check_rays
    from shtools.cli._outputs import guard_outputs

    if basis == "haar":
        from shtools.cli.field_haar import sample_haar

        sample_haar(mesh_path, output, params, keep, emission, force, as_json)
        return
    from shtools.fields.build import planned_cost
    from shtools.tasks import default_workers

    # a source radiance field holds RGB: three SH vectors a sample
    cost = planned_cost(params, workers or (1 if scheduler == "inline" else default_workers()),
                        channels=1 if emission is None else 3)
    fix = "lower --shells, --resolution, --map or --order"
    check_memory("field sample", cost["bytes"], cost["formula"], fix, force=force,
                 path=mesh_path)
    check_rays("field sample", cost["rays"], f"{shells} shells x {resolution}^2 samples x "
               f"{map_size}^2 directions", fix, force=force, path=mesh_path)
    if emission is not None:
        from shtools.fields.emitter import read_emission

        guard_outputs({"-o": output}, [mesh_path, emission, *read_emission(emission)[1]])
        _sample_radiance(mesh_path, emission, output, params, error_scale, scheduler, workers,
                         as_json)
        return
    guard_outputs({"-o": output}, [mesh_path])
    mesh = load_mesh(mesh_path)
    sv = None
    if not no_self_visibility:
        from shtools.geometry.transfer import (
            FIELD_ESTIMATE,
            FIRST_DIRECTIONS,
            TRANSFER_DIRECTIONS,
        )
        from shtools.geometry.transfer import field_self_visibility as sv

        # O_v: every vertex's rays besides the shells' (at most the first pass and the
        # whole dense set each)
        n = len(mesh.vertices)
        per_vertex = FIRST_DIRECTIONS + TRANSFER_DIRECTIONS
        check_rays("field sample (self-visibility)", n * per_vertex,
                   f"{n} vertices x {per_vertex} directions",
                   "pass --no-self-visibility (or use a `transfer` asset)", force=force,
                   path=mesh_path)
    with progress(total=shells * resolution * resolution, desc="field samples") as bar:
        try:
            fld, rep = sample_field(mesh, params, self_visibility=sv, progress=bar.update,
                                    scheduler=scheduler, workers=workers)
        except InputError as exc:
            raise InputError(exc.message, exc.path or mesh_path) from None
    parameters = {k: getattr(params, k) for k in (
        "shells", "resolution", "map_size", "order", "threshold", "min_resolution", "bits",
        "cumulative", "log_floor", "log_eps", "seed")}
    if not no_self_visibility:
        parameters["self_order"] = params.resolved_self_order()
        parameters.update(FIELD_ESTIMATE)  # the bake's estimator (field_self_visibility)
    write_field(output, fld, inputs={"mesh": mesh_path}, parameters=parameters)
    fixed = shells * resolution * resolution * order * order
    summary = {
        **_stored_summary(output, shells, fld, fixed),
        "rays": rep.rays,
        "rays_without_cull": rep.rays_uncull,
        "seconds": {k: round(v, 3) for k, v in rep.seconds.items()},
        "rays_per_second": round(rep.rays / max(rep.seconds["cast"], 1e-9)),
        "closed": fld.attrs["closed"],
        "boundary_edges": fld.attrs["boundary_edges"],
        "self_visibility": fld.self_visibility is not None,
        "self_order": fld.self_order,
    }
    human = (f"wrote {output}: {shells} shells, R_c {summary['resolution']}, "
             f"{summary['bytes']} B ({summary['reduction_percent']:.1f} % below fixed), "
             f"{rep.rays / 1e6:.1f} M rays in {rep.seconds['total']:.1f} s")
    if not fld.attrs["closed"]:
        human += (f"; open mesh ({fld.attrs['boundary_edges']} boundary edges): rays leak "
                  "through its holes")
    report(summary, as_json, human)


def _stored_summary(output, shells: int, fld, fixed: int) -> dict:
    """The summary keys of a sampled field (shadow or radiance) about what it stores:
    ``fixed`` is the value count of the same shells at full resolution."""
    return {
        "output": output,
        "shells": shells,
        "resolution": [int(r) for r in fld.resolution],
        "bytes": fld.stored_bytes(),
        "fixed_bytes": fixed,
        "reduction_percent": round(100 * (1 - fld.stored_bytes() / fixed), 2),
        "cumulative_error": [round(float(e), 6) for e in fld.reduction_error],
        "bounding_radius": fld.bounding_radius,
    }


def _sample_radiance(mesh_path, emission, output, params, error_scale, scheduler, workers,
                     as_json):
    """``field sample MESH --radiance EMISSION``: a lamp's source radiance field."""
    from shtools.data_formats.srf import write_radiance_field
    from shtools.errors import InputError
    from shtools.fields.emitter import load_emitter
    from shtools.fields.radiance import sample_radiance_field

    emitter = load_emitter(mesh_path, emission)
    R0 = params.resolution
    with progress(total=params.shells * R0 * R0, desc="radiance samples") as bar:
        try:
            fld, rep = sample_radiance_field(emitter, params, error_scale=error_scale,
                                             progress=bar.update, scheduler=scheduler,
                                             workers=workers)
        except InputError as exc:
            raise InputError(exc.message, exc.path or mesh_path) from None
    parameters = {k: getattr(params, k) for k in (
        "shells", "resolution", "map_size", "order", "threshold", "min_resolution", "bits",
        "cumulative", "seed")}
    parameters["error_scale"] = error_scale
    write_radiance_field(output, fld, inputs={"mesh": mesh_path, "emission": emission},
                         parameters=parameters)
    fixed = params.shells * R0 * R0 * 3 * params.order ** 2
    summary = {
        **_stored_summary(output, params.shells, fld, fixed),
        "emitter_radius": fld.emitter_radius,
        "radiance": [float(x) for x in fld.radiance],
        "rays": rep.rays,
        "seconds": {k: round(v, 3) for k, v in rep.seconds.items()},
    }
    human = (f"wrote {output}: source radiance field, {params.shells} shells, R_c "
             f"{summary['resolution']}, {summary['bytes']} B "
             f"({summary['reduction_percent']:.1f} % below fixed), "
             f"{rep.rays / 1e6:.1f} M rays in {rep.seconds['total']:.1f} s")
    report(summary, as_json, human)
