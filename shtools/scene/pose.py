"""Posing a prepared scene at a time: receivers, blockers (by their kind), lights."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shtools.scene.animation import (
    light_at,
    transform_normals,
    transform_points,
    vertex_normals,
    world_matrices,
)
from shtools.scene.blockers import blocker_kinds
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
    #: (receiver rows, world-frame O_v (rows, n*n)) of shadow-field objects that receive
    self_visibility: list = field(default_factory=list)


def pose_frame(prepared: PreparedScene, t: float, *, with_meshes: bool = False) -> FrameState:
    """World-space receivers, blockers, lights (and blocker meshes) at time ``t``.

    Each blocker object is posed by its kind (:meth:`BlockerKind.pose`).
    """
    from shtools.runtime import SphereLight

    kinds = blocker_kinds()
    worlds = world_matrices(prepared.scene.objects, t)
    verts, norms, blockers, meshes, self_vis = [], [], [], [], []
    n_rows = 0
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
        rows = None
        if o.spec.receives:
            verts.append(world_v)
            norms.append(transform_normals(m, local_n))
            rows = np.arange(n_rows, n_rows + len(world_v))
            n_rows += len(world_v)
        if o.spec.blocks:
            blockers.append(kinds[o.spec.blocker.kind].pose(o, m, joints))
            if rows is not None and hasattr(blockers[-1], "skip_rows"):
                _own_rows(blockers[-1], rows, self_vis)
            if with_meshes:
                meshes.append((world_v, o.faces))
    lights = []
    for spec in prepared.scene.lights:
        key = light_at(spec, t)
        lights.append(SphereLight(position=key.position, radius=float(key.radius),
                                  color=key.color))
    return FrameState(np.concatenate(verts), np.concatenate(norms), blockers, lights, meshes,
                      [spec.shadows for spec in prepared.scene.lights], self_vis)


def _own_rows(blocker, rows: np.ndarray, self_vis: list) -> None:
    """A shadow field never shades its own object (its surface is inside the innermost
    shells): give it the object's receiver rows, and queue its stored O_v for them."""
    from shtools.sh import rotate

    blocker.skip_rows = rows
    sv = blocker.table.field.self_visibility
    if sv is not None:
        self_vis.append((rows, rotate(np.asarray(sv, np.float64), blocker.rotation)))


def apply_self_visibility(vis: np.ndarray, state: FrameState, order: int) -> np.ndarray:
    """Multiply the field objects' own O_v into their receiver rows (truncated product)."""
    if not state.self_visibility:
        return vis
    from shtools.sh import product

    vis = np.array(vis, dtype=np.float64)
    for rows, sv in state.self_visibility:
        vis[rows] = product(vis[rows], sv, order)
    return vis
