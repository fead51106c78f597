r"""Build an adaptive shadow field of a rigid mesh (``shtools field sample``).

Per shell ``c`` (radius ``r_c = 0.2 V_r (1 + c)`` around the bounding-sphere
centre): the OCV at ``R x R`` cell-centred samples (:mod:`~shtools.fields.sampling`,
cone-culled rays), the adaptive reduction (:mod:`~shtools.fields.reduction`),
the SH log of every kept sample (log-space combination) and 8-bit quantization
of both (:mod:`~shtools.fields.quantize`).

Log of an OCV: eigen-inversion (:func:`shtools.sh.log`, relative eigenvalue
floor ``LOG_EPS``) after raising the mean visibility to at least
:data:`LOG_FLOOR` -- a sample inside the object sees nothing, and a visibility
of 0 has no logarithm.  The floor is recorded in the asset.

Open meshes (teapot, bunny) leak: rays pass through their holes, so samples
inside see some light.  The asset records ``closed`` and ``boundary_edges``
and the summary says so; nothing is patched.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from shtools.data_formats.field import ShadowField
from shtools.errors import InputError
from shtools.field_limits import BITS, MAP_SIZE, RESOLUTION, SHELLS
from shtools.fields.quantize import quantize
from shtools.fields.reduction import ERROR_QUAD_DEGREE, reduce_shell
from shtools.fields.sampling import (
    bounding_sphere,
    direction_map,
    grid_directions,
    sample_ocvs,
    shell_radii,
)
from shtools.runtime.settings import MAX_ACC_ORDER, MAX_ORDER
from shtools.sh import LOG_EPS
from shtools.sh import log as sh_log
from shtools.sh.basis import SQRT_4PI

#: Lowest mean visibility given to the log (samples inside the object).
LOG_FLOOR = 0.02


@dataclass
class FieldParameters:
    """``shtools field sample`` options (the paper's defaults)."""

    shells: int = 32
    resolution: int = 64
    map_size: int = 64
    order: int = 4
    threshold: float = 0.01
    min_resolution: int = 8
    bits: int = 8
    cumulative: bool = False
    log_floor: float = LOG_FLOOR
    log_eps: float = LOG_EPS
    seed: int = 0
    #: SH order of the stored self-visibility O_v (None: ``order``, the paper's O_v; a
    #: bake truncates a higher one to its shading order, which must be ``order``)
    self_order: int | None = None

    def resolved_self_order(self) -> int:
        """The O_v order actually stored."""
        return self.order if self.self_order is None else int(self.self_order)

    def validate(self) -> None:
        """Raise :class:`InputError` naming the bad option."""
        def pow2(x):
            return isinstance(x, int) and x >= 1 and (x & (x - 1)) == 0

        if not (isinstance(self.shells, int) and SHELLS[0] <= self.shells <= SHELLS[1]):
            raise InputError(f"--shells must be an integer {SHELLS[0]}..{SHELLS[1]}, got "
                             f"{self.shells!r}")
        if not pow2(self.resolution) or not RESOLUTION[0] <= self.resolution <= RESOLUTION[1]:
            raise InputError(f"--resolution must be a power of two {RESOLUTION[0]}..{RESOLUTION[1]}"
                             f", got {self.resolution!r}")
        if not pow2(self.min_resolution) or self.min_resolution > self.resolution:
            raise InputError(f"--min-resolution must be a power of two <= --resolution "
                             f"({self.resolution}), got {self.min_resolution!r}")
        if not (isinstance(self.map_size, int) and MAP_SIZE[0] <= self.map_size <= MAP_SIZE[1]):
            raise InputError(f"--map must be an integer {MAP_SIZE[0]}..{MAP_SIZE[1]}, got "
                             f"{self.map_size!r}")
        if not (isinstance(self.order, int) and 1 <= self.order <= MAX_ORDER):
            raise InputError(f"--order must be an integer 1..{MAX_ORDER}, got {self.order!r}")
        if not (self.threshold > 0 and math.isfinite(self.threshold)):
            raise InputError(f"--threshold must be > 0, got {self.threshold!r}")
        if not (isinstance(self.bits, int) and BITS[0] <= self.bits <= BITS[1]):
            raise InputError(f"--bits must be an integer {BITS[0]}..{BITS[1]}, got {self.bits!r}")
        if not 0 < self.log_floor < 1:
            raise InputError(f"log floor must be in (0, 1), got {self.log_floor!r}")
        if self.self_order is not None and not (isinstance(self.self_order, int)
                                                and self.order <= self.self_order <= MAX_ACC_ORDER):
            raise InputError(f"--self-order must be an integer {self.order}..{MAX_ACC_ORDER} (at "
                             f"least --order), got {self.self_order!r}")


#: Bytes per cast ray while a batch is in flight: origin and direction (float64 x 6),
#: the cone mask, the hit flag and its float32 copy for the projection.
RAY_BYTES = 56


def planned_cost(params: FieldParameters, workers: int = 1, channels: int = 1) -> dict:
    """What sampling ``params`` will cost, from the options alone (before any work).

    Peak memory: the initial samples of every shell and their SH logs (float64,
    ``2 x C x R^2 x n^2``), plus per worker one shell's samples and one batch of
    :data:`~shtools.fields.sampling.POINT_CHUNK` points' rays over the
    ``MAP x MAP`` direction map.  Rays: every sample's full map (the cone cull
    only lowers it).  ``channels``: SH vectors a sample holds (3 for the RGB of
    a source radiance field, :mod:`shtools.fields.radiance`).

    Returns
    -------
    dict
        ``bytes``, ``rays`` and ``formula`` (the estimate in words, for a message).
    """
    from shtools.fields.sampling import POINT_CHUNK

    c, r2, q = params.shells, params.resolution ** 2, params.map_size ** 2
    n2 = channels * params.order ** 2  # SH coefficients of every channel of a sample
    w = max(1, min(int(workers), c))
    shells = 2 * c * r2 * n2 * 8
    worker = r2 * n2 * 8 + POINT_CHUNK * q * RAY_BYTES
    return {"bytes": shells + w * worker, "rays": c * r2 * q,
            "formula": f"{c} shells x {params.resolution}^2 samples x {n2} SH coefficients x "
                       f"16 bytes, plus {w} worker(s) x {POINT_CHUNK} points x {q} directions "
                       f"x {RAY_BYTES} bytes"}


@dataclass
class FieldReport:
    """What sampling did: per-shell resolutions and errors, rays, time."""

    resolution: list
    level_errors: list
    cumulative_error: list
    rays: int = 0
    rays_uncull: int = 0
    seconds: dict = field(default_factory=dict)


def log_ocvs(ocv, floor: float = LOG_FLOOR, eps: float = LOG_EPS) -> np.ndarray:
    """SH log of visibility vectors with a floor on the mean visibility, shape ``(..., n*n)``.

    ``g`` whose mean ``g_0 / sqrt(4 pi)`` is below ``floor`` get a constant added
    to reach it; then :func:`shtools.sh.log` (eigen-inversion, eigenvalue floor
    ``eps * lambda_max``).
    """
    g = np.array(ocv, dtype=np.float64)
    g[..., 0] = np.maximum(g[..., 0], floor * SQRT_4PI)
    return sh_log(g, "eigen", eps=eps)


@dataclass
class SampledShells:
    """Full-resolution OCVs of every shell, before reduction (:func:`sample_shells`).

    Attributes
    ----------
    center : ndarray, shape (3,)
    bounding_radius : float
    radii : ndarray, shape (C,)
    grids : ndarray, shape (C, R, R, n*n)
    rays : int
        Rays cast (after the cone cull).
    rays_uncull : int
        Rays a sampler without the cull would cast.
    seconds : float
        Time spent casting and projecting.
    """

    center: np.ndarray
    bounding_radius: float
    radii: np.ndarray
    grids: np.ndarray
    rays: int
    rays_uncull: int
    seconds: float


def _check_solid(v: np.ndarray) -> None:
    # a flat mesh blocks nothing from most points and has no interior (qhull fails on it)
    centred = v - v.mean(axis=0)
    sing = np.linalg.svd(centred, compute_uv=False) if len(v) >= 3 else np.zeros(3)
    if len(sing) < 3 or sing[2] <= 1e-9 * max(sing[0], 1e-300):
        raise InputError("the mesh is flat (no extent along one axis); a shadow field needs a "
                         "solid -- thicken it first (e.g. `shtools spheres fit --thickness`)")


@dataclass
class _ShellJob:
    """What every shell task shares (small arrays; the Embree scene is built per process)."""

    vertices: np.ndarray
    faces: np.ndarray
    center: np.ndarray
    radius: float
    radii: np.ndarray
    sample_dirs: np.ndarray
    dirs: np.ndarray
    weights: np.ndarray
    order: int
    token: str


#: Per-process RayCaster of the current job (a worker keeps one across its shells).
_WORKER_CASTER: dict = {}


def _shell_task(job: _ShellJob, c: int) -> tuple[np.ndarray, int]:
    """Task body: the OCVs of shell ``c``, shape (R0*R0, n*n), and the rays cast."""
    from shtools.geometry.raycast import RayCaster

    caster = _WORKER_CASTER.get(job.token)
    if caster is None:
        _WORKER_CASTER.clear()
        caster = _WORKER_CASTER[job.token] = RayCaster(job.vertices, job.faces)
    stats = {"rays": 0}
    points = job.center + job.radii[c] * job.sample_dirs
    ocv = sample_ocvs(caster, job.center, job.radius, points, job.dirs, job.weights,
                      job.order, stats=stats)
    return ocv, stats["rays"]


def sample_shells(mesh, params: FieldParameters | None = None, *,
                  progress: Callable[[int], None] | None = None,
                  scheduler: str | None = None, workers: int | None = None,
                  pool_summary: dict | None = None) -> SampledShells:
    """Cast and project the OCVs of every shell at the initial resolution.

    Shells are independent tasks (:mod:`shtools.tasks`): spread over the local
    cores by default, or over a Dask cluster (``scheduler``).  Each shell is
    cast identically wherever it runs, so the result does not depend on how
    the shells were spread.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    params : FieldParameters, optional
        ``shells``, ``resolution``, ``map_size`` and ``order`` are used.
    progress : callable, optional
        Called with the number of samples done after each shell.
    scheduler, workers : optional
        Where shells run, as :func:`shtools.tasks.task_pool` (default: local
        worker processes, one per core; ``scheduler="inline"``: this process).
    pool_summary : dict, optional
        Filled with the scheduler's per-worker task counts and times.

    Returns
    -------
    SampledShells
    """
    import uuid

    from shtools.tasks import task_pool

    params = params or FieldParameters()
    params.validate()
    v = np.asarray(mesh.vertices, dtype=np.float64)
    _check_solid(v)
    center, vr = bounding_sphere(v)
    dirs, weights = direction_map(params.map_size)
    radii = shell_radii(vr, params.shells)
    R0 = params.resolution
    n2 = params.order ** 2
    job = _ShellJob(v, np.asarray(mesh.faces), center, vr, np.asarray(radii),
                    grid_directions(R0).reshape(-1, 3), dirs, weights, params.order,
                    uuid.uuid4().hex)
    grids = np.empty((params.shells, R0, R0, n2))
    rays = 0
    t0 = time.perf_counter()
    with task_pool(scheduler, workers, n_tasks=params.shells) as pool:
        for c, (ocv, cast) in enumerate(pool.map_ordered(_shell_task, range(params.shells),
                                                         shared=job)):
            grids[c] = ocv.reshape(R0, R0, n2)
            rays += cast
            if progress is not None:
                progress(R0 * R0)
        if pool_summary is not None:
            pool_summary.update(pool.summary())
    return SampledShells(center, vr, radii, grids, rays,
                         params.shells * R0 * R0 * dirs.shape[0], time.perf_counter() - t0)


def sample_field(mesh, params: FieldParameters | None = None, *,
                 self_visibility: Callable | None = None,
                 progress: Callable[[int], None] | None = None,
                 scheduler: str | None = None,
                 workers: int | None = None) -> tuple[ShadowField, FieldReport]:
    """Sample, reduce and quantize the shadow field of a mesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The object in its own frame (validated, see :func:`shtools.geometry.mesh.load_mesh`).
    params : FieldParameters, optional
    self_visibility : callable, optional
        ``f(vertices, normals, meshes, order) -> (V, m*m)``: per-vertex
        self-visibility O_v stored with the field at ``m =
        params.resolved_self_order()`` (rigid objects;
        :func:`shtools.geometry.transfer.field_self_visibility`, what ``field sample``
        stores).
    progress : callable, optional
        Called with the number of samples done after each shell.
    scheduler, workers : optional
        Where the shells are sampled (:func:`sample_shells`).

    Returns
    -------
    ShadowField, FieldReport

    Raises
    ------
    InputError
        Bad parameters, or a flat mesh.
    """
    params = params or FieldParameters()
    params.validate()
    t0 = time.perf_counter()
    sampled = sample_shells(mesh, params, progress=progress, scheduler=scheduler,
                            workers=workers)
    fld, rep = build_field(sampled, params, mesh=mesh, self_visibility=self_visibility)
    rep.seconds["total"] = time.perf_counter() - t0
    return fld, rep


def build_field(sampled: SampledShells, params: FieldParameters | None = None, *, mesh=None,
                self_visibility: Callable | None = None) -> tuple[ShadowField, FieldReport]:
    """Reduce, log and quantize sampled shells into a :class:`ShadowField`.

    Parameters
    ----------
    sampled : SampledShells
    params : FieldParameters, optional
        ``threshold``, ``min_resolution``, ``cumulative``, ``bits``, ``log_floor``,
        ``log_eps`` are used.
    mesh : trimesh.Trimesh, optional
        For O_v and the open-mesh record.
    self_visibility : callable, optional
        See :func:`sample_field`.

    Returns
    -------
    ShadowField, FieldReport
    """
    from shtools.geometry.mesh import boundary_edges

    params = params or FieldParameters()
    params.validate()
    ocv, log_q, offs, steps, log_offs, log_steps = [], [], [], [], [], []
    res, level_err, cum_err = [], [], []
    t_log = 0.0
    for grid in sampled.grids:
        red = reduce_shell(grid, params.threshold, params.min_resolution,
                           cumulative=params.cumulative)
        q, o, s = quantize(red.grid, params.bits)
        ts = time.perf_counter()
        lq, lo, ls = quantize(log_ocvs(red.grid, params.log_floor, params.log_eps), params.bits)
        t_log += time.perf_counter() - ts
        ocv.append(q)
        offs.append(o)
        steps.append(s)
        log_q.append(lq)
        log_offs.append(lo)
        log_steps.append(ls)
        res.append(red.resolution)
        level_err.append(red.level_errors)
        cum_err.append(red.cumulative_error)
    sv = None
    ts = time.perf_counter()
    if self_visibility is not None and mesh is not None:
        sv = np.asarray(self_visibility(np.asarray(mesh.vertices, dtype=np.float64),
                                        np.asarray(mesh.vertex_normals), [mesh],
                                        params.resolved_self_order()), dtype=np.float32)
    t_sv = time.perf_counter() - ts
    n_boundary = len(boundary_edges(mesh)) if mesh is not None else 0
    attrs = {
        "quadrature": f"latlong {params.map_size}x{params.map_size} cell-centred, exact cell "
                      "solid angles",
        "error_quadrature": f"gauss-legendre x uniform, degree {ERROR_QUAD_DEGREE}",
        "reduction": "tamura sec. 4, per-level" + (" (cumulative)" if params.cumulative else ""),
        "interpolation": "bilinear, theta clamped, phi wrapped; linear across shells",
        "log_method": "eigen",
        "log_eps": float(params.log_eps),
        "log_floor": float(params.log_floor),
        "bits": int(params.bits),
        "threshold": float(params.threshold),
        "closed": bool(n_boundary == 0),
        "boundary_edges": n_boundary,
        "beyond_last_shell": "linear fade to unoccluded over one shell spacing",
        "inside_first_shell": "clamped to the first shell",
    }
    if n_boundary:
        attrs["leak_note"] = (f"open mesh ({n_boundary} boundary edges): rays leak through the "
                              "holes, so samples inside see light through them")
    fld = ShadowField(
        center=sampled.center, bounding_radius=sampled.bounding_radius,
        shell_radii=sampled.radii, resolution=np.asarray(res, dtype=np.int64), ocv=ocv,
        offset=np.stack(offs), step=np.stack(steps), log_ocv=log_q,
        log_offset=np.stack(log_offs), log_step=np.stack(log_steps), order=params.order,
        self_visibility=sv,
        reduction_error=np.asarray(cum_err),
        level_error=np.asarray([e[-1] if e else 0.0 for e in level_err]),
        attrs=attrs,
    )
    report = FieldReport(res, level_err, cum_err, rays=sampled.rays,
                         rays_uncull=sampled.rays_uncull,
                         seconds={"total": sampled.seconds, "cast": sampled.seconds,
                                  "log": t_log, "self_visibility": t_sv})
    return fld, report
