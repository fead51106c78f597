"""Imports every module that registers a blocker kind or a light-shadow way.

The built-in kinds (:mod:`shtools.scene.blockers`) and ways
(:mod:`shtools.scene.shadows`) register themselves; a kind or way in its own
module (e.g. shadow fields) is imported here, one line each, so the scene
schema and the baker see it:

    import shtools.fields.blocker  # noqa: F401  (registers blocker = { field = ... })
"""

# blocker = { deformable = true } (deformable shadow fields, skinned objects)
import shtools.scene.deformable
import shtools.scene.field_blocker  # registers blocker = { field = ... }
import shtools.scene.field_light  # [[lights]] field = "x.srf.h5" (source radiance fields)
import shtools.scene.light_shadows  # noqa: F401  (shadows = "ssoc" | "raytrace" | "auto")
