"""Settings of the shadow runtime (:class:`ShadowSettings`) and their validation."""

from __future__ import annotations

import math
from dataclasses import dataclass

from shtools.errors import InputError

#: exp methods the runtime accepts ("auto" picks one from the accumulation order).
RUNTIME_EXP_METHODS = ("auto", "hyb", "ps*", "ps", "ol", "exact", "volterra")

#: How shadow-field blockers are combined (ShadowSettings.field_space).
FIELD_SPACES = ("log", "product")
#: Accumulation order used when ``acc_order`` is None: ``n + 2`` (at most 6).
#: From ``benchmarks/bench_runtime.py`` (accuracy vs order on a procedural scene,
#: shading order 4): radiance error vs ray tracing of the sphere set 4.7 % at
#: n_acc = 4, 3.0 % at 5, 1.9 % at 6, 1.0 % at 8; battle-scale frame CPU time
#: 1 : 1.3 : 1.5 for 4 : 5 : 6 (8 costs about 3x).  6 is the cheapest order that
#: meets the 3 % target with margin; ``acc_order=4`` is the fast setting.
DEFAULT_EXTRA_ACC_ORDERS = 2
#: Above this accumulation order the default stops growing (cost ~ n_acc^2 per pair).
MAX_DEFAULT_ACC_ORDER = 6

#: "auto" exp: HYB up to this order (OL is an order-4 model, Sec. 4.2), PS*-p above.
HYB_MAX_ORDER = 4


@dataclass
class ShadowSettings:
    """Parameters of the SHEXP runtime.

    Parameters
    ----------
    order : int
        Shading SH order ``n`` (visibility returned with ``n*n`` coefficients).
    acc_order : int or None
        Order ``n_acc >= n`` at which blocker logs are accumulated and
        exponentiated before truncation to ``n``; None picks
        ``min(n + 2, 6)`` (or ``n`` when ``n >= 6``), see :meth:`resolved_acc_order`.
    exp_method : str
        ``"auto"`` (HYB when the accumulation order is <= 4, PS*-p above),
        ``"hyb"``, ``"ps*"``, ``"ps"``, ``"ol"``, ``"exact"``, ``"volterra"``.
    exp_degree : int or None
        Series degree ``p`` of PS-p / PS*-p (None: the library default).
    window : str or None
        Window applied to lighting and visibility when shading (``"cosine"``,
        ``"hann"``, ``"lanczos"`` or None).
    window_h : float or None
        Window size ``h`` (None: ``2n``).
    theta_max : float
        Eq. 36 threshold (radians): a tree node is used for a receiver cluster
        when it subtends less than this over the whole cluster.
    theta_min : float
        Leaf spheres subtending less than this at the cluster centre are left out
        of the detailed sums behind the ratio vectors (eq. 37).
    hierarchy : bool
        Use receiver clusters, tree cuts and ratio vectors (Sec. 6.3); False
        accumulates every leaf sphere at every vertex.
    vertices_per_cluster : int
        Average receiver-cluster size of the Lloyd clustering.
    self_shadow : bool
        Apply the self-shadowing rules of Sec. 6.2 (tangent-plane culling and
        replacement).
    chunk_pairs : int
        Number of sphere-vertex pairs processed per array pass (memory bound).
    threads : int
        Threads accumulating blocks concurrently within a process.  Default 1:
        NumPy releases the GIL in each array pass, but the kernel makes hundreds
        of short passes per block and two threads spend the gain handing the GIL
        over (the battle-scale frame of bench_runtime ran 1.0-1.3x faster with
        2 threads on 2 cores); ``processes`` is the way to use more cores.
    processes : int or None
        Processes sharing the per-vertex stages of a frame (accumulation and
        exp), see :mod:`shtools.runtime.parallel`; None uses the available
        cores (at most 8), 1 evaluates in the calling process.  Workers are
        forked on the first frame with at least ``MIN_PARALLEL_PAIRS``
        sphere-receiver pairs; without ``fork`` (Windows) the runtime uses one
        process.
    field_space : {"log", "product"}
        How shadow-field blockers combine (:mod:`~shtools.runtime.fields`):
        ``"log"`` adds their SH logs to the sphere blockers' log sum before the
        one exp; ``"product"`` multiplies their visibility vectors in with
        truncated SH products at the accumulation order (the papers' way).
    """

    order: int = 4
    acc_order: int | None = None
    exp_method: str = "auto"
    exp_degree: int | None = None
    window: str | None = "cosine"
    window_h: float | None = None
    theta_max: float = math.radians(25.0)
    theta_min: float = math.radians(1.0)
    hierarchy: bool = True
    vertices_per_cluster: int = 400
    self_shadow: bool = True
    chunk_pairs: int = 1 << 16
    threads: int = 1
    processes: int | None = None
    field_space: str = "log"

    def __post_init__(self):
        self.validate()

    def validate(self) -> None:
        """Raise :class:`InputError` naming the bad setting and its allowed range."""
        if not _is_int(self.order) or not 1 <= self.order <= 8:
            raise InputError(f"order must be an integer 1..8, got {self.order!r}")
        if self.acc_order is not None and (
            not _is_int(self.acc_order) or not self.order <= self.acc_order <= 10
        ):
            raise InputError(
                f"acc_order must be an integer between order ({self.order}) and 10, "
                f"got {self.acc_order!r}"
            )
        if self.exp_method not in RUNTIME_EXP_METHODS:
            raise InputError(
                f"unknown exp method {self.exp_method!r}; use one of "
                f"{', '.join(RUNTIME_EXP_METHODS)}"
            )
        if self.exp_degree is not None and (not _is_int(self.exp_degree) or self.exp_degree < 1):
            raise InputError(f"exp_degree must be an integer >= 1, got {self.exp_degree!r}")
        if self.window not in (None, "none", "cosine", "hann", "lanczos"):
            raise InputError(
                f"unknown window {self.window!r}; use cosine, hann, lanczos or none"
            )
        if self.window_h is not None and not self.window_h > 0:
            raise InputError(f"window_h must be > 0, got {self.window_h!r}")
        if not 0.0 < self.theta_max < math.pi / 2:
            raise InputError(f"theta_max must be in (0, pi/2) radians, got {self.theta_max!r}")
        if not 0.0 <= self.theta_min < self.theta_max:
            raise InputError(
                f"theta_min must be in [0, theta_max) radians, got {self.theta_min!r}"
            )
        if not _is_int(self.vertices_per_cluster) or self.vertices_per_cluster < 1:
            raise InputError(
                f"vertices_per_cluster must be an integer >= 1, got {self.vertices_per_cluster!r}"
            )
        if self.field_space not in FIELD_SPACES:
            raise InputError(f"unknown field_space {self.field_space!r}; use log or product")
        if not _is_int(self.threads) or not 1 <= self.threads <= 64:
            raise InputError(f"threads must be an integer 1..64, got {self.threads!r}")
        if self.processes is not None and (not _is_int(self.processes)
                                           or not 1 <= self.processes <= 64):
            raise InputError(
                f"processes must be an integer 1..64 (or None: one per core), "
                f"got {self.processes!r}")
        if not _is_int(self.chunk_pairs) or self.chunk_pairs < 256:
            raise InputError(f"chunk_pairs must be an integer >= 256, got {self.chunk_pairs!r}")

    def resolved_acc_order(self) -> int:
        """The accumulation order actually used."""
        if self.acc_order is not None:
            return int(self.acc_order)
        return max(self.order, min(self.order + DEFAULT_EXTRA_ACC_ORDERS, MAX_DEFAULT_ACC_ORDER))

    def resolved_exp_method(self) -> str:
        """The exp method actually used (resolves ``"auto"``)."""
        if self.exp_method != "auto":
            return self.exp_method
        return "hyb" if self.resolved_acc_order() <= HYB_MAX_ORDER else "ps*"

    def resolved_window(self) -> str | None:
        """Window kind for :func:`shtools.sh.window` (``"none"`` becomes None)."""
        return None if self.window in (None, "none") else self.window


def _is_int(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, int | float) and int(value) == value
