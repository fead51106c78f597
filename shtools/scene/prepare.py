"""Preparing a bake: everything loaded once, before frame 0 (:func:`prepare_scene`).

Meshes (files, primitives, skinned glTF), each blocker by its kind
(:mod:`shtools.scene.blockers`: sphere assets, trees, skin bindings, fits on
the fly, or a kind's own data), the environment SH and the log tables, with
the checks that SH orders agree.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shtools.errors import AssetError, InputError
from shtools.scene.animation import SkinnedMotion, vertex_normals
from shtools.scene.blockers import PrepareContext
from shtools.scene.kinds import BLOCKER_KINDS
from shtools.scene.scene import Scene
from shtools.scene.specs import ObjectSpec


@dataclass
class PreparedObject:
    """An object with its geometry and blocker spheres in its local frame.

    Attributes
    ----------
    spec : ObjectSpec
    vertices, normals : ndarray, shape (V, 3)
        Rest geometry (local frame).
    faces : ndarray, shape (F, 3)
    centers : ndarray, shape (N, 3) or None
        Blocker spheres (local frame, rest pose for skinned objects).
    radii : ndarray, shape (N,) or None
    tree : tuple of (parent (M,), leaf (M,)) or None
    motion : SkinnedMotion or None
    bone_index : ndarray, shape (N, K) or None
        Skin binding of the spheres (skinned blockers).
    bone_vectors : ndarray, shape (N, K, 4) or None
    blocker_data : object
        What a blocker kind that is not a sphere set prepared (its own type).
    self_log : ndarray, shape (V, n_acc^2) or None
        Self-visibility log in the object's frame (exact self-shadowing,
        :mod:`shtools.scene.transfer`: a ``transfer`` asset's, a convex mesh's
        zero); None when the object uses its spheres or only ``self_transfer``.
    self_transfer : ndarray, shape (V, m*m) or None
        The projected self-visibility (a ``transfer`` asset's, a field's O_v, or
        traced at the shading order), in the object's frame: multiplied into its rows after
        the exp (:func:`shtools.scene.pose.pose_frame`) instead of adding a log
        before it, whose eigen-log and exp do not give it back.
    local_log : ndarray, shape (V, n_acc^2) or None
        Rest-pose local visibility log of a skinned object (``local_visibility``).
    traced : bool
        A skinned object whose posed mesh is ray traced every frame on its own
        vertices (``self_visibility``; :func:`shtools.scene.transfer.traced_self_visibility`).
    """

    spec: ObjectSpec
    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    centers: np.ndarray | None = None
    radii: np.ndarray | None = None
    tree: tuple[np.ndarray, np.ndarray] | None = None
    motion: SkinnedMotion | None = None
    bone_index: np.ndarray | None = None
    bone_vectors: np.ndarray | None = None
    blocker_data: Any = None
    self_log: np.ndarray | None = None
    self_transfer: np.ndarray | None = None
    local_log: np.ndarray | None = None
    traced: bool = False

    @property
    def moves(self) -> bool:
        return self.motion is not None or bool(self.spec.keyframes)


@dataclass
class PreparedScene:
    """Everything a bake needs, loaded and checked."""

    scene: Scene
    objects: list[PreparedObject]
    env_sh: np.ndarray | None  # (n*n, 3)
    tables: dict | None
    inputs: dict[str, Path] = field(default_factory=dict)
    #: a finite environment sphere (shtools.scene.midrange), None at infinity
    midrange: object | None = None
    #: the set-up cache the preparation used (shtools.cache.SetupCache; its hits, misses)
    cache: object | None = None

    @property
    def receivers(self) -> list[PreparedObject]:
        return [o for o in self.objects if o.spec.receives]

    @property
    def blockers(self) -> list[PreparedObject]:
        return [o for o in self.objects if o.spec.blocks]

    @property
    def n_vertices(self) -> int:
        return sum(len(o.vertices) for o in self.receivers)

    def receivers_move(self) -> bool:
        """True when any receiver (or one of its parents) is animated."""
        by_name = {o.spec.name: o for o in self.objects}
        for o in self.receivers:
            cur = o
            while cur is not None:
                if cur.moves:
                    return True
                cur = by_name.get(cur.spec.parent) if cur.spec.parent else None
        return False


def _object_geometry(obj: ObjectSpec) -> tuple[PreparedObject, object]:
    """Load or generate an object's mesh; returns it and the skinned model if any."""
    if obj.primitive is not None:
        from shtools.scene.primitives import make_primitive

        kind, params = obj.primitive
        try:
            prim = make_primitive(kind, params)
        except InputError as exc:
            raise InputError(f"objects '{obj.name}': {exc.message}") from None
        prep = PreparedObject(obj, np.asarray(prim.mesh.vertices, float), prim.normals,
                              np.asarray(prim.mesh.faces, np.int64))
        if prim.spheres is not None and obj.blocker is not None and obj.blocker.kind == "exact":
            prep.centers, prep.radii = prim.spheres
        return prep, None
    if obj.skin is not None:
        from shtools.geometry.skin import load_skinned_gltf

        model = load_skinned_gltf(obj.mesh)
        v = np.asarray(model.rest_vertices, float)
        f = np.asarray(model.faces, np.int64)
        prep = PreparedObject(obj, v, vertex_normals(v, f), f)
        prep.motion = SkinnedMotion(model, obj.skin.animation, obj.skin.speed, obj.skin.offset)
        return prep, model
    from shtools.geometry.mesh import load_mesh

    mesh = load_mesh(obj.mesh)
    return PreparedObject(obj, np.asarray(mesh.vertices, float),
                          np.asarray(mesh.vertex_normals, float),
                          np.asarray(mesh.faces, np.int64)), None


def _object_blocker(prep: PreparedObject, model, settings, inputs: dict, progress=None,
                    cache=None) -> None:
    """Prepare the object's blocker with its kind (spheres, tree, skin binding, ...)."""
    spec = prep.spec.blocker
    if spec is None:
        return
    BLOCKER_KINDS[spec.kind].prepare(spec, prep, PrepareContext(settings, model, inputs,
                                                                  progress, cache))


def _environment(scene: Scene, inputs: dict, cache=None) -> np.ndarray | None:
    env = scene.environment
    order = scene.settings.order
    if env.kind is None:
        return None
    if env.kind == "coeffs":
        coeffs = env.coeffs
    elif env.kind == "light":
        from shtools.data_formats.light import check_light_window, read_light

        coeffs, attrs = read_light(env.path)
        n = math.isqrt(len(coeffs))
        if n != order:
            raise AssetError(f"light is SH order {n} but the scene's settings.order is {order}; "
                             f"re-project it with --order {order} or change the order", env.path)
        check_light_window(attrs, scene.settings.window, env.path,
                           "the scene's settings.window")
        inputs["environment"] = env.path
    else:
        # the same code path as `shtools light project`; the runtime windows later
        from shtools.lighting.environment import projected_environment

        coeffs = projected_environment(env.path, order, env.rotate, cache)
        inputs["environment"] = env.path
    coeffs = np.asarray(coeffs, dtype=float) * env.intensity
    if env.rotate and env.kind != "image":
        from shtools.sh.rotation import rotate_about_y

        coeffs = rotate_about_y(coeffs, env.rotate)
    return coeffs


def _tables(scene: Scene, inputs: dict) -> dict | None:
    st = scene.settings
    if st.tables is None:
        return None
    from shtools.data_formats.tables import read_tables
    from shtools.runtime import ShadowSettings

    tables = read_tables(st.tables)
    # cap logs are order-specific (an order-8 log truncated is not the order-6 log),
    # so the tables must be built at exactly the order the runtime accumulates at
    want = ShadowSettings(order=st.order, acc_order=st.acc_order).resolved_acc_order()
    if int(tables["order"]) != want:
        raise AssetError(f"tables are SH order {tables['order']} but the scene accumulates at "
                         f"order {want}; rebuild them with 'shtools tables log --order {want}'",
                         st.tables)
    inputs["tables"] = st.tables
    return tables


def scene_files(scene: Scene) -> list[Path]:
    """Every file a bake of ``scene`` reads: the scene itself and each file it names.

    Used to refuse an output path that would overwrite one of them.
    """
    import dataclasses

    # every path-valued setting, object, blocker, environment and light key: a file
    # key added to the scene is covered without a list to keep in step
    files = [scene.path]
    specs = [scene.settings, scene.environment, *scene.lights]
    for obj in scene.objects:
        specs += [obj, obj.blocker]
    for spec in specs:
        if dataclasses.is_dataclass(spec):
            files += [getattr(spec, f.name) for f in dataclasses.fields(spec)]
    return [f for f in files if isinstance(f, Path)]


def prepare_scene(scene: Scene, *, log: Callable[[str], None] | None = None,
                  progress=None, cache=None) -> PreparedScene:
    """Load meshes, blockers, skins, environment and tables of a parsed scene.

    ``progress`` is a progress factory (:mod:`shtools.progress`): one bar over
    the objects, the environment and the tables, plus the bars of sphere fits
    and trees built on the fly.

    ``cache`` is the set-up cache (:class:`shtools.cache.SetupCache`): the
    self-visibility of rigid objects, the local visibility of skinned ones,
    sphere fits, projected environment images and mid-range scaling tables are
    read from it when their inputs were computed before, and stored in it otherwise.  None: the
    environment's default (:meth:`~shtools.cache.SetupCache.from_environment`);
    False: no cache.  The prepared scene is the same either way.

    Raises
    ------
    InputError, AssetError
        A file cannot be used, a skinned glTF has no skin or animation, SH
        orders disagree between assets, a bound set does not match its rig.
    """
    from shtools.cache import SetupCache
    from shtools.progress import silent
    from shtools.scene.midrange import prepare_midrange

    if cache is None:
        cache = SetupCache.from_environment()
    elif cache is False:
        cache = SetupCache(enabled=False)
    inputs: dict[str, Path] = {}
    objects = []
    # steps: every object, then the environment (an HDR is projected here), the tables
    with (progress or silent)(total=len(scene.objects) + 2, desc="bake set-up",
                              unit="steps") as bar:
        for obj in scene.objects:
            if log:
                log(f"loading {obj.name}")
            prep, model = _object_geometry(obj)
            if obj.mesh is not None:
                inputs[f"{obj.name}.mesh"] = obj.mesh
            _object_blocker(prep, model, scene.settings, inputs, progress, cache)
            objects.append(prep)
            bar.update(1)
        _self_visibility(scene, objects, inputs, log, cache)
        env_sh = _environment(scene, inputs, cache)
        bar.update(1)
        tables = _tables(scene, inputs)
        bar.update(1)
    return PreparedScene(scene, objects, env_sh, tables, inputs,
                         prepare_midrange(scene, env_sh, inputs, cache), cache)


def _self_visibility(scene: Scene, objects: list[PreparedObject], inputs: dict, log,
                     cache=None) -> None:
    """Self-visibility logs of role-"both" objects (:mod:`shtools.scene.transfer`)."""
    from shtools.scene.transfer import (
        object_local_log,
        object_self_log,
        uses_local_visibility,
        uses_self_visibility,
        uses_traced_visibility,
    )

    st = scene.settings
    acc = st.resolved_acc_order()
    for prep in objects:
        if uses_self_visibility(prep, st.self_visibility):
            prep.self_log, prep.self_transfer, path = object_self_log(prep, acc, st.order,
                                                                      log=log, cache=cache)
            if path is not None:
                inputs[f"{prep.spec.name}.transfer"] = path
        elif uses_traced_visibility(prep, st.self_visibility):
            prep.traced = True  # every frame, in pose_frame
        elif uses_local_visibility(prep, st.local_visibility):
            if log:
                log(f"ray tracing the local visibility of {prep.spec.name}")
            prep.local_log = object_local_log(prep, acc, cache=cache)
