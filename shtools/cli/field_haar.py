"""``shtools field sample MESH --basis haar``: an all-frequency (Haar) shadow field.

Thin: validate the Haar options, load the mesh, call
:func:`shtools.fields.haar.build_haar_field`, write one ``haar`` asset, report.
"""

from __future__ import annotations

from shtools.cli._common import option_error, progress, report


def sample_haar(mesh_path, output, params, keep: float, emission, force: bool,
                as_json: bool) -> None:
    """Sample, reduce, quantize and write the Haar field of ``mesh_path`` (see ``field sample``)."""
    from shtools.cli._limits import check_memory, check_rays
    from shtools.cli._outputs import guard_outputs
    from shtools.data_formats.haar import MAX_MAP_SIZE, write_haar_field
    from shtools.fields.haar import build_haar_field, kept_count
    from shtools.geometry.mesh import load_mesh

    M, R, C = params.map_size, params.resolution, params.shells
    if emission is not None:
        raise option_error("--radiance samples a source radiance field in SH; drop --basis "
                           "haar")
    if M & (M - 1) or M > MAX_MAP_SIZE:
        raise option_error(f"--map must be a power of two <= {MAX_MAP_SIZE} with --basis haar "
                           f"(the Haar transform halves it; indices are 16-bit), got {M}")
    if params.self_order is not None:
        raise option_error("--self-order sets the O_v of an SH field; a haar asset stores "
                           "none (drop it, or self-shadow the object with a transfer asset)")
    if params.bits != 8:
        raise option_error(f"--bits must be 8 with --basis haar (values are stored as "
                           f"uint8), got {params.bits}")
    # one shell's maps in flight: float32 samples, the float64 reduction copy, its 2 x 2
    # averages and the interpolated comparison chunk
    peak = R * R * M * M * (4 + 8 + 8 + 8)
    check_memory("field sample --basis haar", peak, f"{R}^2 samples x {M}^2 cells x 28 B",
                 "lower --resolution or --map", force=force, path=mesh_path)
    check_rays("field sample --basis haar", C * R * R * M * M,
               f"{C} shells x {R}^2 samples x {M}^2 directions",
               "lower --shells, --resolution or --map", force=force, path=mesh_path)
    guard_outputs({"-o": output}, [mesh_path])
    mesh = load_mesh(mesh_path)
    with progress(total=C, desc="haar shells"):
        fld, cumulative = build_haar_field(
            mesh, shells=C, resolution=R, map_size=M, keep=keep, threshold=params.threshold,
            min_resolution=params.min_resolution, cumulative=params.cumulative)
    parameters = {"basis": "haar", "shells": C, "resolution": R, "map_size": M, "keep": keep,
                  "threshold": params.threshold, "min_resolution": params.min_resolution,
                  "bits": 8, "cumulative": params.cumulative, "seed": params.seed}
    write_haar_field(output, fld, reduction_error=cumulative, inputs={"mesh": mesh_path},
                     parameters=parameters)
    K = kept_count(M, keep)
    fixed = C * R * R * K * 3
    summary = {
        "output": output,
        "basis": "haar",
        "shells": C,
        "resolution": [int(r) for r in fld.resolution],
        "kept": K,
        "bytes": fld.stored_bytes(),
        "fixed_bytes": fixed,
        "reduction_percent": round(100 * (1 - fld.stored_bytes() / fixed), 2),
        "cumulative_error": [round(float(e), 6) for e in cumulative],
        "bounding_radius": fld.bounding_radius,
    }
    report(summary, as_json,
           f"wrote {output}: Haar field, {C} shells, R_c {summary['resolution']}, {K} of "
           f"{M * M} coefficients kept, {summary['bytes']} B "
           f"({summary['reduction_percent']:.1f} % below fixed)")
