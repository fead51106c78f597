"""Light-shadow ways for small spherical lights: ``shadows = "ssoc" | "raytrace" | "auto"``.

Registered with :func:`shtools.scene.shadows.register_light_shadow` (the
``shadows`` key of ``[[lights]]``; ``"shexp"``, the default, is built in and
keeps existing bakes unchanged):

* ``"ssoc"``: the soft shadow occlusion camera (:mod:`shtools.runtime.ssoc`)
  gives the visible fraction ``S`` per receiver against the posed blocker
  *meshes*; the light contributes ``color * S * E(N)`` with the closed-form
  unshadowed term :func:`shtools.runtime.shading.sphere_light_unshadowed`.
  Where the camera finds the receiver in penumbra (``0 < S < 1``, or umbra next to
  a silhouette record), the light is ray-traced instead with ``rays`` strata
  (:func:`ssoc_radiance`; the spec's
  Sec. 7.4 hybrid: the camera classifies umbra / lit / penumbra, rays resolve
  the penumbra, a few per cent of the receivers).  Settings: the light's
  ``ssoc = { ... }`` table (:class:`SSOCSettings`, plus ``rays``).
* ``"raytrace"``: the visible, cosine-weighted light ray-traced directly
  (:func:`shtools.reference.light_fraction.light_visible_fraction`, ``samples`` strata per
  receiver) -- the ground truth, and the slow path.
* ``"auto"``: ``"ssoc"`` while the light's angular radius seen from the
  receivers (median over receivers of ``asin(r/D)``) is below
  :data:`AUTO_THRESHOLD`, ``"shexp"`` above it, decided per frame.

The environment always keeps SHEXP.
"""

from __future__ import annotations

import dataclasses
import difflib

import numpy as np

from shtools.errors import InputError
from shtools.scene.shadows import LightShadow, register_light_shadow
from shtools.scene.specs import PENUMBRA_RAYS

#: Angular radius (radians) below which ``"auto"`` picks the occlusion camera.
#: ``benchmarks/bench_ssoc.py`` (bunny over a plane): SSOC's radiance error stays
#: below SHEXP order 6's at every radius of its sweep, 0.01-0.3 rad, so the crossover
#: is beyond 0.3 rad; past the swept range, and where SSOC's cost grows with the
#: penumbra width, "auto" hands the light to SHEXP.  See docs/ssoc.md.
AUTO_THRESHOLD = 0.3
#: Strata per receiver of ``shadows = "raytrace"``.
DEFAULT_SAMPLES = 64
#: Keys of a light's ``ssoc`` table (fields of SSOCSettings a scene may set, and ``rays``).
SSOC_KEYS = ("resolution", "camera", "guard", "max_steps", "falloff", "filter", "corners",
             "rays")
#: ``S`` strictly inside (eps, 1 - eps) is penumbra (the 4-tap blend's round-off is far below).
PENUMBRA_EPS = 1e-6


def ssoc_settings(table: dict | None):
    """:class:`~shtools.runtime.ssoc.SSOCSettings` from a light's ``ssoc`` table.

    Raises
    ------
    InputError
        Unknown key (with a did-you-mean hint) or a bad value, in one line.
    """
    from shtools.runtime.ssoc import SSOCSettings

    table = dict(table or {})
    table.pop("rays", None)  # the scene's (ssoc_rays), not the camera's
    for key in table:
        if key not in SSOC_KEYS:
            close = difflib.get_close_matches(key, SSOC_KEYS, n=1, cutoff=0.6)
            hint = f"did you mean '{close[0]}'?" if close else f"allowed: {', '.join(SSOC_KEYS)}"
            raise InputError(f"unknown key '{key}'; {hint}")
    return SSOCSettings(**table)


def ssoc_rays(table: dict | None) -> int:
    """``rays`` of a light's ``ssoc`` table (:data:`PENUMBRA_RAYS` when unset)."""
    rays = (table or {}).get("rays")
    return PENUMBRA_RAYS if rays is None else int(rays)


def ssoc_radiance(camera, vertices, meshes, light, points, normals,
                  rays: int = PENUMBRA_RAYS) -> np.ndarray:
    """One light's shadowed radiance per unit colour through the occlusion camera, ``(V,)``.

    Parameters
    ----------
    camera : shtools.runtime.ssoc.OcclusionCamera
        Built on the blocker meshes' faces.
    vertices : list of ndarray, shape (n_i, 3)
        Posed blocker vertices (the camera's meshes, in order).
    meshes : list of (vertices, faces), or a RayCaster
        The same blockers for the rays.
    light : SphereLight
    points, normals : ndarray, shape (V, 3)
    rays : int
        Strata per receiver the camera finds in penumbra (``0 < S < 1``) or calls umbra
        next to a silhouette record; 0: the camera alone.
    """
    from shtools.runtime.shading import sphere_light_unshadowed

    S = camera.visible_fraction(vertices, light.position, light.radius, points, normals)
    lit = S * sphere_light_unshadowed(light, points, normals)
    # penumbra, and umbra inside a penumbra band of the maps: the camera's misread
    # receivers are mostly umbra next to an edge (a fold just behind, the post-distortion
    # test); plain shadow-map umbra and lit receivers keep the camera's value
    pen = np.flatnonzero(((S > PENUMBRA_EPS) & (S < 1.0 - PENUMBRA_EPS))
                         | ((S <= PENUMBRA_EPS) & camera.last_near_silhouette))
    if rays and pen.size:
        from shtools.reference.light_fraction import light_visible_fraction

        lit[pen] = light_visible_fraction(points[pen], normals[pen], meshes, light.position,
                                          light.radius, n_samples=rays).radiance
    return lit


def angular_radius(position, radius: float, points) -> float:
    """Median over receivers of the light's angular radius ``asin(r / D)`` (radians)."""
    d = np.linalg.norm(np.asarray(points, dtype=np.float64) - np.asarray(position), axis=1)
    return float(np.median(np.arcsin(np.minimum(radius / np.maximum(d, 1e-300), 1.0))))


def _spec_of(run, state, light):
    """The scene's spec of a posed light (lights are posed in the scene's order)."""
    index = next(i for i, lt in enumerate(state.lights) if lt is light)
    return index, run.prepared.scene.lights[index]


def _named(index, spec, run, exc: InputError) -> InputError:
    return InputError(f"lights[{index}] ('{spec.name}'): {exc.message}", run.prepared.scene.path)


class SSOCLight(LightShadow):
    """The soft shadow occlusion camera against the posed blocker meshes."""

    name = "ssoc"
    needs_meshes = True
    uses_visibility = False

    def radiance(self, run, state, visibility, lights):
        from shtools.runtime.shading import sphere_light_unshadowed
        from shtools.runtime.ssoc import OcclusionCamera

        out = np.zeros((len(state.vertices), 3))
        verts = [v for v, _ in state.blocker_meshes]
        for light in lights:
            index, spec = _spec_of(run, state, light)
            key = ("ssoc", index)
            if key not in run.cache:  # adjacency once per topology, per light's settings
                run.cache[key] = OcclusionCamera([f for _, f in state.blocker_meshes],
                                                 spec.ssoc)
            if not verts:
                lit = sphere_light_unshadowed(light, state.vertices, state.normals)
            else:
                try:
                    lit = ssoc_radiance(run.cache[key], verts, state.blocker_meshes, light,
                                        state.vertices, state.normals, spec.ssoc_rays)
                except InputError as exc:
                    raise _named(index, spec, run, exc) from None
            out += lit[:, None] * light.color[None, :]
        return out


class RaytraceLight(LightShadow):
    """The visible light ray-traced per receiver (ground truth, ``samples`` strata)."""

    name = "raytrace"
    needs_meshes = True
    uses_visibility = False

    def radiance(self, run, state, visibility, lights):
        from shtools.reference.light_fraction import light_visible_fraction
        from shtools.runtime.shading import sphere_light_unshadowed

        out = np.zeros((len(state.vertices), 3))
        for light in lights:
            index, spec = _spec_of(run, state, light)
            if not state.blocker_meshes:
                lit = sphere_light_unshadowed(light, state.vertices, state.normals)
            else:
                try:
                    lit = light_visible_fraction(state.vertices, state.normals,
                                                 state.blocker_meshes, light.position,
                                                 light.radius, n_samples=spec.samples).radiance
                except InputError as exc:
                    raise _named(index, spec, run, exc) from None
            out += lit[:, None] * light.color[None, :]
        return out


class AutoLight(LightShadow):
    """``ssoc`` below :data:`AUTO_THRESHOLD` of angular radius, ``shexp`` above (per frame)."""

    name = "auto"
    needs_meshes = True

    def radiance(self, run, state, visibility, lights):
        small, large = [], []
        for light in lights:
            a = angular_radius(light.position, light.radius, state.vertices)
            (small if a < AUTO_THRESHOLD else large).append(light)
        run.cache["auto_ways"] = {id(lt): ("ssoc" if lt in small else "shexp")
                                  for lt in lights}
        out = np.zeros((len(state.vertices), 3))
        if small:
            out += SSOC.radiance(run, state, visibility, small)
        if large:  # the light's SH through the frame's visibility, as "shexp" shades it
            out += run.runtime.shade(visibility, state.vertices, state.normals, None,
                                     sphere_lights=large)
        return out


SSOC = register_light_shadow(SSOCLight())
register_light_shadow(RaytraceLight())
register_light_shadow(AutoLight())


def light_parameters(lights) -> list[dict] | None:
    """What a bake records of its lights' shadows (None when every light uses ``shexp``)."""
    if all(spec.shadows == "shexp" for spec in lights):
        return None
    return [{"name": spec.name, "shadows": spec.shadows, "samples": spec.samples,
             # a field light has no occlusion-camera settings
             "ssoc": None if spec.ssoc is None else dataclasses.asdict(spec.ssoc),
             "ssoc_rays": spec.ssoc_rays}
            for spec in lights]
