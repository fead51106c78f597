"""Ground truth and baselines for the runtime.

* :func:`product_space_visibility` — product-space accumulation (Zhou et al. 2005);
* :func:`raytrace_visibility` — ray tracing of the actual meshes (Embree);
* :func:`sphere_union_visibility` — exact ray tracing of the sphere union;
* :func:`relative_rmse` — the error measure of ``shtools eval``;
* :mod:`shtools.reference.scenes` — procedural evaluation scenes;
* :mod:`shtools.reference.evaluation` — the method comparison behind ``shtools eval``.

Unlike :mod:`shtools.runtime`, this package may import the geometry stack.
"""

import importlib

#: public name -> module (loaded on first use, so ``shtools.reference.scenes`` and
#: the metrics import without the geometry stack)
_LAZY = {
    "relative_l2_per_vertex": "shtools.reference.metrics",
    "relative_rmse": "shtools.reference.metrics",
    "product_space_visibility": "shtools.reference.product_space",
    "DEFAULT_DIRECTIONS": "shtools.reference.raytrace",
    "raytrace_visibility": "shtools.reference.raytrace",
    "sphere_union_visibility": "shtools.reference.raytrace",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'shtools.reference' has no attribute {name!r}")


def __dir__():
    return sorted([*globals(), *_LAZY])
