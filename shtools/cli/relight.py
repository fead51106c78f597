"""``shtools relight BAKE --light LIGHT.h5 -o OUT.h5``: a stored-visibility bake, another light."""

from __future__ import annotations

import click

from shtools.cli._common import (
    errors_name,
    json_option,
    option_type,
    output_option,
    progress,
    report,
)
from shtools.cli._limits import force_option

#: Seconds a relight runs before its progress shows: most take less (a bar would only
#: flicker), and the bar's import (tqdm) costs more than relighting a small bake.
PROGRESS_AFTER = 1.0


@click.command("relight")
@click.argument("baked", type=click.Path(dir_okay=False))
@click.option("--light", required=True, type=click.Path(dir_okay=False),
              help="Light asset of the bake's SH order ('shtools light project').")
@click.option("--rotate", type=option_type("rotate_y"), default=0.0, show_default=True,
              help="Turn the light about +Y, degrees (SH rotation; turntables).")
@click.option("--lights", "scene", type=click.Path(dir_okay=False), default=None,
              metavar="SCENE.toml",
              help="Add this scene's [[lights]] (posed at each frame's time), shadowed "
                   "through the stored visibility (SHEXP).")
@click.option("--compress", is_flag=True,
              help="gzip the output's radiance as a bake does (smaller, slower to write); "
                   "default plain. Geometry is copied as the bake stores it.")
@click.option("--keep-visibility", is_flag=True,
              help="Copy the stored visibility into the output too, to relight it again "
                   "(the largest part of the file); default leave it out, as a bake "
                   "without --store-visibility does.")
@output_option
@force_option("4 GiB of working memory")
@json_option
@errors_name("baked")
def relight(baked, light, rotate, scene, compress, keep_visibility, output, force,
            as_json):
    """Re-shade every frame of BAKED (made with --store-visibility) under LIGHT.

    The radiance is what a fresh bake of the same scene under that light gives
    (the same shading code), without posing, blockers or set-up: one triple
    product per vertex and frame, streamed a few frames at a time.  A bake lit
    from a finite environment sphere is relit on that sphere.  Without --lights
    the output has the environment only.
    """
    from shtools.cli._outputs import guard_outputs
    from shtools.progress import deferred
    from shtools.scene.relight import relight as relight_bake

    guard_outputs({"-o": output}, [baked, light, scene])
    if scene is not None:  # nor any file the scene names (a mesh, a light's field)
        from shtools.scene.light_record import bake_own_lights

        own = bake_own_lights(baked, scene)  # the bake's own scene: no parser
        if own is not None:
            own.check_output(output)
            scene = own
        else:
            from shtools.scene.light_record import scene_lights
            from shtools.scene.prepare import scene_files
            from shtools.scene.scene import load_scene

            scene = load_scene(scene)
            guard_outputs({"-o": output}, scene_files(scene))
            scene = scene_lights(scene)  # lights relighting can add: checked before any work
    _check_memory(baked, force)
    summary = relight_bake(baked, light, output, rotate=rotate, scene=scene,
                           compression="gzip" if compress else None,
                           keep_visibility=keep_visibility,
                           progress=deferred(progress, PROGRESS_AFTER))
    if summary["lamps_as_baked"] is False:
        click.echo(f"warning: {baked}: the lamps of --lights sit or measure otherwise than "
                   "the baked ones; a lamp's long shadow beyond an object's traced reach "
                   "is its blocker's (bake the scene with these lamps for it)", err=True)
    lights = f" + {summary['lights']} spherical light(s)" if summary["lights"] else ""
    report(summary, as_json,
           f"relit {summary['frames']} frame(s) x {summary['vertices']} vertices{lights} "
           f"in {summary['seconds']:.2f} s -> {output}")


def _check_memory(baked, force: bool) -> None:
    """Refuse a relight whose working memory passes the limit, from the bake's metadata.

    Frames stream through a few at a time, so the vertex count sets it, not the
    frame count (:func:`shtools.scene.relight.relight_bytes`)."""
    import h5py

    from shtools.cli._limits import check_memory
    from shtools.scene.relight import relight_bytes
    from shtools.tasks import default_workers

    try:
        with h5py.File(baked, "r") as f:
            T, V = f["radiance"].shape[:2]
            size = int(f.attrs["sh_order"]) ** 2
    except (OSError, KeyError, ValueError, TypeError):  # not a bake: relight says so
        return
    threads = default_workers()
    check_memory("relight", relight_bytes(T, V, size, threads),
                 f"{V:,} vertices x {size} SH coefficients, {threads} thread(s)",
                 "relight a bake of fewer receiver vertices", force=force, path=baked)
