"""Relighting a bake without re-baking it: the stored visibility shaded under another light.

A bake made with ``--store-visibility`` keeps each vertex's SH visibility
``g`` per frame.  Outgoing radiance is the triple product of the clamped
cosine, the light and ``g`` (SHEXP Sec. 7; Sloan et al. 2002, "Precomputed
Radiance Transfer", Sec. 4 — keeping visibility in SH is what makes a new
light cheap), so a new environment, optionally turned about +Y by an SH
rotation, needs no posing, no blockers and no exponential.  Frames are shaded
by :func:`~shtools.runtime.shading.shade`, the call the runtime's
:meth:`~shtools.runtime.ShadowRuntime.shade` makes for the baker's
:func:`~shtools.scene.shadows.shade_frame` (the environment and the ``shexp``
lights; for vertices that never move, through its linear map in ``g``,
:func:`~shtools.runtime.shading.shading_matrix`; :func:`relight_frames`), so
the result is the radiance a fresh bake of the same scene under that light
gives, to float32 rounding.

Spherical lights (a scene's ``[[lights]]``, posed at each frame's time) are
shaded through the same stored visibility, the baker's ``shexp`` way; the
other ways (SSOC, ray tracing) need the posed blocker meshes, which a bake
does not keep.  A bake records its lights, so the lights of the scene it was
baked from are read from it, and the scene parser is imported only for
another scene or an older bake (:mod:`shtools.scene.light_record`).  A bake lit
from a finite environment sphere (mid-range lighting, Wang et al. 2005, Sec.
3.2) records it, and the new light is put on that sphere
(:func:`relight_midrange`).

Frames stream from the open bake a batch at a time
(:func:`~shtools.data_formats.bake_stream.open_bake`), so memory is set by the
vertex count, not the frame count (:func:`relight_bytes`); the per-frame
geometry is copied into the output as stored, and the visibility too when asked
(``keep_visibility``: to relight the output again).

From Python::

    from shtools.scene.relight import relight
    relight("baked.h5", "studio.h5", "relit.h5", rotate=90.0, scene="scene.toml")
"""

from __future__ import annotations

import itertools
import math
import os
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from shtools.errors import AssetError, InputError


def relight_settings(bake):
    """The runtime settings a bake was shaded with (order, window, de-ringing).

    Parameters
    ----------
    bake : shtools.data_formats.bake.Bake

    Returns
    -------
    shtools.runtime.ShadowSettings
    """
    from shtools.runtime import ShadowSettings

    params = bake.parameters
    defaults = ShadowSettings()
    return ShadowSettings(order=bake.sh_order,
                          window=params.get("window", defaults.window),
                          window_h=params.get("window_h", defaults.window_h),
                          deringing=params.get("deringing", defaults.deringing),
                          processes=1)


def relight_environment(light: str | os.PathLike, order: int, window, rotate: float = 0.0,
                        inputs: dict | None = None) -> np.ndarray:
    """A light asset as a bake would load it as ``[environment] light``, turned ``rotate`` degrees.

    The baker's checks (a light windowed twice,
    :func:`~shtools.data_formats.light.check_light_window`) and its SH
    rotation about +Y (:func:`~shtools.sh.rotation.rotate_about_y`), without
    the scene parser.

    Parameters
    ----------
    light : path-like
        A ``light`` asset of SH order ``order``.
    order : int
        The bake's SH order.
    window : str or None
        The bake's ``window`` setting.
    rotate : float
        Degrees about +Y (the scene key ``rotate_deg``).
    inputs : dict, optional
        Filled with ``{"environment": path}`` for provenance.

    Returns
    -------
    ndarray, shape (n*n, 3)

    Raises
    ------
    AssetError
        Not a light asset, another SH order, or windowed twice.
    """
    from shtools.data_formats.light import check_light_window, read_light

    coeffs, attrs = read_light(light)
    n = math.isqrt(len(coeffs))
    if n != order:
        raise AssetError(f"light is SH order {n} but the bake is order {order}; re-project it "
                         f"with 'shtools light project --order {order}'", light)
    check_light_window(attrs, window, light, "the bake's window")
    if inputs is not None:
        inputs["environment"] = light
    coeffs = np.asarray(coeffs, dtype=float)
    if rotate:
        from shtools.sh.rotation import rotate_about_y

        coeffs = rotate_about_y(coeffs, math.radians(float(rotate)))
    return coeffs


def relight_midrange(bake, env_sh: np.ndarray):
    """``env_sh`` on the finite environment sphere the bake was lit from, or None.

    A bake under a mid-range environment (Wang et al. 2005, Sec. 3.2)
    records its sphere (``parameters.environment_sphere``); the new light is
    put on that sphere, with the plain mid-range scaling table a bake of a
    ``light`` asset builds (:func:`shtools.scene.midrange.prepare_midrange`).
    A bake that records no sphere was lit from infinity.

    Parameters
    ----------
    bake : shtools.data_formats.bake.Bake
    env_sh : ndarray, shape (n*n, 3)
        The new light (:func:`relight_environment`).

    Returns
    -------
    shtools.scene.midrange.MidrangeEnvironment or None

    Raises
    ------
    InputError
        The sphere was scaled with a table asset of its own, which a bake does
        not keep.
    """
    sphere = bake.parameters.get("environment_sphere")
    if sphere is None:
        return None
    if sphere.get("scaling") is not None:
        raise InputError(f"was lit from a finite environment sphere scaled by the table "
                         f"'{sphere['scaling']}', which a bake does not keep; bake the scene "
                         "with the new light instead of relighting it", bake.path)
    from shtools.runtime.scaling import ScalingTable
    from shtools.scene.midrange import MidrangeEnvironment, _scaling_table

    return MidrangeEnvironment(np.asarray(sphere["center"], dtype=float),
                               float(sphere["radius"]),
                               ScalingTable(_scaling_table(bake.sh_order)),
                               np.asarray(env_sh, dtype=float), bake.sh_order, bake.path)


def relight_frames(bake, env_sh, scene=None, settings=None, threads: int | None = None,
                   midrange=None):
    """Radiance of every frame of ``bake`` under ``env_sh`` (and ``scene``'s lights).

    Shading is linear in the visibility ``g`` before de-ringing: a vertex whose
    position, normal and lights do not change over the bake has radiance
    ``K g`` with a fixed ``K (3, n*n)`` -- for the environment ``K = M(L) H``,
    the light's product matrix applied to the cosine lobe (Sloan et al. 2002,
    Sec. 4), plus the spherical lights' lobes.  ``K`` is made once, the linear
    map of the runtime shading the baker uses
    (:func:`~shtools.runtime.shading.shading_matrix`), so these vertices cost
    one float32 product per batch of frames; the others are shaded as the
    baker shades them (a batch of frames in one call while the lights do not
    change).  Frames are read from the bake a batch at a time: a batch holds
    at most :data:`BATCH_ROWS` receiver rows, and at most ``2 * threads``
    batches are in flight, so memory does not grow with the frame count
    (:func:`relight_bytes`).  De-ringing (``settings.deringing``) follows, as
    in the runtime's ``shade``.

    Parameters
    ----------
    bake : shtools.data_formats.bake.Bake
        With stored visibility: arrays (:func:`~shtools.data_formats.bake.read_bake`)
        or the open datasets of :func:`~shtools.data_formats.bake_stream.open_bake`.
    env_sh : ndarray, shape (n*n, 3) or None
        Distant environment (:func:`relight_environment`).
    scene : shtools.scene.scene.Scene or shtools.scene.light_record.PosedLights, optional
        Its spherical lights, posed at each frame's time, are shaded through the
        stored visibility (:func:`~shtools.scene.light_record.frame_lights`).
    settings : shtools.runtime.ShadowSettings, optional
        Default :func:`relight_settings` of the bake.
    threads : int, optional
        Threads sharing the work (NumPy releases the GIL in its array loops),
        each with its own runtime; default one per usable core.
    midrange : shtools.scene.midrange.MidrangeEnvironment, optional
        ``env_sh`` on the finite sphere the bake recorded
        (:func:`relight_midrange`).

    Yields
    ------
    ndarray, shape (V, 3) float32
        Frame by frame, in the bake's order.
    """
    from concurrent.futures import ThreadPoolExecutor

    from shtools.data_formats.bake_stream import check_finite
    from shtools.runtime.shading import desaturate_negative
    from shtools.scene.light_record import frame_lights
    from shtools.tasks import default_workers

    check_relightable(bake)
    settings = settings or relight_settings(bake)
    threads = max(1, threads or default_workers())
    lights = frame_lights(bake, scene)
    same = _same_lights(lights)
    # under the same lights, several frames go in one batch: their moving rows in one
    # shading call, their still rows in one product with K
    batch = max(1, BATCH_ROWS // bake.n_vertices) if same else 1
    still, held = _fixed_rows(bake, batch) if same else (np.zeros(bake.n_vertices, bool), None)
    fixed, moving = np.flatnonzero(still), np.flatnonzero(~still)  # indices: faster to gather
    # the still rows as runs (whole still objects): slices, not gathers, when they are few
    runs = _runs(still)
    runs = runs if len(runs) <= MAX_RUNS else [(fixed, 0, fixed.size)]
    batches = [range(a, min(a + batch, bake.n_frames)) for a in range(0, bake.n_frames, batch)]
    shaders = _Shaders(env_sh, settings, midrange)
    path = bake.path

    def linear_part(rows):
        return shaders.linear(_state(bake, range(1), rows, lights[0]))

    def frames_of(frames, K):
        """The finished frames ``frames`` (float32 ``(len, V, 3)``)."""
        out = np.empty((len(frames), bake.n_vertices, 3))
        vis = check_finite(np.asarray(bake.visibility[frames.start:frames.stop]),
                           "visibility", path)
        if moving.size:
            g = vis[:, moving].reshape(-1, vis.shape[2])
            state = (_state(bake, frames, moving, lights[frames.start]) if held is None
                     else _state(held, frames, slice(None), lights[frames.start]))
            shaded = shaders.shade(state, g)
            out[:, moving] = shaded.reshape(len(frames), moving.size, 3)
        if K is not None:  # every frame of the batch in one float32 product, as the
            # baker dots its float32 lit transfer with the visibility
            # (F, T, n*n) @ (F, n*n, 3): one small product per vertex, batched
            for rows, k, z in runs:
                out[:, rows] = np.matmul(vis[:, rows].transpose(1, 0, 2),
                                         K[k:z]).transpose(1, 0, 2)
        if settings.deringing == "desaturate":  # as ShadowRuntime.shade de-rings
            # colours without a negative channel are left as they are by it
            flat = out.reshape(-1, 3)
            low = np.minimum(np.minimum(flat[:, 0], flat[:, 1]), flat[:, 2])
            neg = np.flatnonzero(low < 0.0)
            flat[neg] = desaturate_negative(flat[neg])
        return out.astype(np.float32)

    with ThreadPoolExecutor(threads, thread_name_prefix="relight") as pool:
        K = None
        if fixed.size:  # parts of PART_ROWS rows, whatever the threads: a row's float32
            # products sum in an order that may depend on the rows beside it (row_matmul)
            parts = [fixed[a:a + PART_ROWS] for a in range(0, fixed.size, PART_ROWS)]
            K = np.concatenate(list(pool.map(linear_part, [p for p in parts if p.size])))
            K = np.ascontiguousarray(K.transpose(0, 2, 1))  # (F, n*n, 3) for the product
        window = 2 * threads  # batches in flight: bounded memory, every thread busy
        pending = [pool.submit(frames_of, frames, K) for frames in batches[:window]]
        for i in range(len(batches)):
            done = pending.pop(0).result()
            if i + window < len(batches):
                pending.append(pool.submit(frames_of, batches[i + window], K))
            yield from done


def _runs(mask: np.ndarray) -> list[tuple[slice, int, int]]:
    """The runs of True in ``mask (V,)``: ``(rows, k, z)``, the rows as a slice and their
    positions ``k:z`` among the True rows."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    runs, k = [], 0
    for a, z in zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True):
        runs.append((slice(a, z), k, k + z - a))
        k += z - a
    return runs


#: Most runs of still rows taken as slices; more are gathered by index at once.
MAX_RUNS = 64

#: Most receiver rows (vertices x frames) of one batch of frames under unchanging
#: lights; its visibility, shading scratch and radiance grow with it.
BATCH_ROWS = 1 << 16
#: Still rows per part of their one-time shading table (the threads share the parts;
#: bounded shading scratch).
PART_ROWS = 1 << 13


def relight_bytes(n_frames: int, n_vertices: int, size: int, threads: int) -> int:
    """Peak working memory of :func:`relight_frames`, bytes: the fixed ``K``, the
    geometry held and the batches in flight (a frame count of its own does not add
    to it).

    Parameters
    ----------
    n_frames, n_vertices : int
    size : int
        ``n*n``.
    threads : int
    """
    batch = max(1, BATCH_ROWS // n_vertices) * n_vertices  # receiver rows of one batch
    # float32 visibility as read, gathered, windowed and its products in the shading
    # (6 copies); float64 radiance, scratch and geometry
    per_row = 4 * size * 6 + 8 * 3 * 3 + 8 * 6
    K = n_vertices * 3 * size * 4  # float32
    return int(K + GEOMETRY_BYTES + 2 * threads * batch * per_row + 2 * batch * (4 * 3 + 4 * 6))


class _Shaders:
    """The baker's shading of stored visibility, without de-ringing (applied to each
    whole frame after): :func:`~shtools.runtime.shading.shade` with the lit transfer of
    the environment, the call :meth:`~shtools.runtime.ShadowRuntime.shade` makes, and
    its linear map :func:`~shtools.runtime.shading.shading_matrix`.  Thread-safe: the
    mid-range sphere, which caches the last vertices' radiance SH, is one per thread."""

    def __init__(self, env_sh, settings, midrange=None):
        import threading

        from shtools.runtime.shading import environment_matrices

        self.env_sh, self.midrange, self.order = env_sh, midrange, settings.order
        self.window = {"window_kind": settings.resolved_window(),
                       "window_h": settings.window_h}
        # the environment's product matrices once (the runtime keeps them while the
        # light does not change); a finite sphere's light is per vertex
        self.mats = (environment_matrices(env_sh, self.order, **self.window)
                     if env_sh is not None and midrange is None else None)
        self.local = threading.local()

    def _receivers(self, state):
        """Checked float64 positions and unit normals, and the environment at them."""
        from shtools.runtime.blockers import check_receivers

        pts, nrm = check_receivers(state.vertices, state.normals)
        if self.midrange is None:
            return pts, nrm, self.env_sh
        sphere = getattr(self.local, "sphere", None)
        if sphere is None:
            sphere = self.local.sphere = replace(self.midrange, _cache={})
        return pts, nrm, sphere.radiance_sh(pts)

    def shade(self, state, visibility) -> np.ndarray:
        """Radiance ``(R, 3)`` of ``state``'s rows (before de-ringing).

        What :func:`~shtools.scene.shadows.shade_frame` computes for a frame
        without blockers whose lights are all ``shexp``: the environment (per
        vertex on a finite sphere) and the lights through the visibility.
        """
        from shtools.runtime.shading import cosine_transfer, lit_transfer, shade

        pts, nrm, env = self._receivers(state)
        transfer = cosine_transfer(nrm, self.order)
        return shade(visibility, pts, nrm, env, tuple(state.lights), order=self.order,
                     transfer=transfer,
                     env_transfer=None if self.mats is None else lit_transfer(transfer,
                                                                              self.mats),
                     **self.window)

    def linear(self, state) -> np.ndarray:
        """``K (R, 3, n*n)`` float32: :meth:`shade` of ``state``'s rows is ``K g``."""
        from shtools.runtime.shading import shading_matrix

        pts, nrm, env = self._receivers(state)
        return shading_matrix(pts, nrm, env, tuple(state.lights), order=self.order,
                              **self.window)


def _state(bake, frames: range, rows, lights) -> SimpleNamespace:
    """Rows ``rows`` of asset frames ``frames`` (consecutive), stacked: ``vertices`` and
    ``normals`` ``(R, 3)`` float64 and the frame's posed ``lights``.  ``bake`` has
    ``vertices`` and ``normals``, ``(V, 3)`` or ``(T, V, 3)``, and a ``path`` when they
    are read from its file (then checked for NaN/inf).  No blockers: the visibility is
    stored."""
    from shtools.data_formats.bake_stream import check_finite

    path = getattr(bake, "path", None)

    def block(name):
        values = getattr(bake, name)
        if values.ndim == 2:
            return np.tile(values[rows], (len(frames), 1))
        read = np.asarray(values[frames.start:frames.stop])
        if path is not None:
            check_finite(read, name, path)
        return read[:, rows].reshape(-1, 3)

    return SimpleNamespace(vertices=block("vertices").astype(np.float64),
                           normals=block("normals").astype(np.float64), lights=list(lights))


def _same_lights(lights: list) -> bool:
    """True when the posed lights of every frame equal the first frame's."""
    first = lights[0]
    return all(len(frame) == len(first) and all(
        np.array_equal(a.position, b.position) and a.radius == b.radius
        and np.array_equal(a.color, b.color) for a, b in zip(frame, first, strict=True))
        for frame in lights)


def _fixed_rows(bake, batch: int):
    """Vertices whose position and normal are the same in every frame, ``(V,)`` bool, and
    the others' geometry when it is small.

    Read ``batch`` frames at a time, each checked for NaN/inf.  The second
    value holds ``vertices`` and ``normals`` ``(T, M, 3)`` of the ``M``
    moving rows when every frame's geometry fits in :data:`GEOMETRY_BYTES`
    (read once, not again per batch), else None.
    """
    from shtools.data_formats.bake_stream import check_finite

    if bake.vertices.ndim == 2:
        return np.ones(bake.n_vertices, bool), None
    T, V = bake.n_frames, bake.n_vertices
    names = ("vertices", "normals")
    still = np.ones(V, bool)

    def compare(values, ref):
        nonlocal still
        # any() over the frame axis first: a contiguous reduction, far faster than
        # all() over the frame and coordinate axes together
        still &= ~(values != ref).any(axis=0).any(axis=1)

    if T * V * 3 * 4 * len(names) > GEOMETRY_BYTES:  # a batch at a time, read again later
        first = {name: np.asarray(getattr(bake, name)[0]) for name in names}
        for a in range(0, T, batch):
            for name, ref in first.items():
                compare(check_finite(np.asarray(getattr(bake, name)[a:a + batch]), name,
                                     bake.path), ref)
        return still, None
    # each dataset in one read (no copy into a buffer), the moving rows kept
    held = {name: check_finite(np.asarray(getattr(bake, name)[()]), name, bake.path)
            for name in names}
    for values in held.values():
        compare(values, values[0])
    moving = np.flatnonzero(~still)
    return still, SimpleNamespace(**{name: values[:, moving] for name, values in held.items()})


#: Most bytes of per-frame geometry relighting keeps in memory to read it once.
GEOMETRY_BYTES = 1 << 27


def check_relightable(bake) -> None:
    """Refuse a bake whose stored visibility cannot reproduce its shading.

    The stored visibility is the SH visibility the runtime shaded with.  An
    all-frequency (``haar``) field blocker shades the environment in its map basis
    instead and is not in it, so relighting would silently lose its shadow.
    """
    if bake.visibility is None:
        raise InputError("has no stored visibility; rebake it with 'shtools bake "
                         "--store-visibility' to relight it", bake.path)
    if names := bake.parameters.get("all_frequency_blockers"):
        raise InputError(f"has all-frequency (haar) field blockers ({', '.join(names)}) whose "
                         "shadows its stored SH visibility leaves out; bake the scene under "
                         "the new light instead", bake.path)


def relight(bake: str | os.PathLike, light: str | os.PathLike, output: str | os.PathLike, *,
            rotate: float = 0.0, scene=None, compression: str | None = None,
            keep_visibility: bool = False, threads: int | None = None,
            progress=None) -> dict:
    """Re-shade every frame of a bake under another light; write a new bake asset.

    One call from Python; ``shtools relight`` runs it.  The output is a bake
    like the input (geometry, albedo, objects; the visibility only with
    ``keep_visibility``, as a fresh bake has it only with
    ``--store-visibility``) whose radiance is what a fresh bake of the same scene with
    ``[environment] light = LIGHT`` (``rotate_deg = rotate``; the bake's
    ``radius`` and ``center`` when it was lit from a finite sphere) and,
    given ``scene``, that scene's spherical lights gives.  Frames stream
    through a batch at a time (:func:`relight_frames`); the per-frame geometry
    (and kept visibility) is copied as stored.  The output appears atomically, and
    never replaces the bake or the light it reads.

    Parameters
    ----------
    bake : path-like
        A bake asset made with ``--store-visibility``.
    light : path-like
        A ``light`` asset of the bake's SH order (``shtools light project``).
    output : path-like
        The relit bake asset.
    rotate : float
        Turn the light this many degrees about +Y (SH rotation).
    scene : path-like, Scene or shtools.scene.light_record.PosedLights, optional
        Add this scene's ``[[lights]]`` (``shexp`` shadows from the stored visibility):
        read from the bake when it is the scene file the bake recorded them from,
        else parsed (:func:`~shtools.scene.light_record.scene_lights`).
    compression : str or None
        h5py filter of the output's radiance: None (the default) stores it
        plain, so writing costs no more than the shading; ``"gzip"`` as a bake
        stores it, for a smaller file.
    keep_visibility : bool
        Carry the stored visibility into the output, so that it can be relit
        again (the largest part of the file); without it the output is the bake
        a fresh one without ``--store-visibility`` is.
    threads : int, optional
        Threads shading (:func:`relight_frames`; default one per usable core).
    progress : callable, optional
        A progress factory (:mod:`shtools.progress`).

    Returns
    -------
    dict
        ``frames``, ``vertices``, ``seconds``, ``output``, ``lights``, and
        ``lamps_as_baked``: whether ``scene``'s lamps sit and measure as the bake's
        recorded ones (:func:`~shtools.scene.light_record.lamps_as_baked`; False: a
        lamp's long shadow beyond an object's traced reach is its blocker's, where a
        fresh bake would trace the real mesh; None: no lamps given, or the bake's
        record cannot say).

    Raises
    ------
    InputError, AssetError
        One line naming the file: no stored visibility, a light of another
        SH order, a mid-range bake it cannot relight, an output that is an input.
    """
    from concurrent.futures import ThreadPoolExecutor

    from shtools.data_formats._base import same_file
    from shtools.data_formats.bake import BakeWriter
    from shtools.data_formats.bake_stream import open_bake
    from shtools.progress import silent
    from shtools.scene.light_record import PosedLights, lamps_as_baked, pose_table, posed

    start = time.perf_counter()
    named = scene.path if isinstance(scene, PosedLights) else scene
    for src in (bake, light) + (() if not isinstance(named, str | os.PathLike) else (named,)):
        if same_file(output, src):
            raise InputError(f"is also an input ({src}); choose another output", output)
    with open_bake(bake) as b:
        check_relightable(b)  # before reading the light: the bake is what is missing
        settings = relight_settings(b)
        inputs = {"bake": bake}
        env = relight_environment(light, b.sh_order,
                                  b.parameters.get("window", settings.window), rotate, inputs)
        sphere = relight_midrange(b, env)
        as_baked = poses = None
        if scene is not None:
            scene = posed(b, scene)
            inputs["scene"] = scene.path
            poses = pose_table(scene.frames)
            as_baked = lamps_as_baked(b, poses)
        parameters = dict(b.parameters)
        parameters["relight"] = {"light": Path(light).name, "rotate_deg": float(rotate),
                                 "lights": None if scene is None else Path(scene.path).name}
        static = b.vertices.ndim == 2
        kept = ("vertices", "normals") + (("visibility",) if keep_visibility else ())
        copy = {name: getattr(b, name) for name in kept if getattr(b, name).ndim == 3}
        with ThreadPoolExecutor(1, thread_name_prefix="relight-inputs") as hasher:
            # the writer hashes its inputs (the bake is large; hashlib frees the GIL)
            # while the first frames are shaded
            made = hasher.submit(
                BakeWriter, output, n_frames=b.n_frames, faces=b.faces, sh_order=b.sh_order,
                static_vertices=b.vertices if static else None,
                static_normals=b.normals if static else None, n_vertices=b.n_vertices,
                visibility_size=b.visibility.shape[2] if keep_visibility else None,
                times=b.times,
                frame_index=b.frame_index, albedo=b.albedo, object_offsets=b.object_offsets,
                object_names=b.object_names, parameters=parameters, inputs=inputs,
                fps=b.attrs.get("fps"), compression=compression, copy=copy,
                light_poses=poses)
            frames = relight_frames(b, env, scene, settings, threads, midrange=sphere)
            first = next(frames)
            writer = made.result()
        with writer as w, (progress or silent)(total=b.n_frames, desc="relight",
                                               unit="frames") as bar:
            block = max(1, BATCH_ROWS // b.n_vertices)  # frames in one write
            relit = itertools.chain([first], frames)
            for a in range(0, b.n_frames, block):
                z = min(a + block, b.n_frames)
                w.write_frames(a, np.stack(list(itertools.islice(relit, z - a))))
                bar.update(z - a)
    return {"frames": b.n_frames, "vertices": b.n_vertices,
            "seconds": round(time.perf_counter() - start, 4), "output": os.fspath(output),
            "lights": 0 if scene is None else len(scene.lights), "lamps_as_baked": as_baked}
