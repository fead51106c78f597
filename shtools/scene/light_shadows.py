"""How each spherical light of a scene is shadowed (the ``shadows`` key of ``[[lights]]``).

* ``"shexp"`` (default): the light is shaded through the SHEXP visibility with
  the environment (``ShadowRuntime.shade``) -- existing scenes bake unchanged;
* ``"ssoc"``: the soft shadow occlusion camera (:mod:`shtools.runtime.ssoc`)
  gives the visible fraction ``S`` per receiver against the posed blocker
  *meshes*; the light contributes ``color * S * E(N)`` with the closed-form
  unshadowed term :func:`shtools.runtime.shading.sphere_light_unshadowed`;
* ``"raytrace"``: the visible, cosine-weighted light ray-traced directly
  (:func:`shtools.reference.light_visible_fraction`, ``samples`` strata per
  receiver) -- the ground truth, and the slow path;
* ``"auto"``: ``"ssoc"`` while the light's angular radius seen from the
  receivers (median over receivers of ``asin(r/D)``) is below
  :data:`AUTO_THRESHOLD`, ``"shexp"`` above it, decided per frame.

The environment always keeps SHEXP.  Everything a light-shadow way needs per
frame is in :class:`shtools.scene.bake.FrameState`.
"""

from __future__ import annotations

import numpy as np

from shtools.errors import InputError

SHADOW_WAYS = ("shexp", "ssoc", "raytrace", "auto")
#: Angular radius (radians) below which ``"auto"`` picks the occlusion camera:
#: the measured crossover of ``benchmarks/bench_ssoc.py`` (bunny over a plane,
#: radiance error of SSOC vs SHEXP at order 6), see docs/ssoc.md.
AUTO_THRESHOLD = 0.1
#: Strata per receiver of ``shadows = "raytrace"``.
DEFAULT_SAMPLES = 64


def angular_radius(position, radius: float, points) -> float:
    """Median over receivers of the light's angular radius ``asin(r / D)`` (radians)."""
    d = np.linalg.norm(np.asarray(points, dtype=np.float64) - np.asarray(position), axis=1)
    return float(np.median(np.arcsin(np.minimum(radius / np.maximum(d, 1e-300), 1.0))))


def resolve_way(way: str, light, points) -> str:
    """The way used this frame: ``"auto"`` resolved by :data:`AUTO_THRESHOLD`."""
    if way != "auto":
        return way
    small = angular_radius(light.position, light.radius, points) < AUTO_THRESHOLD
    return "ssoc" if small else "shexp"


class LightShadows:
    """Per-bake state of the lights not shadowed by SHEXP.

    Parameters
    ----------
    specs : sequence of SphereLightSpec
        The scene's lights (their ``shadows``, ``samples`` and ``ssoc`` keys).
    blocker_faces : sequence of ndarray, shape (F_i, 3)
        Triangles of every blocker mesh, in :attr:`FrameState.blocker_meshes` order
        (the occlusion camera's adjacency is built once from them).
    scene_path : path-like, optional
        Named in error messages.
    """

    def __init__(self, specs, blocker_faces, scene_path=None):
        from shtools.runtime.ssoc import OcclusionCamera

        self.specs = list(specs)
        self.scene_path = scene_path
        self.cameras = {}
        for i, spec in enumerate(self.specs):
            if spec.shadows in ("ssoc", "auto"):
                self.cameras[i] = OcclusionCamera(blocker_faces, spec.ssoc)
        #: Way used per light in the last frame.
        self.last_ways: list[str] = []

    @property
    def needed(self) -> bool:
        """True when some light may be shadowed other than by SHEXP."""
        return any(s.shadows != "shexp" for s in self.specs)

    def frame(self, state) -> tuple[list, np.ndarray | None]:
        """Split a frame's lights into SHEXP ones and the radiance of the others.

        Parameters
        ----------
        state : FrameState
            Posed receivers, lights and blocker meshes.

        Returns
        -------
        shexp_lights : list of SphereLight
            Lights for ``ShadowRuntime.shade``.
        extra : ndarray, shape (V, 3) or None
            Radiance of the other lights (None when there are none).
        """
        from shtools.runtime.shading import sphere_light_unshadowed

        shexp, extra, ways = [], None, []
        pts, nrm = state.vertices, state.normals
        for i, (spec, light) in enumerate(zip(self.specs, state.lights, strict=True)):
            way = resolve_way(spec.shadows, light, pts)
            ways.append(way)
            if way == "shexp":
                shexp.append(light)
                continue
            try:
                if way == "ssoc":
                    verts = [v for v, _ in state.blocker_meshes]
                    if verts:
                        S = self.cameras[i].visible_fraction(verts, light.position, light.radius,
                                                             pts, nrm)
                    else:
                        S = np.ones(len(pts))
                    lit = S * sphere_light_unshadowed(light, pts, nrm)
                else:
                    lit = _raytraced(state, light, spec.samples)
            except InputError as exc:
                raise InputError(f"lights[{i}] ('{spec.name}'): {exc.message}",
                                 self.scene_path) from None
            rgb = lit[:, None] * light.color[None, :]
            extra = rgb if extra is None else extra + rgb
        self.last_ways = ways
        return shexp, extra


def _raytraced(state, light, samples: int) -> np.ndarray:
    """Cosine-weighted visible light per unit colour, ray-traced, shape ``(V,)``."""
    from shtools.reference.light_fraction import light_visible_fraction
    from shtools.runtime.shading import sphere_light_unshadowed

    if not state.blocker_meshes:
        return sphere_light_unshadowed(light, state.vertices, state.normals)
    return light_visible_fraction(state.vertices, state.normals, state.blocker_meshes,
                                  light.position, light.radius, n_samples=samples).radiance
