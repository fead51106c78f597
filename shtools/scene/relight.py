"""Relighting a bake without re-baking it: the stored visibility shaded under another light.

A bake made with ``--store-visibility`` keeps each vertex's SH visibility
``g`` per frame.  Outgoing radiance is the triple product of the clamped
cosine, the light and ``g`` (SHEXP Sec. 7; Sloan et al. 2002, "Precomputed
Radiance Transfer", Sec. 4 — keeping visibility in SH is what makes a new
light cheap), so a new environment, optionally turned about +Y by an SH
rotation, needs no posing, no blockers and no exponential: each frame is one
:func:`shtools.scene.shadows.shade_frame` call, the very function the baker
shades with, so the result is the radiance a fresh bake of the same scene
under that light gives, to float32 rounding.

Spherical lights (a scene's ``[[lights]]``, posed at each frame's time) are
shaded through the same stored visibility, the baker's ``shexp`` way; the
other ways (SSOC, ray tracing) need the posed blocker meshes, which a bake
does not keep.

From Python::

    from shtools.scene.relight import relight
    relight("baked.h5", "studio.h5", "relit.h5", rotate=90.0, scene="scene.toml")
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from shtools.errors import AssetError, InputError


@dataclass
class _RelightSource:
    """What :func:`~shtools.scene.shadows.shade_frame` reads of a prepared scene."""

    env_sh: np.ndarray | None
    midrange: None = None  # a relit environment is distant (at infinity)


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

    The same loader as the baker's (:mod:`shtools.scene.prepare`): its checks
    (a light windowed twice) and its SH rotation about +Y.

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
    from shtools.data_formats.light import read_light
    from shtools.scene.prepare import _environment
    from shtools.scene.scene import EnvironmentSpec

    coeffs, _ = read_light(light)
    n = math.isqrt(len(coeffs))
    if n != order:
        raise AssetError(f"light is SH order {n} but the bake is order {order}; re-project it "
                         f"with 'shtools light project --order {order}'", light)
    spec = EnvironmentSpec(kind="light", path=Path(light), rotate=math.radians(float(rotate)))
    scene = SimpleNamespace(environment=spec, settings=SimpleNamespace(order=order,
                                                                       window=window))
    return _environment(scene, {} if inputs is None else inputs)


def scene_lights(scene) -> object:
    """The parsed scene whose ``[[lights]]`` a relight adds (each must use ``shexp``).

    Parameters
    ----------
    scene : path-like or shtools.scene.scene.Scene

    Raises
    ------
    InputError
        A light shadowed another way than ``shexp``.
    """
    from shtools.scene.scene import Scene, load_scene

    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    for spec in scene.lights:
        if spec.shadows != "shexp":
            raise InputError(f"light '{spec.name}' uses shadows = \"{spec.shadows}\", which "
                             "needs the posed blocker meshes a bake does not keep; relighting "
                             "shades spherical lights through the stored visibility (shadows = "
                             "\"shexp\") only", scene.path)
    if not scene.lights:
        raise InputError("has no [[lights]] to add; leave the scene out", scene.path)
    return scene


def relight_frames(bake, env_sh, scene=None, settings=None):
    """Radiance of every frame of ``bake`` under ``env_sh`` (and ``scene``'s lights).

    Shading is linear in the visibility ``g`` before de-ringing: a vertex whose
    position, normal and lights do not change over the bake has radiance
    ``K g`` with a fixed ``K (3, n*n)``.  ``K`` is made once by the baker's own
    :func:`~shtools.scene.shadows.shade_frame` (without de-ringing) of the unit
    visibility vectors, so these vertices cost one small product per frame; the
    others are shaded frame by frame with ``shade_frame`` as the baker does.
    De-ringing (``settings.deringing``) follows, as in the runtime's ``shade``.

    Parameters
    ----------
    bake : shtools.data_formats.bake.Bake
        With stored visibility.
    env_sh : ndarray, shape (n*n, 3) or None
        Distant environment (:func:`relight_environment`).
    scene : shtools.scene.scene.Scene, optional
        Its spherical lights are posed at each frame's time and shaded through
        the stored visibility (:func:`scene_lights`).
    settings : shtools.runtime.ShadowSettings, optional
        Default :func:`relight_settings` of the bake.

    Yields
    ------
    ndarray, shape (V, 3) float32
        Frame by frame, in the bake's order.
    """
    from dataclasses import replace

    from shtools.runtime import ShadowRuntime
    from shtools.runtime.shading import desaturate_negative
    from shtools.scene.pose import pose_lights
    from shtools.scene.shadows import BakeRun, shade_frame

    if bake.visibility is None:
        raise InputError("has no stored visibility; rebake it with 'shtools bake "
                         "--store-visibility' to relight it", bake.path)
    settings = settings or relight_settings(bake)
    times = [float(t) for t in bake.times]
    lights = [[] if scene is None else pose_lights(scene, t) for t in times]
    still = _fixed_rows(bake) if _same_lights(lights) else np.zeros(bake.n_vertices, bool)
    fixed, moving = np.flatnonzero(still), np.flatnonzero(~still)  # indices: faster to gather
    source = _RelightSource(env_sh)
    # one runtime without de-ringing: it is applied below to each whole frame
    with ShadowRuntime(replace(settings, deringing="none")) as runtime:
        run = BakeRun(source, runtime, "relight")
        K = None
        if fixed.size:
            K = _linear_shading(run, _state(bake, 0, fixed, lights[0]), bake.sh_order ** 2)
        for t in range(bake.n_frames):
            out = np.empty((bake.n_vertices, 3))
            g = bake.visibility[t]
            if K is not None:
                out[fixed] = np.einsum("vcj,vj->vc", K, g[fixed].astype(np.float64))
            if moving.size:
                out[moving] = shade_frame(run, _state(bake, t, moving, lights[t]), g[moving])
            if settings.deringing == "desaturate":  # as ShadowRuntime.shade de-rings
                # colours without a negative channel are left as they are by it
                neg = np.flatnonzero(np.minimum(np.minimum(out[:, 0], out[:, 1]), out[:, 2])
                                     < 0.0)
                out[neg] = desaturate_negative(out[neg])
            yield out.astype(np.float32)


def _state(bake, t: int, rows, lights):
    """The FrameState that shading reads: rows ``rows`` of asset frame ``t``, and ``lights``."""
    from shtools.scene.pose import FrameState

    return FrameState(np.asarray(bake.frame_vertices(t)[rows], np.float64),
                      np.asarray(bake.frame_normals(t)[rows], np.float64), [], lights, [],
                      ["shexp"] * len(lights))


def _linear_shading(run, state, size: int) -> np.ndarray:
    """``K (R, 3, n*n)``: the radiance of each unit visibility vector, before de-ringing."""
    from shtools.scene.shadows import shade_frame

    rows = len(state.vertices)
    K = np.empty((rows, 3, size))
    unit = np.zeros((rows, size), np.float32)
    for j in range(size):
        unit[:, j] = 1.0
        K[:, :, j] = shade_frame(run, state, unit)
        unit[:, j] = 0.0
    return K


def _fixed_rows(bake) -> np.ndarray:
    """Vertices whose position and normal are the same in every frame, ``(V,)`` bool."""
    if bake.vertices.ndim == 2:
        return np.ones(bake.n_vertices, bool)
    return (np.all(bake.vertices == bake.vertices[:1], axis=(0, 2))
            & np.all(bake.normals == bake.normals[:1], axis=(0, 2)))


def _same_lights(lights: list) -> bool:
    """True when the posed lights of every frame equal the first frame's."""
    first = lights[0]
    return all(len(frame) == len(first) and all(
        np.array_equal(a.position, b.position) and a.radius == b.radius
        and np.array_equal(a.color, b.color) for a, b in zip(frame, first, strict=True))
        for frame in lights)


def relight(bake: str | os.PathLike, light: str | os.PathLike, output: str | os.PathLike, *,
            rotate: float = 0.0, scene=None, compression: str | None = None,
            progress=None) -> dict:
    """Re-shade every frame of a bake under another light; write a new bake asset.

    One call from Python; ``shtools relight`` runs it.  The output is a bake
    like the input (geometry, albedo, objects, visibility kept, so it can be
    relit again) whose radiance is what a fresh bake of the same scene with
    ``[environment] light = LIGHT`` (``rotate_deg = rotate``) and, given
    ``scene``, that scene's spherical lights gives.  It appears atomically,
    and never replaces the bake or the light it reads.

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
    scene : path-like or Scene, optional
        Add this scene's ``[[lights]]`` (``shexp`` shadows from the stored visibility).
    compression : str or None
        h5py filter of the output's per-frame geometry and radiance: None (the
        default) stores them plain, so writing costs no more than the shading
        (gzip at HDF5's flush took longer than shading every frame); ``"gzip"``
        as a bake stores them, for a smaller file.
    progress : callable, optional
        A progress factory (:mod:`shtools.progress`).

    Returns
    -------
    dict
        ``frames``, ``vertices``, ``seconds``, ``output``, ``lights``.

    Raises
    ------
    InputError, AssetError
        One line naming the file: no stored visibility, a light of another
        SH order, an output that is an input.
    """
    import h5py

    from shtools.data_formats.bake import BakeWriter, read_bake
    from shtools.progress import silent

    start = time.perf_counter()
    for src in (bake, light) + (() if scene is None or not isinstance(scene, str | os.PathLike)
                                 else (scene,)):
        if _same_file(output, src):
            raise InputError(f"is also an input ({src}); choose another output", output)
    b = read_bake(bake)
    if b.visibility is None:  # before reading the light: the bake is what is missing
        raise InputError("has no stored visibility; rebake it with 'shtools bake "
                         "--store-visibility' to relight it", bake)
    settings = relight_settings(b)
    inputs = {"bake": bake}
    env = relight_environment(light, b.sh_order, b.parameters.get("window", settings.window),
                              rotate, inputs)
    if scene is not None:
        scene = scene_lights(scene)
        inputs["scene"] = scene.path
    parameters = dict(b.parameters)
    parameters["relight"] = {"light": Path(light).name, "rotate_deg": float(rotate),
                             "lights": None if scene is None else Path(scene.path).name}
    static = b.vertices.ndim == 2
    writer = BakeWriter(
        output, n_frames=b.n_frames, faces=b.faces, sh_order=b.sh_order,
        static_vertices=b.vertices if static else None,
        static_normals=b.normals if static else None, n_vertices=b.n_vertices,
        visibility_size=b.visibility.shape[2], times=b.times, frame_index=b.frame_index,
        albedo=b.albedo, object_offsets=b.object_offsets, object_names=b.object_names,
        parameters=parameters, inputs=inputs, fps=b.attrs.get("fps"), compression=compression)
    with (h5py.File(bake, "r") as source, writer as w,
          (progress or silent)(total=b.n_frames, desc="relight", unit="frames") as bar):
        # per-frame datasets stored as the output stores them are copied as stored
        # (compressed bytes), not compressed again; the others come from memory
        kept = {name: source[name] for name in ("vertices", "normals", "visibility")
                if source[name].ndim == 3 and source[name].compression
                == (None if name == "visibility" else compression)}
        for t, radiance in enumerate(relight_frames(b, env, scene, settings)):
            frame = {name: kept.get(name, getattr(b, name)[t])
                     for name in ("vertices", "normals") if not static}
            w.write_frame(t, radiance, visibility=kept.get("visibility", b.visibility[t]),
                          **frame)
            bar.update(1)
    return {"frames": b.n_frames, "vertices": b.n_vertices,
            "seconds": round(time.perf_counter() - start, 4), "output": os.fspath(output),
            "lights": 0 if scene is None else len(scene.lights)}


def _same_file(a, b) -> bool:
    """True when ``a`` and ``b`` name one file (links included)."""
    a, b = Path(a), Path(b)
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)
