"""The sphere-fit methods (one list; the fitter, the scene schema and the CLI import it)."""

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
