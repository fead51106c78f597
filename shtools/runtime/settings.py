"""The settings schema: every setting of the shadow runtime, its default and its limits.

:class:`ShadowSettings` is the one place a runtime setting is declared.  Each
field is made by :func:`setting`, which records the default, the allowed range
(integer or real, open or closed ends, or a list of choices), whether ``None``
is allowed and what it means, the scene-file key and a one-line doc.  From that
one declaration come

* the check of every value (:meth:`ShadowSettings.validate`: type, finite,
  range, cross-field bounds such as ``order <= acc_order``), one loop here;
* the ``[settings]`` table of scene files (:mod:`shtools.scene.schema` builds
  its pydantic model from :func:`scene_fields`);
* the command-line choices and ranges (:func:`shtools.cli._common.setting_option`).

Adding a setting is one ``setting(...)`` field here plus its line in
``docs/scenes.md`` (see ``docs/architecture.md``).  Subclasses add their own
fields the same way (the baker's :class:`shtools.scene.scene.Settings`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import MISSING, dataclass, field, fields
from enum import StrEnum
from typing import Any

from shtools.errors import InputError
from shtools.sh.exponential import SQUARING_MARGIN, ExpMethod
from shtools.sh.zonal import WindowKind

#: Shading SH orders the runtime supports (tables, products and the cap log
#: table are exercised up to here by the test suite).
MAX_ORDER = 8
#: Accumulation orders the runtime supports (the exp at n_acc costs ~ n_acc^4).
MAX_ACC_ORDER = 10
#: Largest radiance a light may have (a scene light's colour or intensity, a lamp's
#: emission table): products of it with SH coefficients and exposure stay far inside float32.
MAX_RADIANCE = 1e15

#: Accumulation order used when ``acc_order`` is None: ``n + 2`` (at most 6).
#: At shading order 4, 6 is the cheapest order that meets the 3 % radiance target
#: against ray tracing of the sphere set with margin; ``acc_order=4`` is the fast
#: setting (error and frame time per order: ``benchmarks/bench_runtime.py``,
#: ``benchmarks/RESULTS.md``).
DEFAULT_EXTRA_ACC_ORDERS = 2
#: Above this accumulation order the default stops growing (cost ~ n_acc^2 per pair).
MAX_DEFAULT_ACC_ORDER = 6
#: "auto" exp: HYB up to this order (OL is an order-4 model, Sec. 4.2), PS*-p above.
HYB_MAX_ORDER = 4
#: Squaring-count margin ``c`` (:func:`shtools.sh.exponential.squarings`) of the
#: runtime's PS*-p when ``exp_margin`` is None: the scaled vector's norm below 1
#: instead of the paper's 1/4, two squarings fewer (the exp blends the two counts
#: where the count steps, :data:`shtools.sh.exponential.SQUARING_BLEND`, so the
#: larger series error makes no ring).  Measured against ray tracing of
#: the sphere sets, the radiance is no further off (tests/runtime/
#: test_runtime_accuracy.py) and the battle frame's visibility slightly closer
#: (``benchmarks/bench_runtime.py``); against the exact product-series exp the
#: series' own error grows from ~0.1 % to ~0.5 % (median).  HYB keeps the paper's
#: margin: OL's error grows fast with the scaled norm.
RUNTIME_PS_STAR_MARGIN = 1
#: ``theta_min`` when left None (eq. 37 leaf cut-off).
DEFAULT_THETA_MIN = math.radians(1.0)

#: exp methods a setting accepts: "auto" (picked from the accumulation order) or one of
#: :class:`shtools.sh.ExpMethod`.
EXP_CHOICES = ("auto", *(m.value for m in ExpMethod))
#: windows a setting accepts: one of :class:`shtools.sh.WindowKind` or "none".
WINDOW_CHOICES = (*(k.value for k in WindowKind), "none")
#: Removal of negative radiance left by SH ringing (``shtools.runtime.shading``).
DERINGING_CHOICES = ("desaturate", "none")
#: How shadow-field blockers are combined (``ShadowSettings.field_space``).
FIELD_SPACES = ("log", "product")


class Unit(StrEnum):
    """How a setting is written in scene files."""

    PLAIN = "plain"
    #: stored in radians, written in degrees under ``<name>_deg``
    DEGREES = "deg"


@dataclass(frozen=True)
class Limits:
    """Declared limits of one setting (the ``metadata["limits"]`` of its field).

    Attributes
    ----------
    kind : {"int", "float", "bool", "choice", "path"}
    lo, hi : float or None
        Range ends (None: unbounded); ``lo_open``/``hi_open`` exclude them.
    lo_field, hi_field : str or None
        Another setting that bounds this one (e.g. ``acc_order >= order``).
    choices : tuple of str or callable returning one, optional
        Allowed values of a ``"choice"`` setting.
    nullable : bool
        ``None`` is allowed; ``none_means`` says what it stands for.
    scene : bool
        Settable in a scene's ``[settings]`` table.
    unit : Unit
        ``DEGREES``: the scene key is ``<name>_deg`` and converted to radians.
    doc : str
        One line for ``--help`` and error messages.
    """

    kind: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    lo_field: str | None = None
    hi_field: str | None = None
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None
    nullable: bool = False
    none_means: str = ""
    scene: bool = True
    unit: Unit = Unit.PLAIN
    doc: str = ""

    def choice_values(self) -> tuple[str, ...]:
        """The allowed values of a choice setting."""
        c = self.choices
        return tuple(c() if callable(c) else (c or ()))

    def range_text(self, resolved: dict[str, Any] | None = None) -> str:
        """The range in words, e.g. ``"an integer in 1..8"`` or ``"a number > 0"``."""
        if self.kind == "bool":
            return "true or false"
        if self.kind == "choice":
            return "one of " + ", ".join(self.choice_values())
        if self.kind == "path":
            return "a file path"
        noun = "an integer" if self.kind == "int" else "a number"
        lo = self.lo if self.lo_field is None else (resolved or {}).get(self.lo_field,
                                                                          self.lo_field)
        hi = self.hi if self.hi_field is None else (resolved or {}).get(self.hi_field,
                                                                          self.hi_field)
        if self.lo_field is not None and resolved:
            lo = f"{self.lo_field} ({lo})"
        if self.hi_field is not None and resolved:
            hi = f"{self.hi_field} ({hi})"
        if lo is not None and hi is not None:
            if self.kind == "int" and not (self.lo_open or self.hi_open):
                return f"{noun} in {lo}..{hi}"
            return (f"{noun} in {'(' if self.lo_open else '['}{lo}, {hi}"
                    f"{')' if self.hi_open else ']'}")
        if lo is not None:
            return f"{noun} {'>' if self.lo_open else '>='} {lo}"
        if hi is not None:
            return f"{noun} {'<' if self.hi_open else '<='} {hi}"
        return noun

    def scene_key(self, name: str) -> str:
        """The key of this setting in a scene's ``[settings]`` table."""
        return f"{name}_deg" if self.unit is Unit.DEGREES else name


def setting(default: Any, kind: str, *, doc: str, lo=None, hi=None, lo_open=False,
            hi_open=False, lo_field=None, hi_field=None, choices=None, none_means="",
            scene=True, unit: Unit = Unit.PLAIN) -> Any:
    """A dataclass field declaring one setting (see :class:`Limits`).

    ``None`` is allowed exactly when ``none_means`` says what it stands for.
    """
    limits = Limits(kind, lo, hi, lo_open, hi_open, lo_field, hi_field, choices,
                    nullable=bool(none_means), none_means=none_means, scene=scene, unit=unit,
                    doc=doc)
    return field(default=default, metadata={"limits": limits})


def limits_of(cls_or_obj, name: str) -> Limits:
    """The :class:`Limits` of setting ``name`` of a settings class or instance."""
    for f in fields(cls_or_obj):
        if f.name == name:
            return f.metadata["limits"]
    raise KeyError(name)


def setting_fields(cls_or_obj) -> Iterator[tuple[str, Limits, Any]]:
    """``(name, limits, default)`` of every declared setting, in declaration order."""
    for f in fields(cls_or_obj):
        if "limits" in f.metadata:
            yield f.name, f.metadata["limits"], (None if f.default is MISSING else f.default)


def scene_fields(cls_or_obj) -> Iterator[tuple[str, str, Limits, Any]]:
    """``(scene key, name, limits, default)`` of the settings a scene file may set."""
    for name, limits, default in setting_fields(cls_or_obj):
        if limits.scene:
            yield limits.scene_key(name), name, limits, default


def check_setting(name: str, value: Any, limits: Limits, resolved: dict[str, Any]) -> Any:
    """Check one value against its limits; return it normalised (choices as plain str).

    Raises
    ------
    InputError
        ``"<name> must be <range>, got <value>"``.
    """
    def bad(what: str | None = None) -> InputError:
        what = what or f"must be {limits.range_text(resolved)}"
        if limits.nullable:
            what += f" (or None: {limits.none_means})"
        return InputError(f"{name} {what}, got {value!r}")

    if value is None:
        if limits.nullable:
            return None
        raise bad()
    if limits.kind == "bool":
        if not isinstance(value, bool):
            raise bad()
        return value
    if limits.kind == "choice":
        if not isinstance(value, str) or value not in limits.choice_values():
            raise bad()
        return str(value.value if isinstance(value, StrEnum) else value)
    if limits.kind == "path":
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise bad()
    if not math.isfinite(value):
        raise bad("must be finite")
    if limits.kind == "int" and int(value) != value:
        raise bad()
    lo = resolved.get(limits.lo_field) if limits.lo_field else limits.lo
    hi = resolved.get(limits.hi_field) if limits.hi_field else limits.hi
    if limits.lo_field and limits.lo is not None:
        lo = max(lo, limits.lo) if lo is not None else limits.lo
    if limits.hi_field and limits.hi is not None:
        hi = min(hi, limits.hi) if hi is not None else limits.hi
    if lo is not None and (value <= lo if limits.lo_open else value < lo):
        raise bad()
    if hi is not None and (value >= hi if limits.hi_open else value > hi):
        raise bad()
    return int(value) if limits.kind == "int" else value


def validate_settings(obj) -> None:
    """Check (and normalise in place) every declared setting of a settings dataclass."""
    resolved: dict[str, Any] = {}
    for name, limits, _ in setting_fields(obj):
        value = check_setting(name, getattr(obj, name), limits, resolved)
        if value is not getattr(obj, name):
            object.__setattr__(obj, name, value)
        resolved[name] = value


@dataclass
class ShadowSettings:
    """Parameters of the SHEXP runtime (the settings schema; see the module docstring).

    Every field is declared with :func:`setting` (default, limits, doc), checked
    on construction and by :meth:`validate`.  ``None`` stands for a derived
    default where a field allows it (``acc_order``, ``window_h``, ...).

    Attributes
    ----------
    order : int
        Shading SH order ``n`` (visibility returned with ``n*n`` coefficients).
    acc_order : int or None
        Order ``n_acc >= n`` at which blocker logs are accumulated and
        exponentiated before truncation to ``n``; None: ``min(n + 2, 6)`` (or ``n``
        when ``n >= 6``), see :meth:`resolved_acc_order`.
    exp_method : str
        ``"auto"`` (HYB when the accumulation order is <= 4, PS*-p above) or a
        :class:`shtools.sh.ExpMethod`.
    exp_degree : int or None
        Series degree ``p`` of PS-p / PS*-p (None: the library default).
    exp_margin : int or None
        Squaring-count margin ``c`` of PS*-p and HYB,
        ``q = max(0, floor(log2 |f_hat|) + c)`` (Sec. 4.1); None:
        :data:`RUNTIME_PS_STAR_MARGIN` for PS*-p, the paper's 3 for HYB
        (:meth:`resolved_exp_margin`).
    window : str or None
        Window applied to lighting and visibility when shading (``"cosine"``,
        ``"hann"``, ``"lanczos"``, ``"none"`` or None).
    window_h : float or None
        Window size ``h`` (None: ``2n``).
    theta_max : float
        Eq. 36 threshold (radians): a tree node is used for a receiver cluster
        when it subtends less than this over the whole cluster.
    theta_min : float or None
        Leaf spheres subtending less than this at the cluster centre are left out
        of the detailed sums behind the ratio vectors (eq. 37); None: 1 degree.
    hierarchy : bool
        Use receiver clusters, tree cuts and ratio vectors (Sec. 6.3); False
        accumulates every leaf sphere at every vertex.
    vertices_per_cluster : int
        Average receiver-cluster size of the Lloyd clustering.
    cluster_blend : float
        Receivers within this fraction of a cluster's radius of a cluster boundary
        (in the difference of their distances to the clusters' centres) are
        evaluated with each nearby cluster's cut and blended with weights continuous
        over the surface (:mod:`shtools.runtime.cluster_blend`): no seam where two
        clusters' cuts or ratio vectors differ, for more pairs.  0: no blend.
    self_shadow : bool
        Apply the self-shadowing rules of Sec. 6.2 (tangent-plane culling and
        replacement).
    chunk_pairs : int
        Number of sphere-vertex pairs processed per array pass (memory bound):
        the kernel's ~17 scratch arrays of this many float32 values should fit
        a core's L2 cache (the clustered path's bytes do not depend on it).
    threads : int
        Threads accumulating blocks concurrently within a process.  Default 1:
        NumPy releases the GIL in each array pass, but the kernel makes hundreds
        of short passes per block and two threads spend the gain handing the GIL
        over (the battle-scale frame of bench_runtime ran 1.0-1.3x faster with
        2 threads on 2 cores); ``processes`` is the way to use more cores.
    processes : int or None
        Processes sharing the per-vertex stages of a frame (accumulation and
        exp), see :mod:`shtools.runtime.parallel`.  Default 1: the library
        evaluates in the calling process, so an embedding program gets no
        processes it did not ask for; None uses the available cores (at most
        8) -- what ``shtools bake`` and :func:`shtools.scene.bake.bake_scene`
        choose unless told otherwise.  Workers are
        started on the first frame with at least ``MIN_PARALLEL_PAIRS``
        sphere-receiver pairs (by multiprocessing's fork server; without one,
        on Windows, the runtime uses one process).
    field_space : {"log", "product"} or None
        How shadow-field blockers -- rigid (:mod:`~shtools.runtime.fields`) and
        deformable (:mod:`~shtools.runtime.deformable`) -- combine: ``"log"``
        adds their SH logs to the other blockers' log sum before the one exp;
        ``"product"`` multiplies their visibility vectors in after the exp with
        truncated SH products at the accumulation order (the papers' way).
        None (default): ``"log"`` for rigid fields, ``"product"`` for
        deformable ones (:meth:`resolved_field_space`; the closer to ray tracing of each,
        ``docs/scenes.md``).
    """

    order: int = setting(4, "int", lo=1, hi=MAX_ORDER, doc="shading SH order n")
    acc_order: int | None = setting(
        None, "int", lo_field="order", hi=MAX_ACC_ORDER,
        none_means="min(order + 2, 6)", doc="order the blocker logs are accumulated and "
        "exponentiated at, >= order")
    exp_method: str = setting("auto", "choice", choices=EXP_CHOICES,
                              doc="SH exponential (auto: HYB at n_acc <= 4, PS*-p above)")
    exp_degree: int | None = setting(None, "int", lo=1, none_means="the method's default",
                                     doc="series degree p of PS-p / PS*-p")
    exp_margin: int | None = setting(None, "int", lo=0, hi=8,
                                     none_means="1 for PS*-p, 3 for HYB",
                                     doc="squaring-count margin c of PS*-p and HYB")
    window: str | None = setting("cosine", "choice", choices=WINDOW_CHOICES,
                                 none_means="no window", doc="window applied when shading")
    window_h: float | None = setting(None, "float", lo=0, lo_open=True,
                                     none_means="2n (cosine) or n", doc="window size h")
    theta_max: float = setting(math.radians(25.0), "float", lo=0, lo_open=True,
                               hi=math.pi / 2, hi_open=True, unit=Unit.DEGREES,
                               doc="eq. 36 cut threshold (radians; scenes: degrees)")
    theta_min: float | None = setting(
        None, "float", lo=0, hi_field="theta_max", hi_open=True, unit=Unit.DEGREES,
        none_means="1 degree", doc="eq. 37 leaf cut-off (radians; scenes: degrees)")
    hierarchy: bool = setting(True, "bool", doc="receiver clusters, tree cuts, ratio vectors")
    vertices_per_cluster: int = setting(400, "int", lo=1,
                                        doc="average receiver-cluster size")
    cluster_blend: float = setting(0.0, "float", lo=0,
                                   doc="band over which receivers near a cluster boundary "
                                       "blend the neighbouring clusters' cuts, as a fraction "
                                       "of a cluster's radius (0: no blend; seams where the "
                                       "cuts differ)")
    self_shadow: bool = setting(True, "bool", doc="self-shadow rules of Sec. 6.2")
    deringing: str = setting("desaturate", "choice", choices=DERINGING_CHOICES,
                             doc="negative radiance from SH ringing: desaturate toward "
                                 "luminance (0 where it is negative) or keep it")
    chunk_pairs: int = setting(1 << 15, "int", lo=256, scene=False,
                               doc="sphere-vertex pairs per array pass (memory bound)")
    threads: int = setting(1, "int", lo=1, hi=64, scene=False,
                           doc="threads accumulating blocks within a process")
    processes: int | None = setting(1, "int", lo=1, hi=64, scene=False,
                                    none_means="one per core",
                                    doc="processes sharing each frame")
    field_space: str | None = setting(
        None, "choice", choices=FIELD_SPACES,
        none_means="log for rigid fields, product for deformable ones",
        doc="how shadow-field blockers (rigid and deformable) combine: log (one exp with "
        "every other blocker) or product (truncated SH products)")

    def __post_init__(self):
        self.validate()

    def validate(self) -> None:
        """Raise :class:`InputError` naming the bad setting and its allowed range."""
        validate_settings(self)

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

    def resolved_exp_margin(self) -> int:
        """The squaring-count margin actually used (:data:`RUNTIME_PS_STAR_MARGIN` for
        PS*-p, the paper's :data:`~shtools.sh.exponential.SQUARING_MARGIN` otherwise)."""
        if self.exp_margin is not None:
            return int(self.exp_margin)
        return RUNTIME_PS_STAR_MARGIN if self.resolved_exp_method() == "ps*" else SQUARING_MARGIN

    def resolved_window(self) -> str | None:
        """Window kind for :func:`shtools.sh.window` (``"none"`` becomes None)."""
        return None if self.window in (None, "none") else self.window

    def resolved_field_space(self, kind: str) -> str:
        """How shadow fields of ``kind`` ("rigid" or "deformable") combine: ``field_space``,
        or by default ``"log"`` for rigid fields and ``"product"`` for deformable ones
        (the deformable field's ground is closer to ray tracing in product space at
        about the same frame time; ``benchmarks/bench_fidelity.py --deformable``,
        ``benchmarks/bench_scaling.py``)."""
        if self.field_space is not None:
            return self.field_space
        return "product" if kind == "deformable" else "log"

    def resolved_theta_min(self) -> float:
        """The eq. 37 cut-off actually used (radians)."""
        return DEFAULT_THETA_MIN if self.theta_min is None else float(self.theta_min)

    def runtime_only(self) -> ShadowSettings:
        """These settings as a plain :class:`ShadowSettings` (drops subclass fields)."""
        names = {f.name for f in fields(ShadowSettings)}
        return ShadowSettings(**{k: getattr(self, k) for k in names})
