"""SHEXP runtime: per-vertex soft shadows from sphere blockers (NumPy + h5py only).

This package ships into other pipelines without the geometry stack: it imports
only numpy, h5py, :mod:`shtools.sh`, :mod:`shtools.data_formats` and its own
modules (``tests/test_runtime_imports.py`` enforces it).

Usage (one frame)::

    from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker, SphereLight

    rt = ShadowRuntime(ShadowSettings(order=4))          # tables built if not given
                                                         # (rt.close() stops workers)
    clusters = rt.clusters(rest_vertices)                # Lloyd, once; reuse every frame
    blockers = [SphereBlocker(centers, radii, tree=(parent, leaf))]
    g = rt.visibility(vertices, normals, blockers, clusters)          # (V, 16)
    rgb = rt.shade(g, vertices, normals, env_sh,                       # (V, 3)
                   sphere_lights=[SphereLight((0, 3, 0), 0.5, (5, 5, 4))])

Pipeline per frame (SHEXP sections 6–7):

1. refit the blocker trees from their moved leaves; per receiver cluster take
   the eq. 36 cut (``theta_max``) and the eq. 37 ratio vectors at the cluster
   centre (:mod:`~shtools.runtime.hierarchy`); with ``cluster_blend``, receivers
   near a cluster boundary also take the nearby clusters' cuts and are blended
   with weights continuous over the surface (:mod:`~shtools.runtime.cluster_blend`);
2. per vertex, accumulate eq. 38 log vectors of the cut spheres after the
   self-shadow rules of Sec. 6.2 (:mod:`~shtools.runtime.accumulate`,
   :mod:`~shtools.runtime.self_shadow`) at the accumulation order ``n_acc``;
3. exponentiate (HYB at ``n_acc <= 4``, PS*-p above, or any method of
   :func:`shtools.sh.exp`) and truncate to the shading order ``n``;
4. shade white Lambertian receivers with environment lighting and spherical
   lights, windowed (:mod:`~shtools.runtime.shading`).

Small spherical lights: :mod:`~shtools.runtime.ssoc` (the soft shadow
occlusion camera, Mo et al.; NumPy rasterised shadow and distortion maps) gives
the visible fraction ``S`` of a light per receiver, shaded as ``S`` times
:func:`~shtools.runtime.shading.sphere_light_unshadowed` (``docs/ssoc.md``).

Defaults and costs (``benchmarks/bench_runtime.py``): the log is
accumulated at ``n_acc = min(n + 2, 6)`` and exponentiated there with PS*-2
(HYB when ``n_acc <= 4``), then truncated to ``n``.  Accumulating at 6 for
shading at 4 roughly halves the truncation error of the visibility (Ren et al.
2006, Fig. 7e) — it is what meets the 3 % radiance target against ray tracing of
the sphere set — at a higher frame CPU time than ``acc_order=4``, the fast
setting (``benchmarks/RESULTS.md``).  Tables passed in must have exactly the
accumulation order (the cap log depends on the order it is computed at).

Performance notes: a frame's receiver clusters are split into parts of equal
work, one evaluated in the calling process and the others in worker
processes (accumulation and exp per part; :mod:`~shtools.runtime.parallel`,
``processes=None`` = one per core; the default is 1, the CLI opts in) -- threads do not
scale here, the GIL
hand-over between hundreds of short NumPy passes eats the gain.
Accumulation runs on float32 blocks of (tiles of 32
receivers of one cluster) x (the tile's sphere list, padded with radius-0
spheres), so per-cluster work is batched without per-pair gathers; a tile's
list is its cluster's cut minus the spheres behind the tangent plane of all
its receivers (exactly zero contributions, ~18 % of the pairs of a battle
scene), ordered so the self-shadow rules run on a prefix of rows only; the cap
log comes from one gather per band of a ratio table ``F_l(x)/x``.  The
exp uses exact quadrature SH products on BLAS, split by the z and azimuthal
parity of the coefficients (4x fewer flops at order >= 5), with reused scratch
and the last squaring projected onto the shading order only
(:mod:`~shtools.runtime.fast_exp`); ratio vectors use the addition theorem
(no per-pair ``n*n`` basis); ``H(N)`` is kept for receivers whose normal did
not change, and ``L_H(N)`` as well while the environment light is unchanged.
Set ``OPENBLAS_NUM_THREADS=1`` (the CLI does): threaded OpenBLAS spins on the
small matrix products.

Public API
----------
``ShadowSettings(order=4, acc_order=None, exp_method="auto", window="cosine",
window_h=None, theta_max=radians(25), theta_min=radians(1), hierarchy=True,
vertices_per_cluster=400, threads=1, processes=1, ...)``
    Parameters (:mod:`~shtools.runtime.settings`); ``acc_order=None`` means
    ``min(n + 2, 6)``.
``SphereBlocker(centers (N,3), radii (N,), tree=None | (parent (M,), leaf (M,)))``
``LogBlocker`` — protocol: any object with ``log_visibility(points (V,3), normals (V,3),
order) -> (V, order^2)`` may be passed among the blockers (summed in log space)
``SphereLight(position (3,), radius, color (3,))``
``FieldBlocker(table, rotation (3,3), translation (3,), scale=1.0, skip_rows=None)``
    A rigid object's shadow field (``read_field`` of a ``field`` asset) posed
    for the frame (a ``LogBlocker``); ``FieldBlocker.from_matrix(field, M (4,4))``
    refuses non-uniform scale and shear.  Pass it in ``blockers`` with the others;
    ``settings.field_space`` ("log" default, or "product") says how it combines
    (:mod:`~shtools.runtime.fields`).
``SelfVisibility(log (R, n_acc^2) | None, rows, rotation=None, blocker=None, visibility=None)``
    An object's self-visibility on its own receiver rows, in place of its own
    blocker there (spheres or a log blocker): a rigid object's ``transfer`` log,
    added in log space, or ``visibility (R, m^2)`` (a skinned object's posed mesh
    traced this frame), multiplied in after the exp
    (``visibility(..., self_visibility=[...])``).
``ShadowRuntime(settings=None, tables=None)`` (also a context manager; ``.close()``)
    ``.clusters(vertices, groups=None) -> ReceiverClusters``;
    ``.visibility(vertices, normals, blockers, clusters=None) -> (V, n*n)``;
    ``.log_visibility(...) -> (V, n_acc^2)``; ``.exponentiate(f)``;
    ``.shade(visibility, vertices, normals, env_sh=None, sphere_lights=(),
    local_visibility=None, form="tabulated") -> (V, 3)``; ``.last_stats``
    (pairs, spheres per vertex, clusters, processes, CPU seconds per stage).
``ReceiverClusters``, ``lloyd_clusters(vertices, vertices_per_cluster, groups=None)``
``fast_exp(f, method, tables)`` — HYB / PS*-p / OL / Volterra for many vectors
``accumulate_log(points, normals, centers, radii, table, weights=None, ...)``
``apply_self_shadow_rules(dx, dy, dz, radius, nx, ny, nz)``
``CapLogTable(tables, order)``
``ScalingTable(read_scaling(path))`` — SH scaling (Wang et al.): ``.values_at(k)``,
    ``.matrix(k) -> (V, n*n, n*n)``, ``.apply(f, k, axes) = D^T M(k) D f``
    (:mod:`~shtools.runtime.scaling`)
``midrange_lighting(env_sh, points, center, radius, table, out_order=None)``
    ``-> (V, n*n, 3)`` per-vertex environment inside a finite sphere; pass it as
    ``env_sh`` to ``shade``.
"""

from shtools.registry import lazy_attributes

# a function named as its module: bound here, or importing the module (the shading
# does) would leave the package attribute the module
from shtools.runtime.fast_exp import fast_exp

#: public name -> module, loaded on first use: a caller of one part (the shading, the
#: settings: ``shtools relight``) does not pay for importing the evaluator, the
#: accumulation and the worker processes
_LAZY = {
    "accumulate_log": "shtools.runtime.accumulate",
    "LogBlocker": "shtools.runtime.blockers",
    "SelfVisibility": "shtools.runtime.blockers",
    "SphereBlocker": "shtools.runtime.blockers",
    "SphereLight": "shtools.runtime.blockers",
    "ReceiverClusters": "shtools.runtime.clusters",
    "lloyd_clusters": "shtools.runtime.clusters",
    "ShadowRuntime": "shtools.runtime.evaluator",
    "FieldBlocker": "shtools.runtime.fields",
    "FieldTable": "shtools.runtime.fields",
    "field_log_visibility": "shtools.runtime.fields",
    "field_product_visibility": "shtools.runtime.fields",
    "CapLogTable": "shtools.runtime.log_table",
    "ScalingTable": "shtools.runtime.scaling",
    "midrange_lighting": "shtools.runtime.scaling",
    "apply_self_shadow_rules": "shtools.runtime.self_shadow",
    "ShadowSettings": "shtools.runtime.settings",
    "cosine_transfer": "shtools.runtime.shading",
    "shade": "shtools.runtime.shading",
    "sphere_light_sh": "shtools.runtime.shading",
}


__getattr__, __dir__ = lazy_attributes(__name__, _LAZY)

__all__ = [
    "CapLogTable",
    "FieldBlocker",
    "FieldTable",
    "LogBlocker",
    "ReceiverClusters",
    "ScalingTable",
    "SelfVisibility",
    "ShadowRuntime",
    "ShadowSettings",
    "SphereBlocker",
    "SphereLight",
    "accumulate_log",
    "apply_self_shadow_rules",
    "cosine_transfer",
    "fast_exp",
    "field_log_visibility",
    "field_product_visibility",
    "lloyd_clusters",
    "midrange_lighting",
    "shade",
    "sphere_light_sh",
]
