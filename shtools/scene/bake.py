"""The baker: a parsed scene in, per-frame per-vertex radiance out.

:func:`prepare_scene` loads everything a bake needs once (meshes, blocker
spheres and trees — fitted on the fly when the scene asks —, skins, the
environment SH, the log tables) and checks that SH orders agree.
:func:`bake_scene` then poses the scene frame by frame (rigid keyframes, parent
chains, skinning, keyframed lights), evaluates visibility with the chosen method
and shades it, yielding a :class:`FrameResult` per frame and, given ``output``,
streaming the frames into a ``bake`` asset that appears only when every frame
is done.

Blockers are prepared and posed by their kind (:mod:`shtools.scene.blockers`);
the frame's visibility comes from the registered visibility method
(``default``, an exp method, ``product``, ``raytrace``) and each light is
shadowed by its registered way (:mod:`shtools.scene.shadows`).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from shtools.data_formats.bake import parse_frames  # noqa: F401  (re-exported)
from shtools.errors import AssetError, InputError
from shtools.scene.animation import (
    SkinnedMotion,
    light_at,
    transform_normals,
    transform_points,
    vertex_normals,
    world_matrices,
)
from shtools.scene.blockers import PrepareContext, blocker_kinds
from shtools.scene.scene import ObjectSpec, Scene
from shtools.scene.shadows import (
    LIGHT_SHADOWS,
    VISIBILITY_METHODS,
    BakeRun,
    bake_method_names,
    shade_frame,
)


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


@dataclass
class FrameState:
    """The posed scene at one frame (world space)."""

    vertices: np.ndarray  # (V, 3)
    normals: np.ndarray  # (V, 3)
    blockers: list  # runtime blockers (SphereBlocker or LogBlocker), one per blocker object
    lights: list  # list[shtools.runtime.SphereLight]
    blocker_meshes: list  # list[(vertices (Vb,3), faces (Fb,3))]
    light_shadows: list = field(default_factory=list)  # the way of each light (by name)


@dataclass
class FrameResult:
    """One baked frame.

    Attributes
    ----------
    frame : int
        Scene frame number.
    time : float
        Scene time, seconds.
    radiance : ndarray, shape (V, 3)
    visibility : ndarray, shape (V, n*n) or None
    vertices, normals : ndarray, shape (V, 3)
    seconds : float
        Wall time of posing + visibility + shading.
    """

    frame: int
    time: float
    radiance: np.ndarray
    visibility: np.ndarray | None
    vertices: np.ndarray
    normals: np.ndarray
    seconds: float


# --------------------------------------------------------------------------- preparation
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


def _object_blocker(prep: PreparedObject, model, settings, inputs: dict) -> None:
    """Prepare the object's blocker with its kind (spheres, tree, skin binding, ...)."""
    spec = prep.spec.blocker
    if spec is None:
        return
    blocker_kinds()[spec.kind].prepare(spec, prep, PrepareContext(settings, model, inputs))


def _environment(scene: Scene, inputs: dict) -> np.ndarray | None:
    env = scene.environment
    order = scene.settings.order
    if env.kind is None:
        return None
    if env.kind == "coeffs":
        coeffs = env.coeffs
    elif env.kind == "light":
        from shtools.data_formats.light import read_light

        coeffs, _ = read_light(env.path)
        n = math.isqrt(len(coeffs))
        if n != order:
            raise AssetError(f"light is SH order {n} but the scene's settings.order is {order}; "
                             f"re-project it with --order {order} or change the order", env.path)
        inputs["environment"] = env.path
    else:
        from shtools.lighting.environment import project_environment

        # the same code path as `shtools light project`; the runtime windows later
        coeffs, _ = project_environment(env.path, order, rotate_y=math.degrees(env.rotate))
        inputs["environment"] = env.path
    coeffs = np.asarray(coeffs, dtype=float) * env.intensity
    if env.rotate and env.kind != "image":
        from shtools.sh import rotate

        c, s = np.cos(env.rotate), np.sin(env.rotate)
        r_y = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        coeffs = rotate(coeffs.T, r_y).T
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
    files = [scene.path, scene.settings.tables, scene.environment.path]
    for obj in scene.objects:
        files.append(obj.mesh)
        if obj.blocker is not None:
            files.append(obj.blocker.path)
    return [Path(f) for f in files if f is not None]


def prepare_scene(scene: Scene, *, log: Callable[[str], None] | None = None) -> PreparedScene:
    """Load meshes, blockers, skins, environment and tables of a parsed scene.

    Raises
    ------
    InputError, AssetError
        A file cannot be used, a skinned glTF has no skin or animation, SH
        orders disagree between assets, a bound set does not match its rig.
    """
    inputs: dict[str, Path] = {}
    objects = []
    for obj in scene.objects:
        if log:
            log(f"loading {obj.name}")
        prep, model = _object_geometry(obj)
        if obj.mesh is not None:
            inputs[f"{obj.name}.mesh"] = obj.mesh
        _object_blocker(prep, model, scene.settings, inputs)
        objects.append(prep)
    return PreparedScene(scene, objects, _environment(scene, inputs), _tables(scene, inputs),
                         inputs)


# --------------------------------------------------------------------------- posing
#: Largest world coordinate a posed vertex may have: the runtime works in float32,
#: whose squares overflow above ~1.8e19.
MAX_COORDINATE = 1e18


def pose_frame(prepared: PreparedScene, t: float, *, with_meshes: bool = False) -> FrameState:
    """World-space receivers, blockers, lights (and blocker meshes) at time ``t``.

    Each blocker object is posed by its kind (:meth:`BlockerKind.pose`).
    """
    from shtools.runtime import SphereLight

    kinds = blocker_kinds()
    worlds = world_matrices(prepared.scene.objects, t)
    verts, norms, blockers, meshes = [], [], [], []
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
        if o.spec.receives:
            verts.append(world_v)
            norms.append(transform_normals(m, local_n))
        if o.spec.blocks:
            blockers.append(kinds[o.spec.blocker.kind].pose(o, m, joints))
            if with_meshes:
                meshes.append((world_v, o.faces))
    lights = []
    for spec in prepared.scene.lights:
        key = light_at(spec, t)
        lights.append(SphereLight(position=key.position, radius=float(key.radius),
                                  color=key.color))
    return FrameState(np.concatenate(verts), np.concatenate(norms), blockers, lights, meshes,
                      [spec.shadows for spec in prepared.scene.lights])


# --------------------------------------------------------------------------- baking
def runtime_settings(scene: Scene, method: str, processes: int | None = None):
    """The runtime's :class:`~shtools.runtime.ShadowSettings` for a scene and method.

    ``processes``: processes sharing each frame (None: one per core).
    """
    st = scene.settings
    exp = VISIBILITY_METHODS[method].exp_method(st) if method in VISIBILITY_METHODS \
        else st.exp_method
    return replace(st.runtime_only(), exp_method=exp, processes=processes)


def bake_scene(
    scene: Scene,
    *,
    frames: range | None = None,
    method: str | None = None,
    store_visibility: bool = False,
    output: str | os.PathLike | None = None,
    prepared: PreparedScene | None = None,
    raytrace_dirs: int | None = None,
    processes: int | None = None,
) -> Iterator[FrameResult]:
    """Bake ``scene`` frame by frame, yielding a :class:`FrameResult` per frame.

    Parameters
    ----------
    scene : Scene
    frames : range, optional
        Scene frame numbers (default all ``settings.frames``).
    method : str, optional
        A registered visibility method (:mod:`shtools.scene.shadows`; default
        the scene's ``settings.method``).
    store_visibility : bool
        Keep the visibility vectors (V, n*n) in the results and the asset.
    output : path-like, optional
        Stream the frames into this ``bake`` asset; it is renamed into place
        only after the last frame, so stopping the generator early, an
        exception or Ctrl-C leave no file.
    prepared : PreparedScene, optional
        Reuse loaded assets (:func:`prepare_scene`).
    raytrace_dirs : int, optional
        Directions per vertex for ``raytrace`` (default: the reference's).
    processes : int, optional
        Processes sharing each frame of the runtime methods (default: one per
        core; see :class:`~shtools.runtime.ShadowSettings`).

    Yields
    ------
    FrameResult
    """
    from shtools.runtime import ShadowRuntime

    method = method or scene.settings.method
    names = bake_method_names()
    if method not in names:
        raise InputError(f"unknown method '{method}'; use one of {', '.join(names)}")
    frames = range(scene.settings.frames) if frames is None else frames
    if len(frames) == 0 or frames.start < 0 or frames.stop > scene.settings.frames:
        raise InputError(f"frames {frames.start}:{frames.stop} are outside the scene's frames "
                         f"0..{scene.settings.frames - 1}", scene.path)
    prepared = prepared or prepare_scene(scene)
    vis_method = VISIBILITY_METHODS[method]
    with_meshes = vis_method.needs_meshes or any(
        LIGHT_SHADOWS[spec.shadows].needs_meshes for spec in scene.lights)
    times = scene.frame_times(frames)
    with ExitStack() as stack:
        runtime = stack.enter_context(
            ShadowRuntime(runtime_settings(scene, method, processes), tables=prepared.tables))
        writer = None
        if output is not None:
            writer = stack.enter_context(
                _writer(prepared, output, frames, times, method, store_visibility,
                        prepared.receivers_move(), runtime.processes))
        run = BakeRun(prepared, runtime, method, raytrace_dirs)
        for k, (frame, t) in enumerate(zip(frames, times, strict=True)):
            start = time.perf_counter()
            state = pose_frame(prepared, float(t), with_meshes=with_meshes)
            vis = vis_method.visibility(run, state)
            setup = run.cache.pop("setup_seconds", 0.0)  # one-time setup, not frame time
            radiance = shade_frame(run, state, vis)
            result = FrameResult(frame, float(t), np.asarray(radiance, dtype=np.float32),
                                 np.asarray(vis) if store_visibility else None,
                                 state.vertices, state.normals,
                                 time.perf_counter() - start - setup)
            if writer is not None:
                writer.write_frame(k, result.radiance, vertices=state.vertices,
                                   normals=state.normals,
                                   visibility=vis if store_visibility else None)
            yield result


def _writer(prepared: PreparedScene, output, frames, times, method, store_visibility, moving,
            processes=None):
    from shtools.data_formats.bake import BakeWriter

    scene = prepared.scene
    st = scene.settings
    faces, offsets, albedo, names = [], [0], [], []
    for o in prepared.receivers:
        faces.append(o.faces + offsets[-1])
        offsets.append(offsets[-1] + len(o.vertices))
        albedo.append(np.broadcast_to(o.spec.albedo, (len(o.vertices), 3)))
        names.append(o.spec.name)
    albedo = np.concatenate(albedo)
    static_v = static_n = None
    if not moving:
        state = pose_frame(prepared, float(times[0]))
        static_v, static_n = state.vertices, state.normals
    resolved = runtime_settings(scene, method)
    uses_runtime = VISIBILITY_METHODS[method].uses_runtime
    parameters = {
        "method": method,
        "order": st.order,
        # what the runtime actually used (the scene may leave these to it)
        "acc_order": (resolved.resolved_acc_order() if uses_runtime
                      else st.acc_order or st.order),
        "exp_method": resolved.resolved_exp_method() if uses_runtime else None,
        "window": st.window,
        "window_h": st.window_h,
        "theta_max": st.theta_max,
        "theta_min": st.theta_min,
        "hierarchy": st.hierarchy,
        "vertices_per_cluster": st.vertices_per_cluster,
        "fps": st.fps,
        "frames": [frames.start, frames.stop],
        "scene": scene.path.name,
    }
    from shtools.scene.light_shadows import light_parameters

    if (lights := light_parameters(scene.lights)) is not None:  # absent: all shexp, as before
        parameters["light_shadows"] = lights
    inputs = {"scene": scene.path, **prepared.inputs}
    return BakeWriter(
        output,
        n_frames=len(frames),
        faces=np.concatenate(faces),
        sh_order=st.order,
        static_vertices=static_v,
        static_normals=static_n,
        n_vertices=offsets[-1],
        visibility_size=st.order ** 2 if store_visibility else None,
        times=times,
        frame_index=np.asarray(list(frames)),
        albedo=None if np.all(albedo == 1.0) else albedo,
        object_offsets=np.asarray(offsets),
        object_names=names,
        parameters=parameters,
        inputs=inputs,
        processes=processes,
        fps=st.fps,
    )


def bake_to_file(
    scene: Scene,
    output: str | os.PathLike,
    *,
    frames: range | None = None,
    method: str | None = None,
    store_visibility: bool = False,
    on_frame: Callable[[FrameResult], None] | None = None,
    processes: int | None = None,
    force: bool = False,
) -> dict:
    """Bake ``scene`` into the asset ``output``; returns a summary dict.

    Summary keys: ``frames``, ``vertices``, ``seconds`` (wall, everything),
    ``frame_seconds`` (posing + visibility + shading summed over frames),
    ``setup_seconds`` (loading, fits, tables, clustering, file writes),
    ``vertex_frames_per_second`` (frames x vertices / frame_seconds), ``method``,
    ``output``, ``processes`` (as given; the bytes do not depend on it).
    ``processes`` as in :func:`bake_scene`; ``force`` bakes past
    :func:`check_bake_size`'s limits.
    """
    parent = Path(output).parent
    if str(parent) and not parent.is_dir():  # fail before minutes of fitting, not after
        raise AssetError("output folder does not exist; create it first", output)
    start = time.perf_counter()
    prepared = prepare_scene(scene)
    frames = range(scene.settings.frames) if frames is None else frames
    if not force:
        check_bake_size(len(frames), prepared.n_vertices, store_visibility,
                        scene.settings.order, scene.path)
    n = 0
    frame_seconds = 0.0
    for result in bake_scene(scene, frames=frames, method=method,
                             store_visibility=store_visibility, output=output,
                             prepared=prepared, processes=processes):
        n += 1
        frame_seconds += result.seconds
        if on_frame is not None:
            on_frame(result)
    end = time.perf_counter()
    V = prepared.n_vertices
    return {
        "frames": n,
        "vertices": V,
        "seconds": round(end - start, 4),
        "frame_seconds": round(frame_seconds, 4),
        "setup_seconds": round(end - start - frame_seconds, 4),
        "vertex_frames_per_second": round(n * V / max(frame_seconds, 1e-9), 1),
        "method": method or scene.settings.method,
        "output": os.fspath(output),
        "processes": processes,
    }


#: Most vertex-frames a bake runs without --force: about half an hour at the
#: 0.5 M vertex-frames/s of a battle-scale frame on 2 cores (README).
MAX_VERTEX_FRAMES = 1_000_000_000
#: Largest bake asset written without --force (uncompressed bound).
MAX_BAKE_BYTES = 16 * 2**30


def check_bake_size(frames: int, vertices: int, store_visibility: bool, order: int,
                    path=None) -> None:
    """Refuse a bake past :data:`MAX_VERTEX_FRAMES` or :data:`MAX_BAKE_BYTES`, with the estimate.

    Raises
    ------
    InputError
        Naming the scene; ``bake --frames A:B`` or ``--force`` are the ways out.
    """
    from shtools.data_formats.bake import bake_size_bound

    work = frames * vertices
    size = bake_size_bound(frames, vertices, visibility_size=order ** 2 if store_visibility
                           else None)
    if work > MAX_VERTEX_FRAMES or size > MAX_BAKE_BYTES:
        raise InputError(
            f"the bake would evaluate {work:,} vertex-frames ({frames:,} frames x {vertices:,} "
            f"vertices, about {work / 5e5 / 3600:,.1f} h at 0.5 M/s) and write up to "
            f"{size / 2**30:,.1f} GiB, above the limits ({MAX_VERTEX_FRAMES:,} vertex-frames, "
            f"{MAX_BAKE_BYTES / 2**30:.0f} GiB); bake a range with --frames A:B or pass --force",
            path)
