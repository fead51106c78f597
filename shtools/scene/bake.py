"""The baker: a parsed scene in, per-frame per-vertex radiance out.

:func:`prepare_scene` loads everything a bake needs once (meshes, blocker
spheres and trees — fitted on the fly when the scene asks —, skins, the
environment SH, the log tables) and checks that SH orders agree.
:func:`bake_scene` then poses the scene frame by frame (rigid keyframes, parent
chains, skinning, keyframed lights), evaluates visibility with the chosen method
and shades it, yielding a :class:`FrameResult` per frame and, given ``output``,
streaming the frames into a ``bake`` asset that appears only when every frame
is done.

Methods: ``default`` (the runtime with the scene's exp method), an exp method
name (``hyb``, ``ps*``, ``ps``, ``ol``, ``exact``, ``volterra``; the runtime with
that method), ``product`` (product-space accumulation,
:func:`shtools.reference.product_space_visibility`) and ``raytrace`` (visibility
ray-traced against the posed blocker meshes,
:func:`shtools.reference.raytrace_visibility`).  All shade identically with
:meth:`shtools.runtime.ShadowRuntime.shade`.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from shtools.errors import AssetError, InputError
from shtools.scene.animation import (
    SkinnedMotion,
    light_at,
    transform_normals,
    transform_points,
    transform_spheres,
    vertex_normals,
    world_matrices,
)
from shtools.scene.scene import BAKE_METHODS, ObjectSpec, Scene

EXP_NAMES = ("hyb", "ps*", "ps", "ol", "exact", "volterra")


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
    blockers: list  # list[shtools.runtime.SphereBlocker]
    lights: list  # list[shtools.runtime.SphereLight]
    blocker_meshes: list  # list[(vertices (Vb,3), faces (Fb,3))]


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
    """Fill in the object's blocker spheres, tree and skin binding."""
    spec = prep.spec.blocker
    if spec is None or spec.kind == "exact":
        return
    import trimesh

    if spec.kind == "spheres":
        from shtools.data_formats.spheres import read_spheres

        s = read_spheres(spec.path)
        prep.centers, prep.radii = s.centers, s.radii
        inputs[f"{prep.spec.name}.spheres"] = spec.path
    elif spec.kind == "tree":
        from shtools.data_formats.tree import read_tree

        t = read_tree(spec.path)
        leaves = np.flatnonzero(t.leaf >= 0)
        n = int(t.leaf[leaves].max()) + 1
        centers, radii = np.empty((n, 3)), np.empty(n)
        centers[t.leaf[leaves]] = t.centers[leaves]
        radii[t.leaf[leaves]] = t.radii[leaves]
        prep.centers, prep.radii = centers, radii
        prep.tree = (np.asarray(t.parent), np.asarray(t.leaf))
        inputs[f"{prep.spec.name}.tree"] = spec.path
    elif spec.kind == "bound":
        from shtools.data_formats.bound import read_bound

        b = read_bound(spec.path)
        n_joints = len(model.inverse_bind)
        if b.joint_count != n_joints:
            raise AssetError(f"is bound to a rig with {b.joint_count} joints but "
                             f"'{prep.spec.mesh.name}' has {n_joints}; rebind with "
                             "'shtools spheres bind'", spec.path)
        prep.centers, prep.radii = b.centers, b.radii
        prep.bone_index, prep.bone_vectors = b.bone_index, b.bone_vectors
        inputs[f"{prep.spec.name}.bound"] = spec.path
    else:  # fit on the fly
        from shtools.geometry.sphere_fit import fit_spheres

        mesh = trimesh.Trimesh(prep.vertices, prep.faces, process=False)
        s = fit_spheres(mesh, spec.count, method=spec.method, seed=spec.seed)
        prep.centers, prep.radii = s.centers, s.radii
    if prep.tree is None and settings.hierarchy and len(prep.radii) > 1:
        from shtools.geometry.sphere_tree import build_tree

        branching = spec.branching if spec.kind == "fit" else 4
        t = build_tree(prep.centers, prep.radii, branching=branching, seed=0)
        prep.tree = (np.asarray(t.parent), np.asarray(t.leaf))
    if model is not None and prep.bone_index is None:
        from shtools.geometry.binding import bind_spheres

        binding = bind_spheres(prep.centers, model)
        prep.bone_index = np.asarray(binding.bone_index)
        prep.bone_vectors = np.asarray(binding.bone_vectors)


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
def pose_frame(prepared: PreparedScene, t: float, *, with_meshes: bool = False) -> FrameState:
    """World-space receivers, blocker spheres, lights (and blocker meshes) at time ``t``."""
    from shtools.runtime import SphereBlocker, SphereLight

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
        if o.spec.receives:
            verts.append(world_v)
            norms.append(transform_normals(m, local_n))
        if o.spec.blocks:
            centers = o.centers
            if joints is not None:
                from shtools.runtime.spheres import pose_bound_spheres

                centers = pose_bound_spheres(o.bone_index, o.bone_vectors, joints)
            c, r = transform_spheres(m, centers, o.radii)
            tree = o.tree
            if tree is not None:
                # the runtime refits inner spheres from the leaves every frame
                blockers.append(SphereBlocker(c, r, tree=tree))
            else:
                blockers.append(SphereBlocker(c, r))
            if with_meshes:
                meshes.append((world_v, o.faces))
    lights = []
    for spec in prepared.scene.lights:
        key = light_at(spec, t)
        lights.append(SphereLight(position=key.position, radius=float(key.radius),
                                  color=key.color))
    return FrameState(np.concatenate(verts), np.concatenate(norms), blockers, lights, meshes)


# --------------------------------------------------------------------------- baking
def parse_frames(text: str | None, n_frames: int, path=None) -> range:
    """``"A:B"`` (half-open, like Python), ``"A:"``, ``":B"`` or ``"A"`` -> range of frames.

    Raises
    ------
    InputError
        Not of that form, empty, or outside ``0..n_frames-1``.
    """
    if text is None or text == "":
        return range(n_frames)
    try:
        if ":" in text:
            a, b = text.split(":", 1)
            start = int(a) if a.strip() else 0
            stop = int(b) if b.strip() else n_frames
        else:
            start = int(text)
            stop = start + 1
    except ValueError:
        raise InputError(f"--frames '{text}' is not A:B, A: or A (frame numbers)", path) from None
    if not 0 <= start < stop <= n_frames:
        raise InputError(f"--frames {text} is outside the scene's frames 0..{n_frames - 1} "
                         "(or empty); A:B is half-open like Python", path)
    return range(start, stop)


def runtime_settings(scene: Scene, method: str, processes: int | None = None):
    """The runtime's :class:`~shtools.runtime.ShadowSettings` for a scene and method.

    ``processes``: processes sharing each frame (None: one per core).
    """
    from shtools.runtime import ShadowSettings

    st = scene.settings
    kwargs = dict(
        order=st.order, acc_order=st.acc_order,
        exp_method=method if method in EXP_NAMES else st.exp_method,
        window=st.window, window_h=st.window_h, theta_max=st.theta_max,
        hierarchy=st.hierarchy, vertices_per_cluster=st.vertices_per_cluster,
        processes=processes,
    )
    if st.theta_min is not None:
        kwargs["theta_min"] = st.theta_min
    return ShadowSettings(**kwargs)


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
        One of ``BAKE_METHODS`` (default the scene's ``settings.method``).
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
    if method not in BAKE_METHODS:
        raise InputError(f"unknown method '{method}'; use one of {', '.join(BAKE_METHODS)}")
    frames = range(scene.settings.frames) if frames is None else frames
    if len(frames) == 0 or frames.start < 0 or frames.stop > scene.settings.frames:
        raise InputError(f"frames {frames.start}:{frames.stop} are outside the scene's frames "
                         f"0..{scene.settings.frames - 1}", scene.path)
    prepared = prepared or prepare_scene(scene)
    st = scene.settings
    runtime = ShadowRuntime(runtime_settings(scene, method, processes), tables=prepared.tables)
    moving = prepared.receivers_move()
    times = scene.frame_times(frames)

    writer = None
    if output is not None:
        writer = _writer(prepared, output, frames, times, method, store_visibility, moving)
        writer.__enter__()
    try:
        clusters = None
        for k, (frame, t) in enumerate(zip(frames, times, strict=True)):
            start = time.perf_counter()
            state = pose_frame(prepared, float(t), with_meshes=(method == "raytrace"))
            setup = 0.0
            if method == "product":
                from shtools.reference import product_space_visibility

                vis = product_space_visibility(state.vertices, state.normals, state.blockers,
                                               st.order, acc_order=st.acc_order)
            elif method == "raytrace":
                vis = _raytrace(state, st.order, raytrace_dirs)
            else:
                if clusters is None:  # one-time setup, not counted as frame time
                    setup = time.perf_counter()
                    clusters = _clusters(prepared, state.vertices)
                    setup = time.perf_counter() - setup
                vis = runtime.visibility(state.vertices, state.normals, state.blockers,
                                         clusters=clusters)
            radiance = runtime.shade(vis, state.vertices, state.normals, prepared.env_sh,
                                     sphere_lights=state.lights)
            result = FrameResult(frame, float(t), np.asarray(radiance, dtype=np.float32),
                                 np.asarray(vis) if store_visibility else None,
                                 state.vertices, state.normals,
                                 time.perf_counter() - start - setup)
            if writer is not None:
                writer.write_frame(k, result.radiance, vertices=state.vertices,
                                   normals=state.normals,
                                   visibility=vis if store_visibility else None)
            yield result
    except BaseException as exc:
        runtime.close()
        if writer is not None:
            writer.__exit__(type(exc), exc, exc.__traceback__)
        raise
    runtime.close()
    if writer is not None:
        writer.__exit__(None, None, None)


def _clusters(prepared: PreparedScene, vertices: np.ndarray):
    """Receiver clusters from the first baked frame, reused for every frame.

    Clusters never mix objects, and the runtime recomputes each cluster's bound
    from the current positions, so rigidly moving and skinned receivers keep
    compact clusters without re-clustering every frame.
    """
    from shtools.runtime.clusters import lloyd_clusters

    groups = np.concatenate([np.full(len(o.vertices), k)
                             for k, o in enumerate(prepared.receivers)])
    return lloyd_clusters(vertices, prepared.scene.settings.vertices_per_cluster, groups=groups)


def _raytrace(state: FrameState, order: int, n_dirs: int | None):
    import trimesh

    from shtools.reference import raytrace_visibility

    if not state.blocker_meshes:  # nothing to hit: visibility is the constant 1
        vis = np.zeros((len(state.vertices), order * order))
        vis[:, 0] = math.sqrt(4 * math.pi)
        return vis
    meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
    kwargs = {} if n_dirs is None else {"n_dirs": n_dirs}
    return raytrace_visibility(state.vertices, state.normals, meshes, order, **kwargs)


def _writer(prepared: PreparedScene, output, frames, times, method, store_visibility, moving):
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
    parameters = {
        "method": method,
        "order": st.order,
        # what the runtime actually used (the scene may leave these to it)
        "acc_order": (resolved.resolved_acc_order() if method not in ("product", "raytrace")
                      else st.acc_order or st.order),
        "exp_method": (resolved.resolved_exp_method() if method not in ("product", "raytrace")
                       else None),
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
) -> dict:
    """Bake ``scene`` into the asset ``output``; returns a summary dict.

    Summary keys: ``frames``, ``vertices``, ``seconds`` (wall, everything),
    ``frame_seconds`` (posing + visibility + shading summed over frames),
    ``setup_seconds`` (loading, fits, tables, clustering, file writes),
    ``vertex_frames_per_second`` (frames x vertices / frame_seconds), ``method``,
    ``output``.  ``processes`` as in :func:`bake_scene`.
    """
    parent = Path(output).parent
    if str(parent) and not parent.is_dir():  # fail before minutes of fitting, not after
        raise AssetError("output folder does not exist; create it first", output)
    start = time.perf_counter()
    prepared = prepare_scene(scene)
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
    }
