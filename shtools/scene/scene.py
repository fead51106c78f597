"""Scene files: TOML parsed and validated into dataclasses (see ``docs/scenes.md``).

Parsing checks everything that can be checked without loading meshes or assets:
unknown keys (with a suggestion of the right one), types and ranges, that the
files named exist (paths resolve relative to the scene file), object names and
parent links.  Every problem is an :class:`~shtools.errors.InputError` whose one
line names the scene file and the offending key, e.g.
``scene.toml: objects[2] ('ball'): unknown key 'rotaton'; did you mean 'rotate'?``.
"""

from __future__ import annotations

import difflib
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from shtools.errors import InputError

ROLES = ("receiver", "blocker", "both")
EXP_METHODS = ("auto", "hyb", "ps*", "ps", "ol", "exact", "volterra")
BAKE_METHODS = ("default", "hyb", "ps*", "ps", "ol", "exact", "volterra", "product", "raytrace")
WINDOWS = ("cosine", "hann", "lanczos", "none")
FIT_METHODS = ("variational", "octree", "kmeans")
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
GLTF_SUFFIXES = (".glb", ".gltf")

SETTINGS_KEYS = (
    "order", "acc_order", "exp_method", "window", "window_h", "theta_max_deg",
    "theta_min_deg", "hierarchy", "vertices_per_cluster", "frames", "fps", "tables", "method",
)
OBJECT_KEYS = (
    "name", "mesh", "primitive", "role", "albedo", "parent", "translate", "rotate",
    "quaternion", "scale", "keyframes", "loop", "blocker", "skin",
)
TRANSFORM_KEYS = ("translate", "rotate", "quaternion", "scale")
KEYFRAME_KEYS = ("time", "frame", *TRANSFORM_KEYS)
BLOCKER_KEYS = ("spheres", "tree", "bound", "fit", "method", "seed", "branching", "exact")
SKIN_KEYS = ("animation", "speed", "offset")
ENVIRONMENT_KEYS = ("light", "image", "coeffs", "intensity", "rotate_deg")
LIGHT_KEYS = ("name", "position", "radius", "color", "intensity", "keyframes", "loop")
LIGHT_KEYFRAME_KEYS = ("time", "frame", "position", "radius", "color")
TOP_KEYS = ("settings", "environment", "lights", "objects")


# --------------------------------------------------------------------------- dataclasses
@dataclass
class Settings:
    """``[settings]``: SH and runtime parameters, frame count and rate.

    Angles are stored in radians (the file gives degrees, ``*_deg`` keys).
    """

    order: int = 4
    acc_order: int | None = None
    exp_method: str = "auto"
    window: str | None = "cosine"
    window_h: float | None = None
    theta_max: float = math.radians(25.0)
    theta_min: float | None = None
    hierarchy: bool = True
    vertices_per_cluster: int = 400
    frames: int = 1
    fps: float = 24.0
    tables: Path | None = None
    method: str = "default"


@dataclass
class Pose:
    """A rigid transform ``T * R * S``: translation, unit quaternion (x, y, z, w), scale."""

    translate: np.ndarray = field(default_factory=lambda: np.zeros(3))
    quaternion: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))


@dataclass
class Keyframe:
    """A pose at a time (seconds)."""

    time: float
    pose: Pose


@dataclass
class BlockerSpec:
    """How an object blocks light.

    ``kind`` is ``"spheres"``, ``"tree"`` or ``"bound"`` (an asset at ``path``),
    ``"fit"`` (fit ``count`` spheres on the fly) or ``"exact"`` (the primitive's
    own spheres, for ``sphere`` primitives).
    """

    kind: str
    path: Path | None = None
    count: int | None = None
    method: str = "variational"
    seed: int = 0
    branching: int = 4


@dataclass
class SkinSpec:
    """Skinned animation of a glTF mesh: clip index or name, speed, time offset."""

    animation: int | str = 0
    speed: float = 1.0
    offset: float = 0.0


@dataclass
class ObjectSpec:
    """One ``[[objects]]`` entry."""

    name: str
    index: int
    role: str
    mesh: Path | None = None
    primitive: tuple[str, dict] | None = None
    albedo: np.ndarray = field(default_factory=lambda: np.ones(3))
    parent: str | None = None
    pose: Pose = field(default_factory=Pose)
    keyframes: list[Keyframe] = field(default_factory=list)
    loop: bool = False
    blocker: BlockerSpec | None = None
    skin: SkinSpec | None = None

    @property
    def receives(self) -> bool:
        return self.role in ("receiver", "both")

    @property
    def blocks(self) -> bool:
        return self.role in ("blocker", "both")


@dataclass
class EnvironmentSpec:
    """``[environment]``: exactly one of a light asset, an HDR image or inline SH."""

    kind: str | None = None  # "light" | "image" | "coeffs" | None (no environment)
    path: Path | None = None
    coeffs: np.ndarray | None = None
    intensity: float = 1.0
    rotate: float = 0.0  # radians about +Y


@dataclass
class LightKey:
    time: float
    position: np.ndarray
    radius: float
    color: np.ndarray


@dataclass
class SphereLightSpec:
    """One ``[[lights]]`` spherical light (RGB radiance ``color * intensity``)."""

    name: str
    keys: list[LightKey]
    loop: bool = False


@dataclass
class Scene:
    """A parsed scene file."""

    path: Path
    settings: Settings
    objects: list[ObjectSpec]
    environment: EnvironmentSpec
    lights: list[SphereLightSpec]

    @property
    def base_dir(self) -> Path:
        return self.path.parent

    def object(self, name: str) -> ObjectSpec:
        for obj in self.objects:
            if obj.name == name:
                return obj
        raise KeyError(name)

    def frame_times(self, frames: range | None = None) -> np.ndarray:
        """Times in seconds of ``frames`` (default all), shape (T,)."""
        frames = range(self.settings.frames) if frames is None else frames
        return np.asarray(list(frames), dtype=float) / self.settings.fps


# --------------------------------------------------------------------------- helpers
class _Ctx:
    """Location of a value in the file, for error messages."""

    def __init__(self, path: Path, where: str = ""):
        self.path, self.where = path, where

    def sub(self, where: str) -> _Ctx:
        return _Ctx(self.path, f"{self.where}.{where}" if self.where else where)

    def error(self, message: str) -> InputError:
        prefix = f"{self.where}: " if self.where else ""
        return InputError(prefix + message, self.path)


def _check_keys(table: Any, allowed, ctx: _Ctx) -> dict:
    if not isinstance(table, dict):
        raise ctx.error(f"expected a table, got {type(table).__name__}")
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
            hint = f"did you mean '{close[0]}'?" if close else f"allowed: {', '.join(allowed)}"
            raise ctx.error(f"unknown key '{key}'; {hint}")
    return table


def _number(value, ctx: _Ctx, *, lo=None, hi=None, lo_open=False, integer=False):
    ok_types = (int,) if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, ok_types):
        kind = "an integer" if integer else "a number"
        raise ctx.error(f"must be {kind}, got {value!r}")
    if not math.isfinite(value):
        raise ctx.error(f"must be finite, got {value!r}")
    if lo is not None and (value <= lo if lo_open else value < lo):
        raise ctx.error(f"must be {'>' if lo_open else '>='} {lo}, got {value!r}")
    if hi is not None and value > hi:
        raise ctx.error(f"must be <= {hi}, got {value!r}")
    return value


def _vector(value, n: int, ctx: _Ctx, *, positive=False, nonnegative=False) -> np.ndarray:
    if (
        not isinstance(value, list)
        or len(value) != n
        or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in value)
    ):
        raise ctx.error(f"must be a list of {n} numbers, got {value!r}")
    arr = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise ctx.error(f"must be finite, got {value!r}")
    if positive and np.any(arr <= 0):
        raise ctx.error(f"must be positive, got {value!r}")
    if nonnegative and np.any(arr < 0):
        raise ctx.error(f"must not be negative, got {value!r}")
    return arr


def _choice(value, choices, ctx: _Ctx) -> str:
    if not isinstance(value, str) or value not in choices:
        close = difflib.get_close_matches(str(value), choices, n=1)
        hint = f"did you mean '{close[0]}'? " if close else ""
        raise ctx.error(f"must be one of {', '.join(choices)}; {hint}got {value!r}")
    return value


def _file(value, base: Path, ctx: _Ctx, suffixes=None) -> Path:
    if not isinstance(value, str) or not value:
        raise ctx.error(f"must be a file path string, got {value!r}")
    path = (base / value) if not os.path.isabs(value) else Path(value)
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise ctx.error(f"'{value}' has an unsupported extension; use one of {', '.join(suffixes)}")
    if path.is_dir():
        raise ctx.error(f"'{value}' is a folder; name a file")
    if not path.is_file():
        raise ctx.error(f"file '{value}' not found (paths are relative to the scene file)")
    return path


def euler_to_quaternion(degrees: np.ndarray) -> np.ndarray:
    """Quaternion (x, y, z, w) of ``R = Rz @ Ry @ Rx`` from angles in degrees (x, y, z)."""
    hx, hy, hz = np.radians(np.asarray(degrees, dtype=float)) / 2
    qx = np.array([math.sin(hx), 0, 0, math.cos(hx)])
    qy = np.array([0, math.sin(hy), 0, math.cos(hy)])
    qz = np.array([0, 0, math.sin(hz), math.cos(hz)])
    return quaternion_multiply(quaternion_multiply(qz, qy), qx)


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (x, y, z, w); ``a*b`` rotates by b then a."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ])


def _pose(table: dict, ctx: _Ctx, base: Pose | None = None) -> Pose:
    """Transform keys of ``table``; missing ones are taken from ``base``."""
    base = base or Pose()
    pose = Pose(base.translate.copy(), base.quaternion.copy(), base.scale.copy())
    if "translate" in table:
        pose.translate = _vector(table["translate"], 3, ctx.sub("translate"))
    if "rotate" in table and "quaternion" in table:
        raise ctx.error("give either 'rotate' (Euler degrees) or 'quaternion', not both")
    if "rotate" in table:
        pose.quaternion = euler_to_quaternion(_vector(table["rotate"], 3, ctx.sub("rotate")))
    if "quaternion" in table:
        q = _vector(table["quaternion"], 4, ctx.sub("quaternion"))
        norm = np.linalg.norm(q)
        if norm < 1e-12:
            raise ctx.sub("quaternion").error("must not be zero")
        pose.quaternion = q / norm
    if "scale" in table:
        s = table["scale"]
        if isinstance(s, int | float) and not isinstance(s, bool):
            s = [s, s, s]
        pose.scale = _vector(s, 3, ctx.sub("scale"), positive=True)
    return pose


def _key_time(table: dict, fps: float, ctx: _Ctx) -> float:
    if ("time" in table) == ("frame" in table):
        raise ctx.error("give exactly one of 'time' (seconds) or 'frame'")
    if "time" in table:
        return float(_number(table["time"], ctx.sub("time")))
    return float(_number(table["frame"], ctx.sub("frame"))) / fps


def _sorted_keys(keys, ctx: _Ctx):
    times = [k.time for k in keys]
    if len(set(times)) != len(times):
        raise ctx.error("two keyframes have the same time")
    return sorted(keys, key=lambda k: k.time)


# --------------------------------------------------------------------------- sections
def _settings(table: dict, ctx: _Ctx, base: Path) -> Settings:
    _check_keys(table, SETTINGS_KEYS, ctx)
    s = Settings()
    if "order" in table:
        s.order = _number(table["order"], ctx.sub("order"), lo=1, hi=12, integer=True)
    if "acc_order" in table:
        s.acc_order = _number(table["acc_order"], ctx.sub("acc_order"), lo=s.order, hi=16,
                              integer=True)
    if "exp_method" in table:
        s.exp_method = _choice(table["exp_method"], EXP_METHODS, ctx.sub("exp_method"))
    if "window" in table:
        w = _choice(table["window"], WINDOWS, ctx.sub("window"))
        s.window = None if w == "none" else w
    if "window_h" in table:
        s.window_h = float(_number(table["window_h"], ctx.sub("window_h"), lo=0, lo_open=True))
    if "theta_max_deg" in table:
        s.theta_max = math.radians(_number(table["theta_max_deg"], ctx.sub("theta_max_deg"),
                                           lo=0, lo_open=True, hi=90))
    if "theta_min_deg" in table:
        s.theta_min = math.radians(_number(table["theta_min_deg"], ctx.sub("theta_min_deg"),
                                           lo=0, lo_open=True, hi=90))
    if "hierarchy" in table:
        if not isinstance(table["hierarchy"], bool):
            raise ctx.sub("hierarchy").error("must be true or false")
        s.hierarchy = table["hierarchy"]
    if "vertices_per_cluster" in table:
        s.vertices_per_cluster = _number(table["vertices_per_cluster"],
                                         ctx.sub("vertices_per_cluster"), lo=1, integer=True)
    if "frames" in table:
        s.frames = _number(table["frames"], ctx.sub("frames"), lo=1, integer=True)
    if "fps" in table:
        s.fps = float(_number(table["fps"], ctx.sub("fps"), lo=0, lo_open=True))
    if "tables" in table:
        s.tables = _file(table["tables"], base, ctx.sub("tables"), (".h5",))
    if "method" in table:
        s.method = _choice(table["method"], BAKE_METHODS, ctx.sub("method"))
    return s


def _blocker(value, obj: ObjectSpec, ctx: _Ctx, base: Path) -> BlockerSpec:
    table = _check_keys(value, BLOCKER_KEYS, ctx)
    sources = [k for k in ("spheres", "tree", "bound", "fit", "exact") if k in table]
    if len(sources) != 1:
        raise ctx.error("give exactly one of 'spheres', 'tree', 'bound' (asset files), "
                        "'fit' (number of spheres to fit) or 'exact = true'")
    kind = sources[0]
    spec = BlockerSpec(kind)
    if kind in ("spheres", "tree", "bound"):
        spec.path = _file(table[kind], base, ctx.sub(kind), (".h5",))
    elif kind == "fit":
        spec.count = _number(table["fit"], ctx.sub("fit"), lo=1, integer=True)
    else:
        if table["exact"] is not True:
            raise ctx.sub("exact").error("must be true (or leave it out)")
        if obj.primitive is None or obj.primitive[0] != "sphere":
            raise ctx.sub("exact").error("only a 'sphere' primitive is exactly a sphere set; "
                                         "use 'fit = N' or a spheres asset")
    if kind == "bound" and obj.skin is None:
        raise ctx.sub("bound").error("a bound sphere set needs a skinned object; add "
                                     "'skin = {}' or use 'spheres'/'tree'")
    for key in ("method", "seed", "branching"):
        if key in table and kind != "fit":
            raise ctx.sub(key).error("only applies with 'fit = N'")
    if "method" in table:
        spec.method = _choice(table["method"], FIT_METHODS, ctx.sub("method"))
    if "seed" in table:
        spec.seed = _number(table["seed"], ctx.sub("seed"), lo=0, integer=True)
    if "branching" in table:
        spec.branching = _number(table["branching"], ctx.sub("branching"), lo=2, integer=True)
    return spec


def _object(table: Any, index: int, settings: Settings, ctx: _Ctx, base: Path) -> ObjectSpec:
    if not isinstance(table, dict):
        raise ctx.error("expected a table ([[objects]])")
    name = table.get("name", f"object{index}")
    if not isinstance(name, str) or not name:
        raise ctx.sub("name").error("must be a non-empty string")
    ctx = _Ctx(ctx.path, f"{ctx.where} ('{name}')")
    _check_keys(table, OBJECT_KEYS, ctx)
    if "role" not in table:
        raise ctx.error("missing key 'role' (receiver, blocker or both)")
    obj = ObjectSpec(name=name, index=index, role=_choice(table["role"], ROLES, ctx.sub("role")))
    if ("mesh" in table) == ("primitive" in table):
        raise ctx.error("give exactly one of 'mesh' (a file) or 'primitive' (a generated shape)")
    if "mesh" in table:
        obj.mesh = _file(table["mesh"], base, ctx.sub("mesh"), MESH_SUFFIXES)
    else:
        prim = table["primitive"]
        if isinstance(prim, str):
            prim = {"type": prim}
        if not isinstance(prim, dict) or not isinstance(prim.get("type"), str):
            raise ctx.sub("primitive").error(
                "must be a type name or a table with 'type' and parameters, e.g. "
                "{ type = \"sphere\", radius = 0.5 }")
        from shtools.scene.primitives import PRIMITIVES

        params = {k: v for k, v in prim.items() if k != "type"}
        kind = _choice(prim["type"], tuple(PRIMITIVES), ctx.sub("primitive.type"))
        _check_keys(params, tuple(PRIMITIVES[kind]), ctx.sub("primitive"))
        obj.primitive = (kind, params)
    if "albedo" in table:
        obj.albedo = _vector(table["albedo"], 3, ctx.sub("albedo"), nonnegative=True)
    if "parent" in table:
        if not isinstance(table["parent"], str):
            raise ctx.sub("parent").error("must be the name of another object")
        obj.parent = table["parent"]
    obj.pose = _pose(table, ctx)
    if "loop" in table:
        if not isinstance(table["loop"], bool):
            raise ctx.sub("loop").error("must be true or false")
        obj.loop = table["loop"]
    if "keyframes" in table:
        keys = table["keyframes"]
        if not isinstance(keys, list) or not keys:
            raise ctx.sub("keyframes").error("must be a non-empty array of tables")
        frames = []
        for k, key in enumerate(keys):
            kctx = ctx.sub(f"keyframes[{k}]")
            _check_keys(key, KEYFRAME_KEYS, kctx)
            frames.append(Keyframe(_key_time(key, settings.fps, kctx), _pose(key, kctx, obj.pose)))
        obj.keyframes = _sorted_keys(frames, ctx.sub("keyframes"))
    if "skin" in table:
        sctx = ctx.sub("skin")
        skin = _check_keys(table["skin"], SKIN_KEYS, sctx)
        if obj.mesh is None or obj.mesh.suffix.lower() not in GLTF_SUFFIXES:
            raise sctx.error("skinned animation needs a glTF mesh (.glb or .gltf)")
        spec = SkinSpec()
        if "animation" in skin:
            a = skin["animation"]
            if isinstance(a, bool) or not isinstance(a, int | str):
                raise sctx.sub("animation").error("must be a clip index or name")
            spec.animation = a
        if "speed" in skin:
            spec.speed = float(_number(skin["speed"], sctx.sub("speed")))
        if "offset" in skin:
            spec.offset = float(_number(skin["offset"], sctx.sub("offset")))
        obj.skin = spec
    if "blocker" in table:
        if not obj.blocks:
            raise ctx.sub("blocker").error(f"role is '{obj.role}'; set role = \"blocker\" or "
                                           "\"both\" to use a blocker representation")
        obj.blocker = _blocker(table["blocker"], obj, ctx.sub("blocker"), base)
    elif obj.blocks:
        if obj.primitive is not None and obj.primitive[0] == "sphere":
            obj.blocker = BlockerSpec("exact")
        else:
            raise ctx.error("a blocker needs a representation: add blocker = { fit = 32 } "
                            "or blocker = { spheres = \"file.h5\" }")
    return obj


def _environment(table: dict, settings: Settings, ctx: _Ctx, base: Path) -> EnvironmentSpec:
    _check_keys(table, ENVIRONMENT_KEYS, ctx)
    sources = [k for k in ("light", "image", "coeffs") if k in table]
    if len(sources) > 1:
        raise ctx.error("give only one of 'light' (a light asset), 'image' (an HDR lat-long "
                        "map) or 'coeffs' (inline SH)")
    env = EnvironmentSpec()
    if sources:
        env.kind = sources[0]
    if env.kind == "light":
        env.path = _file(table["light"], base, ctx.sub("light"), (".h5",))
    elif env.kind == "image":
        env.path = _file(table["image"], base, ctx.sub("image"), (".hdr", ".exr", ".pfm"))
    elif env.kind == "coeffs":
        c = table["coeffs"]
        cctx = ctx.sub("coeffs")
        if not isinstance(c, list) or not c:
            raise cctx.error("must be an array of [r, g, b] rows, one per SH coefficient")
        rows = [_vector(row, 3, cctx.sub(f"[{i}]")) for i, row in enumerate(c)]
        n = math.isqrt(len(rows))
        if n * n != len(rows):
            raise cctx.error(f"has {len(rows)} rows; an order-n SH needs n*n rows")
        if n != settings.order:
            raise cctx.error(f"is order {n} but settings.order is {settings.order}; give "
                             f"{settings.order ** 2} rows or change the order")
        env.coeffs = np.stack(rows)
    if "intensity" in table:
        env.intensity = float(_number(table["intensity"], ctx.sub("intensity"), lo=0))
    if "rotate_deg" in table:
        env.rotate = math.radians(_number(table["rotate_deg"], ctx.sub("rotate_deg")))
    return env


def _light(table: Any, index: int, settings: Settings, ctx: _Ctx) -> SphereLightSpec:
    _check_keys(table, LIGHT_KEYS, ctx)
    name = table.get("name", f"light{index}")
    for key in ("position", "radius", "color"):
        if key not in table:
            raise ctx.error(f"missing key '{key}'")
    intensity = float(_number(table.get("intensity", 1.0), ctx.sub("intensity"), lo=0))

    def key_of(t: float, tab: dict, kctx: _Ctx, base: LightKey | None) -> LightKey:
        pos = _vector(tab["position"], 3, kctx.sub("position")) if "position" in tab \
            else base.position
        if "radius" in tab:
            radius = float(_number(tab["radius"], kctx.sub("radius")))
            if radius <= 0:
                raise kctx.sub("radius").error(
                    f"must be > 0 (a zero-area light emits nothing), got {radius!r}")
        else:
            radius = base.radius
        color = (_vector(tab["color"], 3, kctx.sub("color"), nonnegative=True) * intensity
                 if "color" in tab else base.color)
        return LightKey(t, pos, radius, color)

    first = key_of(0.0, table, ctx, None)
    keys = [first]
    if "keyframes" in table:
        kt = table["keyframes"]
        if not isinstance(kt, list) or not kt:
            raise ctx.sub("keyframes").error("must be a non-empty array of tables")
        keys = []
        for k, key in enumerate(kt):
            kctx = ctx.sub(f"keyframes[{k}]")
            _check_keys(key, LIGHT_KEYFRAME_KEYS, kctx)
            keys.append(key_of(_key_time(key, settings.fps, kctx), key, kctx, first))
        keys = _sorted_keys(keys, ctx.sub("keyframes"))
    loop = table.get("loop", False)
    if not isinstance(loop, bool):
        raise ctx.sub("loop").error("must be true or false")
    return SphereLightSpec(str(name), keys, loop)


# --------------------------------------------------------------------------- entry points
def parse_scene(text: str, path: str | os.PathLike = "scene.toml") -> Scene:
    """Parse scene TOML ``text``; relative paths resolve against ``path``'s folder.

    Raises
    ------
    InputError
        Bad TOML (with line and column), unknown keys (with a suggestion), bad
        values, missing files, unknown or cyclic parents, duplicate names.
    """
    path = Path(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"invalid TOML: {exc}", path) from None
    ctx = _Ctx(path)
    _check_keys(data, TOP_KEYS, ctx)
    base = path.parent
    settings = _settings(data.get("settings", {}), ctx.sub("settings"), base)
    objects_raw = data.get("objects", [])
    if not isinstance(objects_raw, list) or not objects_raw:
        raise ctx.error("no objects; add at least one [[objects]] table")
    objects = [
        _object(t, i, settings, ctx.sub(f"objects[{i}]"), base) for i, t in enumerate(objects_raw)
    ]
    names = [o.name for o in objects]
    for o in objects:
        if names.count(o.name) > 1:
            raise ctx.error(f"two objects are named '{o.name}'; names must be unique")
    for o in objects:
        if o.parent is not None:
            if o.parent not in names:
                close = difflib.get_close_matches(o.parent, names, n=1)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                raise ctx.sub(f"objects[{o.index}] ('{o.name}').parent").error(
                    f"no object named '{o.parent}'{hint}")
            seen, cur = {o.name}, o
            while cur.parent is not None:
                if cur.parent in seen:
                    raise ctx.sub(f"objects[{o.index}] ('{o.name}').parent").error(
                        "parents form a cycle")
                seen.add(cur.parent)
                cur = objects[names.index(cur.parent)]
            if o.skin is not None:
                raise ctx.sub(f"objects[{o.index}] ('{o.name}').parent").error(
                    "a skinned object cannot have a parent; place it with translate/rotate")
    if not any(o.receives for o in objects):
        raise ctx.error("no receivers; give at least one object role = \"receiver\" or \"both\"")
    environment = _environment(data.get("environment", {}), settings, ctx.sub("environment"), base)
    lights_raw = data.get("lights", [])
    if not isinstance(lights_raw, list):
        raise ctx.sub("lights").error("must be an array of tables ([[lights]])")
    lights = [_light(t, i, settings, ctx.sub(f"lights[{i}]")) for i, t in enumerate(lights_raw)]
    if environment.kind is None and not lights:
        raise ctx.error("no light; add an [environment] or a [[lights]] table")
    return Scene(path, settings, objects, environment, lights)


def load_scene(path: str | os.PathLike) -> Scene:
    """Read and parse a scene file (see :func:`parse_scene`)."""
    path = Path(path)
    if not path.is_file():
        raise InputError("scene file not found; check the path", path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the scene file ({exc})", path) from None
    return parse_scene(text, path)
