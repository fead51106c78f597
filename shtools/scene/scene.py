"""Scene files: TOML parsed and validated into dataclasses (see ``docs/scenes.md``).

Parsing checks everything that can be checked without loading meshes or assets.
Two passes:

1. the schema (:mod:`shtools.scene.schema`, pydantic): unknown keys (with a
   suggestion of the right one), types, finiteness, ranges, choices;
2. the semantic pass here: files exist (paths resolve relative to the scene
   file), object names are unique, parents exist and form no cycle, keyframe
   times are distinct, orders agree, blocker kinds fit their object.

Every problem is an :class:`~shtools.errors.InputError` whose one line names
the scene file and the offending key, e.g.
``scene.toml: objects[2] ('ball'): unknown key 'rotaton'; did you mean 'rotate'?``.
"""

from __future__ import annotations

import difflib
import math
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from shtools.errors import InputError
from shtools.geometry.transforms import euler_to_quaternion
from shtools.geometry.visibility import CONE_DIRECTIONS
from shtools.runtime.settings import ShadowSettings, Unit, setting
from shtools.runtime.settings import scene_fields as _scene_fields
from shtools.scene import schema
from shtools.scene.kinds import BLOCKER_KINDS, bake_method_names
from shtools.scene.light_shadows import ssoc_rays, ssoc_settings
from shtools.scene.schema import GLTF_SUFFIXES, IMAGE_SUFFIXES, MESH_SUFFIXES
from shtools.scene.skinned_visibility import SKINNED_DIRECTIONS
from shtools.scene.specs import (
    BlockerSpec,
    EnvironmentSpec,
    Keyframe,
    LightKey,
    ObjectSpec,
    Pose,
    SkinSpec,
    SphereLightSpec,
)

__all__ = ["Scene", "Settings", "load_scene", "parse_scene"]


# --------------------------------------------------------------------------- dataclasses
@dataclass
class Settings(ShadowSettings):
    """``[settings]``: the runtime's settings schema plus frame count, rate, tables, method.

    Angles are stored in radians (the file gives degrees, ``*_deg`` keys);
    ``window = "none"`` is stored as None.
    """

    frames: int = setting(1, "int", lo=1, hi=1_000_000,
                          doc="frames to bake (at most 1,000,000: 11.6 hours at 24 fps)")
    fps: float = setting(24.0, "float", lo=0, lo_open=True, doc="frames per second")
    tables: Path | None = setting(None, "path", none_means="built at the accumulation order",
                                  doc="log tables asset (.h5) of the accumulation order")
    method: str = setting("default", "choice", choices=bake_method_names,
                          doc="visibility method (shtools.scene.shadows)")
    self_visibility: bool = setting(True, "bool",
                                    doc="self-shadowing of role-\"both\" objects by their real "
                                        "mesh (rigid: traced once; skinned: every frame)")
    self_visibility_directions: int = setting(
        SKINNED_DIRECTIONS, "int", lo=4, hi=4096,
        doc="directions of each vertex's set tracing skinned objects' posed mesh every "
            "frame (a ninth of them on every vertex finds where the mesh is; the rest are "
            "cast only there)")
    traced_shadows: bool = setting(True, "bool",
                                   doc="the shadow of skinned objects that trace their posed "
                                       "mesh and of rigid sphere-set blockers is ray traced "
                                       "against their real mesh on receiver-only objects")
    traced_shadow_directions: int = setting(
        CONE_DIRECTIONS, "int", lo=4, hi=4096,
        doc="rays per receiver-only vertex, traced object and frame whose hemisphere the "
            "object fills (fewer for smaller cones)")
    local_visibility: bool = setting(False, "bool",
                                     doc="rest-pose local visibility g_p of skinned "
                                         "role-\"both\" objects that do not trace their mesh")


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


def _validate(model, table, data, path: Path, prefix: tuple = ()):
    """``model.model_validate(table)`` with errors as one located line."""
    try:
        return model.model_validate(table)
    except ValidationError as exc:
        raise schema.validation_error(exc, data, path, prefix) from None


def _file(value: str, base: Path, ctx: _Ctx, suffixes=None) -> Path:
    path = (base / value) if not os.path.isabs(value) else Path(value)
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise ctx.error(f"'{value}' has an unsupported extension; use one of {', '.join(suffixes)}")
    if path.is_dir():
        raise ctx.error(f"'{value}' is a folder; name a file")
    if not path.is_file():
        raise ctx.error(f"file '{value}' not found (paths are relative to the scene file)")
    return path


def _pose(t: schema.Transform, base: Pose | None = None) -> Pose:
    """The transform keys of a validated table; missing ones are taken from ``base``."""
    base = base or Pose()
    pose = Pose(base.translate.copy(), base.quaternion.copy(), base.scale.copy())
    if t.translate is not None:
        pose.translate = np.asarray(t.translate, dtype=float)
    if t.rotate is not None:
        pose.quaternion = euler_to_quaternion(np.asarray(t.rotate, dtype=float))
    if t.quaternion is not None:
        q = np.asarray(t.quaternion, dtype=float)
        pose.quaternion = q / np.linalg.norm(q)
    if t.scale is not None:
        pose.scale = np.asarray(t.scale, dtype=float)
    return pose


def _key_time(t, fps: float) -> float:
    return float(t.time) if t.time is not None else float(t.frame) / fps


def _sorted_keys(keys, ctx: _Ctx):
    times = [k.time for k in keys]
    if len(set(times)) != len(times):
        raise ctx.error("two keyframes have the same time")
    return sorted(keys, key=lambda k: k.time)


# --------------------------------------------------------------------------- sections
def _settings(data: dict, ctx: _Ctx, base: Path) -> Settings:
    table = data.get("settings", {})
    model = _validate(schema.settings_model(Settings), table, data, ctx.path, ("settings",))
    kwargs = {}
    for key, name, limits, _ in _scene_fields(Settings):
        value = getattr(model, key)
        if value is None:
            continue
        if limits.unit is Unit.DEGREES:
            value = math.radians(value)
        if limits.kind == "path":
            value = _file(value, base, ctx.sub(key), (".h5",))
        kwargs[name] = value
    if kwargs.get("window") == "none":
        kwargs["window"] = None
    try:
        return Settings(**kwargs)
    except InputError as exc:  # a cross-field bound, e.g. acc_order below order
        raise ctx.error(exc.message) from None


def _blocker(table, obj: ObjectSpec, data: dict, index: int, ctx: _Ctx,
             base: Path) -> BlockerSpec:
    kinds = BLOCKER_KINDS
    model = _validate(schema.blocker_model(tuple(kinds.values())), table, data, ctx.path,
                      ("objects", index, "blocker"))
    given = model.model_fields_set
    (name,) = [k for k in kinds if k in given]
    kind = kinds[name]
    spec = BlockerSpec(name, options={k: v[1] for k, v in kind.options.items()})
    value = getattr(model, name)
    if kind.value == "asset":
        spec.path = _file(value, base, ctx.sub(name), (".h5",))
    elif kind.value == "count":
        spec.count = value
    elif value is not True:
        raise ctx.sub(name).error("must be true (or leave it out)")
    problem = kind.check(spec, obj)
    if problem is not None:
        raise ctx.sub(problem[0]).error(problem[1])
    for key in sorted(given - {name}):
        if key not in kind.options:
            owners = [f"'{k.name} = ...'" for k in kinds.values() if key in k.options]
            raise ctx.sub(key).error(f"only applies with {' or '.join(owners)}")
        spec.options[key] = getattr(model, key)
    return spec


def _object(t: schema.Object, index: int, data: dict, settings: Settings, ctx: _Ctx,
            base: Path) -> ObjectSpec:
    name = t.name if t.name is not None else f"object{index}"
    ctx = _Ctx(ctx.path, f"{ctx.where} ('{name}')")
    obj = ObjectSpec(name=name, index=index, role=t.role, parent=t.parent, loop=t.loop)
    if t.mesh is not None:
        obj.mesh = _file(t.mesh, base, ctx.sub("mesh"), MESH_SUFFIXES)
    else:
        obj.primitive = (t.primitive.type, t.primitive.params)
    if t.albedo is not None:
        obj.albedo = np.asarray(t.albedo, dtype=float)
    obj.pose = _pose(t)
    if t.keyframes is not None:
        frames = [Keyframe(_key_time(k, settings.fps), _pose(k, obj.pose)) for k in t.keyframes]
        obj.keyframes = _sorted_keys(frames, ctx.sub("keyframes"))
    if t.skin is not None:
        if obj.mesh is None or obj.mesh.suffix.lower() not in GLTF_SUFFIXES:
            raise ctx.sub("skin").error("skinned animation needs a glTF mesh (.glb or .gltf)")
        obj.skin = SkinSpec(t.skin.animation, t.skin.speed, t.skin.offset)
    if t.blocker is not None:
        if not obj.blocks:
            raise ctx.sub("blocker").error(f"role is '{obj.role}'; set role = \"blocker\" or "
                                           "\"both\" to use a blocker representation")
        obj.blocker = _blocker(t.blocker, obj, data, index, ctx.sub("blocker"), base)
    elif obj.blocks:
        if obj.primitive is not None and obj.primitive[0] == "sphere":
            obj.blocker = BlockerSpec("exact")
        else:
            raise ctx.error("a blocker needs a representation: add blocker = { fit = 32 } "
                            "or blocker = { spheres = \"file.h5\" }")
    if t.self_visibility is not None:
        value, vctx = t.self_visibility, ctx.sub("self_visibility")
        if obj.role != "both":
            raise vctx.error("self-shadowing from the real mesh is for objects with "
                             "role = \"both\"")
        if isinstance(value, bool):
            obj.self_visibility = value
        elif isinstance(value, str) and obj.skin is not None:
            raise vctx.error("a skinned object deforms: its transfer cannot be precomputed; "
                             "use true (its posed mesh traced every frame) or false")
        elif isinstance(value, str):
            obj.self_visibility = _file(value, base, vctx, (".h5",))
        else:
            raise vctx.error("must be true, false or a transfer asset "
                             "('shtools transfer MESH -o x.transfer.h5')")
    return obj


def _environment(t: schema.Environment, settings: Settings, ctx: _Ctx,
                 base: Path) -> EnvironmentSpec:
    env = EnvironmentSpec(intensity=float(t.intensity), rotate=math.radians(t.rotate_deg))
    if t.radius is not None:
        env.radius = float(t.radius)
        if t.center is not None:
            env.center = np.asarray(t.center, dtype=float)
        if t.scaling is not None:
            env.scaling = _file(t.scaling, base, ctx.sub("scaling"), (".h5",))
    if t.light is not None:
        env.kind, env.path = "light", _file(t.light, base, ctx.sub("light"), (".h5",))
    elif t.image is not None:
        env.kind, env.path = "image", _file(t.image, base, ctx.sub("image"), IMAGE_SUFFIXES)
    elif t.coeffs is not None:
        cctx = ctx.sub("coeffs")
        n = math.isqrt(len(t.coeffs))
        if n * n != len(t.coeffs):
            raise cctx.error(f"has {len(t.coeffs)} rows; an order-n SH needs n*n rows")
        if n != settings.order:
            raise cctx.error(f"is order {n} but settings.order is {settings.order}; give "
                             f"{settings.order ** 2} rows or change the order")
        env.kind, env.coeffs = "coeffs", np.asarray(t.coeffs, dtype=float)
    return env


def _field_light(t: schema.Light, name: str, settings: Settings, ctx: _Ctx,
                 base: Path) -> SphereLightSpec:
    """A ``[[lights]]`` table with ``field = "x.srf.h5"``: keyed lamp poses."""
    from types import SimpleNamespace

    path = _file(t.field, base, ctx.sub("field"), (".h5",))

    def pose_of(k, first: Pose | None) -> Pose:
        scale = None if k.scale is None else [float(k.scale)] * 3
        return _pose(SimpleNamespace(translate=k.position, rotate=k.rotate,
                                     quaternion=k.quaternion, scale=scale), first)

    first = pose_of(t, None)
    poses = [Keyframe(0.0, first)]
    if t.keyframes is not None:
        poses = _sorted_keys([Keyframe(_key_time(k, settings.fps), pose_of(k, first))
                              for k in t.keyframes], ctx.sub("keyframes"))
    keys = [LightKey(k.time, k.pose.translate, 0.0, np.zeros(3)) for k in poses]
    from shtools.scene.field_light import FIELD_SAMPLES, field_light_way

    way = field_light_way(t.shadows if "shadows" in t.model_fields_set else None,
                          ctx.sub("shadows"))
    samples = t.samples if "samples" in t.model_fields_set else FIELD_SAMPLES
    return SphereLightSpec(str(name), keys, t.loop, way, samples=samples, srf=path,
                           poses=poses, intensity=float(t.intensity))


def _light(t: schema.Light, index: int, settings: Settings, ctx: _Ctx,
           base: Path | None = None) -> SphereLightSpec:
    name = t.name if t.name is not None else f"light{index}"
    if t.field is not None:
        return _field_light(t, name, settings, ctx, base)

    def key_of(time: float, k, first: LightKey | None) -> LightKey:
        pos = np.asarray(k.position, dtype=float) if k.position is not None else first.position
        radius = float(k.radius) if k.radius is not None else first.radius
        color = (np.asarray(k.color, dtype=float) * float(t.intensity) if k.color is not None
                 else first.color)
        return LightKey(time, pos, radius, color)

    first = key_of(0.0, t, None)
    keys = [first]
    if t.keyframes is not None:
        keys = [key_of(_key_time(k, settings.fps), k, first) for k in t.keyframes]
        keys = _sorted_keys(keys, ctx.sub("keyframes"))
    table = None if t.ssoc is None else t.ssoc.settings()
    try:
        ssoc = ssoc_settings(table)
    except InputError as exc:
        raise ctx.sub("ssoc").error(exc.message) from None
    return SphereLightSpec(str(name), keys, t.loop, t.shadows, t.samples, ssoc,
                           ssoc_rays=ssoc_rays(table))


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
    base = path.parent
    file = _validate(schema.SceneFile, data, data, path)
    settings = _settings(data, ctx.sub("settings"), base)
    objects = [_object(t, i, data, settings, ctx.sub(f"objects[{i}]"), base)
               for i, t in enumerate(file.objects)]
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
    environment = _environment(file.environment, settings, ctx.sub("environment"), base)
    lights = [_light(t, i, settings, ctx.sub(f"lights[{i}]"), base)
              for i, t in enumerate(file.lights)]
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
