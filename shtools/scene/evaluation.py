"""Evaluation inputs from a scene file (``shtools eval SCENE``): one posed frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from shtools.errors import InputError
from shtools.reference.evaluation import EvalInputs


def scene_eval_inputs(path, frame: int = 0, order: int | None = None) -> EvalInputs:
    """Receivers, blockers, meshes and lights of ``frame`` of the scene file ``path``.

    ``order`` overrides the scene's shading order.
    """
    import trimesh

    from shtools.scene.pose import pose_frame
    from shtools.scene.prepare import prepare_scene
    from shtools.scene.scene import load_scene

    scene = load_scene(path)
    if any(spec.srf is not None for spec in scene.lights):
        raise InputError("the scene has a field light (field = ...): `shtools eval` compares "
                         "visibility methods under spherical lights and the environment; bake "
                         "it with `shtools bake` instead, or remove the field light", path)
    st = scene.settings
    if frame >= st.frames:
        raise InputError(f"--frame {frame} is outside the scene's frames 0..{st.frames - 1}",
                         path)
    prepared = prepare_scene(scene)
    state = pose_frame(prepared, frame / st.fps, with_meshes=True)
    if not state.blockers:
        raise InputError("the scene has no blocker objects to evaluate", path)
    meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
    groups = np.concatenate([np.full(len(o.vertices), k)
                             for k, o in enumerate(prepared.receivers)])
    settings = {"order": order or st.order, "acc_order": st.acc_order, "window": st.window,
                "window_h": st.window_h, "theta_max": st.theta_max, "theta_min": st.theta_min,
                "hierarchy": st.hierarchy, "vertices_per_cluster": st.vertices_per_cluster,
                "cluster_blend": st.cluster_blend, "deringing": st.deringing,
                "field_space": st.field_space}
    receivers = [o.spec.name for o in prepared.receivers]
    blocking = [o.spec.name for o in prepared.objects if o.spec.blocks]
    return EvalInputs(Path(path).name, state.vertices, state.normals, groups, state.blockers,
                      meshes, prepared.env_sh, state.lights, settings, prepared.tables,
                      receiver_names=receivers, self_visibility=state.self_visibility,
                      faces=[o.faces for o in prepared.receivers],
                      blocker_groups=[receivers.index(b) if b in receivers else -1
                                      for b in blocking])


