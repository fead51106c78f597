"""The per-frame evaluator: :class:`ShadowRuntime` (see ``docs/architecture.md``, runtime).

Its parts live beside it: the frame's cuts and split (:mod:`~shtools.runtime.frame_work`),
the shadow-field parts (:mod:`~shtools.runtime.frame_parts`), the objects' own
self-visibility (:mod:`~shtools.runtime.self_visibility`), the shading caches
(:mod:`~shtools.runtime.shading_cache`) and the worker processes
(:mod:`~shtools.runtime.parallel`).
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from shtools.errors import InputError, ShtoolsError
from shtools.runtime.accumulate import BlockKernel, accumulate_log
from shtools.runtime.blockers import (
    SelfVisibility,
    SphereBlocker,
    SphereLight,
    check_blockers,
    check_receivers,
)
from shtools.runtime.clusters import ReceiverClusters, lloyd_clusters
from shtools.runtime.fast_exp import FAST_METHODS, fast_exp
from shtools.runtime.fields import FieldBlocker
from shtools.runtime.frame_parts import (
    DEFORMABLE_RECEIVER_PAIRS,
    PART_BLOCKERS,
    NoField,
    PartBlockers,
    combine_parts,
    own_rows,
    part_blockers,
)
from shtools.runtime.frame_work import FrameWork, frame_work
from shtools.runtime.log_table import CapLogTable
from shtools.runtime.parallel import (
    FRAME_PARTS,
    MIN_PARALLEL_PAIRS,
    PoolParts,
    VertexWorkers,
    resolve_processes,
)
from shtools.runtime.rigid_pairs import RigidPairs
from shtools.runtime.self_visibility import SelfTerms
from shtools.runtime.settings import ShadowSettings
from shtools.runtime.shading import desaturate_negative
from shtools.runtime.shading import shade as _shade
from shtools.runtime.shading_cache import ShadingCache
from shtools.runtime.static_pairs import StaticPairs
from shtools.runtime.tiling import accumulate_clusters
from shtools.sh import exp as sh_exp


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
        self._self = SelfTerms(self.order, self.acc_order)  # self-visibility and its caches
        self._shading = ShadingCache(self.order, self.settings)
        self._static = StaticPairs()  # static spheres x static receivers, kept
        self._rigid = RigidPairs()  # rigid objects' own pairs, kept in object space
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
        pts, nrm = check_receivers(vertices, normals)
        spheres, _ = self._blockers(blockers)
        own, exclude, skip = self._self.terms(self_visibility, pts.shape[0], blockers)
        work = self._frame_work(pts, spheres, clusters, exclude)
        t1 = time.process_time()
        f = work.combine(self._accumulate(work.task(pts, nrm), self.last_stats), pts.shape[0])
        extra = _add(self._other_logs(pts, nrm, blockers, skip), own)
        if extra is not None:
            f += extra
        self.last_stats["seconds"]["accumulate"] = time.process_time() - t1
        return f

    def visibility(self, vertices, normals, blockers: list[SphereBlocker],
                   clusters: ReceiverClusters | None = None, *,
                   self_visibility: tuple[SelfVisibility, ...] | list = (),
                   static_receivers=None, rigid_receivers=None) -> np.ndarray:
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
        static_receivers : array_like of bool, shape (V,), optional
            Rows that do not move between frames: with sphere blockers flagged
            ``static``, those pairs' log sum is kept while they stay equal
            (:mod:`~shtools.runtime.static_pairs`).
        rigid_receivers : array_like of int, shape (V,), optional
            Per row, the index in ``blockers`` of the sphere blocker it moves
            rigidly with (-1: none): those pairs' log sum is kept in the object's
            frame and turned with it (:mod:`~shtools.runtime.rigid_pairs`).
            Frames with and without either flag agree to float32 rounding; both
            are ignored in frames with shadow fields.

        Returns
        -------
        ndarray, shape (V, n*n) float32
            Visibility vectors ``g`` (eq. 8) at the shading order.

        Notes
        -----
        Frames of at least ``MIN_PARALLEL_PAIRS`` sphere-receiver pairs are split
        by receiver cluster into ``FRAME_PARTS`` parts, shared with worker processes
        when ``settings.processes > 1`` (:mod:`shtools.runtime.parallel`; :meth:`close`
        stops them); the split does not depend on the process count (same bytes).
        """
        pts, nrm = check_receivers(vertices, normals)
        g = self._visibility(pts, nrm, blockers, clusters, self_visibility, static_receivers,
                             rigid_receivers)
        return self._multiply_self(g, self_visibility)

    def _visibility(self, pts, nrm, blockers, clusters, self_visibility,
                    static_receivers=None, rigid_receivers=None) -> np.ndarray:
        """:meth:`visibility` before the self-visibilities given as visibility."""
        spheres, others = self._blockers(blockers)
        if any(isinstance(b, FieldBlocker) for b in others):
            return self._visibility_with_fields(pts, nrm, blockers, clusters, self_visibility)
        own, exclude, skip = self._self.terms(self_visibility, pts.shape[0], blockers)
        kept, rigid = None, []
        kept_seconds = 0.0
        if (static_receivers is not None or rigid_receivers is not None) and \
                self.settings.hierarchy and spheres:
            if clusters is None:  # the clusters a frame without the flags would use
                clusters = self._clusters_for(pts, None if exclude is None else exclude.labels)
            t0 = time.process_time()
            if rigid_receivers is not None:
                exclude, rigid = self._rigid.frame(pts, nrm, blockers, spheres, rigid_receivers,
                                                   exclude, clusters, self._kept_sum,
                                                   self.acc_order)
            split = None if static_receivers is None else self._static.split(
                pts, nrm, spheres, static_receivers, exclude, clusters)
            if split is not None:
                kept = self._static.log_sum(split, lambda skipped: self._kept_sum(
                    pts, nrm, spheres, clusters, skipped))
                exclude = split.frame_exclude
            kept_seconds = time.process_time() - t0
        work = self._frame_work(pts, spheres, clusters, exclude)
        stats = self.last_stats
        extra = _add(self._other_logs(pts, nrm, blockers, skip, in_parts=True), own)
        extra = self._rigid.add_rows(_add(extra, kept), rigid, pts.shape[0])
        stats["seconds"]["kept_pairs"] = kept_seconds
        parts = self._part_blockers(blockers, skip, pts.shape[0])
        cost = 0 if parts is None else DEFORMABLE_RECEIVER_PAIRS * len(parts.deformables)
        # (a blend over clusters exponentiates its entries, then blends: as parts do)
        if work.blend is not None or stats["pairs"] + cost * len(pts) >= MIN_PARALLEL_PAIRS:
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

        ``task`` comes from :meth:`FrameWork.split` (also what a worker process runs;
        :mod:`shtools.runtime.parallel`), or is ``("with_log", task, extra)`` with the
        part's rows of the other blockers' log sum.  The rows are the part's receivers,
        or its entries of a blend over clusters (:meth:`FrameWork.assemble`)."""
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
        """:func:`~shtools.runtime.blockers.check_blockers`; fields must have the shading order."""
        spheres, others = check_blockers(blockers)
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
            f = self.log_visibility(pts, nrm, [NoField() if isinstance(b, PART_BLOCKERS)
                                               else b for b in blockers], clusters,
                                    self_visibility=self_visibility)
        else:
            self.last_stats = {"pairs": 0, "pairs_evaluated": 0, "clusters": 0,
                               "seconds": {}, "processes": 1}
            f = None
        stats = self.last_stats
        own = own_rows(self_visibility, pts.shape[0], blockers)
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
                self._workers = VertexWorkers(self.processes - 1, self.settings, self.tables,
                                              ShadowRuntime)
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
                       ) -> PartBlockers | None:
        """:func:`~shtools.runtime.frame_parts.part_blockers` with this runtime's settings."""
        return part_blockers(self.settings, blockers, skip, n_vertices)

    def _combine_parts(self, blocks: PartBlockers, pts, nrm, f) -> np.ndarray:
        """:func:`~shtools.runtime.frame_parts.combine_parts` at this runtime's orders."""
        return combine_parts(blocks, pts, nrm, f, self.order, self.acc_order, self.exponentiate)

    def _other_logs(self, pts, nrm, blockers: list, skip: dict | None = None, *,
                    in_parts: bool = False) -> np.ndarray | None:
        """Sum of the log visibilities of the non-sphere blockers, ``(V, n_acc^2)`` or None.

        ``skip``: position in ``blockers`` -> bool mask ``(V,)`` of the rows that
        blocker is not evaluated on (its object's own rows, which its
        self-visibility covers).  ``in_parts``: leave out the shadow fields the
        frame's parts evaluate (:data:`PART_BLOCKERS`).
        """
        left_out = (SphereBlocker, NoField, *(PART_BLOCKERS if in_parts else ()))
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

    def _multiply_self(self, g: np.ndarray, self_visibility) -> np.ndarray:
        """:meth:`~shtools.runtime.self_visibility.SelfTerms.multiply` into ``g``."""
        return self._self.multiply(g, self_visibility)

    def _frame_work(self, pts, blockers, clusters, exclude=None) -> FrameWork:
        """:func:`~shtools.runtime.frame_work.frame_work` of this frame (sets ``last_stats``)."""
        work, self.last_stats = frame_work(self.settings, self.table, pts, blockers, clusters,
                                           exclude, self._clusters_for)
        return work

    def _kept_sum(self, pts, nrm, spheres, clusters, exclude=None) -> np.ndarray:
        """Log sums ``(V, n_acc^2)`` of a kept part of a frame, by its cuts and kernel."""
        work = self._frame_work(pts, spheres, clusters, exclude)
        return work.combine(self._accumulate(work.task(pts, nrm), {"pairs_evaluated": 0}),
                            pts.shape[0])

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
                          blocks: PartBlockers | None = None,
                          receiver_cost: float = 0.0) -> np.ndarray:
        """Visibility of a frame evaluated as ``FRAME_PARTS`` independent parts.

        Each part's bytes depend only on the part (its receivers, cuts and blocking),
        never on the process evaluating it or the process count.  With workers, this
        process evaluates the first part, then takes the parts no worker has started,
        from the end of the queue.  ``extra``: the other blockers' log sum; ``blocks``:
        deformable fields each part evaluates on its rows (``receiver_cost`` pairs each).
        """
        split = work.split(pts, nrm, FRAME_PARTS, receiver_cost)
        parts = [task for _, _, task in split]
        if extra is not None or blocks is not None:  # each part's rows of them
            parts = [("with_log", task, None if extra is None else np.take(extra, rows, 0),
                      None if blocks is None else blocks.take(rows))
                     for rows, _, task in split]
        results: list = [None] * len(parts)  # each part's visibility, in part order
        evaluated, processes = 0, 1
        if self._part_pool is not None and len(parts) > 1:
            if self._pool_parts is None:
                self._pool_parts = PoolParts(self._part_pool, self.settings, self.tables,
                                             ShadowRuntime)
            for k, (g_part, count) in enumerate(self._pool_parts.map(parts)):
                results[k] = g_part
                evaluated += count
            processes = min(self._part_pool.workers, len(parts))
        elif self.processes == 1 or len(parts) == 1:
            for k, task in enumerate(parts):
                results[k], count = self.run_part(task)
                evaluated += count
        else:
            if self._workers is None:
                self._workers = VertexWorkers(min(self.processes, FRAME_PARTS) - 1,
                                              self.settings, self.tables, ShadowRuntime)
            try:
                queued = [(k, t, self._workers.submit(t)) for k, t in enumerate(parts) if k]
                results[0], evaluated = self.run_part(parts[0])
                # take back, one at a time from the end, parts no worker has started
                for k, task, future in reversed(queued):
                    if not future.cancel():
                        break  # this one and every earlier one are with a worker
                    results[k], count = self.run_part(task)
                    evaluated += count
                for k, _, future in queued:
                    if not future.cancelled():
                        results[k], count = self._workers.result(future)
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
        return work.assemble(split, results, pts.shape[0], self.order * self.order)

    def exponentiate(self, log_vis) -> np.ndarray:
        """exp at the accumulation order, truncated to the shading order, shape ``(V, n*n)``.

        A log that is zero everywhere (no blocker reaches these receivers, e.g. every
        row's own blocker skipped) gives ``exp(0)`` of the same method, computed once
        for one row (equal to the exp of every row up to the last bits of the float32
        products, which may depend on a row's place in its block:
        :func:`~shtools.runtime.fast_exp.row_matmul`).
        """
        log_vis = np.asarray(log_vis)
        if log_vis.shape[0] == 0 or log_vis.any():
            return self._exp(log_vis)
        if self._exp_zero is None:
            self._exp_zero = self._exp(np.zeros((1, log_vis.shape[1]), dtype=log_vis.dtype))[0]
        return np.repeat(self._exp_zero[None], log_vis.shape[0], axis=0)

    def _exp(self, log_vis) -> np.ndarray:
        """:meth:`exponentiate` of every row."""
        kwargs = {"tables": self.tables} if self.exp_method in ("ol", "hyb") else {}
        if self.settings.exp_degree is not None and self.exp_method in ("ps", "ps*"):
            kwargs["degree"] = self.settings.exp_degree
        if self.exp_method in ("ps*", "hyb"):
            kwargs["margin"] = self.settings.resolved_exp_margin()
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
        pts, nrm = check_receivers(vertices, normals)
        transfer, changed = self._shading.cosine_transfer(nrm)
        kw = {"order": self.order, "window_kind": s.resolved_window(), "window_h": s.window_h}
        if local_visibility is None and form == "tabulated" and (
                env_sh is None or np.ndim(env_sh) == 2):  # a per-vertex light is not cached
            lit = self._shading.lit_rows(env_sh, tuple(sphere_lights), pts, transfer, changed)
            out = _shade(visibility, pts, nrm, lit_rows=lit, **kw)
        else:
            out = _shade(visibility, pts, nrm, env_sh, tuple(sphere_lights),
                         local_visibility=local_visibility, form=form, transfer=transfer,
                         light_terms=self._shading.light_terms(sphere_lights, pts)
                         if sphere_lights else None, **kw)
        if s.deringing == "desaturate":
            out = desaturate_negative(out)
        return out

    def _clusters_for(self, pts: np.ndarray, groups=None) -> ReceiverClusters:
        same_groups = (groups is None and self._auto_groups is None) or (
            groups is not None and self._auto_groups is not None
            and np.array_equal(groups, self._auto_groups))
        if (self._auto_clusters is None or self._auto_clusters.n_vertices != pts.shape[0]
                or not same_groups):
            self._auto_clusters = self.clusters(pts, groups=groups)
            self._auto_groups = None if groups is None else np.array(groups)
        return self._auto_clusters


def _add(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """Sum of two optional log arrays (None is zero)."""
    if a is None:
        return b
    if b is None:
        return a
    return a + b

