"""Mid-range environment lighting in scenes (Wang et al. 2005, Sec. 3.2).

``[environment]`` with ``radius`` (and optionally ``center``, ``scaling``) puts
the environment on a sphere of that radius instead of at infinity.  The
environment SH is what an observer at ``center`` sees; every receiver vertex
gets its own radiance SH by plain mid-range SH scaling
(:func:`shtools.runtime.scaling.midrange_lighting`), and is shaded with it.

The scaling order: a ``scaling`` asset's order; else ``n + 4`` (at most 12) for
an ``image`` environment, projected again at that order (the warp moves the
environment's higher bands into the shaded ones), and ``n`` for a ``light``
asset or inline ``coeffs`` (only order ``n`` is known).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shtools.errors import AssetError, InputError

#: Extra bands of the scaling over the shading order for image environments.
EXTRA_BANDS = 4
MAX_SCALING_ORDER = 12
#: Largest k = d/R of the table built in memory (receivers beyond are refused).
DEFAULT_KMAX = 0.98
DEFAULT_SAMPLES = 48


@dataclass
class MidrangeEnvironment:
    """A prepared finite environment sphere.

    Attributes
    ----------
    center : ndarray, shape (3,)
    radius : float
    table : shtools.runtime.scaling.ScalingTable
        A plain ``midrange`` table.
    env_sh : ndarray, shape (N*N, 3)
        Radiance SH seen from the centre, at the table's order ``N``.
    order : int
        Shading order ``n``.
    """

    center: np.ndarray
    radius: float
    table: object
    env_sh: np.ndarray
    order: int
    scene_path: object = None
    _cache: dict = field(default_factory=dict)

    def radiance_sh(self, vertices) -> np.ndarray:
        """Per-vertex radiance SH ``(V, n*n, 3)``; kept while the vertices do not move.

        Raises
        ------
        InputError
            A receiver on or outside the sphere, or beyond the table's ``kmax``.
        """
        from shtools.runtime.scaling import midrange_lighting

        cached = self._cache.get("vertices")
        if cached is not None and cached.shape == vertices.shape and np.array_equal(
                cached, vertices):
            return self._cache["radiance"]
        dist = np.linalg.norm(vertices - self.center, axis=1)
        worst = int(np.argmax(dist))
        kmax = self.table.k_range[1]
        if dist[worst] >= self.radius * kmax:
            where = "outside" if dist[worst] >= self.radius else "too close to"
            raise InputError(
                f"environment.radius: a receiver vertex at {np.round(vertices[worst], 4).tolist()}"
                f" is {where} the environment sphere (distance {dist[worst]:.4g} from the "
                f"center, radius {self.radius:g}, usable up to k = d/R = {kmax:g}); enlarge "
                "'radius' or move 'center'", self.scene_path)
        out = midrange_lighting(self.env_sh, vertices, self.center, self.radius, self.table,
                                out_order=self.order)
        self._cache.update(vertices=vertices.copy(), radiance=out)
        return out


def prepare_midrange(scene, env_sh, inputs: dict, cache=None) -> MidrangeEnvironment | None:
    """The scene's finite environment sphere, or None for an environment at infinity.

    Parameters
    ----------
    scene : shtools.scene.scene.Scene
    env_sh : ndarray, shape (n*n, 3) or None
        The environment as the bake prepared it (intensity and rotation applied).
    inputs : dict
        Provenance; a scaling asset is added.
    cache : shtools.cache.SetupCache, optional
        Where an image projected again at the scaling order is read from or stored.
    """
    env = scene.environment
    if env.radius is None or env_sh is None:
        return None
    from shtools.runtime.scaling import ScalingTable

    order = scene.settings.order
    if env.scaling is not None:
        from shtools.data_formats.scaling import read_scaling

        table = read_scaling(env.scaling)
        if table["function"] != "midrange" or table["energy_preserving"]:
            raise AssetError("mid-range lighting needs a plain 'midrange' scaling table "
                             "(shtools tables scaling --function midrange)", env.scaling)
        if int(table["order"]) < order:
            raise AssetError(f"scaling table is SH order {table['order']} but the scene's "
                             f"settings.order is {order}; rebuild it with --order {order} or "
                             "more", env.scaling)
        inputs["environment.scaling"] = env.scaling
        scale_order = int(table["order"])
    else:
        scale_order = (min(order + EXTRA_BANDS, MAX_SCALING_ORDER) if env.kind == "image"
                       else order)
        table = _scaling_table(scale_order, cache)
    coeffs = env_sh
    if env.kind == "image" and scale_order > order:
        from shtools.lighting.environment import projected_environment

        coeffs = projected_environment(env.path, scale_order, env.rotate, cache) * env.intensity
    return MidrangeEnvironment(np.asarray(env.center, dtype=float), float(env.radius),
                               ScalingTable(table), np.asarray(coeffs, dtype=float), order,
                               scene.path)


#: Algorithm version of a cached mid-range scaling table (:mod:`shtools.cache`).
SCALING_TABLE_VERSION = 1


def _scaling_table(order: int, cache=None) -> dict:
    """The plain mid-range scaling table at ``order`` built in memory (read from
    ``cache`` when it was built before): its arrays, and its scalars as Python values."""
    from shtools.sh.scaling import build_scaling_table

    def build():
        return build_scaling_table(order, "midrange", samples=DEFAULT_SAMPLES,
                                   k_range=(0.0, DEFAULT_KMAX))

    if cache is None:
        return build()
    parts = {"order": int(order), "function": "midrange", "samples": DEFAULT_SAMPLES,
             "k_range": [0.0, DEFAULT_KMAX]}
    got = cache.fetch("scaling_table", SCALING_TABLE_VERSION, parts, build)
    # a hit stores scalars as 0-d arrays: the same Python values back, on a miss too
    return {k: (np.asarray(v).item() if np.ndim(v) == 0 else v) for k, v in got.items()}
