"""Ways to shadow light in a bake: visibility methods and per-light shadow ways (registries).

Two small protocols, each registered by name:

:class:`VisibilityMethod` — how a frame's SH visibility ``(V, n*n)`` is made,
the ``--method`` of ``shtools bake`` and ``settings.method`` of a scene:
``default`` and each exp method (the SHEXP runtime), ``product``
(product-space accumulation) and ``raytrace`` (ray tracing of the posed
blocker meshes).  The environment is always shaded with this visibility.

:class:`LightShadow` — how one spherical light is shadowed, the ``shadows``
key of a ``[[lights]]`` table.  ``shexp`` (the default) shades the light
analytically with the frame's SH visibility, in the same call as the
environment (:meth:`shtools.runtime.ShadowRuntime.shade`); another way (SSOC,
ray tracing) returns the light's radiance ``(V, 3)`` itself, which the baker
adds.

Adding one is a subclass and a ``register_*`` call in its own module, imported
by :mod:`shtools.scene.kinds` (see ``docs/architecture.md``).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from shtools.registry import Registry
from shtools.sh.exponential import ExpMethod


@dataclass
class BakeRun:
    """What a method or way may use while baking (one per :func:`bake_scene` call).

    Attributes
    ----------
    prepared : shtools.scene.prepare.PreparedScene
    runtime : shtools.runtime.ShadowRuntime
        Shading (and the SHEXP visibility) at the scene's settings.
    method : str
        The visibility method's name.
    raytrace_dirs : int or None
        Directions per vertex of ray-traced visibility (None: the reference's default).
    cache : dict
        Per-bake state a method keeps between frames (e.g. receiver clusters).
    """

    prepared: Any
    runtime: Any
    method: str
    raytrace_dirs: int | None = None
    cache: dict = field(default_factory=dict)

    @property
    def settings(self):
        return self.prepared.scene.settings


# --------------------------------------------------------------------------- visibility
class VisibilityMethod(ABC):
    """A way to compute a frame's SH visibility (see the module docstring)."""

    name: ClassVar[str]
    #: posed blocker meshes are needed in the FrameState
    needs_meshes: ClassVar[bool] = False
    #: uses the runtime's accumulation and exp (records them in the asset)
    uses_runtime: ClassVar[bool] = False

    def exp_method(self, settings) -> str:
        """The exp method the runtime is set up with for this method."""
        return settings.exp_method

    def acc_order(self, settings) -> int | None:
        """Order the method accumulates blockers at (None: it projects at the shading order).

        Methods compared with each other accumulate at the same order (a baseline at
        a lower order than SHEXP would look worse than it is).
        """
        return None

    @abstractmethod
    def visibility(self, run: BakeRun, state) -> np.ndarray:
        """SH visibility of the posed frame ``state`` (FrameState), shape ``(V, n*n)``."""


class RuntimeVisibility(VisibilityMethod):
    """The SHEXP runtime with the scene's exp method (``default``) or a named one."""

    uses_runtime = True

    def __init__(self, name: str, exp: str | None = None):
        self.name, self._exp = name, exp

    def exp_method(self, settings) -> str:
        return self._exp or settings.exp_method

    def acc_order(self, settings) -> int:
        return settings.resolved_acc_order()

    def visibility(self, run, state):
        import time

        clusters = run.cache.get("clusters")
        if clusters is None:  # one-time setup, not counted as frame time
            start = time.perf_counter()
            clusters = run.cache["clusters"] = receiver_clusters(run.prepared, state.vertices)
            run.cache["setup_seconds"] = time.perf_counter() - start
        return run.runtime.visibility(state.vertices, state.normals, state.blockers,
                                      clusters=clusters,
                                      self_visibility=state.self_visibility,
                                      static_receivers=state.static_rows)


class ProductVisibility(VisibilityMethod):
    """Product-space accumulation (:func:`shtools.reference.product_space_visibility`).

    Sphere caps, then shadow fields and deformable fields, then the objects'
    self-visibilities, each multiplied in with truncated SH products at the
    accumulation order.  As in the SHEXP runtime, an object with a
    self-visibility (its real mesh on its own rows) does not use its own
    blocker there: its spheres / deformable field are skipped on those rows.
    """

    name = "product"

    def acc_order(self, settings) -> int:
        # the same order as the SHEXP default, so the baseline is compared fairly
        return settings.resolved_acc_order()

    def visibility(self, run, state):
        from shtools.reference import product_space_visibility
        from shtools.runtime import FieldBlocker, field_product_visibility
        from shtools.runtime.deformable import DeformableBlocker
        from shtools.sh import product

        st = run.settings
        acc = self.acc_order(st)
        n_rows = len(state.vertices)
        pts, nrm = state.vertices, state.normals
        skip = _own_blocker_rows(state.self_visibility, n_rows, len(state.blockers))
        # shadow fields and deformable fields are multiplied in after the sphere caps
        fields = [b for b in state.blockers if isinstance(b, FieldBlocker)]
        deformables = [(k, b) for k, b in enumerate(state.blockers)
                       if isinstance(b, DeformableBlocker)]
        spheres = [(k, b) for k, b in enumerate(state.blockers)
                   if not isinstance(b, FieldBlocker | DeformableBlocker)
                   and not getattr(b, "all_frequency", False)]  # shaded in the map basis
        vis = None
        if spheres or not (fields or deformables):
            vis = np.zeros((n_rows, st.order * st.order))
            # rows grouped by the sphere blocker they skip (-1: none; an object's own)
            label = np.full(n_rows, -1)
            for k, _ in spheres:
                if k in skip:
                    label[skip[k]] = k
            for k in np.unique(label):
                rows = np.flatnonzero(label == k)
                kept = [b for j, b in spheres if j != k]
                if kept:
                    vis[rows] = product_space_visibility(pts[rows], nrm[rows], kept,
                                                         st.order, acc_order=acc)
                else:
                    vis[rows, 0] = math.sqrt(4 * math.pi)
        if fields:
            vis = field_product_visibility(pts, nrm, fields, st.order,
                                           acc_order=acc, base=vis)
        # each deformable field's scaled visibility (sampled at the accumulation order),
        # then each self-visibility, multiplied at that order and truncated at the end
        g = np.zeros((n_rows, acc * acc))
        if vis is None:
            g[:, 0] = math.sqrt(4 * math.pi)
        else:
            g[:, :vis.shape[1]] = vis
        for k, blocker in deformables:
            rows = np.arange(n_rows) if k not in skip else np.flatnonzero(~skip[k])
            g[rows] = product(g[rows], blocker.visibility(pts[rows], nrm[rows], acc), acc)
        for sv in state.self_visibility:
            rows = np.arange(n_rows)[sv.rows]
            own = np.zeros((rows.size, acc * acc))
            own_vis = _self_visibility_values(run.runtime, sv)
            m = min(own_vis.shape[1], acc * acc)
            own[:, :m] = own_vis[:, :m]
            g[rows] = product(g[rows], own, acc)
        return g[:, : st.order * st.order]


def _own_blocker_rows(self_visibility, n_rows: int, n_blockers: int) -> dict:
    """Blocker position -> bool mask ``(V,)`` of the rows a self-visibility covers for it."""
    from shtools.errors import InputError

    skip = {}
    for sv in self_visibility:
        for k in sv.skipped:
            if not 0 <= k < n_blockers:
                raise InputError(f"self-visibility names blocker {k}, which is not one of "
                                 f"the {n_blockers} blockers given")
            skip.setdefault(k, np.zeros(n_rows, dtype=bool))[np.arange(n_rows)[sv.rows]] = True
    return skip


def _self_visibility_values(runtime, sv) -> np.ndarray:
    """A self-visibility's world-space visibility vectors ``(R, m*m)``: given, or the
    runtime's exp of its (rotated) log, truncated to the shading order."""
    from shtools.sh import rotation_matrix

    if sv.visibility is not None:
        return np.asarray(sv.visibility, dtype=np.float64)
    log = np.asarray(sv.log, dtype=np.float32)
    if sv.rotation is not None:
        d = rotation_matrix(sv.rotation, runtime.acc_order).astype(np.float32)
        log = log @ d.T
    return np.asarray(runtime.exponentiate(log), dtype=np.float64)


class RaytraceVisibility(VisibilityMethod):
    """Ray tracing of the posed blocker meshes (:func:`shtools.reference.raytrace_visibility`)."""

    name = "raytrace"
    needs_meshes = True

    def visibility(self, run, state):
        import trimesh

        from shtools.reference import raytrace_visibility

        order = run.settings.order
        if not state.blocker_meshes:  # nothing to hit: visibility is the constant 1
            vis = np.zeros((len(state.vertices), order * order))
            vis[:, 0] = math.sqrt(4 * math.pi)
            return vis
        meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
        kwargs = {} if run.raytrace_dirs is None else {"n_dirs": run.raytrace_dirs}
        return raytrace_visibility(state.vertices, state.normals, meshes, order, **kwargs)


def receiver_clusters(prepared, vertices: np.ndarray):
    """Receiver clusters of posed receivers (the baker uses frame 0), reused every frame.

    Clusters never mix objects, and the runtime recomputes each cluster's bound
    from the current positions, so rigidly moving and skinned receivers keep
    compact clusters without re-clustering every frame.
    """
    from shtools.runtime.clusters import lloyd_clusters

    groups = np.concatenate([np.full(len(o.vertices), k)
                             for k, o in enumerate(prepared.receivers)])
    return lloyd_clusters(vertices, prepared.scene.settings.vertices_per_cluster, groups=groups)


#: name -> method, in the order ``--help`` lists them; complete once
#: :mod:`shtools.scene.kinds` is imported
VISIBILITY_METHODS: Registry[VisibilityMethod] = Registry("visibility method")
#: add a visibility method (a ``bake --method`` / ``settings.method`` value); returns it
register_visibility_method = VISIBILITY_METHODS.register


register_visibility_method(RuntimeVisibility("default"))
for _exp in ExpMethod:
    register_visibility_method(RuntimeVisibility(_exp.value, _exp.value))
register_visibility_method(ProductVisibility())
register_visibility_method(RaytraceVisibility())


# --------------------------------------------------------------------------- lights
class LightShadow(ABC):
    """A way to shadow spherical lights (see the module docstring)."""

    name: ClassVar[str]
    #: shaded with the SH visibility in the environment's shade call
    joins_environment: ClassVar[bool] = False
    #: posed blocker meshes are needed in the FrameState
    needs_meshes: ClassVar[bool] = False
    #: reads the frame's SH visibility (False: a frame whose environment and lights
    #: all do without it evaluates no SHEXP visibility; :func:`visibility_needed`)
    uses_visibility: ClassVar[bool] = True

    @abstractmethod
    def radiance(self, run: BakeRun, state, visibility: np.ndarray | None,
                 lights: list) -> np.ndarray:
        """Outgoing radiance ``(V, 3)`` from ``lights`` (SphereLight) at the receivers.

        ``state`` is the posed FrameState, ``visibility`` the frame's SH visibility
        (None when no light's way :attr:`uses_visibility` and nothing else needs it).
        """


class ShexpLight(LightShadow):
    """The light's analytic SH, shaded with the frame's SH visibility (SHEXP Sec. 7)."""

    name = "shexp"
    joins_environment = True

    def radiance(self, run, state, visibility, lights):
        return run.runtime.shade(visibility, state.vertices, state.normals, None,
                                 sphere_lights=lights)


#: name -> way; complete once :mod:`shtools.scene.kinds` is imported
LIGHT_SHADOWS: Registry[LightShadow] = Registry("light-shadow way")
#: add a light-shadow way (a ``shadows = "<name>"`` value of ``[[lights]]``); returns it
register_light_shadow = LIGHT_SHADOWS.register


register_light_shadow(ShexpLight())


def visibility_needed(prepared, store_visibility: bool = False) -> bool:
    """Whether a bake's frames need the SH visibility of the visibility method.

    Only to shade the environment (at infinity or mid-range), the lights whose
    way :attr:`~LightShadow.uses_visibility` (``shexp``, ``auto``), or to store
    it.  Otherwise (no environment, only lights shadowed by ``ssoc`` or
    ``raytrace``) a frame evaluates neither the visibility nor what only feeds
    it (traced shadows on the ground, traced self-visibility of skinned objects).
    """
    if store_visibility or prepared.env_sh is not None or prepared.midrange is not None:
        return True
    return any(LIGHT_SHADOWS[spec.shadows].uses_visibility for spec in prepared.scene.lights)


def shade_frame(run: BakeRun, state, visibility: np.ndarray | None) -> np.ndarray:
    """Radiance ``(V, 3)`` of a posed frame: environment and every light, each its own way.

    The environment and the lights whose way joins it are shaded in one
    :meth:`~shtools.runtime.ShadowRuntime.shade` call; every other way adds
    its lights' radiance.  ``visibility`` None (:func:`visibility_needed` is
    false: no environment, no light that joins it) starts from zero radiance.
    """
    groups: dict[str, list] = {}
    for light, way in zip(state.lights, state.light_shadows, strict=True):
        groups.setdefault(way, []).append(light)
    joined = [light for way, group in groups.items() if LIGHT_SHADOWS[way].joins_environment
              for light in group]
    env = run.prepared.env_sh
    if visibility is None:
        if joined or env is not None or run.prepared.midrange is not None:
            raise ValueError("the frame's visibility is needed to shade its environment "
                             "and the lights that join it")
        radiance = np.zeros((len(state.vertices), 3))
    else:
        from shtools.scene.haar_blocker import haar_blockers, shade_all_frequency

        haar = haar_blockers(run, state)
        if haar:  # all-frequency fields: the environment in their map basis
            radiance = shade_all_frequency(run, state, visibility, haar, joined)
        else:
            if run.prepared.midrange is not None:  # a finite environment sphere: per-vertex SH
                env = run.prepared.midrange.radiance_sh(state.vertices)
            radiance = run.runtime.shade(visibility, state.vertices, state.normals, env,
                                         sphere_lights=joined)
    for way, group in groups.items():
        if not LIGHT_SHADOWS[way].joins_environment:
            radiance = radiance + LIGHT_SHADOWS[way].radiance(run, state, visibility, group)
    return radiance
