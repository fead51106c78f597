"""USD export of a bake (``.usda`` text or ``.usdc`` crate), with ``usd-core``'s ``pxr``.

Layout of the stage (Y up, ``metersPerUnit = 1``: scene units are taken as metres):

* ``/World`` -- an ``Xform``, the default prim;
* ``/World/<object>`` -- one ``Mesh`` per receiver object of the bake, named
  after it (made a valid USD identifier; the original name is the prim's
  ``displayName`` when it differs), ``subdivisionScheme = "none"``;
* ``points``, ``normals`` (``vertex`` interpolation) and ``extent``:
  time-sampled for an object whose vertices change over the exported frames
  (moving or skinned), a default value otherwise;
* ``primvars:displayColor`` (``vertex``): the display colour, linear (USD
  colours are linear; :func:`shtools.export.quantity.display_linear`);
* ``primvars:<quantity>`` (``vertex``): the raw radiance / irradiance
  (``float3[]``) or visibility (``float[]``), before albedo;
* ``primvars:albedo`` (``color3f[]``) when the bake has one: ``constant``
  interpolation (one element) for an object of one albedo -- the usual case,
  a scene object has one -- ``vertex`` otherwise.

A value uniform over an object is written once as a ``constant`` primvar, in
general: ``displayColor`` and the raw quantity too when every vertex of the
object has the same value in every exported frame.  How Blender and usdview
read the time samples: ``docs/usd.md``.

Time codes are the scene's frame numbers; ``timeCodesPerSecond`` and
``framesPerSecond`` are the bake's fps, ``startTimeCode``/``endTimeCode`` the
first and last exported frame.  With one exported frame every value is a
default (no time samples).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from shtools.data_formats import atomic_path
from shtools.data_formats.bake import Bake
from shtools.errors import InputError
from shtools.export.quantity import channels, display_linear, raw_values
from shtools.progress import silent

SUFFIXES = (".usda", ".usdc", ".usd")


def _require_pxr() -> None:
    """Raise a one-line :class:`InputError` when ``usd-core`` is not installed."""
    import importlib.util

    if importlib.util.find_spec("pxr") is None:
        raise InputError("USD export needs usd-core; install it with "
                         "\"pip install 'shtools[usd]'\"")


def prim_names(names: list[str]) -> list[str]:
    """Valid, unique USD prim names for the bake's object names (same order)."""
    _require_pxr()
    from pxr import Tf

    out: list[str] = []
    for name in names:
        ident = Tf.MakeValidIdentifier(name) or "object"
        base, k = ident, 1
        while ident in out:
            ident, k = f"{base}_{k}", k + 1
        out.append(ident)
    return out


def write_usd(
    path: str | os.PathLike,
    bake: Bake,
    positions: list[int],
    *,
    quantity: str = "radiance",
    scale: float = 1.0,
    curve: str = "aces",
    progress=None,
) -> dict:
    """Write asset frames ``positions`` of ``bake`` as a USD stage, atomically.

    Parameters
    ----------
    path : path-like
        ``.usda``, ``.usdc`` or ``.usd`` (crate).
    bake : Bake
    positions : list of int
        Asset frame positions (0-based) to export, in order.
    quantity : {"radiance", "irradiance", "visibility"}
    scale : float
        Exposure of the display colour (shared by all frames).
    curve : str
        Tone curve of the display colour.
    progress : callable, optional
        Progress factory (:mod:`shtools.progress`), one step per frame.

    Returns
    -------
    dict
        ``prims`` (paths written), ``animated`` (prims with time-sampled points).
    """
    _require_pxr()
    from pxr import Sdf, Usd, UsdGeom, Vt

    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(f"not a USD file name; use one of {', '.join(SUFFIXES)}", path)
    fps = float(bake.attrs.get("fps", 24.0))
    frames = [int(bake.frame_index[t]) for t in positions]
    sampled = len(positions) > 1

    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(frames[0])
    stage.SetEndTimeCode(frames[-1])
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())

    raw_type = (Sdf.ValueTypeNames.Float3Array if channels(quantity) == 3
                else Sdf.ValueTypeNames.FloatArray)
    meshes, animated = [], []
    for o, (name, ident) in enumerate(zip(bake.object_names, prim_names(bake.object_names),
                                          strict=True)):
        lo, hi = int(bake.object_offsets[o]), int(bake.object_offsets[o + 1])
        mesh = UsdGeom.Mesh.Define(stage, f"/World/{ident}")
        if ident != name:
            mesh.GetPrim().SetDisplayName(name)
        faces = bake.object_faces(o)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(
            np.full(len(faces), 3, dtype=np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(
            np.ascontiguousarray(faces.reshape(-1), dtype=np.int32)))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateNormalsAttr()
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        primvars = UsdGeom.PrimvarsAPI(mesh)
        # uniform over the object in every frame: one constant element
        if quantity == "visibility":
            normals = (bake.normals[lo:hi] if bake.normals.ndim == 2
                       else bake.normals[positions, lo:hi])
            lit_uniform = (_uniform(bake.visibility[positions, lo:hi], axis=1)
                           and _uniform(normals, axis=normals.ndim - 2))
        else:
            lit_uniform = _uniform(bake.radiance[positions, lo:hi], axis=1)
        albedo = None if bake.albedo is None else np.asarray(bake.albedo[lo:hi], np.float32)
        albedo_uniform = albedo is None or _uniform(albedo, axis=0)
        raw_mode = UsdGeom.Tokens.constant if lit_uniform else UsdGeom.Tokens.vertex
        # only radiance's display colour multiplies the albedo
        color_mode = (UsdGeom.Tokens.constant
                      if lit_uniform and (quantity != "radiance" or albedo_uniform)
                      else UsdGeom.Tokens.vertex)
        color = mesh.CreateDisplayColorPrimvar(color_mode)
        raw = primvars.CreatePrimvar(quantity, raw_type, raw_mode)
        if albedo is not None:
            primvars.CreatePrimvar(
                "albedo", Sdf.ValueTypeNames.Color3fArray,
                UsdGeom.Tokens.constant if albedo_uniform else UsdGeom.Tokens.vertex).Set(
                Vt.Vec3fArray.FromNumpy(albedo[:1] if albedo_uniform else albedo))
        moves = sampled and bake.vertices.ndim == 3 and bool(
            np.any(bake.vertices[positions, lo:hi] != bake.vertices[positions[0], lo:hi]))
        if moves:
            animated.append(mesh.GetPath().pathString)
        meshes.append((mesh, color, raw, lo, hi, moves, color_mode == UsdGeom.Tokens.constant,
                       raw_mode == UsdGeom.Tokens.constant))
        if not moves:  # geometry once, as defaults
            _set_geometry(mesh, bake, positions[0], lo, hi, None)

    with (progress or silent)(positions, desc="usd", unit="frames") as steps:
        for t, frame in zip(steps, frames, strict=True):
            time_code = Usd.TimeCode(frame) if sampled else Usd.TimeCode.Default()
            display = display_linear(bake, t, quantity, scale, curve).astype(np.float32)
            values = raw_values(bake, t, quantity).astype(np.float32)
            for mesh, color, raw, lo, hi, moves, color_one, raw_one in meshes:
                color.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(
                    display[lo:lo + 1] if color_one else display[lo:hi])), time_code)
                part = np.ascontiguousarray(values[lo:lo + 1] if raw_one else values[lo:hi])
                raw.Set((Vt.Vec3fArray if part.ndim == 2 else Vt.FloatArray).FromNumpy(part),
                        time_code)
                if moves:
                    _set_geometry(mesh, bake, t, lo, hi, time_code)

    with atomic_path(path) as tmp:
        # USD picks the file format from the suffix: export beside the temporary
        # file under the right one, then move it onto the temporary name
        named = tmp.with_name(tmp.name + (".usdc" if suffix == ".usd" else suffix))
        try:
            if not stage.GetRootLayer().Export(str(named)):
                raise InputError("USD could not write the stage", path)
            os.replace(named, tmp)
        finally:
            if named.exists():
                named.unlink()
    return {"prims": [m.GetPath().pathString for m, *_ in meshes], "animated": animated}


def _uniform(values: np.ndarray, axis: int) -> bool:
    """True when ``values`` is the same along ``axis`` (and not empty there)."""
    values = np.asarray(values)
    if values.shape[axis] == 0:
        return False
    first = np.take(values, [0], axis=axis)
    return bool(np.all(values == first))


def _set_geometry(mesh, bake: Bake, t: int, lo: int, hi: int, time_code) -> None:
    """Author points, normals and extent of one object at ``time_code`` (None: default)."""
    from pxr import Usd, Vt

    when = Usd.TimeCode.Default() if time_code is None else time_code
    points = np.ascontiguousarray(bake.frame_vertices(t)[lo:hi], dtype=np.float32)
    normals = np.ascontiguousarray(bake.frame_normals(t)[lo:hi], dtype=np.float32)
    mesh.GetPointsAttr().Set(Vt.Vec3fArray.FromNumpy(points), when)
    mesh.GetNormalsAttr().Set(Vt.Vec3fArray.FromNumpy(normals), when)
    extent = np.stack([points.min(axis=0), points.max(axis=0)]) if len(points) else np.zeros(
        (2, 3), np.float32)
    mesh.GetExtentAttr().Set(Vt.Vec3fArray.FromNumpy(extent.astype(np.float32)), when)
