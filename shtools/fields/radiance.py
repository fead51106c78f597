r"""Source radiance fields (SRF) of local lights (Zhou et al. 2005; Tamura et al. Sec. 3.1).

The light counterpart of an object occlusion field: on the same shells
(``r_c = 0.2 V_r (1 + c)`` around the lamp's bounding-sphere centre, the same
cell-centred (theta, phi) grid of :mod:`~shtools.fields.sampling`), each
sample stores the **incoming radiance from the lamp** as a function of
direction, projected to SH per colour channel: an RCV of shape ``(3, n*n)``.
What the lamp's own fixture blocks (a lampshade) is in it: a ray carries the
emitter's radiance only when its nearest hit is an emitter face seen from the
front (:func:`~shtools.fields.emitter.emitted_radiance`).

Directions per sample: the emitter radiates nothing outside the cone of its
bounding sphere, so from a point outside that sphere the ``M x M`` directions
(``map_size``) are stratified over the cone only -- equal-area cells in
(cos, azimuth) about the axis to the emitter's centre, each weighted by the
cone's solid angle over ``M**2`` -- rather than spread over the whole sphere,
where a small bulb would be hit by a handful of a 64 x 64 map's directions.
From a point inside it the whole-sphere map of
:func:`~shtools.fields.sampling.direction_map` is used.

Reduction and quantization are the occlusion field's
(:func:`~shtools.fields.reduction.reduce_shell` with ``channels=3``, RCV in
place of OCV; :func:`~shtools.fields.quantize.quantize`).  Eq. (1) is taken on
what :data:`ERROR_SCALES` names, by default the Lambertian radiance the RCVs
cast relative to the brightest receiver at the shell, so that the threshold
means for a lamp what it means for an occlusion field under a unit
environment; the RCVs themselves are stored, reduced by the halvings that
criterion accepts.
"""

from __future__ import annotations

import math
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from shtools.data_formats.srf import RadianceField
from shtools.errors import InputError
from shtools.fields.build import FieldParameters, FieldReport, SampledShells
from shtools.fields.emitter import Emitter, emitted_radiance
from shtools.fields.quantize import quantize
from shtools.fields.reduction import ERROR_QUAD_DEGREE, box2, reduce_shell
from shtools.fields.sampling import (
    CONE_MARGIN,
    bounding_sphere,
    direction_map,
    grid_directions,
    shell_radii,
)
from shtools.sh import basis, sphere_quadrature

#: Sample points per cast batch (bounds the (P, M*M, n*n) basis to ~64 MiB at M = 64).
RADIANCE_CHUNK = 64
#: Colour channels of an RCV.
CHANNELS = 3
#: What eq. (1) compares, so that one threshold means what it means for an
#: occlusion field.  An OOF's tau is an error in visibility, whose unoccluded value is
#: 1: under a unit environment, the radiance of an unshadowed white Lambertian receiver.
#: ``"receiver"`` (default) gives the SRF the same unit: the RCVs are turned into the
#: Lambertian radiance they cast as a function of the receiver's normal (band ``l``
#: times ``A_l / pi``, Ramamoorthi and Hanrahan's clamped-cosine factors; an odd band
#: ``l >= 3``, which the clamped cosine lacks but a shadowed receiver's transfer
#: carries, weighted as band ``l - 1``) and divided by the shell's largest such
#: radiance, the brightest receiver at that distance: tau is then the mean error of a
#: receiver's radiance relative to the lamp's full light there, as it is relative to
#: the full environment for an OOF.  ``"peak"``: the raw RCVs divided by each shell's
#: largest reconstructed radiance (relative to the lobe's own peak; the band-3 ringing
#: of a compact lamp, which no Lambertian receiver sees, keeps far shells fine).
#: ``"emitter"``: divided by the emitter's radiance -- the lamp's coverage in [0, 1],
#: an OOF's scale literally -- which lets the far shells, where the lamp covers a small
#: solid angle, halve until the lamp's light there is off by far more than tau.
ERROR_SCALES = {
    "receiver": "eq. (1) on the Lambertian radiance the RCVs cast (band l times A_l/pi, "
                "odd l >= 3 as l-1) divided by each shell's largest",
    "peak": "eq. (1) on RCVs divided by each shell's largest reconstructed radiance",
    "emitter": "eq. (1) on RCVs divided by the emitter's largest channel radiance",
}
#: The default of ``--error-scale``.
DEFAULT_ERROR_SCALE = "receiver"


def receiver_weights(order: int) -> np.ndarray:
    """Per-coefficient factors of the ``"receiver"`` error scale, shape ``(n*n,)``.

    Band ``l``: ``A_l / pi`` (the clamped cosine's convolution factor: 1, 2/3,
    1/4, 0, -1/24, ...) in absolute value; an odd band ``l >= 3`` (where it is
    0) takes band ``l - 1``'s.
    """
    from shtools.sh.zonal import clamped_cosine_zh

    z = clamped_cosine_zh(order)
    a = np.abs(np.sqrt(4 * math.pi / (2 * np.arange(order) + 1)) * z)
    for band in range(3, order, 2):
        a[band] = a[band - 1]
    return np.repeat(a, 2 * np.arange(order) + 1)


def cone_directions(axis, cos_alpha, size: int) -> tuple[np.ndarray, np.ndarray]:
    """``size x size`` equal-area directions in cones, and each cone's weight per direction.

    Cell ``(i, j)``: ``cos = 1 - (i + 1/2)(1 - cos_alpha) / size`` from the axis,
    azimuth ``(j + 1/2) 2 pi / size``; every cell has the solid angle
    ``2 pi (1 - cos_alpha) / size**2``.

    Parameters
    ----------
    axis : array_like, shape (P, 3)
        Unit cone axes.
    cos_alpha : array_like, shape (P,)
        Cosine of each cone's half-angle.
    size : int

    Returns
    -------
    dirs : ndarray, shape (P, size*size, 3)
    weight : ndarray, shape (P,)
    """
    a = np.asarray(axis, dtype=np.float64).reshape(-1, 3)
    ca = np.asarray(cos_alpha, dtype=np.float64).reshape(-1)
    k = (np.arange(size) + 0.5) / size
    cos_t = 1.0 - k[None, :] * (1.0 - ca[:, None])  # (P, size)
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 0.0))
    phi = 2 * math.pi * k
    # an orthonormal frame per axis: the helper axis is the one least aligned with it
    helper = np.eye(3)[np.argmin(np.abs(a), axis=1)]
    t1 = np.cross(a, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(a, t1)
    cp, sp = np.cos(phi), np.sin(phi)
    dirs = (sin_t[:, :, None, None] * (cp[None, None, :, None] * t1[:, None, None, :]
                                       + sp[None, None, :, None] * t2[:, None, None, :])
            + cos_t[:, :, None, None] * a[:, None, None, :])
    weight = 2 * math.pi * (1.0 - ca) / (size * size)
    return dirs.reshape(a.shape[0], size * size, 3), weight


def sample_rcvs(caster, emitter: Emitter, emitter_center, emitter_radius: float, points,
                map_size: int, order: int, *, stats: dict | None = None) -> np.ndarray:
    """Radiance coefficient vectors of a lamp at points, shape ``(P, 3, n*n)``.

    Parameters
    ----------
    caster : shtools.geometry.raycast.RayCaster
        Over the lamp's triangles (``emitter.vertices``, ``emitter.faces``).
    emitter : Emitter
    emitter_center, emitter_radius
        A sphere bounding the emissive faces.
    points : array_like, shape (P, 3)
    map_size : int
        ``M``: ``M x M`` directions per point (in the cone, or the whole map).
    order : int
    stats : dict, optional
        ``stats["rays"]`` is increased by the rays cast.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(emitter_center, dtype=np.float64)
    r = float(emitter_radius) * (1 + CONE_MARGIN)
    full_dirs, full_w = direction_map(map_size)
    y_full = basis(full_dirs, order) * full_w[:, None]
    out = np.zeros((p.shape[0], CHANNELS, order * order))
    rel = c - p
    d = np.linalg.norm(rel, axis=1)
    outside = d > r
    inside_rows = np.flatnonzero(~outside)
    for s in range(0, inside_rows.size, RADIANCE_CHUNK):
        rows = inside_rows[s:s + RADIANCE_CHUNK]
        origins = np.repeat(p[rows], full_dirs.shape[0], axis=0)
        rad = emitted_radiance(caster, emitter, origins, np.tile(full_dirs, (rows.size, 1)))
        out[rows] = np.einsum("pqc,qk->pck", rad.reshape(rows.size, -1, CHANNELS), y_full)
        if stats is not None:
            stats["rays"] = stats.get("rays", 0) + origins.shape[0]
    out_rows = np.flatnonzero(outside)
    for s in range(0, out_rows.size, RADIANCE_CHUNK):
        rows = out_rows[s:s + RADIANCE_CHUNK]
        axis = rel[rows] / d[rows, None]
        cos_a = np.sqrt(np.maximum(1.0 - (r / d[rows]) ** 2, 0.0))
        dirs, w = cone_directions(axis, cos_a, map_size)
        flat = dirs.reshape(-1, 3)
        origins = np.repeat(p[rows], map_size * map_size, axis=0)
        rad = emitted_radiance(caster, emitter, origins, flat).reshape(rows.size, -1, CHANNELS)
        y = basis(flat, order).reshape(rows.size, -1, order * order)
        out[rows] = np.einsum("pqc,pqk->pck", rad, y) * w[:, None, None]
        if stats is not None:
            stats["rays"] = stats.get("rays", 0) + origins.shape[0]
    return out


@dataclass
class _RadianceJob:
    """What every shell task shares (the Embree scene is built once per process)."""

    emitter: Emitter
    center: np.ndarray
    emitter_center: np.ndarray
    emitter_radius: float
    radii: np.ndarray
    sample_dirs: np.ndarray
    map_size: int
    order: int
    token: str


_WORKER_CASTER: dict = {}


def _radiance_shell_task(job: _RadianceJob, c: int) -> tuple[np.ndarray, int]:
    """Task body: the RCVs of shell ``c``, shape (R0*R0, 3*n*n), and the rays cast."""
    from shtools.geometry.raycast import RayCaster

    caster = _WORKER_CASTER.get(job.token)
    if caster is None:
        _WORKER_CASTER.clear()
        caster = _WORKER_CASTER[job.token] = RayCaster(job.emitter.vertices, job.emitter.faces)
    stats = {"rays": 0}
    points = job.center + job.radii[c] * job.sample_dirs
    rcv = sample_rcvs(caster, job.emitter, job.emitter_center, job.emitter_radius, points,
                      job.map_size, job.order, stats=stats)
    return rcv.reshape(points.shape[0], -1), stats["rays"]


def emitter_sphere(emitter: Emitter) -> tuple[np.ndarray, float]:
    """Bounding sphere of the emissive faces' vertices: centre (3,), radius."""
    used = np.unique(emitter.faces[emitter.emissive])
    return bounding_sphere(emitter.vertices[used])


def sample_radiance_shells(emitter: Emitter, params: FieldParameters | None = None, *,
                           progress: Callable[[int], None] | None = None,
                           scheduler: str | None = None,
                           workers: int | None = None) -> SampledShells:
    """Cast and project the RCVs of every shell at the initial resolution.

    Shells are centred on the whole lamp's bounding sphere (emitter and
    fixture), as an occlusion field is on its object's.  Shells are
    independent tasks (:mod:`shtools.tasks`), cast identically wherever they run.

    Returns
    -------
    SampledShells
        ``grids`` of shape ``(C, R, R, 3*n*n)`` (channel-major RCVs).
    """
    from shtools.tasks import task_pool

    params = params or FieldParameters()
    params.validate()
    center, vr = bounding_sphere(emitter.vertices[np.unique(emitter.faces)])
    e_center, e_radius = emitter_sphere(emitter)
    radii = shell_radii(vr, params.shells)
    R0 = params.resolution
    K = CHANNELS * params.order ** 2
    job = _RadianceJob(emitter, center, e_center, e_radius, np.asarray(radii),
                       grid_directions(R0).reshape(-1, 3), params.map_size, params.order,
                       uuid.uuid4().hex)
    grids = np.empty((params.shells, R0, R0, K))
    rays = 0
    t0 = time.perf_counter()
    with task_pool(scheduler, workers, n_tasks=params.shells) as pool:
        for c, (rcv, cast) in enumerate(pool.map_ordered(_radiance_shell_task,
                                                         range(params.shells), shared=job)):
            grids[c] = rcv.reshape(R0, R0, K)
            rays += cast
            if progress is not None:
                progress(R0 * R0)
    return SampledShells(center, vr, radii, grids, rays,
                         params.shells * R0 * R0 * params.map_size ** 2,
                         time.perf_counter() - t0)


def shell_peak(grid, order: int) -> float:
    """Largest value of the radiance functions a shell's RCVs reconstruct (any channel).

    Parameters
    ----------
    grid : array_like, shape (R, R, 3*n*n)
    """
    dirs, _ = sphere_quadrature(ERROR_QUAD_DEGREE)
    y = basis(dirs, order)
    g = np.asarray(grid, dtype=np.float64).reshape(-1, order * order)
    peak = float((g @ y.T).max())
    return peak if peak > 0 else 1.0  # a dark shell: nothing to scale


def build_radiance_field(sampled: SampledShells, emitter: Emitter,
                         params: FieldParameters | None = None, *,
                         error_scale: str = DEFAULT_ERROR_SCALE
                         ) -> tuple[RadianceField, FieldReport]:
    """Reduce and quantize sampled RCV shells into a :class:`RadianceField`.

    Parameters
    ----------
    sampled : SampledShells
    emitter : Emitter
    params : FieldParameters, optional
    error_scale : {"receiver", "peak", "emitter"}
        What eq. (1) compares (:data:`ERROR_SCALES`).
    """
    params = params or FieldParameters()
    params.validate()
    if error_scale not in ERROR_SCALES:
        raise InputError(f"--error-scale must be one of {', '.join(ERROR_SCALES)}, got "
                         f"{error_scale!r}")
    rcv, offs, steps, res, level_err, cum_err = [], [], [], [], [], []
    weights = np.tile(receiver_weights(params.order), CHANNELS)
    for grid in sampled.grids:
        compared = grid * weights if error_scale == "receiver" else grid
        if error_scale == "emitter":
            scale = float(emitter.radiance.max())
        else:
            scale = shell_peak(compared, params.order)
        red = reduce_shell(compared / scale, params.threshold, params.min_resolution,
                           cumulative=params.cumulative, channels=CHANNELS)
        kept = np.asarray(grid, dtype=np.float64)
        while kept.shape[0] > red.resolution:  # the halvings accepted, on the RCVs
            kept = box2(kept)
        q, o, s = quantize(kept, params.bits)
        rcv.append(q)
        offs.append(o)
        steps.append(s)
        res.append(red.resolution)
        level_err.append(red.level_errors)
        cum_err.append(red.cumulative_error)
    e_center, e_radius = emitter_sphere(emitter)
    attrs = {
        "quadrature": f"{params.map_size}x{params.map_size} equal-area cells over the "
                      "emitter's bounding cone (whole-sphere latlong map inside it)",
        "error_quadrature": f"gauss-legendre x uniform, degree {ERROR_QUAD_DEGREE}",
        "error_scale": ERROR_SCALES[error_scale],
        "reduction": "tamura sec. 4, per-level" + (" (cumulative)" if params.cumulative else ""),
        "bits": int(params.bits),
        "threshold": float(params.threshold),
        "emission": "uniform RGB radiance from the outside of a closed emitter mesh",
        "emitter_faces": int(emitter.emissive.sum()),
        "fixture_faces": int((~emitter.emissive).sum()),
    }
    fld = RadianceField(
        center=sampled.center, bounding_radius=sampled.bounding_radius,
        shell_radii=sampled.radii, resolution=np.asarray(res, dtype=np.int64), rcv=rcv,
        offset=np.stack(offs), step=np.stack(steps), order=params.order,
        radiance=np.asarray(emitter.radiance, dtype=np.float64),
        emitter_center=e_center, emitter_radius=e_radius,
        emitter_area=float(emitter.areas[emitter.emissive].sum()),
        reduction_error=np.asarray(cum_err),
        level_error=np.asarray([e[-1] if e else 0.0 for e in level_err]),
        lamp_vertices=np.asarray(emitter.vertices, dtype=np.float64),
        lamp_faces=np.asarray(emitter.faces, dtype=np.int64),
        lamp_emissive=np.asarray(emitter.emissive, dtype=bool),
        attrs=attrs,
    )
    report = FieldReport(res, level_err, cum_err, rays=sampled.rays,
                         rays_uncull=sampled.rays_uncull,
                         seconds={"total": sampled.seconds, "cast": sampled.seconds})
    return fld, report


def sample_radiance_field(emitter: Emitter, params: FieldParameters | None = None, *,
                          error_scale: str = DEFAULT_ERROR_SCALE,
                          progress: Callable[[int], None] | None = None,
                          scheduler: str | None = None,
                          workers: int | None = None) -> tuple[RadianceField, FieldReport]:
    """Sample, reduce and quantize the source radiance field of a lamp.

    Parameters
    ----------
    emitter : Emitter
        The lamp in its own frame (:func:`shtools.fields.emitter.load_emitter`).
    params : FieldParameters, optional
        ``shells``, ``resolution``, ``map_size``, ``order``, ``threshold``,
        ``min_resolution``, ``bits``, ``cumulative`` are used.
    error_scale : {"receiver", "peak", "emitter"}
        See :data:`ERROR_SCALES`.
    progress, scheduler, workers
        As :func:`shtools.fields.build.sample_shells`.

    Returns
    -------
    RadianceField, FieldReport
    """
    if error_scale not in ERROR_SCALES:  # before the long sampling
        raise InputError(f"--error-scale must be one of {', '.join(ERROR_SCALES)}, got "
                         f"{error_scale!r}")
    t0 = time.perf_counter()
    sampled = sample_radiance_shells(emitter, params, progress=progress, scheduler=scheduler,
                                     workers=workers)
    fld, rep = build_radiance_field(sampled, emitter, params, error_scale=error_scale)
    rep.seconds["total"] = time.perf_counter() - t0
    return fld, rep
