"""Posing a prepared scene at a time: receivers, blockers (by their kind), lights."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from shtools.errors import InputError
from shtools.scene.animation import (
    light_at,
    transform_normals,
    transform_points,
    vertex_normals,
    world_matrices,
)
from shtools.scene.contact_shadows import (
    ContactPart,
    contact_casters,
    contact_directions,
    rigid_caster,
)
from shtools.scene.kinds import BLOCKER_KINDS
from shtools.scene.prepare import PreparedScene


@dataclass
class FrameState:
    """The posed scene at one frame (world space)."""

    vertices: np.ndarray  # (V, 3)
    normals: np.ndarray  # (V, 3)
    blockers: list  # runtime blockers (SphereBlocker or LogBlocker), one per blocker object
    lights: list  # list[shtools.runtime.SphereLight]
    blocker_meshes: list  # list[(vertices (Vb,3), faces (Fb,3))]
    light_shadows: list = field(default_factory=list)  # the way of each light (by name)
    self_visibility: list = field(default_factory=list)  # list[shtools.runtime.SelfVisibility]
    # (V,) bool: rows of objects that never move (their sphere blockers are flagged
    # static too), so the runtime keeps the static pairs' log sum between frames
    static_rows: np.ndarray | None = None


#: Largest world coordinate a posed vertex may have: the runtime works in float32,
#: whose squares overflow above ~1.8e19.
MAX_COORDINATE = 1e18


def pose_frame(prepared: PreparedScene, t: float, *, with_meshes: bool = False,
               trace: bool = True, clusters=None, sky_gain: bool = True) -> FrameState:
    """World-space receivers, blockers, lights (and blocker meshes) at time ``t``.

    Each blocker object is posed by its kind (:meth:`BlockerKind.pose`).
    ``trace=False`` leaves out the traced self-visibility of skinned objects and their
    traced shadow on the receiver-only objects (the frame's largest cost): for callers
    that need only the posed geometry.  ``clusters`` (the runtime's
    :class:`~shtools.runtime.clusters.ReceiverClusters` of this bake) groups the
    receivers where a traced shadow hands over to the object's blocker, so the
    blocker is evaluated there by the same cuts of its tree as on the receivers
    next door.  ``sky_gain=False`` leaves the environment out of the traced shadows'
    hand-over (:func:`~shtools.scene.traced_shadows.sky_gain`): the visibility is then
    the same under any environment, as a visibility stored for relighting must be.
    """
    from shtools.runtime import FieldBlocker, SelfVisibility, SphereBlocker
    from shtools.scene.transfer import (
        posed_caster,
        posed_local_log,
        rotation_of,
        traced_self_visibility,
        world_transfer,
    )

    st = prepared.scene.settings
    kinds = BLOCKER_KINDS
    worlds = world_matrices(prepared.scene.objects, t)
    verts, norms, blockers, meshes, selfs = [], [], [], [], []
    still = static_objects(prepared.scene.objects, prepared.objects)
    static_rows = []
    n_rows = 0
    ground = []  # (rows, vertices, normals) of receiver-only objects
    ground_still = True  # none of them moves
    casters = []  # (caster, posed vertices, blocker index) of the objects traced on the ground
    rigid = []  # (object, transform, posed vertices, blocker index) of rigid traced objects
    parts = []  # ContactPart of the objects that receive and block (contact shadows)
    has_ground = any(o.spec.receives and not o.spec.blocks for o in prepared.objects)
    # a lamp's field leaves out the blockers beyond it by the blocker a traced shadow
    # names (shtools.scene.field_light), which a field's traced shadow cannot name
    field_traced = not any(spec.srf is not None for spec in prepared.scene.lights)
    for o in prepared.objects:
        m = worlds[o.spec.name]
        if o.motion is not None:
            joints = o.motion.joint_matrices(t)
            local_v = np.asarray(o.motion.model.skin(joints), dtype=float)
            local_n = vertex_normals(local_v, o.faces)
        else:
            joints = None
            local_v, local_n = o.vertices, o.normals
        world_v = transform_points(m, local_v)
        if not np.all(np.abs(world_v) <= MAX_COORDINATE):
            raise InputError(f"objects '{o.spec.name}': posed vertices at t = {t:g} s are not "
                             f"finite or beyond +-{MAX_COORDINATE:g} (the runtime computes in "
                             "float32); check its translate/scale and its parents'",
                             prepared.scene.path)
        world_n = transform_normals(m, local_n) if o.spec.receives else None
        own = slice(n_rows, n_rows + len(world_v))
        exact_self = o.self_log is not None or o.self_transfer is not None
        rotation = rotation_of(m) if exact_self else None
        if rotation is not None and o.self_transfer is not None:
            # exact self-shadowing, the transfer itself multiplied in after the exp
            # (its log's round trip would not give it back); its own spheres skipped
            selfs.append(SelfVisibility(None, own, blocker=len(blockers),
                                        visibility=world_transfer(o.self_transfer, rotation,
                                                                  st.order)))
        elif rotation is not None:
            # exact self-shadowing: its own spheres (appended next) are skipped on its rows
            selfs.append(SelfVisibility(o.self_log, own, rotation=rotation,
                                        blocker=len(blockers)))
        caster = None
        if o.traced and trace:  # its posed real mesh, traced this frame; its own blocker skipped
            caster = posed_caster(world_v, o.faces)
            selfs.append(SelfVisibility(None, own, blocker=len(blockers), visibility=(
                traced_self_visibility(world_v, world_n, o.faces, st.order,
                                       st.self_visibility_directions, caster=caster))))
            casters.append((caster, world_v, o.faces, len(blockers)))
        if o.spec.receives and not o.spec.blocks:
            ground.append((np.arange(n_rows, n_rows + len(world_v)), world_v, world_n))
            ground_still = ground_still and o.spec.name in still
        if o.local_log is not None and joints is not None:
            selfs.append(SelfVisibility(
                posed_local_log(o.local_log, o.motion.model.blend_matrices(joints), m), own))
        if o.spec.receives:
            verts.append(world_v)
            norms.append(world_n)
            static_rows.append(np.full(len(world_v), o.spec.name in still))
            n_rows += len(world_v)
        if o.spec.blocks:
            blockers.append(kinds[o.spec.blocker.kind].pose(o, m, joints))
            if o.spec.name in still and isinstance(blockers[-1], SphereBlocker):
                blockers[-1].static = True
            stands_in = (o.motion is None and trace and st.traced_shadows and len(o.faces)
                         and ((field_traced and isinstance(blockers[-1], FieldBlocker))
                              or (isinstance(blockers[-1], SphereBlocker)
                                  and not kinds[o.spec.blocker.kind].exact)))
            if stands_in and has_ground:
                # a rigid sphere-set or field blocker: its real mesh shadows the ground
                # near it instead (a field's innermost shells are coarse next to the object)
                rigid.append((o, m, world_v, len(blockers) - 1))
            # an exact sphere shades the receivers outside it exactly, but not those
            # buried in it where objects interpenetrate: its mesh is traced there too
            touches = stands_in or caster is not None or (
                o.motion is None and trace and st.traced_shadows and len(o.faces)
                and isinstance(blockers[-1], SphereBlocker))
            if o.spec.receives or touches:
                parts.append(ContactPart(o, world_v, m, rows=(
                    np.arange(n_rows - len(world_v), n_rows) if o.spec.receives else None),
                    normals=world_n, caster=caster,
                    blocker=len(blockers) - 1 if touches else None,
                    # a convex mesh's traced self-visibility is zero: it cannot shadow itself
                    convex=o.motion is None and o.self_log is not None and not o.self_log.any(),
                    exact=touches and not (stands_in or caster is not None)))
            if o.spec.receives and hasattr(blockers[-1], "skip_rows"):
                _field_own_rows(o, blockers[-1], m, np.arange(n_rows - len(world_v), n_rows),
                                selfs, len(blockers) - 1, st.order)
            if with_meshes:
                meshes.append((world_v, o.faces))
    # rigid objects whose bounding spheres overlap (a character's parts) traced jointly,
    # the others each in its own cone, the visibilities multiplied: one trace, filter
    # and hand-over for the parts instead of one each, at the same ray density (the
    # shared direction set), and no product of visibilities that overlap
    still_casters = [False] * len(casters)  # the skinned ones move; then the rigid groups
    for group in _overlapping(rigid):
        casters.append(_rigid_caster(group))
        still_casters.append(all(o.spec.name in still for o, _, _, _ in group))
    lights = pose_lights(prepared.scene, t)
    if casters and ground and st.traced_shadows:
        # (rows, points, normals) of every receiver-only object, once for all casters
        receivers = tuple(np.concatenate(a) for a in zip(*ground, strict=True))
        # a still group over a still ground under still lights: the same trace every
        # frame and every bake of these inputs (kept in the set-up cache)
        calm = ground_still and not any(len(spec.keys) > 1 for spec in prepared.scene.lights)
        sky = _sky(prepared) if sky_gain else None
        selfs.extend(v for v in (
            _traced_shadow(c, receivers, st, clusters, blockers, prepared, lights,
                           receivers_still=ground_still, still=calm and c_still, sky=sky)
            for c, c_still in zip(casters, still_casters, strict=True)) if v is not None)
    if trace and st.traced_shadows and field_traced:
        # the other objects' real meshes on each object receiver near them (contact)
        n_contact = contact_directions(st.traced_shadow_directions)
        selfs.extend(v for v in (_traced_shadow(c, receivers, st, clusters, blockers, prepared,
                                                lights, n_dirs=n_contact, strata=True)
                                 for receivers, c in contact_casters(
                                     parts, n_contact, _sphere_lights(lights)))
                     if v is not None)
    return FrameState(np.concatenate(verts), np.concatenate(norms), blockers, lights, meshes,
                      [spec.shadows for spec in prepared.scene.lights], selfs,
                      np.concatenate(static_rows))


def static_objects(specs: list, prepared_objects: list) -> set[str]:
    """Names of the objects that never move: no skinned motion, and no keyframes on
    them or on any of their parents (a fact of the scene file, not of the frames)."""
    by_name = {o.name: o for o in specs}
    skinned = {o.spec.name for o in prepared_objects if o.motion is not None}

    def moves(name: str) -> bool:
        o = by_name[name]
        return bool(o.keyframes) or name in skinned or (
            o.parent is not None and moves(o.parent))

    return {o.name for o in specs if not moves(o.name)}


def pose_lights(scene, t: float) -> list:
    """The scene's ``[[lights]]`` at time ``t``, one per light: a runtime SphereLight, or
    the pose of a lamp with a source radiance field
    (:func:`shtools.scene.field_light.field_light_pose`)."""
    from shtools.runtime import SphereLight

    lights = []
    for spec in scene.lights:
        if spec.srf is not None:  # a lamp with a source radiance field
            from shtools.scene.field_light import field_light_pose

            lights.append(field_light_pose(spec, t))
            continue
        key = light_at(spec, t)
        lights.append(SphereLight(position=key.position, radius=float(key.radius),
                                  color=key.color))
    return lights


def _traced_shadow(caster_of, receivers: tuple, st, clusters, blockers: list, prepared,
                   lights=(), n_dirs: int | None = None, strata: bool = False,
                   receivers_still: bool = False, still: bool = False, sky=None):
    """A traced object's shadow on the receiver-only objects (the ground): its real mesh
    near it, its blocker far from it, a per-vertex blend between
    (:mod:`shtools.scene.traced_shadows`); its blocker is skipped on the rows handed
    over.  Each traced object gives one such visibility; the runtime multiplies them
    (the product of separately traced visibilities, not a joint trace: measured on
    ``bench_fidelity``'s rigid scenes).

    ``receivers`` is ``(rows, points, normals)`` of all receiver-only vertices, shapes
    ``(R,)``, ``(R, 3)``, ``(R, 3)`` (or of object receivers, for contact shadows, with
    a lone rigid receiver's rest geometry fourth: ``rest`` of
    :func:`~shtools.scene.receiver_filter.neighbours`);
    ``n_dirs`` the rays of a cone filling the hemisphere (default
    ``traced_shadow_directions``); ``receivers_still`` when the receivers never move
    (their neighbour lists, or a lone rigid receiver's rest ones, are then entries of
    the set-up cache: a moving receiver's would be a new entry every frame), ``still``
    when the object and the lights do not either (``still`` of
    :func:`~shtools.scene.traced_shadows.traced_ground`); ``sky`` the environment's
    luminance in SH ``(n*n,)``, whose light behind the object lengthens its hand-over
    (:func:`~shtools.scene.traced_shadows.sky_gain`; None on object receivers, which
    :func:`~shtools.scene.contact_shadows.contact_casters` pairs at the reach without
    it); returns None when none is within the object's reach."""
    from shtools.runtime import FieldBlocker, SelfVisibility
    from shtools.scene.traced_shadows import traced_ground

    caster, mesh_v, faces, index = caster_of
    rows, points, normals = receivers[:3]
    rest = receivers[3] if len(receivers) > 3 else None
    cache = prepared.cache if receivers_still or rest is not None else None
    labels = None if clusters is None else clusters.labels[rows]
    indices = index if isinstance(index, tuple) else (index,)
    # the blocker alone on the hand-over rows: a field's own skipped rows are another
    # numbering (the frame's), not the hand-over's
    own = [dataclasses.replace(blockers[k], skip_rows=None)
           if isinstance(blockers[k], FieldBlocker) else blockers[k] for k in indices]
    handed, weight, g = traced_ground(points, normals, mesh_v, faces, caster, st.order,
                                      n_dirs or st.traced_shadow_directions,
                                      spheres=_bounding_spheres(own),
                                      lights=_sphere_lights(lights),
                                      strata=strata, rest=rest, cache=cache, still=still,
                                      sky=sky)
    if not len(handed):  # every receiver beyond the object's reach keeps its blocker
        return None
    part = np.flatnonzero(weight < 1.0)
    if part.size:  # the blend with the object's own blocker: w T + (1 - w) S
        from shtools.runtime.clusters import ReceiverClusters

        at = handed[part]
        # grouped as the bake's clusters: the cuts of the sphere tree the runtime makes
        # for the rows next door, which keep the blocker
        groups = None if labels is None else ReceiverClusters.from_labels(labels[at],
                                                                          clusters.groups)
        s = _handover_runtime(prepared).visibility(points[at], normals[at], own,
                                                   clusters=groups)
        w = weight[part, None]
        g[part] = w * g[part] + (1.0 - w) * np.asarray(s, dtype=np.float64)
    return SelfVisibility(None, rows[handed], blocker=_skip_handed(blockers, indices,
                                                                   rows[handed]),
                          visibility=g.astype(np.float32))


def _sphere_lights(lights: list) -> list:
    """``[(position (3,), radius), ...]`` of the frame's spherical lights (a lamp with a
    source radiance field is not one)."""
    from shtools.runtime import SphereLight

    return [(x.position, x.radius) for x in lights if isinstance(x, SphereLight)]


def _sky(prepared):
    """The environment's luminance in SH ``(n*n,)``, or None without one."""
    from shtools.runtime.shading import LUMINANCE

    return None if prepared.env_sh is None else np.asarray(prepared.env_sh) @ LUMINANCE


def _skip_handed(blockers: list, indices: tuple, handed: np.ndarray):
    """The traced object's blockers skipped on the rows ``handed`` (R,): a field skips
    them itself (its ``skip_rows``, joined to its object's own rows), a sphere set
    through the self-visibility; returns the latter's indices (int, tuple or None) for
    :class:`~shtools.runtime.SelfVisibility`."""
    from shtools.runtime import FieldBlocker

    spheres = []
    for k in indices:
        b = blockers[k]
        if isinstance(b, FieldBlocker):
            skip = handed if b.skip_rows is None else np.union1d(
                np.asarray(b.skip_rows, dtype=np.int64), handed)
            b.skip_rows = np.asarray(skip, dtype=np.int64)
        else:
            spheres.append(k)
    if not spheres:
        return None
    return spheres[0] if len(spheres) == 1 else tuple(spheres)


def _bounding_spheres(blockers: list):
    """Leaf spheres ``(centres (S, 3), radii (S,))`` of sphere-set blockers; None if any
    blocker is not a sphere set."""
    from shtools.runtime import SphereBlocker
    from shtools.runtime.hierarchy import leaf_spheres

    if not all(isinstance(b, SphereBlocker) for b in blockers):
        return None
    return leaf_spheres(blockers)


#: The runtime that evaluates a traced object's own blocker where its traced shadow hands
#: over to it, per process: (pid, id of the prepared scene, the scene itself, runtime).
_HANDOVER: list = []


def _handover_runtime(prepared):
    """A one-process runtime of the scene's settings (the hand-over rows are evaluated
    with the traced object's own blocker alone)."""
    import os

    from shtools.runtime import ShadowRuntime

    if _HANDOVER and _HANDOVER[0][:2] == (os.getpid(), id(prepared)) and \
            _HANDOVER[0][2] is prepared:
        return _HANDOVER[0][3]
    settings = dataclasses.replace(prepared.scene.settings.runtime_only(), processes=1)
    runtime = ShadowRuntime(settings, tables=prepared.tables)
    _HANDOVER[:] = [(os.getpid(), id(prepared), prepared, runtime)]
    return runtime


def _rigid_caster(rigid: list):
    """``(caster, vertices, faces, blocker indices)``: one Embree scene of rigid objects'
    real meshes at their transforms (kept while the transforms hold:
    :func:`~shtools.scene.contact_shadows.rigid_caster`); ``rigid`` holds
    ``(object, transform, posed vertices, blocker index)``."""
    vertices = np.concatenate([v for _, _, v, _ in rigid])
    faces = _joint_faces(rigid)
    caster = rigid_caster([o for o, _, _, _ in rigid], [m for _, m, _, _ in rigid], vertices,
                          faces)
    return caster, vertices, faces, tuple(k for _, _, _, k in rigid)


def _overlapping(rigid: list) -> list[list]:
    """``rigid`` (object, transform, posed vertices, blocker index) grouped by bounding
    spheres that overlap, directly or through others (in the objects' order)."""
    from shtools.geometry.bounding import box_sphere, overlapping_groups

    return [[rigid[i] for i in group]
            for group in overlapping_groups([box_sphere(v) for _, _, v, _ in rigid])]


def _joint_faces(rigid: list) -> np.ndarray:
    """The faces of rigid objects' meshes, indices into their concatenated vertices."""
    offsets = np.cumsum([0] + [len(v) for _, _, v, _ in rigid])
    return np.concatenate([o.faces + offsets[i] for i, (o, _, _, _) in enumerate(rigid)])


def _field_own_rows(o, blocker, world, rows, selfs: list, index: int, order: int) -> None:
    """A shadow field never shades its own object (its surface lies inside the innermost
    shells): the posed field skips the object's receiver rows, and the object's
    self-shadowing comes from ``self_visibility`` when that is on for it, else from the
    O_v stored in the field asset (rotated with the object, multiplied in at the shading
    ``order``)."""
    from shtools.runtime import SelfVisibility
    from shtools.scene.transfer import rotation_of, world_transfer

    blocker.skip_rows = rows
    # the field already skips these rows: its self-visibility names no sphere blocker
    for k, sv in enumerate(selfs):
        if sv.blocker == index:
            selfs[k] = dataclasses.replace(sv, blocker=None)
    own = getattr(o.blocker_data, "self_visibility", None)
    rotation = rotation_of(world)
    if o.self_log is None and o.self_transfer is None and own is not None and \
            rotation is not None:
        selfs.append(SelfVisibility(None, slice(int(rows[0]), int(rows[-1]) + 1),
                                    visibility=world_transfer(own, rotation, order)))
