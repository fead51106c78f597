"""Names and defaults of sphere-set choices (light: the scene schema and the CLI import them).

The fit methods (the fitter checks them) and the spaces a set to bind may be given in
(:func:`shtools.geometry.binding.spheres_to_bind_space`).
"""

from enum import StrEnum


class FitMethod(StrEnum):
    """Methods of :func:`shtools.geometry.sphere_fit.fit_spheres`."""

    #: Wang et al. 2006 variational fit (the default)
    VARIATIONAL = "variational"
    #: circumscribed spheres of octree cells (baseline)
    OCTREE = "octree"
    #: k-means clusters of surface/inside points (baseline)
    KMEANS = "kmeans"


FIT_METHODS = tuple(m.value for m in FitMethod)

#: default round budget of the variational fit, in rounds at N spheres: half the
#: budget of 30 rounds leaves E well above its settled value, while more rounds
#: lower it little for their CPU (the fits of docs/sphere-fits.md)
DEFAULT_ROUNDS = 60

#: spaces a sphere set to bind may be given in: "bind" (the rig's POSITION data),
#: "scene" (the glTF as placed in its scene) or "auto" (whichever the spheres cover)
SPHERE_SPACES = ("auto", "bind", "scene")
