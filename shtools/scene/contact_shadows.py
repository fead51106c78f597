r"""Objects' shadows on each other where they touch: the other objects' real meshes traced.

An object that both receives and blocks (``role = "both"``) is shadowed by the
other objects' blockers.  Far from a blocker its spheres (or its field) shade a
receiver well; close to it they do not: a sphere set bulges out of the surface
it bounds, so where two objects touch or interpenetrate (a character's arm on
its torso, the parts of a walker, a dragon against an armadillo) the receivers
next to the contact sit inside or against spheres that the real mesh does not
fill, and come out far too dark.  Contact surfaces are exactly where spheres fail.

So an object receiver gets the same treatment as the ground
(:mod:`shtools.scene.traced_shadows`): the **real posed meshes of the other
objects near it** are traced on its vertices over the shared world direction
set, filtered over its surface by the distance to them, and handed over per
vertex, smoothly, to their blockers far from them.  The caller
(:func:`shtools.scene.pose.pose_frame`) runs that hand-over; this module says
who is traced on whom (:func:`contact_casters`):

* the traceable blockers (sphere sets fitted to a mesh, shadow fields, skinned
  objects that trace their posed mesh) are grouped as the ground's are, by
  bounding spheres that overlap, directly or through others;
* a receiver is traced against each group some member of which its hand-over
  reaches (beyond the hand-over's outer edge,
  :data:`~shtools.scene.traced_shadows.HANDOVER_RAYS`, it keeps their blockers,
  exactly what the hand-over would give it), and the group's blockers other than
  its own are skipped on the rows traced;
* the members of a group are traced jointly (one Embree scene, one cone), so the
  parts around a receiver never multiply visibilities that overlap.  The scene is
  the whole group's, shared by its receivers, unless the receiver is a member that
  can shadow itself: its own mesh would then shadow it twice (its self-visibility
  does already), so it is traced against the others alone.

The Embree scene of rigid objects is kept while their transforms hold (a static
scene builds it once per bake); a lone skinned object's per-frame scene is reused.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np


@dataclass
class ContactPart:
    """One object of the frame, as the contact shadows see it (world space).

    Attributes
    ----------
    obj : object
        The prepared object (identity and faces; ``motion`` None for rigid ones).
    vertices : ndarray, shape (V, 3)
        Its posed vertices.
    matrix : ndarray, shape (4, 4)
        Its world transform this frame.
    rows : ndarray of int, shape (V,), or None
        Its receiver rows in the frame (None: it does not receive).
    normals : ndarray, shape (V, 3), or None
        Its unit normals (receivers only).
    blocker : int or None
        Index of its blocker in the frame's blockers when its real mesh can stand for
        that blocker near it (None: it blocks exactly already, or not at all).
    caster : RayCaster or None
        Its posed mesh's Embree scene when the frame built one (skinned objects).
    convex : bool
        Its own mesh cannot block its vertices above their tangent planes (a convex
        rigid mesh, whose self-visibility is exactly 1).
    """

    obj: object
    vertices: np.ndarray
    matrix: np.ndarray
    rows: np.ndarray | None = None
    normals: np.ndarray | None = None
    blocker: int | None = None
    caster: object = None
    convex: bool = False


def reach_factor(n_dirs: int) -> float:
    """Distance from a sphere's centre, in its radii, where the hand-over to its blocker
    ends: the cone of half-angle ``θ`` with ``n_dirs (1 - cos θ)`` at the lower end of
    :data:`~shtools.scene.traced_shadows.HANDOVER_RAYS` (beyond it the weight is 0)."""
    from shtools.scene.traced_shadows import HANDOVER_RAYS

    cos_t = max(-1.0, 1.0 - HANDOVER_RAYS[0] / int(n_dirs))
    sin_t = math.sqrt(max(1e-12, 1.0 - cos_t * cos_t))
    return 1.0 / sin_t


def _sphere(v: np.ndarray) -> tuple[np.ndarray, float]:
    """Bounding sphere of posed vertices: the box centre and the farthest vertex."""
    center = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return center, float(np.sqrt(((v - center) ** 2).sum(axis=1).max()))


def groups_of(spheres: list) -> list[list[int]]:
    """Indices of ``spheres`` (centre, radius) grouped by overlap, directly or through
    others, each group in the given order."""
    group = list(range(len(spheres)))

    def root(i):
        while group[i] != i:
            i = group[i]
        return i

    for i in range(len(spheres)):
        for j in range(i):
            (ci, ri), (cj, rj) = spheres[i], spheres[j]
            if np.linalg.norm(ci - cj) < ri + rj:
                group[max(root(i), root(j))] = min(root(i), root(j))
    out: dict = {}
    for i in range(len(spheres)):
        out.setdefault(root(i), []).append(i)
    return list(out.values())


def contact_casters(parts: list[ContactPart], n_dirs: int) -> list[tuple[tuple, tuple]]:
    """Who is traced on whom: ``[(receivers, caster_of), ...]`` for the frame's object
    receivers.

    Parameters
    ----------
    parts : list of ContactPart
        Every object of the frame that receives or has a traceable blocker.
    n_dirs : int
        Rays of a receiver whose cone fills its hemisphere (the hand-over's scale).

    Returns
    -------
    list of (receivers, caster_of)
        ``receivers`` is ``(rows (R,), points (R, 3), normals (R, 3))`` of one object
        receiver; ``caster_of`` is ``(caster, vertices (Vc, 3), faces (Fc, 3),
        blocker indices tuple)`` of the other objects traced on it jointly.
    """
    traceable = [p for p in parts if p.blocker is not None and len(p.obj.faces)]
    if not traceable:
        return []
    spheres = [_sphere(p.vertices) for p in traceable]
    groups = groups_of(spheres)
    reach = reach_factor(n_dirs)
    built: dict = {}  # the frame's Embree scenes, one per set of members
    out = []
    for receiver in parts:
        if receiver.rows is None or not len(receiver.rows):
            continue
        center, radius = _sphere(receiver.vertices)
        for group in groups:
            members = [traceable[k] for k in group]
            others = [m for m in members if m is not receiver]
            near = [k for k in group if traceable[k] is not receiver
                    and np.linalg.norm(spheres[k][0] - center) - radius
                    < reach * spheres[k][1]]
            if not near:
                continue
            if len(others) < len(members) and not receiver.convex:
                # its own mesh would shadow it twice (its self-visibility does already):
                # the others alone, which it may sit next to or inside
                traced = others
            else:
                # a convex receiver's own mesh never blocks above its tangent planes: the
                # whole group's scene, shared with the group's other receivers
                traced = members
            key = tuple(id(m) for m in traced)
            if key not in built:
                built[key] = _joint_caster(traced)
            caster, vertices, faces, _ = built[key]
            out.append(((receiver.rows, receiver.vertices, receiver.normals),
                        (caster, vertices, faces, tuple(m.blocker for m in others))))
    return out


#: Embree scenes of rigid objects' meshes in world space, per process: ids of the
#: objects -> (pid, their faces, their matrices, caster); rebuilt when a transform changes.
_CASTERS: dict = {}


def _joint_caster(members: list[ContactPart]) -> tuple:
    """``(caster, vertices, faces, blocker indices)`` of the members' real meshes."""
    from shtools.scene.transfer import posed_caster

    vertices = np.concatenate([m.vertices for m in members])
    offsets = np.cumsum([0] + [len(m.vertices) for m in members])
    faces = np.concatenate([m.obj.faces + offsets[i] for i, m in enumerate(members)])
    index = tuple(m.blocker for m in members)
    if len(members) == 1 and members[0].caster is not None:
        return members[0].caster, vertices, faces, index
    if any(m.obj.motion is not None for m in members):  # a skinned mesh moves every frame
        return posed_caster(vertices, faces), vertices, faces, index
    key = tuple(id(m.obj) for m in members)
    hit = _CASTERS.get(key)
    # the entry holds the faces arrays themselves: an id alone can be reused once freed
    if (hit is not None and hit[0] == os.getpid()
            and all(a is m.obj.faces for a, m in zip(hit[1], members, strict=True))
            and all(np.array_equal(a, m.matrix) for a, m in zip(hit[2], members, strict=True))):
        return hit[3], vertices, faces, index
    if len(_CASTERS) >= 64:
        _CASTERS.clear()
    caster = posed_caster(vertices, faces)
    _CASTERS[key] = (os.getpid(), [m.obj.faces for m in members],
                     [np.array(m.matrix, copy=True) for m in members], caster)
    return caster, vertices, faces, index
