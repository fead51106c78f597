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
objects touching it** are traced on its vertices over the shared world direction
set, filtered over its surface by the distance to them, and handed over per
vertex, smoothly, to their blockers far from them.  The caller
(:func:`shtools.scene.pose.pose_frame`) runs that hand-over; this module says
who is traced on whom (:func:`contact_casters`):

* the traceable blockers are sphere sets fitted to a mesh, shadow fields, skinned
  objects that trace their posed mesh, and sphere primitives for the receivers with
  vertices buried in them (exact outside, they leave the buried vertices lit where
  objects interpenetrate);
* a receiver is traced against the traceable objects whose bounding spheres overlap
  its own, or nearly (:data:`NEAR_MARGIN`: the objects it may touch), jointly (one
  Embree scene, one cone, so the parts around a receiver never multiply
  visibilities that overlap), and their
  blockers are skipped on the rows traced;
* a receiver is traced against the farther objects within their hand-over reach
  (:func:`~shtools.scene.traced_shadows.handover_reach`), each group of overlapping
  ones on its own, as the ground is (its visibility multiplies the others'), and
  handed over per vertex to their blockers: a mid-range object's spheres misplace
  its shadow as much on an object as on the ground (spot beside the teapot,
  ``bench_look``'s held-out ``spottea``);
  objects beyond that reach keep their blockers, which shade them well, unless they
  may hide a spherical light from it (their long shadow stays traced, as on the
  ground);
* a convex receiver (its own mesh never blocks above its tangent planes) is traced
  with itself among them (one scene serves the receivers that touch the same objects); a receiver
  that can shadow itself is traced against the others alone (its self-visibility
  shadows it already).

The Embree scene of rigid objects is kept while their transforms hold (a static
scene builds it once per bake); a lone skinned object's per-frame scene is reused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from shtools.geometry.bounding import box_sphere, overlapping_groups


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
    exact : bool
        Its blocker is its exact shape (a sphere primitive): traced only on the
        receivers with vertices buried in it, which the exact sphere leaves lit.
    """

    obj: object
    vertices: np.ndarray
    matrix: np.ndarray
    rows: np.ndarray | None = None
    normals: np.ndarray | None = None
    blocker: int | None = None
    caster: object = None
    convex: bool = False
    exact: bool = False


#: Rays of an object receiver's cone that fills its hemisphere, as a share of the
#: ground's ``traced_shadow_directions``: an object's receivers sit close to what they
#: trace, where the surface filter is narrow, so their error is the set's quadrature
#: (``make demo``'s legs, between each other and buried in the torso); they cast the
#: set in strata (:func:`~shtools.scene.traced_shadows.set_visibility`), the rays
#: only where the first ones found the mesh (what each share costs and buys:
#: ``benchmarks/bench_look.py --demo``, docs/scenes.md).
CONTACT_SCALE = 1.25


def contact_directions(ground_directions: int) -> int:
    """Rays of an object receiver whose cone fills its hemisphere (at least 8)."""
    return max(8, round(CONTACT_SCALE * int(ground_directions)))


#: Objects whose bounding spheres come within this factor of the sum of their radii
#: may touch (bounding spheres are loose about long or flat meshes).
NEAR_MARGIN = 1.25


def _buried(points, center, radius) -> bool:
    """Whether any point lies inside the sphere."""
    d = np.asarray(points, dtype=np.float64) - center
    return bool((np.einsum("vk,vk->v", d, d) < radius * radius).any())


def contact_casters(parts: list[ContactPart], n_dirs: int, lights=()
                    ) -> list[tuple[tuple, tuple]]:
    """Who is traced on whom: ``[(receivers, caster_of), ...]`` for the frame's object
    receivers.

    Parameters
    ----------
    parts : list of ContactPart
        Every object of the frame that receives or has a traceable blocker.
    n_dirs : int
        Rays of a receiver whose cone fills its hemisphere (the hand-over's scale).
    lights : sequence of (position (3,), radius)
        The frame's spherical lights: a farther object that may hide one from a
        receiver is traced on it however far (its long shadow, as on the ground:
        :func:`~shtools.scene.traced_shadows.light_weights`).

    Returns
    -------
    list of (receivers, caster_of)
        ``receivers`` is ``(rows (R,), points (R, 3), normals (R, 3), rest)`` of the
        object receivers traced against one scene that skip the same blockers (``rest``
        the rest geometry of a lone rigid receiver, :func:`_rest`, else None); ``caster_of``
        is ``(caster, vertices (Vc, 3), faces (Fc, 3), blocker indices tuple)`` of that
        scene and those blockers.
    """
    from shtools.scene.traced_shadows import handover_reach

    traceable = [p for p in parts if p.blocker is not None and len(p.obj.faces)]
    if not traceable:
        return []
    spheres = [box_sphere(p.vertices) for p in traceable]
    reach = handover_reach(n_dirs)
    built: dict = {}  # the frame's Embree scenes, one per set of members
    bounds: dict = {}  # the bounding sphere of each set of farther members, once a frame
    out: dict = {}  # (scene, blockers skipped, receiver or None) -> its receivers
    for receiver in parts:
        if receiver.rows is None or not len(receiver.rows):
            continue
        center, radius = box_sphere(receiver.vertices)
        near, farther = [], []
        for p, (c, r) in zip(traceable, spheres, strict=True):
            if p is receiver or (p.exact and not _buried(receiver.vertices, c, r)):
                continue
            if np.linalg.norm(c - center) < NEAR_MARGIN * (r + radius):
                near.append(p)
            else:
                farther.append((p, (c, r)))
        # the farther ones in groups of overlapping spheres (a walker's parts seen from
        # a column: one scene, as on the ground), each group within its hand-over reach
        for group in overlapping_groups([sphere for _, sphere in farther]):
            members = [farther[i][0] for i in group]
            key = tuple(id(m) for m in members)
            if key not in bounds:
                bounds[key] = box_sphere(np.concatenate([m.vertices for m in members]))
            c, r = bounds[key]
            if (np.linalg.norm(c - center) - radius >= reach * r
                    and not _hides_a_light(receiver, c, r, lights)):
                continue  # no vertex inside its hand-over: its blockers shade it
            if key not in built:
                built[key] = _joint_caster(members)
            # one call per receiver: a lone rigid receiver's neighbour lists are its rest
            # geometry's, computed once (moving receivers joined would search theirs
            # every frame)
            out[key, tuple(m.blocker for m in members), id(receiver)] = [receiver]
        if not near:
            continue
        if receiver.convex and any(p is receiver for p in traceable):
            # a convex receiver's own mesh never blocks above its tangent planes: traced
            # with the others, the scene is the one its neighbours share; its own
            # blocker, which its self-visibility skips on its rows already, is skipped
            # too (it lies inside the members' bounding sphere, where the traced mesh
            # takes the whole weight, no hand-over)
            near = [p for p in traceable if p is receiver or any(p is q for q in near)]
        key = tuple(id(m) for m in near)
        if key not in built:
            built[key] = _joint_caster(near)
        out.setdefault((key, tuple(m.blocker for m in near), None), []).append(receiver)
    calls = []
    for (key, skipped, _), receivers in out.items():
        caster, vertices, faces, _ = built[key]
        joint = tuple(np.concatenate(a) for a in zip(
            *((r.rows, r.vertices, r.normals) for r in receivers), strict=True))
        calls.append(((*joint, _rest(receivers)), (caster, vertices, faces, skipped)))
    return calls


def _hides_a_light(receiver: ContactPart, center, radius: float, lights) -> bool:
    """Whether a bounding sphere may hide one of ``lights`` from a vertex of
    ``receiver``: the same test as the traced rows' light weights (> 0 somewhere), so
    the pairing never cuts a long shadow that the hand-over would trace."""
    if not lights:
        return False
    from shtools.geometry.visibility import bounding_cones
    from shtools.scene.traced_shadows import light_weights

    axis, cos_half = bounding_cones(receiver.vertices, receiver.normals, center, radius)
    return any(light_weights(receiver.vertices, axis, cos_half, center, radius, position,
                             light_radius).max() > 0 for position, light_radius in lights)


def similarity_scale(matrix) -> float | None:
    """The uniform scale of a rotation, translation and uniform scale ``(4, 4)``; None for
    any other transform (a shear or an unequal scale changes distances unequally)."""
    m = np.asarray(matrix, dtype=np.float64)[:3, :3]
    gram = m.T @ m
    s2 = float(np.trace(gram)) / 3.0
    if not s2 > 0 or np.abs(gram - s2 * np.eye(3)).max() > 1e-9 * s2:
        return None
    return float(np.sqrt(s2))


def _rest(receivers: list[ContactPart]):
    """``(rest vertices, rest normals, scale)`` of a lone rigid receiver posed by a
    similarity (its neighbours are its rest geometry's:
    :func:`~shtools.scene.receiver_filter.neighbours`), else None."""
    if len(receivers) != 1 or receivers[0].obj.motion is not None:
        return None
    obj = receivers[0].obj
    scale = similarity_scale(receivers[0].matrix)
    if scale is None or obj.normals is None or len(obj.vertices) != len(receivers[0].rows):
        return None
    return obj.vertices, obj.normals, scale


#: Embree scenes of rigid objects' meshes in world space, per process: ids of the
#: objects -> (pid, their faces, their matrices, caster); rebuilt when a transform changes.
#: Shared by the contact shadows and the ground's traced rigid groups
#: (:func:`shtools.scene.pose.pose_frame`): a walker's parts are one scene for both.
_CASTERS: dict = {}


def rigid_caster(objects: list, matrices: list, vertices: np.ndarray, faces: np.ndarray):
    """The Embree scene of rigid objects' meshes posed at ``matrices``, kept while their
    transforms hold (a static scene is built once per bake).

    Parameters
    ----------
    objects : list
        The prepared objects (identity and ``faces``), in the order of ``vertices``.
    matrices : list of ndarray, shape (4, 4)
        Their world transforms this frame.
    vertices, faces : ndarray, shapes (V, 3) and (F, 3)
        Their posed meshes concatenated (faces indexing the concatenation).
    """
    from shtools.scene.transfer import posed_caster

    key = tuple(id(o) for o in objects)
    hit = _CASTERS.get(key)
    # the entry holds the faces arrays themselves: an id alone can be reused once freed
    if (hit is not None and hit[0] == os.getpid()
            and all(a is o.faces for a, o in zip(hit[1], objects, strict=True))
            and all(np.array_equal(a, m) for a, m in zip(hit[2], matrices, strict=True))):
        return hit[3]
    if len(_CASTERS) >= 64:
        _CASTERS.clear()
    # built on its first query: a still scene's traces may all come from the set-up cache
    caster = posed_caster(vertices, faces, deferred=True)
    _CASTERS[key] = (os.getpid(), [o.faces for o in objects],
                     [np.array(m, copy=True) for m in matrices], caster)
    return caster


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
    caster = rigid_caster([m.obj for m in members], [m.matrix for m in members], vertices,
                          faces)
    return caster, vertices, faces, index
