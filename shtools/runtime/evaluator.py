"""The per-frame evaluator: :class:`ShadowRuntime` (see ``docs/architecture.md``, runtime)."""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from dataclasses import dataclass

import numpy as np

from shtools.errors import InputError, ShtoolsError
from shtools.runtime.accumulate import BlockKernel, accumulate_log
from shtools.runtime.blockers import LogBlocker, SelfVisibility, SphereBlocker, SphereLight
from shtools.runtime.clusters import ReceiverClusters, lloyd_clusters
from shtools.runtime.deformable import DeformableBlocker
from shtools.runtime.fast_exp import FAST_METHODS, QuadratureProducts, fast_exp
from shtools.runtime.fields import FieldBlocker, field_log_visibility, field_product_visibility
from shtools.runtime.hierarchy import build_forest, leaf_spheres, ratio_weights, tree_cuts
from shtools.runtime.log_table import CapLogTable
from shtools.runtime.parallel import (
    FRAME_PARTS,
    MIN_PARALLEL_PAIRS,
    PoolParts,
    VertexWorkers,
    resolve_processes,
    split_clusters,
)
from shtools.runtime.settings import ShadowSettings
from shtools.runtime.shading import (
    cosine_transfer,
    desaturate_negative,
    environment_matrices,
    lit_transfer,
)
from shtools.runtime.shading import shade as _shade
from shtools.runtime.tiling import accumulate_clusters
from shtools.sh import exp as sh_exp
from shtools.sh import product as sh_product
from shtools.sh import rotation_matrix

#: Blockers evaluated per part of a frame (in the worker processes too) and
#: combined as ``settings.field_space`` says: rigid and deformable shadow fields.
PART_BLOCKERS = (FieldBlocker, DeformableBlocker)
#: A deformable field at one receiver (lookup, scaling, exp) costs about as much CPU
#: as this many sphere-receiver pairs; it weighs receivers when a frame is split
#: (``MIN_PARALLEL_PAIRS``, cluster costs): the CPU of one deformable receiver over
#: that of one sphere-receiver pair, exp included (order 4, acc 6, either field space).
DEFORMABLE_RECEIVER_PAIRS = 64


def _self_rows(sv: SelfVisibility, n_vertices: int, covered: int) -> np.ndarray:
    """Indices ``(R,)`` of the rows ``sv.rows`` selects among ``n_vertices``; they must
    number ``covered``, the vertices its log or visibility holds."""
    rows = np.arange(n_vertices)[sv.rows]
    if rows.shape[0] != covered:
        raise InputError(f"self-visibility covers {covered} vertices but its rows select "
                         f"{rows.shape[0]}")
    return rows


class ShadowRuntime:
    """SHEXP soft shadows per receiver vertex from sphere blockers.

    Parameters
    ----------
    settings : ShadowSettings, optional
        Defaults when omitted.
    tables : dict, optional
        Log tables (``theta``, ``log_zh``, ``ol_norm``, ``ol_a``, ``ol_b``) of
        the accumulation order, as from :func:`shtools.sh.tables.build_log_tables`
        or :func:`shtools.data_formats.tables.read_tables`; built when omitted.
        The cap log depends on the order it was computed at, so the tables must
        have exactly the accumulation order.
    part_pool : shtools.tasks.TaskPool, optional
        Run the parts of a large frame as tasks of this pool (e.g. a Dask
        cluster; :class:`~shtools.runtime.parallel.PoolParts`) instead of on
        local worker processes; the bytes are the same.

    Attributes
    ----------
    last_stats : dict
        Counters and timings of the last :meth:`visibility` call: ``pairs``
        (sphere-vertex pairs accumulated), ``spheres_per_vertex``,
        ``clusters``, ``pairs_evaluated`` (pairs the kernel ran, after dropping
        spheres behind every receiver of a tile, with padding), ``seconds`` per
        stage (``cuts``, ``accumulate``, ``exp``; process CPU time, robust to
        other jobs on the machine).
    """

    def __init__(self, settings: ShadowSettings | None = None, tables: dict | None = None,
                 part_pool=None):
        self.settings = settings if settings is not None else ShadowSettings()
        self.settings.validate()
        self.order = self.settings.order
        self.acc_order = self.settings.resolved_acc_order()
        self.exp_method = self.settings.resolved_exp_method()
        if tables is None:
            from shtools.sh.tables import default_tables

            tables = default_tables(self.acc_order)
        table_order = np.asarray(tables["log_zh"]).shape[-1]
        if table_order != self.acc_order:
            raise InputError(
                f"log tables have order {table_order} but the accumulation order is "
                f"{self.acc_order}; build them with `shtools tables log --order "
                f"{self.acc_order}` or set acc_order={table_order}"
            )
        self.tables = tables
        self.table = CapLogTable(tables, self.acc_order)
        self._kernels = [BlockKernel(self.table) for _ in range(self.settings.threads)]
        self._auto_clusters: ReceiverClusters | None = None
        self._auto_groups: np.ndarray | None = None
        self._rotated_logs: dict = {}  # id(log) -> (log, rotation, rotated log), last frame
        self._transfer_cache: tuple[np.ndarray, np.ndarray] | None = None
        self._products: QuadratureProducts | None = None  # self-visibility products
        self._lit_cache: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._exp_workspaces: list = []  # fast_exp scratch, kept between frames
        self._exp_zero: np.ndarray | None = None  # exp(0) at the shading order
        #: processes sharing the per-vertex stages (worker processes start on the
        #: first frame of at least MIN_PARALLEL_PAIRS pairs)
        self.processes = resolve_processes(self.settings.processes)
        self._workers: VertexWorkers | None = None
        self._part_pool = part_pool
        self._pool_parts: PoolParts | None = None  # started on the first split frame
        self.last_stats: dict = {}

    # -- clusters --------------------------------------------------------------
    def clusters(self, vertices, groups=None) -> ReceiverClusters:
        """Lloyd receiver clusters for :meth:`visibility`; compute once, reuse every frame.

        Parameters
        ----------
        vertices : array_like, shape (V, 3)
            Receiver positions (e.g. the first frame).
        groups : array_like of int, shape (V,), optional
            Object id per vertex; clusters never span two objects.

        Returns
        -------
        ReceiverClusters
        """
        return lloyd_clusters(vertices, self.settings.vertices_per_cluster, groups=groups)

    # -- visibility ------------------------------------------------------------
    def log_visibility(self, vertices, normals, blockers: list[SphereBlocker],
                       clusters: ReceiverClusters | None = None, *,
                       self_visibility: tuple[SelfVisibility, ...] | list = ()) -> np.ndarray:
        """Accumulated log visibility at the accumulation order, shape ``(V, n_acc^2)`` float32.

        Parameters are those of :meth:`visibility`.  Evaluated in this process.
        """
        pts, nrm = _check_receivers(vertices, normals)
        spheres, _ = self._blockers(blockers)
        own, exclude, skip = self._self_terms(self_visibility, pts.shape[0], blockers)
        work = self._frame_work(pts, spheres, clusters, exclude)
        t1 = time.process_time()
        f = self._accumulate(work.task(pts, nrm), self.last_stats)
        extra = _add(self._other_logs(pts, nrm, blockers, skip), own)
        if extra is not None:
            f += extra
        self.last_stats["seconds"]["accumulate"] = time.process_time() - t1
        return f

    def visibility(self, vertices, normals, blockers: list[SphereBlocker],
                   clusters: ReceiverClusters | None = None, *,
                   self_visibility: tuple[SelfVisibility, ...] | list = ()) -> np.ndarray:
        """Shadowing visibility per receiver vertex: accumulate logs, exp, truncate.

        Parameters
        ----------
        vertices : array_like, shape (V, 3)
            Receiver positions this frame.
        normals : array_like, shape (V, 3)
            Unit receiver normals this frame.
        blockers : list of SphereBlocker or LogBlocker
            Blockers this frame: sphere sets (trees are refit from their
            leaves) and blockers that give their own log visibility, added to
            the spheres' log sum before the exp.
        clusters : ReceiverClusters, optional
            From :meth:`clusters`; with ``hierarchy`` on and none given, clusters
            are computed on the first call and reused while the vertex count
            stays the same (built per object when ``self_visibility`` is given).
        self_visibility : sequence of SelfVisibility
            Self-visibility of objects' real meshes on their own receiver rows:
            logs are added in log space, visibilities multiply the result after
            the exp; each skips its object's own blocker (an index into
            ``blockers``: a sphere set or a log blocker such as a deformable
            field) on those rows.  Clusters must not mix rows of different
            objects (build them with ``groups``).

        Returns
        -------
        ndarray, shape (V, n*n) float32
            Visibility vectors ``g`` (eq. 8) at the shading order.

        Notes
        -----
        Frames of at least ``MIN_PARALLEL_PAIRS`` sphere-receiver pairs are
        split by receiver cluster into ``FRAME_PARTS`` parts; with
        ``settings.processes > 1`` (the default on a multi-core machine) worker
        processes share them with this process (:mod:`shtools.runtime.parallel`;
        :meth:`close` stops them).  The split does not depend on the process
        count, so the result is the same bytes with any number of processes.
        """
        pts, nrm = _check_receivers(vertices, normals)
        g = self._visibility(pts, nrm, blockers, clusters, self_visibility)
        return self._multiply_self(g, self_visibility)

    def _visibility(self, pts, nrm, blockers, clusters, self_visibility) -> np.ndarray:
        """:meth:`visibility` before the self-visibilities given as visibility."""
        spheres, others = self._blockers(blockers)
        if any(isinstance(b, FieldBlocker) for b in others):
            return self._visibility_with_fields(pts, nrm, blockers, clusters, self_visibility)
        own, exclude, skip = self._self_terms(self_visibility, pts.shape[0], blockers)
        work = self._frame_work(pts, spheres, clusters, exclude)
        stats = self.last_stats
        extra = _add(self._other_logs(pts, nrm, blockers, skip, in_parts=True), own)
        parts = self._part_blockers(blockers, skip, pts.shape[0])
        cost = 0 if parts is None else DEFORMABLE_RECEIVER_PAIRS * len(parts.deformables)
        if stats["pairs"] + cost * pts.shape[0] >= MIN_PARALLEL_PAIRS:
            w0 = time.perf_counter()
            g = self._split_visibility(work, pts, nrm, extra, parts, cost)
            stats["seconds"]["accumulate_exp_wall"] = time.perf_counter() - w0
            return g
        t1 = time.process_time()
        f = self._accumulate(work.task(pts, nrm), stats)
        if extra is not None:
            f += extra
        t2 = time.process_time()
        g = self.exponentiate(f) if parts is None else self._combine_parts(parts, pts, nrm, f)
        stats["seconds"]["accumulate"] = t2 - t1
        stats["seconds"]["exp"] = time.process_time() - t2
        return g

    def run_part(self, task) -> tuple[np.ndarray, int]:
        """Visibility ``(V', n*n)`` and evaluated pairs of one part of a frame.

        ``task`` comes from :meth:`FrameWork.task` (also what a worker process
        runs; see :mod:`shtools.runtime.parallel`), or is ``("with_log", task,
        extra)`` with the part's rows of the other blockers' log sum.
        """
        if task[0] == "fields":
            return self._field_part(task), 0
        extra = parts = None
        if task[0] == "with_log":
            _, task, extra, parts = task
        stats = {"pairs_evaluated": 0}
        f = self._accumulate(task, stats)
        if extra is not None:
            f += extra
        if parts is not None:
            return self._combine_parts(parts, task[1], task[2], f), stats["pairs_evaluated"]
        return self.exponentiate(f), stats["pairs_evaluated"]

    def _blockers(self, blockers) -> tuple[list[SphereBlocker], list]:
        """:func:`_check_blockers`, and shadow fields must have the shading order."""
        spheres, others = _check_blockers(blockers)
        for b in others:
            if isinstance(b, FieldBlocker) and b.table.order != self.order:
                raise InputError(f"a shadow field has SH order {b.table.order} but the runtime "
                                 f"shades at order {self.order}; resample it with "
                                 f"`shtools field sample --order {self.order}`")
        return spheres, others

    def _visibility_with_fields(self, pts, nrm, blockers, clusters, self_visibility
                                ) -> np.ndarray:
        """Visibility of a frame with shadow fields.

        The other blockers' log sum (spheres, other log blockers, self-visibility)
        is made in this process with :meth:`log_visibility` (field positions are
        kept in the list so self-visibility blocker indices stay valid); the field
        lookups and the exp (``field_space = "log"``) or the exp and the products
        (``"product"``) are split by receiver rows over this process and the
        workers when the frame has enough (receiver, field) pairs.
        """
        rest = [b for b in blockers if not isinstance(b, PART_BLOCKERS)]
        if rest or self_visibility:
            f = self.log_visibility(pts, nrm, [_NoField() if isinstance(b, PART_BLOCKERS)
                                               else b for b in blockers], clusters,
                                    self_visibility=self_visibility)
        else:
            self.last_stats = {"pairs": 0, "pairs_evaluated": 0, "clusters": 0,
                               "seconds": {}, "processes": 1}
            f = None
        stats = self.last_stats
        own = _own_rows(self_visibility, pts.shape[0], blockers)
        blocks = self._part_blockers(blockers, own, pts.shape[0])
        stats["field_pairs"] = pts.shape[0] * (len(blocks.fields) + DEFORMABLE_RECEIVER_PAIRS
                                               * len(blocks.deformables))
        parts = self.processes if stats["field_pairs"] >= MIN_PARALLEL_PAIRS else 1
        bounds = np.linspace(0, pts.shape[0], parts + 1).astype(np.int64)
        tasks = [(a, b, ("fields", pts[a:b], nrm[a:b], None if f is None else f[a:b],
                         blocks.take(np.arange(a, b))))
                 for a, b in itertools.pairwise(bounds) if b > a]
        w0 = time.perf_counter()
        g = np.empty((pts.shape[0], self.order * self.order), dtype=np.float32)
        if len(tasks) == 1:
            g[:] = self._field_part(tasks[0][2])
        else:
            if self._workers is None:
                self._workers = VertexWorkers(self.processes - 1, self.settings, self.tables)
            try:
                futures = [self._workers.submit(task) for _, _, task in tasks[1:]]
                a, b, task = tasks[0]
                g[a:b] = self._field_part(task)
                for (a, b, _), future in zip(tasks[1:], futures, strict=True):
                    g[a:b] = self._workers.result(future)[0]
            except ShtoolsError:
                self.close()
                raise
        stats["processes"] = len(tasks)
        stats.setdefault("seconds", {})["fields_exp_wall"] = time.perf_counter() - w0
        return g

    def _field_part(self, task) -> np.ndarray:
        """Visibility ``(V', n*n)`` of one ``"fields"`` part (:meth:`_combine_parts`)."""
        _, pts, nrm, f, blocks = task
        return self._combine_parts(blocks, pts, nrm, f)

    def _part_blockers(self, blockers, skip: dict | None, n_vertices: int
                       ) -> _PartBlockers | None:
        """The frame's shadow fields (rigid, deformable) for :meth:`_combine_parts`, or None.

        ``skip``: position in ``blockers`` -> bool mask ``(V,)`` of the rows a
        deformable field is not evaluated on (its object's own rows).  The
        deformable samples are turned into their axis frames here, once, before
        the parts go to the workers.
        """
        s = self.settings
        space = s.resolved_field_space("deformable")
        fields, deformables = [], []
        for k, b in enumerate(blockers):
            if isinstance(b, FieldBlocker):
                mask = None
                if b.skip_rows is not None:
                    mask = np.zeros(n_vertices, dtype=bool)
                    mask[np.asarray(b.skip_rows, dtype=np.int64)] = True
                fields.append((b, mask))
            elif isinstance(b, DeformableBlocker):
                b.prepare(log=space == "log")
                deformables.append((b, None if not skip else skip.get(k)))
        if not (fields or deformables):
            return None
        return _PartBlockers(s.resolved_field_space("rigid"), space, fields, deformables)

    def _combine_parts(self, blocks: _PartBlockers, pts, nrm, f) -> np.ndarray:
        """Visibility ``(V', n*n)`` float32 of receivers with the other blockers' log sum
        ``f (V', n_acc^2)`` (or None) and the shadow fields ``blocks``.

        Fields combined in ``"log"`` space add their logs to ``f`` and one exp
        follows; those in ``"product"`` space are then multiplied in with
        truncated SH products at the accumulation order -- deformable fields
        first, then rigid ones (nearest first) -- and the result is truncated to
        the shading order.
        """
        m = self.acc_order
        if f is not None and not f.any():
            f = None  # nothing else blocks these receivers: no exp of zeros
        fields = [fb for fb, _ in blocks.fields]
        log_fields = fields if blocks.rigid_space == "log" else []
        log_deformables = blocks.deformable_space == "log" and bool(blocks.deformables)
        if log_fields or log_deformables:
            f = (np.zeros((pts.shape[0], m * m), dtype=np.float32) if f is None
                 else np.array(f, dtype=np.float32))
            if log_fields:
                field_log_visibility(pts, nrm, log_fields, self.order, m, out=f)
            if log_deformables:
                for d, rows in _deformable_rows(blocks, pts.shape[0]):
                    f[rows] += d.log_visibility(pts[rows], nrm[rows], m)
        base = None if f is None else self.exponentiate(f)
        if blocks.deformables and not log_deformables:
            g = np.zeros((pts.shape[0], m * m))
            if base is None:
                g[:, 0] = math.sqrt(4.0 * math.pi)
            else:
                g[:, :base.shape[1]] = base
            for d, rows in _deformable_rows(blocks, pts.shape[0]):
                g[rows] = sh_product(g[rows], d.visibility(pts[rows], nrm[rows], m), m)
            base = g
        if fields and not log_fields:
            return field_product_visibility(pts, nrm, fields, self.order, m,
                                            base=base).astype(np.float32)
        if base is None:  # nothing blocks these receivers
            base = np.zeros((pts.shape[0], self.order * self.order), dtype=np.float32)
            base[:, 0] = math.sqrt(4.0 * math.pi)
        return np.ascontiguousarray(base[:, :self.order * self.order], dtype=np.float32)

    def _other_logs(self, pts, nrm, blockers: list, skip: dict | None = None, *,
                    in_parts: bool = False) -> np.ndarray | None:
        """Sum of the log visibilities of the non-sphere blockers, ``(V, n_acc^2)`` or None.

        ``skip``: position in ``blockers`` -> bool mask ``(V,)`` of the rows that
        blocker is not evaluated on (its object's own rows, which its
        self-visibility covers).  ``in_parts``: leave out the shadow fields the
        frame's parts evaluate (:data:`PART_BLOCKERS`).
        """
        left_out = (SphereBlocker, _NoField, *(PART_BLOCKERS if in_parts else ()))
        others = [(k, b) for k, b in enumerate(blockers) if not isinstance(b, left_out)]
        if not others:
            return None
        t0 = time.process_time()
        total = np.zeros((pts.shape[0], self.acc_order ** 2), dtype=np.float32)
        for k, b in others:
            rows = None if not skip or k not in skip else np.flatnonzero(~skip[k])
            if rows is not None and rows.size == 0:
                continue
            p, n = (pts, nrm) if rows is None else (pts[rows], nrm[rows])
            f = np.asarray(b.log_visibility(p, n, self.acc_order))
            want = (p.shape[0], total.shape[1])
            if f.shape != want or not np.isfinite(f).all():
                raise InputError(
                    f"{type(b).__name__}.log_visibility returned shape {f.shape} (or "
                    f"non-finite values); expected finite values of shape {want}")
            if rows is None:
                total += f
            else:
                total[rows] += f
        self.last_stats["seconds"]["other_blockers"] = time.process_time() - t0
        return total

    def close(self, *, kill: bool = False) -> None:
        """Stop the worker processes, if any were started (the runtime stays usable).

        ``kill=True`` kills them at once instead of letting running parts finish
        (an interrupted frame).
        """
        if self._workers is not None:
            self._workers.close(kill=kill)
            self._workers = None
        if self._pool_parts is not None:
            self._pool_parts.close()
            self._pool_parts = None

    def __enter__(self) -> ShadowRuntime:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _self_terms(self, self_visibility, n_vertices: int, blockers: list):
        """Rotated self-visibility logs ``(V, n_acc^2)`` and the own blocker each row skips.

        Returns ``(None, None, None)`` without self-visibility; ``exclude``
        (:class:`_Skipped`) says which *sphere* blockers each row skips (several on a
        row that several traced objects shadow, e.g. the ground); ``skip`` maps the position of a
        log blocker (e.g. a deformable field) named by a self-visibility to the
        bool mask ``(V,)`` of the rows it skips.  A rotated log is kept while its
        object's rotation does not change (static objects).
        """
        if not self_visibility:
            self._rotated_logs = {}
            return None, None, None
        size = self.acc_order * self.acc_order
        sphere_index = {}  # position in `blockers` -> position among the sphere blockers
        for k, b in enumerate(blockers):
            if isinstance(b, SphereBlocker):
                sphere_index[k] = len(sphere_index)
        extra = np.zeros((n_vertices, size), dtype=np.float32)
        skipped = np.zeros((n_vertices, len(sphere_index)), dtype=bool)
        skip = {}
        kept = {}
        for sv in self_visibility:
            if not isinstance(sv, SelfVisibility):
                raise InputError(f"self_visibility must hold SelfVisibility objects, got "
                                 f"{type(sv).__name__}")
            if sv.log is not None and sv.log.shape[1] != size:
                raise InputError(
                    f"self-visibility log has {sv.log.shape[1]} coefficients but the runtime "
                    f"accumulates at order {self.acc_order} ({size}); rebuild the transfer "
                    f"with --order {self.acc_order}")
            given = sv.log if sv.log is not None else sv.visibility
            rows = _self_rows(sv, n_vertices, given.shape[0])
            if sv.log is not None:  # a visibility is multiplied in after the exp
                extra[rows] += self._rotated_log(sv, kept)
            for k in sv.skipped:
                if k in sphere_index:
                    skipped[rows, sphere_index[k]] = True
                elif 0 <= k < len(blockers) and isinstance(blockers[k], LogBlocker):
                    skip.setdefault(k, np.zeros(n_vertices, dtype=bool))[rows] = True
                else:
                    raise InputError(f"self-visibility names blocker {k}, which is not "
                                     f"one of the {len(blockers)} blockers given")
        self._rotated_logs = kept
        if all(sv.log is None for sv in self_visibility):
            extra = None  # visibilities only: nothing to add before the exp
        return extra, (_Skipped.of(skipped) if skipped.any() else None), (skip or None)

    def _rotated_log(self, sv: SelfVisibility, kept: dict) -> np.ndarray:
        """``sv.log (R, n_acc*n_acc)`` turned with its object; remembered in ``kept``
        while the rotation holds (static objects pay the rotation once)."""
        if sv.rotation is None or np.allclose(sv.rotation, np.eye(3), atol=1e-12):
            return sv.log
        cached = self._rotated_logs.get(id(sv.log))
        # the entry holds the source array itself: an id alone can be reused by a
        # new array once the old one is freed
        if cached is not None and cached[0] is sv.log and np.array_equal(cached[1], sv.rotation):
            log = cached[2]
        else:
            d = rotation_matrix(sv.rotation, self.acc_order).astype(np.float32)
            log = sv.log @ d.T
        kept[id(sv.log)] = (sv.log, sv.rotation.copy(), log)
        return log

    def _multiply_self(self, g: np.ndarray, self_visibility) -> np.ndarray:
        """``g`` with the self-visibilities given as visibility multiplied into their rows.

        The exact truncated SH product at the shading order (quadrature); on rows
        where ``g`` is a constant (no other blocker reaches them: ``exp(0)``) the
        product is the given visibility times that constant, and on rows where the
        given visibility is exactly 1 (a traced shadow none of whose rays was blocked:
        most of a ground) it is ``g`` itself, with no quadrature.
        """
        given = [sv for sv in self_visibility or () if sv.visibility is not None]
        if not given:
            return g
        size = self.order * self.order
        if self._products is None:
            self._products = QuadratureProducts(self.order, np.float32)
        for sv in given:
            values = sv.visibility
            rows = _self_rows(sv, g.shape[0], values.shape[0])
            k = values.shape[1]
            if math.isqrt(k) ** 2 != k:
                raise InputError(f"self-visibility has {k} coefficients, not an SH order's n*n")
            vis = np.zeros((rows.shape[0], size), dtype=np.float32)
            vis[:, :min(k, size)] = values[:, :size]
            sub = g[rows]
            flat = ~sub[:, 1:].any(axis=1)  # constant: c Y_00 = c / sqrt(4 pi) everywhere
            out = vis * (sub[:, :1] * np.float32(1.0 / math.sqrt(4.0 * math.pi)))
            one = ~vis[:, 1:].any(axis=1) & (vis[:, 0] == np.float32(math.sqrt(4.0 * math.pi)))
            out[one] = sub[one]
            full = ~flat & ~one
            if full.any():
                out[full] = self._products.product(sub[full], vis[full])
            g[rows] = out
        return g

    def _frame_work(self, pts, blockers, clusters, exclude=None) -> FrameWork:
        """Cuts, ratio weights and per-cluster sphere lists of a frame (this process).

        ``exclude`` (:class:`_Skipped`): the sphere blockers each receiver skips.
        """
        s = self.settings
        stats = {"pairs": 0, "pairs_evaluated": 0, "clusters": 0, "seconds": {},
                 "processes": 1}
        self.last_stats = stats
        t0 = time.process_time()
        if exclude is not None and exclude.masks.shape == (1, len(blockers)) and \
                exclude.masks.all():
            # every receiver skips every sphere set (their objects' real meshes were
            # traced on all of them): nothing to accumulate, no cuts to make
            stats["seconds"]["cuts"] = time.process_time() - t0
            stats["spheres_per_vertex"] = 0.0
            return FrameWork(centers=np.zeros((0, 3)), radii=np.zeros(0))
        if not s.hierarchy and exclude is None:
            centers, radii = leaf_spheres(blockers)
            stats["seconds"]["cuts"] = time.process_time() - t0
            stats["pairs"] = stats["pairs_evaluated"] = pts.shape[0] * centers.shape[0]
            stats["spheres_per_vertex"] = float(centers.shape[0])
            return FrameWork(centers=centers, radii=radii)
        forest = build_forest(blockers)
        if not s.hierarchy:
            # every leaf everywhere, but per exclusion group: one "cluster" per group
            clusters = ReceiverClusters.from_labels(exclude.labels)
            in_cut = np.broadcast_to(forest.is_leaf, (clusters.n_clusters, forest.n_nodes))
            weights = np.ones((clusters.n_clusters, forest.n_nodes, self.acc_order))
        else:
            if clusters is None:
                clusters = self._clusters_for(
                    pts, None if exclude is None else exclude.labels)
            if clusters.n_vertices != pts.shape[0]:
                raise InputError(
                    f"clusters were built for {clusters.n_vertices} vertices but "
                    f"{pts.shape[0]} were given; call clusters() on this receiver set"
                )
            if exclude is not None:  # a cluster's receivers must skip the same blockers
                clusters = clusters.split(exclude.labels)
            cl_centers, cl_radii = clusters.bounds(pts)
            cuts = tree_cuts(forest, cl_centers, cl_radii, s.theta_max)
            weights = ratio_weights(forest, cuts, cl_centers, self.table,
                                    s.resolved_theta_min())
            in_cut = cuts.in_cut
        if exclude is not None:
            in_cut = in_cut & ~_excluded_nodes(clusters, exclude, forest.blocker)
        sizes = in_cut.sum(axis=1)
        s_max = max(1, int(sizes.max(initial=0)))
        # each cluster's cut nodes first (stable), padded with radius 0
        node_idx = np.argsort(~in_cut, axis=1, kind="stable")[:, :s_max]
        valid = np.arange(s_max)[None, :] < sizes[:, None]
        any_inner = bool((in_cut & ~forest.is_leaf[None, :]).any())
        work = FrameWork(
            order=clusters.order, offsets=clusters.offsets, sizes=sizes,
            centers=forest.centers[node_idx],
            radii=np.where(valid, forest.radii[node_idx], 0.0),
            weights=(np.take_along_axis(weights, node_idx[:, :, None], axis=1)
                     if any_inner else None))
        stats["seconds"]["cuts"] = time.process_time() - t0
        stats["pairs"] = int((np.diff(clusters.offsets) * sizes).sum())
        stats["clusters"] = clusters.n_clusters
        stats["spheres_per_vertex"] = stats["pairs"] / max(1, pts.shape[0])
        return work

    def _accumulate(self, task, stats: dict) -> np.ndarray:
        """Log sums ``(V', n_acc^2)`` of a :meth:`FrameWork.task` in this process."""
        s = self.settings
        if task[0] == "spheres":
            _, pts, nrm, centers, radii = task
            f = np.zeros((pts.shape[0], self.acc_order ** 2), dtype=np.float32)
            if centers.shape[0] == 0:  # every sphere skipped (FrameWork of _frame_work)
                stats["pairs_evaluated"] = 0
                return f
            accumulate_log(pts, nrm, centers, radii, self.table, self_shadow=s.self_shadow,
                           chunk_pairs=s.chunk_pairs, out=f, kernel=self._kernels[0])
            stats["pairs_evaluated"] = pts.shape[0] * centers.shape[0]
            return f
        _, pts, nrm, order, offsets, centers, radii, weights, sizes = task
        if not np.any(sizes):  # no sphere reaches these receivers (e.g. fields only)
            return np.zeros((pts.shape[0], self.acc_order ** 2), dtype=np.float32)
        return accumulate_clusters(pts, nrm, order, offsets, centers, radii, weights, sizes,
                                   self.table, self_shadow=s.self_shadow,
                                   chunk_pairs=s.chunk_pairs, threads=s.threads,
                                   kernels=self._kernels, stats=stats)

    def _split_visibility(self, work: FrameWork, pts, nrm, extra=None,
                          blocks: _PartBlockers | None = None,
                          receiver_cost: float = 0.0) -> np.ndarray:
        """Visibility of a frame evaluated as ``FRAME_PARTS`` independent parts.

        Each part's bytes depend only on the part (its receivers, cuts and
        blocking), never on which process evaluates it or on the process count.
        With workers, this process evaluates the first part and then takes the
        parts no worker has started yet, from the end of the queue.  ``extra``:
        the other blockers' log sum; ``blocks``: deformable fields each part
        evaluates on its rows (``receiver_cost`` sphere pairs per receiver).
        """
        parts = work.split(pts, nrm, FRAME_PARTS, receiver_cost)
        if extra is not None or blocks is not None:  # each part's rows of them
            parts = [(rows, ("with_log", task, None if extra is None else extra[rows],
                             None if blocks is None else blocks.take(rows)))
                     for rows, task in parts]
        g = np.empty((pts.shape[0], self.order * self.order), dtype=np.float32)
        evaluated = 0
        processes = 1
        if self._part_pool is not None and len(parts) > 1:
            if self._pool_parts is None:
                self._pool_parts = PoolParts(self._part_pool, self.settings, self.tables)
            results = self._pool_parts.map([task for _, task in parts])
            for (rows, _), (g_part, count) in zip(parts, results, strict=True):
                g[rows] = g_part
                evaluated += count
            processes = min(self._part_pool.workers, len(parts))
        elif self.processes == 1 or len(parts) == 1:
            for rows, task in parts:
                g[rows], count = self.run_part(task)
                evaluated += count
        else:
            if self._workers is None:
                self._workers = VertexWorkers(min(self.processes, FRAME_PARTS) - 1,
                                              self.settings, self.tables)
            try:
                queued = [(rows, task, self._workers.submit(task)) for rows, task in parts[1:]]
                g[parts[0][0]], evaluated = self.run_part(parts[0][1])
                # take back, one at a time from the end, parts no worker has started
                for rows, task, future in reversed(queued):
                    if not future.cancel():
                        break  # this one and every earlier one are with a worker
                    g[rows], count = self.run_part(task)
                    evaluated += count
                for rows, _, future in queued:
                    if not future.cancelled():
                        g[rows], count = self._workers.result(future)
                        evaluated += count
                processes = min(self.processes, FRAME_PARTS, len(parts))
            except ShtoolsError:
                self.close()  # a dead worker: the next frame starts fresh ones
                raise
            except BaseException:
                self.close(kill=True)  # Ctrl-C / SIGTERM: do not wait for running parts
                raise
        self.last_stats["pairs_evaluated"] = evaluated
        self.last_stats["processes"] = processes
        return g

    def exponentiate(self, log_vis) -> np.ndarray:
        """exp at the accumulation order, truncated to the shading order, shape ``(V, n*n)``.

        A log that is zero everywhere (no blocker reaches these receivers, e.g. every
        row's own blocker skipped) gives ``exp(0)`` of the same method without an exp.
        (The fast exp's products give each row the same bytes whatever rows share
        its batch: :data:`~shtools.runtime.fast_exp.PRODUCT_BLOCK_ROWS`.)
        """
        log_vis = np.asarray(log_vis)
        if log_vis.shape[0] == 0 or log_vis.any():
            return self._exp(log_vis)
        if self._exp_zero is None:
            self._exp_zero = self._exp(np.zeros((1, log_vis.shape[1]), dtype=log_vis.dtype))[0]
        return np.repeat(self._exp_zero[None], log_vis.shape[0], axis=0)

    def _exp(self, log_vis) -> np.ndarray:
        """:meth:`exponentiate` of every row."""
        kwargs = {}
        if self.exp_method in ("ol", "hyb"):
            kwargs["tables"] = self.tables
        if self.settings.exp_degree is not None and self.exp_method in ("ps", "ps*"):
            kwargs["degree"] = self.settings.exp_degree
        if self.exp_method in FAST_METHODS:
            # the last squaring projects onto the shading order only
            g = fast_exp(log_vis, self.exp_method, threads=self.settings.threads,
                         out_order=self.order, workspaces=self._exp_workspaces, **kwargs)
        else:
            g = sh_exp(log_vis, self.exp_method, **kwargs)
        n2 = self.order * self.order
        return np.ascontiguousarray(g[:, :n2])

    # -- shading ---------------------------------------------------------------
    def shade(self, visibility, vertices, normals, env_sh=None,
              sphere_lights: tuple[SphereLight, ...] | list = (), *,
              local_visibility=None, form: str = "tabulated") -> np.ndarray:
        """White Lambertian outgoing radiance, shape ``(V, 3)``.

        Radiance as defined in ``docs/conventions.md`` ("Light and radiance").

        Parameters
        ----------
        visibility : array_like, shape (V, n*n)
            From :meth:`visibility`.
        vertices, normals : array_like, shape (V, 3)
        env_sh : array_like, shape (n'*n', 3) or (V, n'*n', 3), optional
            RGB environment lighting in SH (truncated/padded to ``n``), shared
            or per vertex (mid-range lighting).
        sphere_lights : sequence of SphereLight
        local_visibility : array_like, shape (V, n*n), optional
            Baked visibility of static local occluders (Sec. 7).
        form : {"tabulated", "on_the_fly"}
            Environment evaluation (same result).

        Negative radiance left by SH ringing is desaturated toward luminance
        (``settings.deringing = "desaturate"``, the default;
        :func:`~shtools.runtime.shading.desaturate_negative`).
        """
        s = self.settings
        pts, nrm = _check_receivers(vertices, normals)
        transfer, changed = self._cosine_transfer(nrm)
        env_transfer = None
        if (env_sh is not None and local_visibility is None and form == "tabulated"
                and np.ndim(env_sh) == 2):  # a per-vertex (V, n*n, 3) light is not cached
            env_transfer = self._lit_transfer(env_sh, transfer, changed)
        out = _shade(visibility, pts, nrm, env_sh, tuple(sphere_lights), order=self.order,
                     window_kind=s.resolved_window(), window_h=s.window_h,
                     local_visibility=local_visibility, form=form, transfer=transfer,
                     env_transfer=env_transfer)
        if s.deringing == "desaturate":
            out = desaturate_negative(out)
        return out

    def _cosine_transfer(self, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """H(N) per vertex, recomputed only for vertices whose normal changed since last call.

        Static receivers (most of a scene) keep their tabulated transfer across
        frames, as the paper keeps L_H per normal.

        Returns
        -------
        transfer : ndarray, shape (V, n*n) float32
        changed : ndarray of int or None
            Rows recomputed by this call (None: all of them).
        """
        cached = self._transfer_cache
        if cached is None or cached[0].shape != normals.shape:
            transfer = cosine_transfer(normals, self.order)
            self._transfer_cache = (normals.copy(), transfer)
            return transfer, None
        old_n, transfer = cached
        changed = np.flatnonzero(np.any(old_n != normals, axis=1))
        if changed.size:
            transfer[changed] = cosine_transfer(normals[changed], self.order)
            old_n[changed] = normals[changed]
        return transfer, changed

    def _lit_transfer(self, env_sh, transfer: np.ndarray, changed: np.ndarray | None
                      ) -> np.ndarray:
        """L_H = L * H(N) per vertex (V, 3, n*n), kept while the light is unchanged.

        Rows are refreshed where the normal changed (``changed``), all of them
        when the light, the window or the receivers changed.
        """
        s = self.settings
        env = np.array(env_sh, dtype=np.float64)
        cached = self._lit_cache
        if (cached is None or changed is None or cached[1].shape[0] != transfer.shape[0]
                or cached[0].shape != env.shape or not np.array_equal(cached[0], env)):
            mats = environment_matrices(env, self.order, s.resolved_window(), s.window_h)
            self._lit_cache = (env, lit_transfer(transfer, mats), mats)
            return self._lit_cache[1]
        _, l_h, mats = cached
        if changed.size:
            l_h[changed] = lit_transfer(transfer[changed], mats)
        return l_h

    def _clusters_for(self, pts: np.ndarray, groups=None) -> ReceiverClusters:
        same_groups = (groups is None and self._auto_groups is None) or (
            groups is not None and self._auto_groups is not None
            and np.array_equal(groups, self._auto_groups))
        if (self._auto_clusters is None or self._auto_clusters.n_vertices != pts.shape[0]
                or not same_groups):
            self._auto_clusters = self.clusters(pts, groups=groups)
            self._auto_groups = None if groups is None else np.array(groups)
        return self._auto_clusters


@dataclass
class FrameWork:
    """What one frame accumulates: per-cluster sphere lists, or one list for all.

    Attributes
    ----------
    centers : ndarray, shape (C, S, 3) or (S, 3)
        Cut spheres of each cluster (padded), or the leaf spheres (no hierarchy).
    radii : ndarray, shape (C, S) or (S,)
    order, offsets : ndarray of int, shapes (V,), (C + 1,) or None
        Receivers sorted by cluster and the cluster boundaries.
    sizes : ndarray of int, shape (C,) or None
        Valid spheres per cluster.
    weights : ndarray, shape (C, S, n_acc) or None
        Ratio weights (eq. 37) where inner tree nodes are used.
    """

    centers: np.ndarray
    radii: np.ndarray
    order: np.ndarray | None = None
    offsets: np.ndarray | None = None
    sizes: np.ndarray | None = None
    weights: np.ndarray | None = None

    def task(self, pts, nrm) -> tuple:
        """The whole frame as one task for :meth:`ShadowRuntime.run_part`."""
        if self.order is None:
            return ("spheres", pts, nrm, self.centers, self.radii)
        return ("clusters", pts, nrm, self.order, self.offsets, self.centers, self.radii,
                self.weights, self.sizes)

    def split(self, pts, nrm, parts: int, receiver_cost: float = 0.0
              ) -> list[tuple[np.ndarray, tuple]]:
        """``parts`` tasks of about equal work, with the receiver rows each covers.

        Clusters are dealt whole (:func:`split_clusters`, cost = receivers x
        (cut size + ``receiver_cost``, the per-receiver work of other blockers));
        without a hierarchy the receivers are cut into equal ranges.  Empty parts
        are dropped.
        """
        pts32 = np.asarray(pts, dtype=np.float32)
        nrm32 = np.asarray(nrm, dtype=np.float32)
        if self.order is None:
            bounds = np.linspace(0, pts.shape[0], parts + 1).astype(np.int64)
            return [(np.arange(a, b), ("spheres", pts32[a:b], nrm32[a:b], self.centers,
                                       self.radii))
                    for a, b in itertools.pairwise(bounds) if b > a]
        counts = np.diff(self.offsets)
        groups = split_clusters(counts * (self.sizes + receiver_cost), parts)
        cluster_of = np.repeat(np.arange(counts.size), counts)  # cluster of each order slot
        part_of = np.empty(counts.size, dtype=np.int64)
        for k, group in enumerate(groups):
            part_of[group] = k
        slot_part = part_of[cluster_of]
        out = []
        for k, group in enumerate(groups):
            rows = self.order[slot_part == k]  # cluster by cluster, ascending
            if rows.size == 0:
                continue
            offsets = np.concatenate([[0], np.cumsum(counts[group])])
            out.append((rows, ("clusters", pts32[rows], nrm32[rows], np.arange(rows.size),
                               offsets, self.centers[group], self.radii[group],
                               None if self.weights is None else self.weights[group],
                               self.sizes[group])))
        return out


def _check_receivers(vertices, normals) -> tuple[np.ndarray, np.ndarray]:
    pts = np.asarray(vertices, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or nrm.shape != pts.shape:
        raise InputError(
            f"vertices and normals must both have shape (V, 3), got {pts.shape} and {nrm.shape}"
        )
    if not (np.isfinite(pts).all() and np.isfinite(nrm).all()):
        raise InputError("receiver vertices or normals contain NaN or infinite values")
    # mesh normals are often only nearly unit; a zero normal (unreferenced vertex)
    # stays zero and shades black
    length = np.linalg.norm(nrm, axis=1, keepdims=True)
    if not np.allclose(length, 1.0, atol=1e-6):
        nrm = nrm / np.where(length > 0, length, 1.0)
    return pts, nrm


def _check_blockers(blockers) -> tuple[list[SphereBlocker], list[LogBlocker]]:
    """Split blockers into sphere sets and blockers with their own log visibility."""
    spheres, others = [], []
    for b in blockers:
        if isinstance(b, SphereBlocker):
            spheres.append(b)
        elif isinstance(b, LogBlocker):
            others.append(b)
        else:
            raise InputError(f"blockers must be SphereBlocker objects or have "
                             f"log_visibility(points, normals, order), got {type(b).__name__}")
    return spheres, others


def _add(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """Sum of two optional log arrays (None is zero)."""
    if a is None:
        return b
    if b is None:
        return a
    return a + b


@dataclass
class _Skipped:
    """The sphere blockers each receiver row skips, as a label per row and one mask per label.

    Attributes
    ----------
    labels : ndarray of int, shape (V,)
        ``0..L-1``; rows with the same label skip the same blockers.  Ordered as the
        sets' bitmasks would be (nothing skipped first, then by highest blocker), so a
        scene whose rows skip at most one blocker each keeps its clusters.
    masks : ndarray of bool, shape (L, S)
        Sphere blockers (positions among the sphere blockers) each label skips.
    """

    labels: np.ndarray
    masks: np.ndarray

    @classmethod
    def of(cls, skipped: np.ndarray) -> _Skipped:
        """From a ``(V, S)`` bool matrix of skipped sphere blockers."""
        n_sets = skipped.shape[1]
        if n_sets > 62:  # rows as bit codes need S < 63; the row-wise unique is slower
            masks, labels = np.unique(skipped[:, ::-1], axis=0, return_inverse=True)
            return cls(labels.reshape(-1).astype(np.int64), masks[:, ::-1])
        # a row's code has bit s for blocker s: sorting codes sorts the rows by their
        # highest skipped blocker first, the order documented above
        bits = np.left_shift(np.int64(1), np.arange(n_sets, dtype=np.int64))
        codes, labels = np.unique(skipped.astype(np.int64) @ bits, return_inverse=True)
        return cls(labels.reshape(-1).astype(np.int64), (codes[:, None] & bits) != 0)


def _excluded_nodes(clusters: ReceiverClusters, exclude: _Skipped,
                    node_blocker: np.ndarray) -> np.ndarray:
    """``(C, M)`` bool: forest nodes of the blockers each cluster's receivers skip.

    Raises InputError when a cluster mixes receivers that skip different blockers.
    """
    labels = exclude.labels
    counts = np.diff(clusters.offsets)
    first = labels[clusters.order[clusters.offsets[:-1]]]
    if not np.array_equal(labels[clusters.order], np.repeat(first, counts)):
        raise InputError("receiver clusters mix vertices of different self-visibility "
                         "objects; build the clusters with groups = object id per vertex")
    return exclude.masks[first][:, node_blocker]


class _NoField:
    """Stands in for a shadow field in :meth:`ShadowRuntime.log_visibility` when the
    fields are evaluated separately (keeps the other blockers' indices)."""

    def log_visibility(self, points, normals, order):
        return np.zeros((np.asarray(points).shape[0], order * order), dtype=np.float32)


@dataclass
class _PartBlockers:
    """The shadow fields of a frame (or of one part's rows), as the parts evaluate them.

    Attributes
    ----------
    rigid_space, deformable_space : {"log", "product"}
        How each kind combines (``settings.resolved_field_space``).
    fields : list of (FieldBlocker, ndarray of bool (V,) or None)
        Rigid fields and the rows each skips (its own object's).
    deformables : list of (DeformableBlocker, ndarray of bool (V,) or None)
        Deformable fields and the rows each skips (its object's own rows, which
        a self-visibility covers).
    """

    rigid_space: str
    deformable_space: str
    fields: list
    deformables: list

    def take(self, rows: np.ndarray) -> _PartBlockers:
        """The same blockers for receiver rows ``rows`` (masks cut, skip rows renumbered)."""
        fields = [(dataclasses.replace(fb, skip_rows=None if mask is None
                                       else np.flatnonzero(mask[rows])),
                   None if mask is None else mask[rows]) for fb, mask in self.fields]
        deformables = [(d, None if mask is None else mask[rows])
                       for d, mask in self.deformables]
        return _PartBlockers(self.rigid_space, self.deformable_space, fields, deformables)


def _deformable_rows(blocks: _PartBlockers, n_rows: int):
    """``(blocker, rows)`` of each deformable field, rows it is evaluated on (not skipped)."""
    for d, mask in blocks.deformables:
        rows = np.arange(n_rows) if mask is None else np.flatnonzero(~mask)
        if rows.size:
            yield d, rows


def _own_rows(self_visibility, n_vertices: int, blockers: list) -> dict | None:
    """Position of each deformable field a self-visibility names -> bool mask ``(V,)``
    of its object's rows (the field skips them)."""
    skip = {}
    for sv in self_visibility or ():
        for k in sv.skipped:
            if 0 <= k < len(blockers) and isinstance(blockers[k], DeformableBlocker):
                mask = skip.setdefault(k, np.zeros(n_vertices, dtype=bool))
                mask[np.arange(n_vertices)[sv.rows]] = True
    return skip or None
