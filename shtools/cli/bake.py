"""``shtools bake SCENE -o baked.h5``: bake a scene into a ``bake`` asset."""

from __future__ import annotations

import click

from shtools.cli._common import (
    InputPath,
    errors_name,
    json_option,
    output_option,
    progress,
    report,
    scheduler_options,
    setting_type,
)
from shtools.cli.cache import cache_options, open_cache
from shtools.scene.kinds import bake_method_names


@click.command("bake")
@click.argument("scene", type=InputPath())
@output_option
@click.option("--frames", "frames_text", metavar="A:B",
              help="Frames to bake, half-open like Python (A:B, A:, :B or one frame A); "
                   "default all.")
@click.option("--method", type=click.Choice(bake_method_names()), default=None,
              help="Visibility method: the runtime (default = the scene's exp method, or an "
                   "exp method by name), product-space accumulation, or ray tracing of the "
                   "posed meshes (ground truth).  Default: settings.method of the scene.")
@click.option("--store-visibility", is_flag=True,
              help="Also store the per-vertex visibility SH vectors (T, V, n*n), for "
                   "`shtools relight`: the traced shadows' hand-over then leaves the sky "
                   "out, so the visibility holds under any light.")
@click.option("--processes", type=setting_type("processes"), default=None,
              help="Processes sharing ONE frame's shadow evaluation, when frames are "
                   "evaluated in this process (a single frame, or --workers 1); default one "
                   "per core.")
@scheduler_options("frames")
@click.option("--split-frames/--no-split-frames", default=None,
              help="With --scheduler: evaluate frames one after the other here and run each "
                   "large frame's parts as tasks on the cluster (for one huge frame).  "
                   "Default: when the bake has fewer frames than workers and than the 8 parts of "
                   "a frame.  Same bytes.")
@click.option("--force", is_flag=True,
              help="Bake even past the size limits (1e9 vertex-frames, 16 GiB of output).")
@cache_options
@json_option
@errors_name("scene")
def bake(scene, output, frames_text, method, store_visibility, processes, scheduler, workers,
         split_frames, force, cache_dir, no_cache, as_json):
    """Bake SCENE (TOML) frame by frame into the bake asset OUTPUT.

    Frames are independent tasks spread over the local cores (or a Dask
    cluster with --scheduler) and written in frame order by this process; the
    file appears only when every frame is done (an error or Ctrl-C leaves
    nothing behind), and is the same bytes however the frames were spread.
    """
    from shtools.cli._outputs import guard_outputs
    from shtools.scene.bake import bake_to_file, parse_frames, scene_files
    from shtools.scene.scene import load_scene

    guard_outputs({"-o": output}, [scene])
    parsed = load_scene(scene)
    guard_outputs({"-o": output}, scene_files(parsed))
    frames = parse_frames(frames_text, parsed.settings.frames, scene)
    summary = bake_to_file(parsed, output, frames=frames, method=method,
                           store_visibility=store_visibility, processes=processes,
                           scheduler=scheduler, workers=workers, progress=progress, force=force,
                           split_frames=split_frames, cache=open_cache(cache_dir, no_cache))
    human = (
        f"baked {summary['frames']} frame(s) x {summary['vertices']} vertices "
        f"({summary['method']}) in {summary['seconds']:.2f} s "
        f"({summary['setup_seconds']:.2f} s setup), "
        f"{summary['vertex_frames_per_second']:,.0f} vertex-frames/s -> {output}"
    )
    report(summary, as_json, human)
