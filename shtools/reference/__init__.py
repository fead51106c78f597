"""Ground truth and baselines for the runtime.

* :func:`product_space_visibility` — product-space accumulation (Zhou et al. 2005);
* :func:`raytrace_visibility` — ray tracing of the actual meshes (Embree);
* :func:`sphere_union_visibility` — exact ray tracing of the sphere union;
* :func:`relative_rmse` — the error measure of ``shtools eval``;
* :mod:`shtools.reference.scenes` — procedural evaluation scenes;
* :mod:`shtools.reference.evaluation` — the method comparison behind ``shtools eval``.

Unlike :mod:`shtools.runtime`, this package may import the geometry stack.
"""

from shtools.reference.metrics import relative_l2_per_vertex, relative_rmse
from shtools.reference.product_space import product_space_visibility
from shtools.reference.raytrace import (
    DEFAULT_DIRECTIONS,
    raytrace_visibility,
    sphere_union_visibility,
)

__all__ = [
    "DEFAULT_DIRECTIONS",
    "product_space_visibility",
    "raytrace_visibility",
    "relative_l2_per_vertex",
    "relative_rmse",
    "sphere_union_visibility",
]
