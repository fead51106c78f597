"""``shtools view BAKE``: look at a bake in the browser (a local server on 127.0.0.1)."""

from __future__ import annotations

import click

from shtools.cli._limits import force_option


@click.command("view")
@click.argument("baked", type=click.Path(dir_okay=False))
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="Port on 127.0.0.1 (0: a free one).")
@click.option("--scene", type=click.Path(dir_okay=False), default=None, metavar="SCENE.toml",
              help="The bake's scene: overlay its blocker spheres, posed per frame.")
@click.option("--no-browser", is_flag=True, help="Print the URL only; open no browser.")
@force_option("4 GiB of memory")
def view(baked, port, scene, no_browser, force):
    """Serve a viewer of BAKED on 127.0.0.1 until Ctrl-C: orbit camera, frame slider and
    play at the bake's fps, per-object toggles, radiance / irradiance / visibility and
    exposure (the export's tone mapping), and optionally the blocker spheres.

    Works offline: the page is plain WebGL 2 shipped with shtools.
    """
    try:
        from shtools.view import BakeView, scene_spheres, serve
    except ImportError as exc:  # an install without the extra's modules
        from shtools.errors import InputError

        raise InputError(f"the viewer cannot start ({exc.name or exc} is missing); install "
                         "the 'view' extra: pip install 'shtools[view]'") from None

    from shtools.cli._limits import check_asset_memory

    # the bake is read whole, then served as float32 arrays
    check_asset_memory("view", baked, "view a bake of fewer frames (bake --frames)",
                       force=force)
    data = BakeView(baked)
    if scene is not None:
        try:
            data.spheres = scene_spheres(scene, data.bake)
        except ImportError as exc:  # preparing a scene loads its meshes
            from shtools.errors import InputError

            raise InputError(f"--scene needs the 'geometry' extra ({exc.name} is missing); "
                             "pip install 'shtools[geometry]' or leave --scene out",
                             scene) from None

    def ready(url: str) -> None:
        click.echo(f"shtools view: {url}  (Ctrl-C to stop)")
        if not no_browser:
            import webbrowser

            webbrowser.open(url)

    serve(data, port, on_ready=ready)
    click.echo("shtools view: stopped")
