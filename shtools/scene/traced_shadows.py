r"""A traced object's shadow on the receiver-only objects, continuous over the surface.

The ground under a traced object (a skinned character's posed mesh, a rigid
sphere-set or shadow-field blocker's real mesh; ``traced_shadows``) is shadowed
by the object's real mesh near it and by its spheres (or its field) far from it.
Four things keep that shadow free of seams, rings and per-vertex noise:

**One direction set for every receiver.**  A spherical Fibonacci set of
``2 n_dirs`` world directions (:func:`world_directions`) is shared by all
receivers and frames; a receiver traces the directions of the set that fall in
the cone it sees the object's bounding sphere in (everything outside that cone
is exactly unblocked) and above its tangent plane, each standing for the same
solid angle ``4π / 2 n_dirs``:

.. math::

    g_v = \sqrt{4\pi}\,\delta_{i0} - \frac{4\pi}{2 n}\sum_{q\ \mathrm{blocked}} y(s_q).

A receiver whose cone fills its hemisphere gets ``n_dirs`` rays, a smaller
cone fewer in proportion: the count follows the cone with no steps, since a
direction enters the cone where it grazes the bounding sphere, unblocked, and
neighbouring receivers sample the same directions, so their estimates differ
only as the mesh's silhouette crosses them (no per-vertex pattern, no frame
that flips over the ground).  The basis is evaluated once per set, not per ray.
Object receivers (:mod:`shtools.scene.contact_shadows`), whose cones the meshes
touching them fill, cast the set in strata: every :data:`COARSE_STRIDE`-th direction
first, the rest only in the strata where a first ray of the receiver or of a
neighbouring receiver was blocked, and next to them (on the ground, where the
silhouette is thin in a wide cone, the strata missed it: 2.0 % instead of 1.5 % over
CesiumMan's shadow, and no faster).

**A surface filter of the traced visibility**
(:func:`~shtools.scene.receiver_filter.surface_filter`).  A silhouette crossing a
direction is a step of ``4π / 2n`` in the estimate.  The steps come every ``d α``
of receiver motion, ``d`` the distance to the nearest point of the mesh and ``α``
the set's angular spacing; the true visibility projected to order
``n`` changes on the scale ``d π / n``.  A Gaussian of width ``d α`` over the
neighbouring receivers (same facing) smooths the steps and leaves the order-``n``
visibility: where the mesh touches the receiver (``d -> 0``) nothing is filtered, so
contact shadows stay sharp.  Far from the object that width spans more receivers than
a receiver's ``FILTER_NEIGHBOURS`` nearest: the filter is applied ``FILTER_PASSES``
times at ``1 / sqrt(FILTER_PASSES)`` of its width (the same variance), each pass
reading the last, so its reach grows as many times.  The filter is linear in the SH
vector, so it holds for any light.

**A denser set where the receivers are sparse.**  Where the receivers are not well
inside a step of each other (a coarse ground, or any ground near its object) the
filter cannot smooth the steps without blurring the shadow, and a step between two
receivers is noise.  There a receiver of the ground (not of an object: those cast in
strata) is traced with a set ``REFINE_FACTOR`` times denser (:func:`refine_weights`:
blended in as the step falls from ``REFINE_STEPS`` receiver spacings to half of that,
so no seam where the density changes).  Only
receivers in the shadow near the object qualify: a band around a character's feet,
a few hundred receivers on a coarse ground.  An object and receivers that do not move
are traced the same way, once per bake (the kept result,
:mod:`shtools.scene.kept_traces`).

**A per-vertex hand-over to the spheres** (:func:`handover_weights`).  The
cone's expected ray count ``k = n_dirs (1 - cos θ)`` decides: beyond
``HANDOVER_RAYS[0]`` rays (about 5 bounding radii) the object's spheres
shadow the receiver, within ``HANDOVER_RAYS[1]`` (about 3.5 radii) its traced
mesh, and in between the blend ``w T + (1 - w) S`` of the traced visibility
``T`` and the spheres' ``S``, ``w`` a smoothstep of ``k``.  The blend is in SH
visibility, not log: ``T`` is a visibility whose per-frame log (eigen) would
cost more than the frame, and where the blend happens the object is far and
faint (both visibilities near 1), where a visibility blend and a log blend
agree to first order in the log.  The ray count is weighed by the light behind
the object (:func:`sky_gain`): a receiver that sees the object against a sun
darkens by more than the count says, and its shadow stays traced farther (the
long shadow of a low sun, where the spheres' outline is not the mesh's).  A
spherical light the object may hide keeps its long shadow traced however far
(:func:`light_weights`), where spheres shade it poorly.  Receivers of weight 0
keep the blocker in the runtime (which splits a receiver cluster whose rows skip
different blockers).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from shtools.blend import smoothstep
from shtools.geometry.visibility import RAY_OFFSET
from shtools.scene.kept_traces import _GROUND  # noqa: F401  the kept traces (tests clear it)
from shtools.scene.kept_traces import keep as _keep_ground
from shtools.scene.kept_traces import kept as _kept_ground
from shtools.scene.receiver_filter import (
    mesh_distance,
    nearest_distance,
    neighbours,
    receiver_spacing,
    sphere_distance,
    surface_filter,
)
from shtools.sh.basis import SQRT_4PI

#: Ray counts (at the hemisphere density ``n_dirs``) of a receiver's cone where the
#: hand-over from the object's spheres to its traced mesh starts and ends: 2 (about 5
#: bounding radii) and 4 (about 3.5 radii, the reach of the former per-cluster rule,
#: within which the whole shadow is the real mesh's).
HANDOVER_RAYS = (2.0, 4.0)
#: Most that :func:`sky_gain` lengthens a cone's ray count by (a sun against a grazing
#: receiver's dim sky would otherwise trace the whole ground).
SKY_GAIN_MAX = 8.0
#: Directions searched for the sky's brightest (:func:`brightest_direction`): about
#: 3 degrees apart.
SKY_SEARCH = 4096
#: Gap (in the cone's half-angle plus the light disc's) over which a spherical light
#: hidden by the object hands its long shadow over to the spheres (:func:`light_weights`).
LIGHT_MARGIN = 0.5
#: Width of the surface filter, in the set's angular spacing times the distance to
#: the nearest point of the mesh: one spacing (a step per width) smooths the steps
#: and keeps the order-n visibility, whose angular scale is several spacings (1.5
#: blurs a coarse ground: 0.77 % off the ray tracer under a torus against 0.47 %).
FILTER_SPACING = 1.0
#: Passes of the surface filter, each at ``1 / sqrt(FILTER_PASSES)`` of its width: a far
#: receiver's width spans more than its ``FILTER_NEIGHBOURS`` (6 receiver spacings a
#: unit from CesiumMan on the benchmark's ground, the neighbours about 3).
FILTER_PASSES = 3
#: Rays of the denser set where the receivers are too sparse for the filter
#: (:func:`refine_weights`), in multiples of the shared set's (the noise left falls as
#: the set's spacing to the power 1.5).  Receivers that cast the set in strata (object
#: receivers) take none.
REFINE_FACTOR = 8
#: The denser set starts where a step (``d α``) is below this many receiver spacings.
REFINE_STEPS = 1.5
#: Receivers per block of :func:`set_visibility` (neighbours in the receivers' order
#: see nearby runs of the set: the block tests only the run its cones span).
SET_CHUNK = 256


@functools.lru_cache(maxsize=8)
def world_directions(n: int) -> np.ndarray:
    """Spherical Fibonacci set of ``n`` unit directions over the sphere, ``(n, 3)``.

    Point ``i`` sits at height ``y_i = 1 - 2 (i + 1/2) / n`` (equal-area bands about
    +Y, in decreasing order) and azimuth ``i`` golden angles; every point stands for
    ``4π / n``.  Read-only (cached).
    """
    i = np.arange(int(n)) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    # bands along +Y (up in a scene): a cone's directions are one run of the set
    d = np.stack([r * np.cos(phi), z, r * np.sin(phi)], axis=1)
    d.setflags(write=False)
    return d


def cone_rays(cos_half, n_dirs: int) -> np.ndarray:
    """Expected rays ``n_dirs (1 - cos θ)`` of each receiver's cone, ``(V,)``."""
    return int(n_dirs) * (1.0 - np.asarray(cos_half, dtype=np.float64))


def handover_reach(n_dirs: int) -> float:
    """Distance from a bounding sphere's centre, in its radii, beyond which a receiver's
    cone holds at most ``HANDOVER_RAYS[0]`` rays of ``n_dirs`` (its hand-over weight is
    0 there at a sky gain of 1): ``1 / sin θ`` for ``1 - cos θ = HANDOVER_RAYS[0] / n_dirs``.
    """
    c = 1.0 - min(1.0, HANDOVER_RAYS[0] / int(n_dirs))
    return 1.0 / math.sqrt(max(1e-300, 1.0 - c * c))


def handover_weights(rays) -> np.ndarray:
    """Weight ``(V,)`` of the traced mesh against the spheres: a smoothstep of the rays.

    0 at or below ``HANDOVER_RAYS[0]``, 1 at or above ``HANDOVER_RAYS[1]``, ``C^1``
    between (``3t² - 2t³``).
    """
    lo, hi = HANDOVER_RAYS
    t = np.clip((np.asarray(rays, dtype=np.float64) - lo) / (hi - lo), 0.0, 1.0)
    return smoothstep(t)


def sky_gain(axis, normals, cos_half, sky) -> np.ndarray:
    r"""Factor ``(V,)`` of each receiver's cone ray count by the light behind the object.

    A cone of ``k`` rays darkens a receiver by about ``k / n_dirs`` of its light under
    a uniform sky; against a brighter part of the sky by more.  The factor is the
    cosine-weighted radiance toward the sky's brightest point in the cone, over the
    receiver's cosine-weighted mean radiance,

    .. math::

        \rho = \max_{s \in \{a,\ s^*\}} \frac{L^+(s)\,\max(s\cdot N, 0)}
                {\mathbf H(N)\cdot\mathbf L},

    ``L^+`` the sky's order-``n`` luminance reconstruction clamped at 0, ``H(N) . L =
    E(N) / π`` (:func:`~shtools.sh.zonal.clamped_cosine_zh`), ``a`` the cone's axis and
    ``s*`` its direction nearest the sky's brightest one (:func:`brightest_direction`;
    a low sun inside a wide cone, off its axis, is what lengthens the shadow).  ``s*``
    moves continuously with the cone (it is the sun's direction inside the cone, the
    rim's point toward it outside), so the factor does too.  Clamped to
    ``[1, SKY_GAIN_MAX]``: never below 1 (a uniform sky gives ``s . N <= 1``: the count
    as it was), so the traced reach only grows toward bright light.

    Parameters
    ----------
    axis, normals : ndarray, shape (V, 3)
        The cones' unit axes and the receivers' unit normals.
    cos_half : ndarray, shape (V,)
        The cones' half-angle cosines.
    sky : array_like, shape (n*n,), or None
        The environment's luminance in SH (None: no environment, factor 1).

    Returns
    -------
    ndarray, shape (V,) float64
        The factors, in ``[1, SKY_GAIN_MAX]``.
    """
    from shtools.runtime.shading import cosine_transfer
    from shtools.sh import basis

    if sky is None or not len(axis):
        return np.ones(len(axis))
    lum = np.asarray(sky, dtype=np.float64)
    order = math.isqrt(len(lum))
    a = np.asarray(axis, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    c = np.clip(np.asarray(cos_half, dtype=np.float64), -1.0, 1.0)
    sun = brightest_direction(tuple(lum))
    along = a @ sun
    side = sun[None] - along[:, None] * a  # the sun's direction off each axis
    length = np.linalg.norm(side, axis=1)
    u = side / np.maximum(length, 1e-300)[:, None]
    rim = c[:, None] * a + np.sqrt(1.0 - c * c)[:, None] * u
    # inside the cone the sun itself; a sun straight behind the axis (no rim point
    # toward it, and the rim is as far from it all round) leaves the axis alone
    near = np.where((along >= c)[:, None], sun[None], np.where((length > 1e-9)[:, None], rim, a))
    s = np.stack([a, near], axis=1)  # (V, 2, 3)
    bright = np.maximum(basis(s.reshape(-1, 3), order) @ lum, 0.0).reshape(s.shape[:2])
    facing = np.maximum(np.einsum("vsk,vk->vs", s, nrm), 0.0)
    mean = cosine_transfer(nrm, order).astype(np.float64) @ lum
    rho = (bright * facing).max(axis=1) / np.maximum(mean, 1e-12 * max(abs(lum[0]), 1e-300))
    return np.clip(rho, 1.0, SKY_GAIN_MAX)


@functools.lru_cache(maxsize=8)
def brightest_direction(sky: tuple) -> np.ndarray:
    """The unit direction ``(3,)`` where a luminance in SH ``(n*n,)`` (as a tuple: a
    cache key) is brightest, to the spacing of :data:`SKY_SEARCH` directions (a
    constant of the sky: :func:`sky_gain` stays continuous in the cones however
    coarse it is)."""
    from shtools.sh import basis

    lum = np.asarray(sky, dtype=np.float64)
    d = world_directions(SKY_SEARCH)
    out = np.array(d[int(np.argmax(basis(d, math.isqrt(len(lum))) @ lum))])
    out.setflags(write=False)
    return out


def light_weights(points, axis, cos_half, center, radius, position, light_radius
                  ) -> np.ndarray:
    """Weight ``(V,)`` of the traced mesh where the object may hide a spherical light.

    A small light casts the object's shadow far beyond the hand-over of
    :func:`handover_weights` (a lamp's long shadow), where the object's spheres shade
    it poorly.  1 where the light's disc overlaps the cone of the object's bounding
    sphere (and the light is beyond the sphere's near side), 0 once the gap between
    them reaches ``LIGHT_MARGIN`` times the cone's half-angle plus the disc's, a
    smoothstep between.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    to = np.asarray(position, dtype=np.float64)[None] - p
    far = np.sqrt(np.einsum("vk,vk->v", to, to))
    u = to / np.maximum(far, 1e-300)[:, None]
    disc = np.arcsin(np.clip(float(light_radius) / np.maximum(far, 1e-300), 0.0, 1.0))
    cone = np.arccos(np.clip(cos_half, -1.0, 1.0))
    gap = np.arccos(np.clip(np.einsum("vk,vk->v", axis, u), -1.0, 1.0)) - cone - disc
    margin = LIGHT_MARGIN * (cone + disc)
    t = np.clip(1.0 - gap / np.maximum(margin, 1e-300), 0.0, 1.0)
    w = smoothstep(t)
    beyond = far > np.linalg.norm(np.asarray(center, dtype=np.float64)[None] - p,
                                  axis=1) - radius
    return np.where(beyond & (cos_half < 1.0), w, 0.0)


def set_visibility(points, normals, caster, axis, cos_half, order: int, n_dirs: int,
                   offset: float | None = None, around=None) -> np.ndarray:
    """Binary visibility of the caster on the shared set's directions in each cone, in SH.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers and their unit normals (world space).
    caster : RayCaster
        The object's real mesh.
    axis, cos_half : ndarray, shapes (V, 3) and (V,)
        The cones of its bounding sphere
        (:func:`~shtools.geometry.visibility.bounding_cones`).
    order : int
        SH order ``n`` of the result.
    n_dirs : int
        Rays of a receiver whose cone fills its hemisphere (the set has ``2 n_dirs``).
    offset : float, optional
        Ray origin offset along the normal (default ``RAY_OFFSET`` times the caster's
        bounding-box diagonal).
    around : ndarray of int, shape (V, K), optional
        Each receiver's neighbours (indices into ``points``, -1 for none): the set is
        then cast in strata (:func:`set_strata`), every :data:`COARSE_STRIDE`-th
        direction first and the rest only in the strata where a first ray of the
        receiver or of a neighbour was blocked, and next to them.

    Returns
    -------
    ndarray, shape (V, n*n) float64
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    dirs, proj = _set_projection(2 * int(n_dirs), order)
    g = np.zeros((p.shape[0], order * order))
    g[:, 0] = SQRT_4PI
    if offset is None:
        offset = RAY_OFFSET * caster.diagonal
    origins = caster.embree_points(p + offset * nrm)
    a32, n32 = axis.astype(np.float32), nrm.astype(np.float32)
    cos32 = np.asarray(cos_half, dtype=np.float32)[:, None]
    # the run of the set (sorted by height) each cone can hold: its heights' range
    n = dirs.shape[0]
    polar = np.arccos(np.clip(axis[:, 1], -1.0, 1.0))
    half = np.arccos(np.clip(cos_half, -1.0, 1.0))
    first = np.floor(0.5 * n * (1.0 - np.cos(np.maximum(0.0, polar - half))) - 1.0)
    last = np.ceil(0.5 * n * (1.0 - np.cos(np.minimum(math.pi, polar + half))))
    first = np.clip(first, 0, n).astype(np.int64)
    last = np.clip(last, 0, n - 1).astype(np.int64)
    chunks = []
    for start in range(0, p.shape[0], SET_CHUNK):
        stop = min(p.shape[0], start + SET_CHUNK)
        lo, hi = int(first[start:stop].min()), int(last[start:stop].max()) + 1
        if hi > lo:
            chunks.append((start, stop, lo, hi))

    def cone(start, stop, lo, hi):
        """The directions of the chunk's run inside each cone and above the tangent plane."""
        d = dirs[lo:hi]
        return (a32[start:stop] @ d.T >= cos32[start:stop]) & (n32[start:stop] @ d.T > 0)

    def cast(start, stop, lo, hi, take):
        return _cast_chunk(caster, origins[start:stop], dirs[lo:hi], proj[lo:hi],
                           g[start:stop], take)

    if around is None:
        for chunk in chunks:
            cast(*chunk, cone(*chunk))
        return g
    from scipy import sparse

    coarse, cell, touching = set_strata(n)
    found = np.zeros((p.shape[0], touching.shape[0]), dtype=np.float32)
    cones = [cone(*chunk) for chunk in chunks]  # both passes' (a chunk's run is small)
    for (start, stop, lo, hi), take in zip(chunks, cones, strict=True):
        hits = cast(start, stop, lo, hi, take & coarse[lo:hi])
        if hits is not None:  # the strata of the blocked first rays (only > 0 counts below)
            found[start + hits[0], cell[lo + hits[1]]] = 1.0
    # a receiver's strata and its neighbours' (around holds itself first), and those
    # touching them (a sparse product: a stratum touches a few)
    ok = around >= 0
    near = sparse.csr_matrix((np.ones(int(ok.sum()), dtype=np.float32),
                              (np.nonzero(ok)[0], around[ok])), shape=(len(p), len(p)))
    active = (sparse.csr_matrix(touching).T @ (near @ found).T).T > 0
    for (start, stop, lo, hi), take in zip(chunks, cones, strict=True):
        cast(start, stop, lo, hi, take & ~coarse[lo:hi] & active[start:stop][:, cell[lo:hi]])
    return g


def _cast_chunk(caster, origins, dirs, proj, g, take):
    """Cast a chunk's rays ``take`` ``(B, Q)`` (receivers x directions of its run) and
    subtract the blocked ones' projection from ``g`` ``(B, n*n)`` in place; returns the
    (receiver, direction) of each blocked ray, or None when nothing was cast."""
    flat = np.flatnonzero(take)
    if not flat.size:
        return None
    vi, qi = np.divmod(flat, take.shape[1])
    # np.take gathers rows several times faster than fancy indexing
    blocked = caster.occluded_embree(np.take(origins, vi, axis=0), np.take(dirs, qi, axis=0))
    hits = np.zeros(take.size, dtype=np.float32)
    # np.compress, not a boolean index: on a mask without runs (NumPy 2) 4x faster
    hits[np.compress(blocked, flat)] = 1.0
    g -= hits.reshape(take.shape) @ proj
    return np.compress(blocked, vi), np.compress(blocked, qi)


#: Every this-th direction of the shared set is cast first where it is cast in strata
#: (:func:`set_visibility` with ``around``).
COARSE_STRIDE = 4


@functools.lru_cache(maxsize=8)
def set_strata(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The shared set of ``n`` directions cut into strata about every
    :data:`COARSE_STRIDE`-th: ``(n,)`` bool of those, the stratum ``(n,)`` of each
    direction (its nearest of them) and ``(S, S)`` float32 1 where two strata touch (a
    direction of one has the other's first second nearest) or are the same."""
    from shtools.geometry.visibility import cut_into_strata

    first, cell, touching = cut_into_strata(world_directions(n), COARSE_STRIDE)
    coarse = np.zeros(n, dtype=bool)
    coarse[first] = True
    out = (coarse, cell, touching)
    for x in out:
        x.setflags(write=False)
    return out


@functools.lru_cache(maxsize=8)
def _set_projection(n: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The shared set in float32 ``(n, 3)``, its projection ``(4π / n) y(s)`` ``(n, order^2)``."""
    from shtools.sh import basis

    dirs = world_directions(n)
    proj = (basis(dirs, order) * (4.0 * math.pi / n)).astype(np.float32)
    d32 = np.ascontiguousarray(dirs, dtype=np.float32)
    d32.setflags(write=False)
    proj.setflags(write=False)
    return d32, proj


def traced_ground(points, normals, vertices, faces, caster, order: int, n_dirs: int,
                  spheres=None, lights=(), strata: bool = False, rest=None, *, cache=None,
                  still: bool = False, sky=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The traced part of an object's shadow on receivers, and each one's hand-over weight.

    Parameters
    ----------
    points, normals : array_like, shape (R, 3)
        The receivers (world space) and their unit normals.
    vertices, faces : array_like, shapes (V, 3) and (F, 3)
        The posed mesh (its bounding sphere: the box centre and the farthest vertex).
    caster : RayCaster
        Its Embree scene.
    order : int
        Shading order.
    n_dirs : int
        Rays of a receiver whose cone fills its hemisphere.
    spheres : tuple of ndarray, shapes (S, 3) and (S,), optional
        Spheres bounding the mesh (its blocker's): the filter's distance to the mesh
        is the exact one near them and the distance to their union beyond
        (:func:`~shtools.scene.receiver_filter.mesh_distance`; object receivers, which
        touch the mesh, take the spheres' throughout); without them, the distance to
        the mesh's nearest vertex or face centroid.
    lights : sequence of (position (3,), radius)
        Spherical lights: a receiver that sees one behind the object is traced
        however far (:func:`light_weights`).
    strata : bool
        The receivers are objects' (contact shadows): the set is cast in strata
        (``around`` of :func:`set_visibility`: the receivers' neighbours share what
        their first rays found), with no denser set, and the filter's distance is
        the spheres'.
    rest : tuple, optional
        The receivers' rest geometry when they are one rigid object (``rest`` of
        :func:`~shtools.scene.receiver_filter.neighbours`).
    cache : SetupCache, optional
        The set-up cache (:mod:`shtools.cache`): the receivers' neighbour lists (or
        those of ``rest``), and with ``still`` the whole result, are computed once for
        all bakes of the same inputs.  Only for receivers that do not move: a moving
        receiver's lists would be a new entry every frame.
    still : bool
        The object, the receivers and the lights never move in this bake (the result
        is the same every frame: worth a cache entry, and the caster is not used on a
        hit).
    sky : array_like, shape (n*n,), optional
        The environment's luminance in SH: the hand-over's ray count weighed by the
        light behind the object (:func:`sky_gain`).

    Returns
    -------
    rows : ndarray of int, shape (T,)
        Indices into ``points`` of the receivers of weight above 0.
    weight : ndarray, shape (T,)
        Their weights of the traced mesh (the rest is the spheres').
    visibility : ndarray, shape (T, order^2) float64
        The filtered traced visibility.
    """
    sky = None if sky is None else np.asarray(sky, dtype=np.float64)
    key = (caster, points, normals, vertices, faces, order, n_dirs, spheres, tuple(lights),
           strata, sky)
    kept = _kept_ground(key)
    if kept is not None:  # a static object over static receivers: the last frame's result
        return kept
    args = (points, normals, vertices, faces, caster, order, n_dirs, spheres, lights, strata,
            rest, cache, sky)
    if still and cache is not None:
        parts = {"points": np.asarray(points, dtype=np.float64),
                 "normals": np.asarray(normals, dtype=np.float64),
                 "vertices": np.asarray(vertices, dtype=np.float64),
                 "faces": np.asarray(faces, dtype=np.int64), "order": int(order),
                 "n_dirs": int(n_dirs), "strata": bool(strata),
                 "spheres": None if spheres is None else [np.asarray(x) for x in spheres],
                 "lights": [[np.asarray(c, dtype=np.float64), float(r)] for c, r in lights],
                 "sky": sky,
                 "rest": None if rest is None else [np.asarray(rest[0]), np.asarray(rest[1]),
                                                    float(rest[2])]}
        got = cache.fetch("traced_ground", TRACED_GROUND_VERSION, parts, lambda: dict(
            zip(("rows", "weight", "visibility"), _trace_ground(*args), strict=True)))
        return _keep_ground(key, (got["rows"], got["weight"], got["visibility"]))
    return _keep_ground(key, _trace_ground(*args))


#: Version of :func:`traced_ground`'s results in the set-up cache.
TRACED_GROUND_VERSION = 4


def _trace_ground(points, normals, vertices, faces, caster, order, n_dirs, spheres, lights,
                  strata, rest, cache, sky) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`traced_ground` computed (its parameters, in order)."""
    from shtools.geometry.bounding import box_sphere
    from shtools.geometry.visibility import bounding_cones

    v = np.asarray(vertices, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    # the bound the pairing's reach and light tests use (contact_casters)
    center, radius = box_sphere(v)
    axis, cos_half = bounding_cones(p, nrm, center, radius)
    rays = cone_rays(cos_half, n_dirs)
    # the gain matters only between the hand-over's ends (at most SKY_GAIN_MAX short)
    band = np.flatnonzero((rays < HANDOVER_RAYS[1]) & (rays * SKY_GAIN_MAX > HANDOVER_RAYS[0]))
    rays[band] *= sky_gain(axis[band], nrm[band], cos_half[band], sky)
    weight = handover_weights(rays)
    for position, light_radius in lights:
        weight = np.maximum(weight, light_weights(p, axis, cos_half, center, radius,
                                                  position, light_radius))
    rows = np.flatnonzero(weight > 0)
    weight = weight[rows]
    if not rows.size:
        return rows, weight, np.zeros((0, order * order))
    idx, dist = neighbours(p, nrm, rest, cache)
    # neighbours among the traced receivers only (row of each in ``rows``, -1 if none)
    where = np.full(len(p) + 1, -1)
    where[rows] = np.arange(len(rows))
    local = where[idx[rows]]  # idx -1 (facing away) reads the sentinel
    g = set_visibility(p[rows], nrm[rows], caster, axis[rows], cos_half[rows], order, n_dirs,
                       around=local if strata else None)
    # receivers with no blocked ray around them keep the exact constant
    hit = np.zeros(len(rows) + 1, dtype=bool)
    hit[:-1] = g[:, 1:].any(axis=1) | (g[:, 0] != SQRT_4PI)
    busy = np.flatnonzero(hit[local].any(axis=1))
    if busy.size:
        at = rows[busy]
        if spheres is None or not len(spheres[1]):
            near = nearest_distance(p[at], v, faces, caster)
        elif strata:
            # object receivers touching the mesh: all of them near its spheres, where
            # the exact distance would cost more than their filter (their smoothness
            # holds without it: bench_look's demo walker parts, 1.00-1.03)
            near = sphere_distance(p[at], *spheres)
        else:
            near = mesh_distance(p[at], v, faces, spheres)
        step = math.sqrt(4.0 * math.pi / (2 * int(n_dirs))) * near
        # object receivers (strata) take no denser set: near a touching mesh nearly all
        # of them would, at more than the rest of a frame's cost, for an error already
        # within the objects' target (measured: CHANGELOG, bench_look --demo)
        fine = (np.zeros(busy.size) if strata else
                refine_weights(step / REFINE_STEPS, receiver_spacing(idx[at], dist[at])))
        sparse = np.flatnonzero(fine > 0)
        if sparse.size:  # too few neighbours inside the filter: the denser set there
            rs = rows[busy[sparse]]
            dense = set_visibility(p[rs], nrm[rs], caster, axis[rs], cos_half[rs], order,
                                   REFINE_FACTOR * int(n_dirs))
            w = fine[sparse, None]
            g[busy[sparse]] = w * dense + (1.0 - w) * g[busy[sparse]]
        around = local[busy]
        g[busy] = surface_filter(g, FILTER_SPACING / math.sqrt(FILTER_PASSES) * step, around,
                                 np.where(around >= 0, dist[at], np.inf), rows=busy,
                                 passes=FILTER_PASSES)
    return rows, weight, g


def refine_weights(step, spacing) -> np.ndarray:
    """Weight ``(R,)`` of the ``REFINE_FACTOR`` times denser direction set per receiver.

    0 where ``step`` ``(R,)`` (in the caller's units of one direction's step spacing)
    is at least the receivers' ``spacing`` ``(R,)`` (:func:`receiver_spacing`), 1 where
    at most half of it, a smoothstep of ``spacing / step`` between (a receiver mixes the
    two estimates, each unbiased: no seam where the density changes).
    """
    s = np.asarray(spacing, dtype=np.float64)
    w = np.asarray(step, dtype=np.float64)
    ratio = np.where(w > 0, s / np.where(w > 0, w, 1.0), np.inf)
    t = np.clip(ratio - 1.0, 0.0, 1.0)
    return np.where(np.isfinite(s), smoothstep(t), 0.0)
