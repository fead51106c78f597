"""``shtools view``: a bake in the browser (orbit, frames, objects, quantity, exposure).

:class:`~shtools.view.data.BakeView` turns a bake into what the page draws (the
export's display colours per frame); :func:`~shtools.view.server.serve` runs a
local HTTP server on 127.0.0.1 for the page in ``static/`` (plain WebGL 2, no
download at run time).  From Python::

    from shtools.view import BakeView, serve
    serve(BakeView("baked.h5"), port=0, on_ready=print)
"""

from shtools.view.data import BakeView, scene_spheres
from shtools.view.server import ViewerServer, serve

__all__ = ["BakeView", "ViewerServer", "scene_spheres", "serve"]
