r"""Field lights: ``[[lights]] field = "lamp.srf.h5"`` (a lamp's source radiance field).

The lamp is posed like a rigid object (``position``, ``rotate`` or
``quaternion``, uniform ``scale``, keyframed; translation lerped, rotation
slerped) and shaded by the registered light-shadow way ``"field"``
(Tamura et al. Fig. 3): per receiver vertex its world RCV
(:class:`shtools.runtime.radiance.FieldLight`) double-producted with the
receiver's transfer times the visibility of **only the blockers nearer than
the lamp** -- a blocker counts at a vertex when its centre is closer to the
vertex than the lamp's emitter centre (the paper sorts entities by distance
per object; here per vertex, so a long ground is right at both ends).  The
frame's visibility method makes that visibility (so the lamp combines with
sphere sets, shadow fields, deformable fields and traced objects alike): the
frame's own visibility where every blocker is nearer, and a re-evaluation
with the farther blockers left out for each other set of vertices.  A
blocker left out also drops the traced shadow it casts on other receivers and
the self-visibility that stands for it on its own rows.

A blocker whose centre is unknown (no centre, no sphere) is always counted.
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


class FieldLightShadow(LightShadow):
    """A lamp's source radiance field through the visibility of the nearer blockers."""

    name = "field"
    #: set by ``field = "x.srf.h5"``, never chosen with ``shadows =``
    implied = True

    def radiance(self, run, state, visibility, lights):
        from shtools.runtime.radiance import FieldLight, field_light_radiance
        from shtools.runtime.shading import desaturate_negative

        st = run.settings
        out = np.zeros((len(state.vertices), 3))
        centers = blocker_centers(state.blockers)
        method = VISIBILITY_METHODS[run.method]
        for pose in lights:
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
            far = farther_blockers(state.vertices, light.world_center, centers)
            groups, label = np.unique(far, axis=0, return_inverse=True)
            label = label.reshape(-1)
            for g, left_out in enumerate(groups):
                rows = np.flatnonzero(label == g)
                if left_out.any():
                    vis = method.visibility(run, _without(state, left_out))[rows]
                else:
                    vis = np.asarray(visibility)[rows]
                lit = field_light_radiance(light, vis, state.vertices[rows],
                                           state.normals[rows], order=st.order,
                                           window_kind=st.resolved_window(),
                                           window_h=st.window_h)
                if st.deringing == "desaturate":
                    lit = desaturate_negative(lit)
                out[rows] += lit
        return out


register_light_shadow(FieldLightShadow())
