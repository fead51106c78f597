r"""Field lights: ``[[lights]] field = "lamp.srf.h5"`` (a lamp's source radiance field).

The lamp is posed like a rigid object (``position``, ``rotate`` or
``quaternion``, uniform ``scale``, keyframed; translation lerped, rotation
slerped).  Per receiver vertex its world RCV
(:class:`shtools.runtime.radiance.FieldLight`) is double-producted with the
receiver's transfer (Tamura et al. Fig. 3).  Two registered light-shadow ways
put the blockers' shadow in, chosen by the light's ``shadows`` key:

* ``"raytrace"`` (the default; way ``"field"``): the transfer without the
  blockers gives the receiver's unshadowed light from the lamp, multiplied by
  the fraction of the lamp's emission the receiver sees past the blocker
  meshes (:func:`shtools.scene.lamp_shadow.emission_visible_fraction`,
  ``samples`` strata per receiver toward the lamp's own triangles).  A shadow
  ray ends at the lamp, so only blockers nearer than the lamp shadow it.
* ``"shexp"`` (way ``"field-shexp"``, the paper's product path): the transfer
  multiplied by the SH visibility of **only the blockers nearer than the
  lamp** -- a blocker counts at a vertex when its centre is closer to the
  vertex than the lamp's emitter centre (the paper sorts entities by distance
  per object; here per vertex, so a long ground is right at both ends).  The
  frame's visibility method makes that visibility (so the lamp combines with
  sphere sets, shadow fields, deformable fields and traced objects alike):
  the frame's own visibility where every blocker is nearer, and a
  re-evaluation with the farther blockers left out for each other set of
  vertices.  A blocker left out also drops the traced shadow it casts on other
  receivers and the self-visibility that stands for it on its own rows.  A
  blocker whose centre is unknown (no centre, no sphere) is always counted.
  Order 4 cannot hold the product of a compact lamp and a blocker's
  visibility: the shadow comes out far too light (``benchmarks/bench_srf.py``).

A lamp whose emitter centre lies inside a closed receiver is refused (its
light could not get out).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shtools.errors import InputError
from shtools.scene.shadows import VISIBILITY_METHODS, LightShadow, register_light_shadow

#: Strata per receiver of a field light's traced shadow when ``samples`` is not given.
#: More than a spherical light's 64: only receivers whose cone toward the lamp meets a
#: blocker cast them, and ``benchmarks/bench_srf.py`` measures the shadow's noise.
FIELD_SAMPLES = 256
#: ``shadows =`` of a field light -> its registered light-shadow way.
FIELD_SHADOWS = {"raytrace": "field", "shexp": "field-shexp"}


def field_light_way(shadows: str | None, ctx) -> str:
    """The light-shadow way of a field light whose ``shadows`` key is ``shadows``
    (None: not given, the traced default); ``ctx`` makes the one-line error."""
    if shadows is None:
        return FIELD_SHADOWS["raytrace"]
    if shadows not in FIELD_SHADOWS:
        raise ctx.error(f"a field light takes shadows = 'raytrace' (the default: its "
                        f"emission traced past the blocker meshes) or 'shexp' (the SH "
                        f"product), got '{shadows}'")
    return FIELD_SHADOWS[shadows]


@dataclass
class FieldLightPose:
    """A field light at one frame: lamp-to-world matrix, intensity, asset, index."""

    matrix: np.ndarray
    intensity: float
    path: Path


def field_light_pose(spec, t: float) -> FieldLightPose:
    """The lamp's pose at time ``t`` (:func:`shtools.scene.animation.interpolate_pose`)."""
    from shtools.scene.animation import interpolate_pose, pose_matrix

    pose = interpolate_pose(spec.poses, t, spec.loop)
    return FieldLightPose(pose_matrix(pose), float(spec.intensity), spec.srf)


def _table(run, index: int, spec, pose: FieldLightPose):
    """The lamp's lookup table, loaded once per bake (its order checked)."""
    from shtools.data_formats.srf import read_radiance_field
    from shtools.errors import AssetError
    from shtools.runtime.radiance import RadianceTable

    key = ("srf", index)
    if key not in run.cache:
        fld = read_radiance_field(pose.path)
        order = run.settings.order
        if fld.order != order:
            raise AssetError(f"radiance field is SH order {fld.order} but the scene's "
                             f"settings.order is {order}; resample it with `shtools field "
                             f"sample --radiance ... --order {order}`", pose.path)
        run.cache[key] = RadianceTable(fld)
    return run.cache[key]


def blocker_centers(blockers) -> list[np.ndarray | None]:
    """A world centre per runtime blocker (None when it has none), for distance sorting."""
    out = []
    for b in blockers:
        if hasattr(b, "world_center"):
            out.append(np.asarray(b.world_center, dtype=np.float64))
        elif getattr(b, "centers", None) is not None and len(b.centers):
            c = np.asarray(b.centers, dtype=np.float64)
            r = np.asarray(getattr(b, "radii", np.ones(len(c))), dtype=np.float64)
            w = r ** 3 if r.sum() > 0 else np.ones(len(c))
            out.append((c * w[:, None]).sum(axis=0) / w.sum())
        else:
            out.append(None)
    return out


def farther_blockers(points, light_center, centers) -> np.ndarray:
    """``(V, B)`` bool: blocker ``b`` is farther from vertex ``v`` than the lamp."""
    p = np.asarray(points, dtype=np.float64)
    d_light = np.linalg.norm(p - light_center, axis=1)
    far = np.zeros((p.shape[0], len(centers)), dtype=bool)
    for k, c in enumerate(centers):
        if c is not None:
            far[:, k] = np.linalg.norm(p - c, axis=1) >= d_light
    return far


def _absent():
    """A blocker that blocks nothing, keeping the others' positions."""
    from shtools.runtime import SphereBlocker

    return SphereBlocker(np.zeros((1, 3)), np.zeros(1))


def _without(state, left_out: np.ndarray):
    """The frame with the blockers ``left_out`` (bool per blocker) removed."""
    out = set(np.flatnonzero(left_out).tolist())

    def names_left_out(sv) -> bool:
        b = sv.blocker
        ids = b if isinstance(b, tuple | list) else (() if b is None else (b,))
        return any(int(i) in out for i in ids)

    blockers = [_absent() if k in out else b for k, b in enumerate(state.blockers)]
    meshes = [m for k, m in enumerate(state.blocker_meshes) if k not in out]
    selfs = [sv for sv in state.self_visibility if not names_left_out(sv)]
    return dataclasses.replace(state, blockers=blockers, blocker_meshes=meshes,
                               self_visibility=selfs)


def _check_outside(run, light, state, index: int, spec) -> None:
    """Refuse a lamp whose emitter centre is inside a closed receiver."""
    import trimesh

    from shtools.geometry.mesh import boundary_edges

    closed = run.cache.setdefault("srf_closed", {})
    start = 0
    c = light.world_center
    for o in run.prepared.receivers:
        n = len(o.vertices)
        v = state.vertices[start:start + n]
        start += n
        if o.spec.name not in closed:
            # vertices merged: primitives repeat them along their seams
            mesh = trimesh.Trimesh(o.vertices, o.faces, process=True)
            closed[o.spec.name] = len(o.faces) > 0 and len(boundary_edges(mesh)) == 0
        if not closed[o.spec.name]:
            continue
        lo, hi = v.min(axis=0), v.max(axis=0)
        if np.any(c < lo) or np.any(c > hi):
            continue
        if trimesh.Trimesh(v, o.faces, process=True).contains(c[None, :])[0]:
            raise InputError(f"lights[{index}] ('{spec.name}'): the lamp is inside the "
                             f"receiver '{o.spec.name}', which is closed: no light gets out; "
                             "move the lamp or the object", run.prepared.scene.path)


def _posed_light(run, state, pose):
    """The scene index, spec and :class:`FieldLight` of a posed field light."""
    from shtools.runtime.radiance import FieldLight

    index = next(i for i, lt in enumerate(state.lights) if lt is pose)
    spec = run.prepared.scene.lights[index]
    try:
        light = FieldLight.from_matrix(_table(run, index, spec, pose), pose.matrix,
                                       pose.intensity)
    except InputError as exc:
        if exc.path is not None:
            raise
        raise InputError(f"lights[{index}] ('{spec.name}'): {exc.message}",
                         run.prepared.scene.path) from None
    _check_outside(run, light, state, index, spec)
    return index, spec, light


def _shade(run, light, vis, rows, state) -> np.ndarray:
    """The field light's radiance at ``rows`` through the visibility ``vis`` (rows')."""
    from shtools.runtime.radiance import field_light_radiance
    from shtools.runtime.shading import desaturate_negative

    st = run.settings
    lit = field_light_radiance(light, vis, state.vertices[rows], state.normals[rows],
                               order=st.order, window_kind=st.resolved_window(),
                               window_h=st.window_h)
    if st.deringing == "desaturate":
        lit = desaturate_negative(lit)
    return lit


def _lamp_caster(run, index: int, light, path):
    """The lamp's triangles as a :class:`~shtools.scene.lamp_shadow.LampCaster` (per bake)."""
    from shtools.errors import AssetError
    from shtools.scene.lamp_shadow import LampCaster

    key = ("srf_lamp", index)
    if key not in run.cache:
        fld = light.table.field
        if fld.lamp_vertices is None:
            raise AssetError("this radiance field (format version 1) has no lamp mesh to "
                             "trace its shadows to; resample it with `shtools field sample "
                             "--radiance`, or give the light shadows = \"shexp\"", path)
        run.cache[key] = LampCaster(fld.lamp_vertices, fld.lamp_faces, fld.lamp_emissive,
                                    fld.emitter_center, fld.emitter_radius)
    return run.cache[key]


class FieldLightShadow(LightShadow):
    """A lamp's source radiance field, its emission traced past the blocker meshes."""

    name = "field"
    #: set by ``field = "x.srf.h5"``, never chosen with ``shadows =``
    implied = True
    needs_meshes = True
    uses_visibility = False

    def radiance(self, run, state, visibility, lights):
        from shtools.scene.lamp_shadow import Blockers, emission_visible_fraction

        out = np.zeros((len(state.vertices), 3))
        method = VISIBILITY_METHODS[run.method]
        blockers = Blockers(state.blocker_meshes)
        free = None
        for pose in lights:
            index, spec, light = _posed_light(run, state, pose)
            lamp = _lamp_caster(run, index, light, pose.path)
            if free is None:  # the transfer without the blockers, once per frame
                free = np.asarray(method.visibility(
                    run, _without(state, np.ones(len(state.blockers), dtype=bool))))
            rows = np.arange(len(state.vertices))
            lit = _shade(run, light, free, rows, state)
            frac = emission_visible_fraction(lamp, light.rotation, light.translation,
                                             light.scale, blockers, state.vertices,
                                             state.normals, n_samples=spec.samples)
            out += lit * frac[:, None]
        return out


class FieldProductShadow(LightShadow):
    """A lamp's source radiance field through the SH visibility of the nearer blockers."""

    name = "field-shexp"
    implied = True

    def radiance(self, run, state, visibility, lights):
        out = np.zeros((len(state.vertices), 3))
        centers = blocker_centers(state.blockers)
        method = VISIBILITY_METHODS[run.method]
        for pose in lights:
            _, _, light = _posed_light(run, state, pose)
            far = farther_blockers(state.vertices, light.world_center, centers)
            groups, label = np.unique(far, axis=0, return_inverse=True)
            label = label.reshape(-1)
            for g, left_out in enumerate(groups):
                rows = np.flatnonzero(label == g)
                if left_out.any():
                    vis = method.visibility(run, _without(state, left_out))[rows]
                else:
                    vis = np.asarray(visibility)[rows]
                out[rows] += _shade(run, light, vis, rows, state)
        return out


register_light_shadow(FieldLightShadow())
register_light_shadow(FieldProductShadow())
