"""``shtools export baked.h5 -o out.{ply,glb,usda,usdc,exr,png,gif}``: hand a bake on."""

from __future__ import annotations

from pathlib import Path

import click

from shtools.cli._common import (
    InputPath,
    errors_name,
    json_option,
    option_error,
    option_type,
    output_option,
    progress,
    report,
)
from shtools.cli._limits import force_option
from shtools.export.tonemap import CURVES


@click.command("export")
@click.argument("baked", type=InputPath())
@output_option
@click.option("--frame", type=option_type("frame"), default=None,
              help="Scene frame number to export (default the bake's first).")
@click.option("--frames", "frames_text", metavar="A:B[:S]",
              help="Frame range, half-open with step S: a contact sheet (.png), the frames of "
                   "a .gif/USD/.exr, one animated .glb, or a numbered .ply sequence "
                   "NAME.<frame>.ply.")
@click.option("--sequence", is_flag=True,
              help="With .glb and --frames: one file per frame, NAME.<frame>.glb, instead "
                   "of one animated file.")
@click.option("--quantity", type=click.Choice(["radiance", "irradiance", "visibility"]),
              default="radiance", show_default=True,
              help="Per-vertex value exported, before albedo (visibility: cosine-weighted, "
                   "needs a bake with --store-visibility).")
@click.option("--target", metavar="OBJECT", default=None,
              help="Frame this receiver object in a .png/.gif preview.")
@click.option("--rig", metavar="OBJECT=RIG.glb", default=None,
              help="With .glb: write skinned OBJECT as its source glTF with skin and clips "
                   "kept and the baked colours of --frame (static) or of --frames (morph "
                   "targets in an added 'bake' animation).")
@click.option("--distance", type=option_type("distance"), default=None,
              help="Camera distance from the framed centre, scene units (default: fitted).")
@click.option("--exposure", type=option_type("exposure"), default=0.0, show_default=True,
              help="Exposure in stops on top of the automatic exposure.")
@click.option("--fixed-exposure", is_flag=True,
              help="No automatic exposure: radiance x 2^exposure goes straight to the tone curve.")
@click.option("--tonemap", "curve", type=click.Choice(tuple(CURVES)),
              default="aces", show_default=True, help="Tone curve.")
@click.option("--size", nargs=2, type=option_type("size"), default=None, metavar="W H",
              help="Image size in pixels (default 800 600; 320 240 per sheet tile / GIF frame).")
@click.option("--elevation", type=option_type("elevation"), default=30.0, show_default=True,
              help="Camera elevation above the horizon, degrees.")
@click.option("--azimuth", type=option_type("azimuth"), default=35.0, show_default=True,
              help="Camera azimuth about +Y, degrees.")
@click.option("--zoom", type=option_type("zoom"), default=1.0, show_default=True,
              help="> 1 moves the camera closer than the fitted bounding sphere.")
@click.option("--columns", type=option_type("columns"), default=None,
              help="Contact sheet columns.")
@click.option("--fps", type=option_type("fps"), default=None,
              help="GIF frame rate (default the bake's).")
@force_option("4 GiB of memory to read the bake")
@json_option
@errors_name("baked")
def export(baked, output, frame, frames_text, sequence, quantity, target, rig, distance, exposure,
           fixed_exposure, curve, size, elevation, azimuth, zoom, columns, fps, force, as_json):
    """Export a bake: a GLB (one named mesh per object; a frame range plays as one
    animated file), PLY frames, a time-sampled USD stage, a vertex animation
    texture (.exr + .glb), PNG previews, a contact sheet or an animated GIF.
    """
    from shtools.cli._limits import check_asset_memory
    from shtools.cli._outputs import guard_outputs, planned
    from shtools.data_formats.bake import read_bake
    from shtools.errors import InputError
    from shtools.export.png import View
    from shtools.export.writer import FORMATS, export_bake, output_files

    if rig is not None:
        name, sep, rig_path = rig.partition("=")
        if not sep or not name or not rig_path:
            raise option_error(f"--rig '{rig}' is not OBJECT=RIG.glb; give the object's "
                               "name and its rig, e.g. --rig character=character.glb")
        rig = (name, rig_path)
    inputs = [baked, rig[1] if rig else None]
    guard_outputs({"-o": output}, inputs)
    suffix = Path(output).suffix.lower()
    if suffix not in FORMATS:
        raise InputError(f"unsupported output format '{suffix or '(none)'}'; use one of "
                         f"{', '.join(FORMATS)}", output)
    # the bake is read whole before any frame is chosen
    check_asset_memory("export", baked, "export a bake of fewer frames (bake --frames)",
                       force=force)
    bake_asset = read_bake(baked)
    # every file the export writes (a sequence's frames, a VAT's companions), before work
    guard_outputs(planned("-o", output, output_files(
        bake_asset, output, frame=frame, frames_text=frames_text, sequence=sequence,
        rig=rig)), inputs)
    view = View(elevation=elevation, azimuth=azimuth, zoom=zoom, exposure=exposure,
                auto_exposure=not fixed_exposure, curve=curve, distance=distance)
    summary = export_bake(bake_asset, output, frame=frame, frames_text=frames_text, view=view,
                          size=size, columns=columns, fps=fps, quantity=quantity,
                          target=target, rig=rig, sequence=sequence, progress=progress)
    files = summary.get("files", [output])
    written = files[0] if len(files) == 1 else f"{len(files)} files"
    report(summary, as_json, f"wrote {written} ({summary['detail']})")
