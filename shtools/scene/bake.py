"""The baker: a parsed scene in, per-frame per-vertex radiance out.

Three jobs, one module each: :func:`~shtools.scene.prepare.prepare_scene`
(:mod:`shtools.scene.prepare`) loads everything a bake needs once (meshes, blocker
spheres and trees — fitted on the fly when the scene asks —, skins, the
environment SH, the log tables) and checks that SH orders agree;
:func:`~shtools.scene.pose.pose_frame` (:mod:`shtools.scene.pose`) poses it at a
time (rigid keyframes, parent chains, skinning, keyframed lights);
:func:`bake_scene` (here) runs the frames: it evaluates visibility with the chosen method
and shades it, yielding a :class:`FrameResult` per frame and, given ``output``,
streaming the frames into a ``bake`` asset that appears only when every frame
is done.

Blockers are prepared and posed by their kind (:mod:`shtools.scene.blockers`);
the frame's visibility comes from the registered visibility method
(``default``, an exp method, ``product``, ``raytrace``) and each light is
shadowed by its registered way (:mod:`shtools.scene.shadows`).
"""

from __future__ import annotations

import itertools
import os
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from shtools.errors import AssetError, InputError
from shtools.scene.kinds import LIGHT_SHADOWS, VISIBILITY_METHODS, bake_method_names
from shtools.scene.pose import FrameState, pose_frame
from shtools.scene.prepare import PreparedObject, PreparedScene, prepare_scene, scene_files
from shtools.scene.scene import Scene
from shtools.scene.shadows import BakeRun, shade_frame, visibility_needed

#: the three jobs' public names, importable from here as before the split
__all__ = ["FrameResult", "FrameState", "PreparedObject", "PreparedScene", "bake_scene",
           "bake_to_file", "check_bake_size", "parse_frames", "pose_frame", "prepare_scene",
           "runtime_settings", "scene_files"]


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


def runtime_settings(scene: Scene, method: str, processes: int | None = None):
    """The runtime's :class:`~shtools.runtime.ShadowSettings` for a scene and method.

    ``processes``: processes sharing each frame (None: one per core).
    """
    st = scene.settings
    exp = VISIBILITY_METHODS[method].exp_method(st) if method in VISIBILITY_METHODS \
        else st.exp_method
    return replace(st.runtime_only(), exp_method=exp, processes=processes)


class FrameBaker:
    """Evaluates posed frames of a prepared scene; one per process that bakes frames.

    Holds the runtime (and its worker processes) and the per-bake state of the
    visibility method.  The receiver clusters are fixed up front (from the
    scene's frame 0) so every process evaluates a frame identically,
    whichever frames it is given: a bake is the same bytes on one process,
    a local pool or a Dask cluster.

    Parameters
    ----------
    prepared : PreparedScene
    method : str
        A registered visibility method.
    clusters : ndarray or None
        Receiver clusters of the runtime methods (:func:`bake_clusters`).
    raytrace_dirs : int, optional
    processes : int, optional
        Processes the runtime shares each frame over (1: this process only).
    store_visibility : bool
    part_pool : shtools.tasks.TaskPool, optional
        Run each large frame's parts as tasks of this pool (a Dask cluster)
        instead of on local worker processes (:class:`~shtools.runtime.ShadowRuntime`).
    """

    def __init__(self, prepared: PreparedScene, method: str, clusters=None, *,
                 raytrace_dirs: int | None = None, processes: int | None = None,
                 store_visibility: bool = False, part_pool=None):
        from shtools.runtime import ShadowRuntime

        scene = prepared.scene
        self.method = VISIBILITY_METHODS[method]
        self.with_meshes = self.method.needs_meshes or any(
            LIGHT_SHADOWS[spec.shadows].needs_meshes for spec in scene.lights)
        self.store_visibility = store_visibility
        #: False: no environment and only lights shadowed without the SH visibility
        #: (ssoc, raytrace): the frames evaluate no visibility (shadows.visibility_needed)
        self.needs_visibility = visibility_needed(prepared, store_visibility)
        self.runtime = ShadowRuntime(runtime_settings(scene, method, processes),
                                     tables=prepared.tables, part_pool=part_pool)
        self.run = BakeRun(prepared, self.runtime, method, raytrace_dirs)
        if clusters is not None:
            self.run.cache["clusters"] = clusters

    def close(self) -> None:
        """Stop the runtime's worker processes."""
        self.runtime.close()

    def __enter__(self) -> FrameBaker:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def frame(self, frame: int, t: float) -> FrameResult:
        """Pose, shadow and shade scene frame ``frame`` at time ``t``."""
        start = time.perf_counter()
        # the traced shadows and self-visibilities of a frame only feed its visibility
        # a stored visibility is relit under other skies: it may not depend on this one
        state = pose_frame(self.run.prepared, float(t), with_meshes=self.with_meshes,
                           trace=self.needs_visibility, clusters=self.run.cache.get("clusters"),
                           sky_gain=not self.store_visibility)
        vis = self.method.visibility(self.run, state) if self.needs_visibility else None
        setup = self.run.cache.pop("setup_seconds", 0.0)  # one-time setup, not frame time
        radiance = shade_frame(self.run, state, vis)
        return FrameResult(frame, float(t), np.asarray(radiance, dtype=np.float32),
                           np.asarray(vis) if self.store_visibility else None,
                           state.vertices, state.normals,
                           time.perf_counter() - start - setup)


def bake_clusters(prepared: PreparedScene, method: str, t: float):
    """Receiver clusters of a runtime method, from the scene posed at time ``t``; else None."""
    from shtools.scene.shadows import receiver_clusters

    if not VISIBILITY_METHODS[method].uses_runtime:
        return None
    state = pose_frame(prepared, float(t), trace=False)  # only the vertices are used
    return receiver_clusters(prepared, state.vertices)


@dataclass
class _FrameJob:
    """What every frame task shares: the prepared scene and how to bake it."""

    prepared: PreparedScene
    method: str
    clusters: Any
    raytrace_dirs: int | None
    store_visibility: bool
    moving: bool  # receivers move: each frame's vertices and normals go to the asset
    token: str  # tells one bake's job from another's in a long-lived worker


#: Per-process FrameBaker of the current job (a worker keeps one across its tasks).
_WORKER_BAKER: dict[str, FrameBaker] = {}


def _worker_baker(job: _FrameJob) -> FrameBaker:
    """This worker's FrameBaker of ``job`` (built once: the pool's per-worker set-up)."""
    baker = _WORKER_BAKER.get(job.token)
    if baker is None:
        for old in _WORKER_BAKER.values():
            old.close()
        _WORKER_BAKER.clear()
        baker = _WORKER_BAKER[job.token] = FrameBaker(
            job.prepared, job.method, job.clusters, raytrace_dirs=job.raytrace_dirs,
            processes=1, store_visibility=job.store_visibility)
    return baker


def _bake_frames_task(job: _FrameJob, items: list[tuple[int, float]]) -> list[FrameResult]:
    """Task body: consecutive frames on a worker (one process per frame: ``processes=1``).

    Only what the asset stores travels back, in the dtype it stores it (float32):
    radiance, the visibility when kept, and vertices and normals only when the
    receivers move (the caller fills in the static pose).  For the 65k-vertex
    battle scene that is 0.8 MB a frame instead of 3.9 MB.
    """
    results = [_worker_baker(job).frame(*item) for item in items]
    for result in results:
        if job.moving:
            result.vertices = result.vertices.astype(np.float32)
            result.normals = result.normals.astype(np.float32)
        else:
            result.vertices = result.normals = None
        if result.visibility is not None:
            result.visibility = np.asarray(result.visibility, dtype=np.float32)
    return results


#: Most frames one Dask task bakes: a task of a few frames (about a second for a
#: battle frame) spreads Dask's fixed cost per task (scheduling, messages, the
#: hand-over of the result) over them, as Dask's own guidance on task sizes asks.
MAX_FRAMES_PER_TASK = 4
#: Tasks per worker at least, before frames are grouped: keeps the load balanced
#: at the end of a bake and a dead worker's rerun short.
MIN_TASKS_PER_WORKER = 8


def frames_per_task(scheduler: str, frames: int, workers: int) -> int:
    """Frames one task bakes: 1 on local pools, up to :data:`MAX_FRAMES_PER_TASK` on Dask
    while every worker still gets :data:`MIN_TASKS_PER_WORKER` tasks."""
    if scheduler != "dask":
        return 1  # a local pool's cost per task is a pickle through a pipe
    return max(1, min(MAX_FRAMES_PER_TASK, frames // (MIN_TASKS_PER_WORKER * workers)))


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
    scheduler: str | None = None,
    workers: int | None = None,
    pool_summary: dict | None = None,
    split_frames: bool | None = None,
) -> Iterator[FrameResult]:
    """Bake ``scene`` frame by frame, yielding a :class:`FrameResult` per frame.

    Frames are independent tasks (:mod:`shtools.tasks`): with several frames
    and cores they are spread over local worker processes by default, or over a
    Dask cluster (``scheduler``; a task bakes up to :data:`MAX_FRAMES_PER_TASK`
    consecutive frames when there are many, :func:`frames_per_task`); results
    are yielded and written in frame order by this process, the one writer,
    and the asset is the same bytes whichever way it was computed.

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
        Processes sharing each frame of the runtime methods when frames are
        evaluated in this process (one frame, or ``workers=1``); default one
        per core (see :class:`~shtools.runtime.ShadowSettings`).
    scheduler : str, optional
        Where frames run: None (local cores), ``"inline"``, ``"local"`` (a Dask
        LocalCluster), ``"tcp://HOST:PORT"`` or a scheduler file
        (:func:`shtools.tasks.task_pool`).
    workers : int, optional
        Local workers (default: the usable cores).
    pool_summary : dict, optional
        Filled with the scheduler's per-worker task counts and times.
    split_frames : bool, optional
        On Dask: evaluate the frames one after the other in this process and
        run each large frame's parts (:data:`shtools.runtime.parallel.FRAME_PARTS`
        groups of receiver clusters) as tasks on the cluster, for a bake of one
        huge frame or of fewer frames than workers.  Default: when there are
        fewer frames than workers and than parts (a frame's 8 parts then keep
        more workers busy than the frames would).  The bytes are the same
        either way.

    Yields
    ------
    FrameResult
        From Dask or local workers, moving receivers' ``vertices`` and
        ``normals`` are float32 (what the asset stores; float64 otherwise).
    """
    from shtools.tasks import task_pool

    method = method or scene.settings.method
    names = bake_method_names()
    if method not in names:
        raise InputError(f"unknown method '{method}'; use one of {', '.join(names)}")
    frames = range(scene.settings.frames) if frames is None else frames
    if len(frames) == 0 or frames.start < 0 or frames.stop > scene.settings.frames:
        raise InputError(f"frames {frames.start}:{frames.stop} are outside the scene's frames "
                         f"0..{scene.settings.frames - 1}", scene.path)
    prepared = prepared or prepare_scene(scene)
    times = scene.frame_times(frames)
    with ExitStack() as stack:
        pool = stack.enter_context(task_pool(scheduler, workers, n_tasks=len(frames)))
        writer = None
        if output is not None:
            writer = stack.enter_context(
                _writer(prepared, output, frames, times, method, store_visibility,
                        prepared.receivers_move()))
        # Clusters from the scene's frame 0, whatever range is baked: a partial
        # bake (--frames 2:4) gives the same values as those frames of a full one.
        # (none when the frames evaluate no visibility: nothing shades through it)
        clusters = (bake_clusters(prepared, method, 0.0)
                    if visibility_needed(prepared, store_visibility) else None)
        items = [(int(f), float(t)) for f, t in zip(frames, times, strict=True)]
        if split_frames is None:  # few frames for a cluster: share each frame instead
            from shtools.runtime.parallel import FRAME_PARTS

            split_frames = len(frames) < min(pool.workers, FRAME_PARTS)
        parts_on_pool = bool(split_frames) and pool.scheduler == "dask"
        if pool.scheduler == "inline" or parts_on_pool:
            # Frames one after the other here; on Dask with split_frames, each
            # large frame's parts are tasks on the cluster.
            start = time.perf_counter()
            baker = stack.enter_context(FrameBaker(
                prepared, method, clusters, raytrace_dirs=raytrace_dirs,
                processes=1 if parts_on_pool else processes, store_visibility=store_visibility,
                part_pool=pool if parts_on_pool else None))
            pool.setup_seconds += time.perf_counter() - start
            results = (baker.frame(*item) for item in items)
        else:
            import uuid

            moving = prepared.receivers_move()
            job = _FrameJob(prepared, method, clusters, raytrace_dirs, store_visibility,
                            moving, uuid.uuid4().hex)
            k = frames_per_task(pool.scheduler, len(items), pool.workers)
            groups = [items[i:i + k] for i in range(0, len(items), k)]
            results = itertools.chain.from_iterable(
                pool.map_ordered(_bake_frames_task, groups, shared=job, setup=_worker_baker))
            if not moving:  # the workers send no static pose back (see _bake_frames_task)
                results = _with_pose(results, pose_frame(prepared, float(times[0]), trace=False))
        for k, result in enumerate(results):
            if writer is not None:
                writer.write_frame(k, result.radiance, vertices=result.vertices,
                                   normals=result.normals, visibility=result.visibility)
            yield result
        if pool_summary is not None:
            pool_summary.update(pool.summary())


def _with_pose(results: Iterator[FrameResult], state: FrameState) -> Iterator[FrameResult]:
    """``results`` with the static receivers' vertices and normals filled in."""
    for result in results:
        result.vertices, result.normals = state.vertices, state.normals
        yield result


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
        state = pose_frame(prepared, float(times[0]), trace=False)
        static_v, static_n = state.vertices, state.normals
    resolved = runtime_settings(scene, method)
    uses_runtime = VISIBILITY_METHODS[method].uses_runtime
    parameters = {
        "method": method,
        "order": st.order,
        # what the runtime actually used (the scene may leave these to it)
        "acc_order": VISIBILITY_METHODS[method].acc_order(resolved) or st.order,
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
    if st.cluster_blend:  # absent when 0: a bake without a blend keeps its bytes
        parameters["cluster_blend"] = st.cluster_blend
    from shtools.runtime.settings import ShadowSettings

    if st.deringing != ShadowSettings.deringing:  # absent: the default; relighting reads it
        parameters["deringing"] = st.deringing
    from shtools.runtime.haar import HaarField

    if haar := [o.spec.name for o in prepared.objects if isinstance(o.blocker_data, HaarField)]:
        parameters["all_frequency_blockers"] = haar  # absent: none; relighting refuses them
    if (sphere := prepared.midrange) is not None:  # absent: at infinity; relighting reads it
        scaling = scene.environment.scaling
        parameters["environment_sphere"] = {
            "center": [float(c) for c in sphere.center], "radius": sphere.radius,
            "scaling": None if scaling is None else Path(scaling).name}
    inputs = {"scene": scene.path, **prepared.inputs}
    from shtools.scene.light_record import scene_pose_table

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
        light_poses=scene_pose_table(scene, times),  # relighting reads them (--lights)
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
    scheduler: str | None = None,
    workers: int | None = None,
    progress=None,
    split_frames: bool | None = None,
    cache=None,
) -> dict:
    """Bake ``scene`` into the asset ``output``; returns a summary dict.

    Summary keys: ``frames``, ``vertices``, ``seconds`` (wall, everything),
    ``frame_seconds`` (posing + visibility + shading summed over frames, in
    whichever process ran them), ``setup_seconds`` (wall time of loading, fits,
    tables, clustering and pool start-up before the first frame: the rest of the
    wall time is the frames and their writes), ``vertex_frames_per_second``
    (frames x vertices per wall second after the set-up), ``method``,
    ``output``, ``pool`` (scheduler, workers, per-worker task counts and
    seconds), ``cache`` (the set-up cache's location, ``enabled``, ``hits`` and
    ``misses``; :mod:`shtools.cache`).  ``cache`` is the
    :class:`~shtools.cache.SetupCache` (None: the environment's default, False:
    none; the asset is the same bytes either way).  ``processes``, ``scheduler``,
    ``workers`` and ``split_frames`` as in :func:`bake_scene`; ``progress`` a progress factory
    (:mod:`shtools.progress`) for the set-up and the frames; ``force`` bakes past
    :func:`check_bake_size`'s limits.
    """
    from shtools.progress import silent

    parent = Path(output).parent
    if str(parent) and not parent.is_dir():  # fail before minutes of fitting, not after
        raise AssetError("output folder does not exist; create it first", output)
    start = time.perf_counter()
    prepared = prepare_scene(scene, progress=progress, cache=cache)
    frames = range(scene.settings.frames) if frames is None else frames
    if not force:
        check_bake_size(len(frames), prepared.n_vertices, store_visibility,
                        scene.settings.order, scene.path)
    n = 0
    frame_seconds = 0.0
    first = None  # wall time when the first frame arrived (frames may run in parallel)
    pool: dict = {}
    total = len(frames) if frames is not None else scene.settings.frames
    with (progress or silent)(total=total, desc="bake", unit="frames") as bar:
        for result in bake_scene(scene, frames=frames, method=method,
                                 store_visibility=store_visibility, output=output,
                                 prepared=prepared, processes=processes, scheduler=scheduler,
                                 workers=workers, pool_summary=pool,
                                 split_frames=split_frames):
            n += 1
            frame_seconds += result.seconds
            if first is None:
                first = time.perf_counter() - result.seconds
            bar.update(1)
            if on_frame is not None:
                on_frame(result)
    end = time.perf_counter()
    V = prepared.n_vertices
    return {
        "frames": n,
        "vertices": V,
        "seconds": round(end - start, 4),
        "frame_seconds": round(frame_seconds, 4),
        "setup_seconds": round((first or end) - start, 4),
        "vertex_frames_per_second": round(n * V / max(end - (first or end), 1e-9), 1),
        "method": method or scene.settings.method,
        "output": os.fspath(output),
        "pool": pool,
        "cache": prepared.cache.summary(),
        # not stored in the asset: its bytes must not depend on how it was computed
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
