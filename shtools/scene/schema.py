"""The scene file's schema: pydantic v2 models of the TOML tables, and their one-line errors.

Validation here is per value and per table: the keys each table allows
(unknown keys are an error with a did-you-mean hint), types, finiteness,
ranges, choices and "exactly one of" rules.  The semantic pass that needs the
whole scene or the file system (files exist, parents exist and form no cycle,
keyframe times, orders that must agree) is in :mod:`shtools.scene.scene`.

The ``[settings]`` model is generated from the settings schema
(:class:`shtools.scene.scene.Settings`, itself a :class:`ShadowSettings`), and
the blocker table from the registry of blocker kinds
(:mod:`shtools.scene.blockers`), so neither list is written here.

Every error becomes :class:`~shtools.errors.InputError` with the TOML path of
the bad key, e.g. ``objects[2] ('ball'): unknown key 'rotaton'; did you mean
'rotate'?`` (:func:`validation_error`).
"""

from __future__ import annotations

import difflib
import math
from functools import cache
from typing import Annotated, Any

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    create_model,
    model_validator,
)
from pydantic_core import PydanticCustomError

from shtools.errors import InputError
from shtools.runtime.settings import MAX_RADIANCE

ROLES = ("receiver", "blocker", "both")
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
GLTF_SUFFIXES = (".glb", ".gltf")
IMAGE_SUFFIXES = (".hdr", ".exr", ".pfm")


# --------------------------------------------------------------------------- errors
def fail(text: str, sub: str = "") -> PydanticCustomError:
    """A validation error whose message is ``text`` (``sub``: a key below the field)."""
    return PydanticCustomError("shtools", "{text}", {"text": text, "sub": sub})


_TEMPLATES = {
    "greater_than_equal": "must be >= {ge}",
    "greater_than": "must be > {gt}",
    "less_than_equal": "must be <= {le}",
    "less_than": "must be < {lt}",
    "int_type": "must be an integer",
    "int_from_float": "must be an integer",
    "float_type": "must be a number",
    "finite_number": "must be finite",
    "bool_type": "must be true or false",
    "string_type": "must be a string",
    "dict_type": "expected a table",
    "model_type": "expected a table",
    "model_attributes_type": "expected a table",
    "list_type": "must be an array",
}


def _where(loc: tuple, data: Any) -> str:
    """The TOML path of ``loc`` in ``data``: ``objects[2] ('ball').keyframes[0].time``."""
    where, node = "", data
    for part in loc:
        if isinstance(part, int):
            where += f"[{part}]"
            node = node[part] if isinstance(node, list) and part < len(node) else None
            if where.startswith("objects[") and where.count("[") == 1:
                name = node.get("name", f"object{part}") if isinstance(node, dict) else None
                if isinstance(name, str) and name:
                    where += f" ('{name}')"
        else:
            where = f"{where}.{part}" if where else str(part)
            node = node.get(part) if isinstance(node, dict) else None
    return where


def validation_error(exc: ValidationError, data: Any, path, prefix: tuple = ()) -> InputError:
    """The first error of a pydantic ``ValidationError`` as a one-line :class:`InputError`.

    ``data`` is the whole parsed TOML (for object names in the path), ``prefix``
    the location of the validated table within it.
    """
    err = exc.errors(include_url=False)[0]
    loc, kind, ctx = (*prefix, *err["loc"]), err["type"], err.get("ctx") or {}
    if kind == "shtools":
        text = ctx["text"]
        if ctx.get("sub"):
            loc = (*loc, *ctx["sub"].split("."))
    elif kind == "missing":
        loc, key = loc[:-1], loc[-1]
        text = f"missing key '{key}'"
    elif kind == "extra_forbidden":  # normally caught with a hint by Table._known_keys
        loc, key = loc[:-1], loc[-1]
        text = f"unknown key '{key}'"
    elif kind in _TEMPLATES:
        bounds = {k: f"{v:g}" if isinstance(v, float) else v for k, v in ctx.items()}
        text = _TEMPLATES[kind].format(**bounds) + f", got {err['input']!r}"
    else:  # a pydantic message we have no wording for: still one line, still located
        text = err["msg"]
    where = _where(loc, data)
    return InputError(f"{where}: {text}" if where else text, path)


# --------------------------------------------------------------------------- value types
def _number(value):
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise fail(f"must be a number, got {value!r}")
    if not math.isfinite(value):
        raise fail(f"must be finite, got {value!r}")
    return float(value)


#: Largest magnitude of a light's position or radius: the runtime works in float32,
#: whose squares overflow above ~1.8e19 (as posed vertices, shtools.scene.pose).
MAX_LENGTH = 1e18


def vector(n: int, *, positive=False, nonnegative=False, scalar_ok=False, limit=None):
    """An array of ``n`` finite numbers (``scalar_ok``: a number means ``[x] * n``;
    ``limit``: the largest magnitude allowed)."""
    def check(value):
        if scalar_ok and isinstance(value, int | float) and not isinstance(value, bool):
            value = [value] * n
        if (not isinstance(value, list) or len(value) != n
                or not all(isinstance(x, int | float) and not isinstance(x, bool)
                           for x in value)):
            what = f"a number or a list of {n} numbers" if scalar_ok else f"a list of {n} numbers"
            raise fail(f"must be {what}, got {value!r}")
        if not all(math.isfinite(x) for x in value):
            raise fail(f"must be finite, got {value!r}")
        if positive and any(x <= 0 for x in value):
            raise fail(f"must be positive, got {value!r}")
        if nonnegative and any(x < 0 for x in value):
            raise fail(f"must not be negative, got {value!r}")
        if limit is not None and any(abs(x) > limit for x in value):
            raise fail(f"must be within +-{limit:g}, got {value!r}")
        return [float(x) for x in value]
    return Annotated[list[float], BeforeValidator(check)]


def choice(choices):
    """A string out of ``choices`` (a tuple, or a callable returning one)."""
    def check(value):
        allowed = tuple(choices() if callable(choices) else choices)
        if not isinstance(value, str) or value not in allowed:
            close = difflib.get_close_matches(str(value), allowed, n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            raise fail(f"must be one of {', '.join(allowed)}; {hint}got {value!r}")
        return str(value)
    return Annotated[str, BeforeValidator(check)]


def _file_string(value):
    if not isinstance(value, str) or not value:
        raise fail(f"must be a file path string, got {value!r}")
    return value


#: a file path as written in the scene (resolved and checked by the semantic pass)
FilePath = Annotated[str, BeforeValidator(_file_string)]
Number = Annotated[float, BeforeValidator(_number)]
StrictInt = Annotated[int, Field(strict=True)]
StrictBool = Annotated[bool, Field(strict=True)]
#: a light's position, colour and intensity (lights and the environment)
Position = vector(3, limit=MAX_LENGTH)
Color = vector(3, nonnegative=True, limit=MAX_RADIANCE)
Intensity = Annotated[Number, Field(ge=0, le=MAX_RADIANCE)]


# --------------------------------------------------------------------------- tables
class Table(BaseModel):
    """A TOML table: unknown keys are refused with a did-you-mean hint."""

    model_config = ConfigDict(extra="forbid", strict=True, populate_by_name=False,
                              arbitrary_types_allowed=True)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        if not isinstance(data, dict):
            raise fail(f"expected a table, got {type(data).__name__}")
        allowed = [f.alias or name for name, f in cls.model_fields.items()]
        for key in data:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
                hint = (f"did you mean '{close[0]}'?" if close
                        else f"allowed: {', '.join(allowed)}")
                raise fail(f"unknown key '{key}'; {hint}")
        return data


def exactly_one(data: dict, keys: tuple[str, ...], message: str) -> None:
    """Raise ``message`` unless exactly one of ``keys`` is in ``data``."""
    if sum(k in data for k in keys) != 1:
        raise fail(message)


class Transform(Table):
    """The transform keys shared by objects and their keyframes."""

    translate: vector(3) | None = None
    rotate: vector(3) | None = None
    quaternion: vector(4) | None = None
    scale: vector(3, positive=True, scalar_ok=True) | None = None

    @model_validator(mode="after")
    def _one_rotation(self):
        if self.rotate is not None and self.quaternion is not None:
            raise fail("give either 'rotate' (Euler degrees) or 'quaternion', not both")
        if self.quaternion is not None and math.hypot(*self.quaternion) < 1e-12:
            raise fail("must not be zero", "quaternion")
        return self


class ObjectKeyframe(Transform):
    """``[[objects.keyframes]]``: a time (seconds) or frame and transform keys."""

    time: Number | None = None
    frame: Number | None = None

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        data = Table._known_keys.__func__(cls, data)
        exactly_one(data, ("time", "frame"), "give exactly one of 'time' (seconds) or 'frame'")
        return data


class Skin(Table):
    """``skin = { animation, speed, offset }`` of a skinned glTF object."""

    animation: Any = 0
    speed: Number = 1.0
    offset: Number = 0.0

    @model_validator(mode="after")
    def _clip(self):
        if isinstance(self.animation, bool) or not isinstance(self.animation, int | str):
            raise fail("must be a clip index or name", "animation")
        return self


class Primitive(Table):
    """``primitive = "sphere"`` or ``{ type = "sphere", radius = 0.5, ... }``."""

    model_config = ConfigDict(extra="allow", strict=True)
    type: str

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        from shtools.scene.primitives import PRIMITIVES

        if isinstance(data, str):
            data = {"type": data}
        if not isinstance(data, dict) or not isinstance(data.get("type"), str):
            raise fail("must be a type name or a table with 'type' and parameters, e.g. "
                       "{ type = \"sphere\", radius = 0.5 }")
        kinds = tuple(PRIMITIVES)
        if data["type"] not in kinds:
            close = difflib.get_close_matches(data["type"], kinds, n=1)
            hint = f"did you mean '{close[0]}'? " if close else ""
            raise fail(f"must be one of {', '.join(kinds)}; {hint}got {data['type']!r}", "type")
        allowed = tuple(PRIMITIVES[data["type"]])
        for key in data:
            if key != "type" and key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1, cutoff=0.6)
                hint = (f"did you mean '{close[0]}'?" if close
                        else f"allowed: {', '.join(allowed)}")
                raise fail(f"unknown key '{key}'; {hint}")
        from shtools.scene.primitives import check_parameters

        try:  # types, lengths, ranges and the vertex count, at parse time
            check_parameters(data["type"], {k: v for k, v in data.items() if k != "type"})
        except InputError as exc:
            raise fail(exc.message) from None
        return data

    @property
    def params(self) -> dict:
        return dict(self.model_extra or {})


class Object(Transform):
    """``[[objects]]``."""

    name: str | None = None
    mesh: FilePath | None = None
    primitive: Primitive | None = None
    role: choice(ROLES) = Field(description="receiver, blocker or both")
    albedo: vector(3, nonnegative=True) | None = None
    parent: str | None = None
    keyframes: Annotated[list[ObjectKeyframe], Field(min_length=1)] | None = None
    loop: StrictBool = False
    blocker: Any = None  # validated against the blocker-kind registry (blocker_model())
    skin: Skin | None = None
    #: true, false or a transfer asset; checked in the semantic pass (shtools.scene.scene)
    self_visibility: Any = None

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        if not isinstance(data, dict):
            raise fail("expected a table ([[objects]])")
        name = data.get("name")
        if name is not None and (not isinstance(name, str) or not name):
            raise fail("must be a non-empty string", "name")
        if "parent" in data and not isinstance(data["parent"], str):
            raise fail("must be the name of another object", "parent")
        data = Table._known_keys.__func__(cls, data)
        if "role" not in data:
            raise fail("missing key 'role' (receiver, blocker or both)")
        exactly_one(data, ("mesh", "primitive"),
                    "give exactly one of 'mesh' (a file) or 'primitive' (a generated shape)")
        if "keyframes" in data and (not isinstance(data["keyframes"], list)
                                    or not data["keyframes"]):
            raise fail("must be a non-empty array of tables", "keyframes")
        return data


class Environment(Table):
    """``[environment]``: at most one of a light asset, an HDR image or inline SH."""

    light: FilePath | None = None
    image: FilePath | None = None
    coeffs: list[vector(3)] | None = None
    intensity: Intensity = 1.0
    rotate_deg: Number = 0.0
    # mid-range lighting (Wang et al. Sec. 3.2): the environment on a finite sphere
    radius: Annotated[Number, Field(gt=0)] | None = None
    center: vector(3) | None = None
    scaling: FilePath | None = None

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        data = Table._known_keys.__func__(cls, data)
        for key in ("center", "scaling"):
            if key in data and "radius" not in data:
                raise fail("only applies with 'radius' (a finite environment sphere)", key)
        if sum(k in data for k in ("light", "image", "coeffs")) > 1:
            raise fail("give only one of 'light' (a light asset), 'image' (an HDR "
                       "lat-long map) or 'coeffs' (inline SH)")
        c = data.get("coeffs")
        if "coeffs" in data and (not isinstance(c, list) or not c):
            raise fail("must be an array of [r, g, b] rows, one per SH coefficient", "coeffs")
        return data


def _radius(value):
    value = _number(value)
    if value <= 0:
        raise fail(f"must be > 0 (a zero-area light emits nothing), got {value!r}")
    if value > MAX_LENGTH:
        raise fail(f"must be <= {MAX_LENGTH:g}, got {value!r}")
    return value




Radius = Annotated[float, BeforeValidator(_radius)]


class LightKeyframe(Table):
    """``[[lights.keyframes]]``: a time or frame and any of position, radius, colour
    (a field light: position, rotate or quaternion, scale)."""

    time: Number | None = None
    frame: Number | None = None
    position: Position | None = None
    radius: Radius | None = None
    color: Color | None = None
    rotate: vector(3) | None = None
    quaternion: vector(4) | None = None
    scale: Annotated[Number, Field(gt=0)] | None = None

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        data = Table._known_keys.__func__(cls, data)
        exactly_one(data, ("time", "frame"), "give exactly one of 'time' (seconds) or 'frame'")
        return data


def _ssoc_choices(name: str):
    def allowed() -> tuple[str, ...]:
        from shtools.runtime import ssoc

        return getattr(ssoc, name)
    return allowed


class SSOCTable(Table):
    """A light's ``ssoc = { ... }`` table: the types here, the ranges in
    :class:`shtools.runtime.ssoc.SSOCSettings` (checked by the semantic pass)."""

    resolution: StrictInt | None = None
    camera: choice(_ssoc_choices("CAMERAS")) | None = None
    guard: Number | None = None
    max_steps: StrictInt | None = None
    falloff: choice(_ssoc_choices("FALLOFFS")) | None = None
    filter: StrictBool | None = None
    corners: choice(_ssoc_choices("CORNERS")) | None = None
    #: strata per receiver the camera finds in penumbra (0: the camera alone)
    rays: Annotated[int, Field(strict=True, ge=0, le=65536)] | None = None

    def settings(self) -> dict:
        """The keys the scene set, as :class:`SSOCSettings` keywords."""
        return self.model_dump(exclude_unset=True)


def _light_shadow_names() -> tuple[str, ...]:
    from shtools.scene.shadows import LIGHT_SHADOWS

    # a way set by the light's own kind (a field light's "field") is not a choice
    return tuple(name for name, way in LIGHT_SHADOWS.items()
                 if not getattr(way, "implied", False))


#: Keys of a spherical light that a field light (``field = "x.srf.h5"``) does not take,
#: and keys only a field light takes.
SPHERE_ONLY = ("radius", "color", "ssoc")
FIELD_ONLY = ("rotate", "quaternion", "scale")


class Light(Table):
    """``[[lights]]``: a spherical light or a field light (a lamp's source radiance
    field, ``field = "x.srf.h5"``), optionally keyframed."""

    name: str | None = None
    position: Position
    radius: Radius | None = None
    color: Color | None = None
    field: FilePath | None = None
    rotate: vector(3) | None = None
    quaternion: vector(4) | None = None
    scale: Annotated[Number, Field(gt=0)] | None = None
    intensity: Intensity = 1.0
    keyframes: Annotated[list[LightKeyframe], Field(min_length=1)] | None = None
    loop: StrictBool = False
    shadows: choice(_light_shadow_names) = "shexp"
    #: strata per receiver of shadows = "raytrace" (shtools.scene.light_shadows)
    samples: Annotated[int, Field(strict=True, ge=1, le=65536)] = 64
    #: occlusion-camera settings of shadows = "ssoc" / "auto" (checked by the semantic pass)
    ssoc: SSOCTable | None = None

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        data = Table._known_keys.__func__(cls, data)
        is_field = "field" in data
        for key in ("position",) if is_field else ("position", "radius", "color"):
            if key not in data:
                raise fail(f"missing key '{key}'")
        keys = [data] + (data["keyframes"] if isinstance(data.get("keyframes"), list) else [])
        for table in keys:
            if not isinstance(table, dict):
                continue
            for key in (SPHERE_ONLY if is_field else FIELD_ONLY):
                if key in table:
                    why = ("a field light's shape and colour are in its field "
                           "(scale it with 'intensity')" if is_field else
                           "only a field light (field = \"x.srf.h5\") has an orientation")
                    raise fail(f"'{key}' does not apply: {why}", key)
            if "rotate" in table and "quaternion" in table:
                raise fail("give either 'rotate' (Euler degrees) or 'quaternion', not both")
        if "keyframes" in data and (not isinstance(data["keyframes"], list)
                                    or not data["keyframes"]):
            raise fail("must be a non-empty array of tables", "keyframes")
        return data


# --------------------------------------------------------------------------- generated
def _setting_annotation(limits, default):
    """The pydantic annotation of one setting of the settings schema (scene units)."""
    from shtools.runtime.settings import Unit

    scale = (180.0 / math.pi) if limits.unit is Unit.DEGREES else 1.0
    bounds = {}
    if limits.lo is not None:
        bounds["gt" if limits.lo_open else "ge"] = _round(limits.lo * scale)
    if limits.hi is not None:
        bounds["lt" if limits.hi_open else "le"] = _round(limits.hi * scale)
    if limits.kind == "int":
        return Annotated[int, Field(strict=True, **bounds)]
    if limits.kind == "float":
        return Annotated[Number, Field(**bounds)]
    if limits.kind == "bool":
        return StrictBool
    if limits.kind == "choice":
        return choice(limits.choice_values)
    if limits.kind == "path":
        return FilePath
    raise ValueError(f"setting kind {limits.kind!r} has no scene type")


def _round(x: float) -> float | int:
    return round(x) if abs(x - round(x)) < 1e-9 else x


@cache
def settings_model(settings_cls) -> type[Table]:
    """The ``[settings]`` table model of a settings dataclass (from its declared limits)."""
    from shtools.runtime.settings import scene_fields

    spec = {key: (_setting_annotation(limits, default) | None, None)
            for key, _name, limits, default in scene_fields(settings_cls)}
    return create_model("SettingsTable", __base__=Table, **spec)


def blocker_model(kinds: tuple) -> type[Table]:
    """The ``blocker = { ... }`` table model of the registered blocker kinds."""
    return _blocker_model(tuple((k.name, k.value, tuple(k.options.items())) for k in kinds))


@cache
def _blocker_model(kinds: tuple) -> type[Table]:
    value_types = {"asset": FilePath, "count": Annotated[int, Field(strict=True, ge=1)],
                   "flag": StrictBool}
    spec: dict[str, Any] = {}
    for name, value, options in kinds:
        spec[name] = (value_types[value] | None, None)
        for opt, (annotation, _default) in options:
            spec.setdefault(opt, (annotation | None, None))
    names = tuple(k[0] for k in kinds)
    listed = ", ".join(f"'{n}'" for n in names)

    def known_keys(cls, data):
        data = Table._known_keys.__func__(cls, data)
        if sum(k in data for k in names) != 1:
            raise fail(f"give exactly one of {listed} (see docs/scenes.md)")
        return data

    validators = {"_known_keys": model_validator(mode="before")(classmethod(known_keys))}
    return create_model("BlockerTable", __base__=Table, __validators__=validators, **spec)


class SceneFile(Table):
    """The whole file: ``[settings]``, ``[environment]``, ``[[lights]]``, ``[[objects]]``."""

    settings: dict = Field(default_factory=dict)
    environment: Environment = Field(default_factory=Environment)
    lights: list[Light] = Field(default_factory=list)
    objects: list[Object] = Field(default_factory=list)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data):
        data = Table._known_keys.__func__(cls, data)
        objects = data.get("objects", [])
        if not isinstance(objects, list) or not objects:
            raise fail("no objects; add at least one [[objects]] table")
        if "lights" in data and not isinstance(data["lights"], list):
            raise fail("must be an array of tables ([[lights]])", "lights")
        if "settings" in data and not isinstance(data["settings"], dict):
            raise fail(f"expected a table, got {type(data['settings']).__name__}", "settings")
        return data
