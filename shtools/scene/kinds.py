"""The scene's registries, complete: every module that registers a kind or a way is imported here.

The protocols and their built-in entries live with their registries
(:data:`~shtools.scene.blockers.BLOCKER_KINDS` in :mod:`shtools.scene.blockers`;
:data:`~shtools.scene.shadows.VISIBILITY_METHODS` and
:data:`~shtools.scene.shadows.LIGHT_SHADOWS` in :mod:`shtools.scene.shadows`).  A kind
or way in a module of its own registers itself there when imported, and this module
imports each such module, one line each.  The parser, the preparation, the poses and
the baker read the registries from here, so they always see every entry; the
registries and the plugins never import this module, so no import cycle closes
through it.
"""

# each plugin registers itself when imported
from shtools.scene import (
    deformable,  # noqa: F401  blocker = { deformable = true }
    field_blocker,  # noqa: F401  blocker = { field = "x.field.h5" }
    field_light,  # noqa: F401  [[lights]] field = "x.srf.h5"
    light_shadows,  # noqa: F401  shadows = "ssoc" | "raytrace" | "auto"
)
from shtools.scene.blockers import BLOCKER_KINDS
from shtools.scene.shadows import LIGHT_SHADOWS, VISIBILITY_METHODS

__all__ = ["BLOCKER_KINDS", "LIGHT_SHADOWS", "VISIBILITY_METHODS", "bake_method_names"]


def bake_method_names() -> tuple[str, ...]:
    """The registered visibility methods (choices of ``settings.method`` and ``--method``)."""
    return VISIBILITY_METHODS.names()
