"""The ``bake`` asset: per-frame, per-vertex outgoing radiance of the receivers.

Layout (``docs/formats.md``; all frames ``T``, receiver vertices ``V``):

=====================  =================  ==============================================
dataset                shape / dtype      meaning
=====================  =================  ==============================================
``vertices``           (V,3) or (T,V,3)   receiver positions (world, Y up); per frame
                       f4                 when receivers move
``normals``            like vertices      unit vertex normals
``faces``              (F,3) i4           triangles into ``vertices``
``radiance``           (T,V,3) f4         outgoing radiance of a white Lambertian
                                          receiver, linear RGB
``visibility``         (T,V,n*n) f4       optional (``--store-visibility``)
``times``              (T,) f8            scene time of each frame, seconds
``frame_index``        (T,) i4            scene frame number of each frame
``albedo``             (V,3) f4           optional per-vertex albedo from the scene;
                                          multiplies ``radiance`` at export only
``object_offsets``     (O+1,) i8          receiver object ``o`` owns vertices
                                          ``object_offsets[o]:object_offsets[o+1]``
``light_poses``        (T,S,7) f8         optional: the spherical lights shaded, posed
                                          (:mod:`shtools.scene.light_record`)
=====================  =================  ==============================================

Root attributes: the provenance set of every asset plus ``sh_order``,
``object_names`` (JSON list) and ``fps``.  The file is the same bytes whatever
the process count (the count is in ``bake --json``'s summary, not in the file).

:class:`BakeWriter` streams frames into the file as they are computed (memory
stays bounded by one frame) and renames the temporary file into place only when
every frame was written; an exception or Ctrl-C leaves no file behind.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from shtools.data_formats._base import (
    FORMAT_PREFIX,
    DatasetSpec,
    Schema,
    _json,
    atomic_path,
    generator_string,
    read_asset,
    register,
    reserve_space,
    sha256_file,
)
from shtools.errors import AssetError

VERSION = 1


def _check(f: h5py.File, ctx: dict) -> None:
    """Everything a reader (``export``, the runtime) relies on beyond shapes and dtypes."""
    dims, path, attrs = ctx["dims"], ctx["path"], ctx["attrs"]
    if dims["T"] == 0 or dims["V"] == 0:
        raise AssetError(f"the bake holds {dims['T']} frame(s) of {dims['V']} vertices; "
                         "an empty bake cannot be exported, rebake it", path)
    n_objects = 1
    if "object_offsets" in f:
        offsets = f["object_offsets"][()]
        if (offsets.size < 2 or offsets[0] != 0 or offsets[-1] != dims["V"]
                or np.any(np.diff(offsets) < 0)):
            raise AssetError("dataset 'object_offsets' does not partition the vertices", path)
        n_objects = offsets.size - 1
    if "object_names" in attrs:
        try:
            names = json.loads(attrs["object_names"])
        except (TypeError, json.JSONDecodeError):
            names = None
        if (not isinstance(names, list) or not all(isinstance(n, str) for n in names)
                or len(names) != n_objects):
            raise AssetError(f"attribute 'object_names' must be a JSON list of {n_objects} "
                             "name(s), one per receiver object; rebake it", path)
    if "fps" in attrs:
        fps = attrs["fps"]
        if isinstance(fps, bool) or not isinstance(fps, int | float) or not 0 < fps < np.inf:
            raise AssetError(f"attribute 'fps' is {fps!r}, expected a positive number", path)
    if "visibility" in f and f["visibility"].shape[2] != int(attrs["sh_order"]) ** 2:
        raise AssetError(f"dataset 'visibility' has {f['visibility'].shape[2]} coefficients "
                         f"but sh_order {attrs['sh_order']} needs {int(attrs['sh_order']) ** 2}",
                         path)
    faces = f["faces"][()]
    if faces.size and (faces.min() < 0 or faces.max() >= dims["V"]):
        raise AssetError("dataset 'faces' indexes vertices that do not exist; rebuild it", path)


SCHEMA = register(
    Schema(
        kind="bake",
        version=VERSION,
        has_sh=True,
        datasets=(
            DatasetSpec("radiance", ("T", "V", 3)),
            DatasetSpec("vertices", ndim_options=(("V", 3), ("T", "V", 3))),
            DatasetSpec("normals", ndim_options=(("V", 3), ("T", "V", 3))),
            DatasetSpec("faces", ("F", 3), dtype_kind="iu", finite=False),
            DatasetSpec("visibility", ("T", "V", None), optional=True),
            DatasetSpec("times", ("T",), optional=True),
            DatasetSpec("frame_index", ("T",), dtype_kind="iu", finite=False, optional=True),
            DatasetSpec("albedo", ("V", 3), optional=True),
            DatasetSpec("object_offsets", (None,), dtype_kind="iu", finite=False, optional=True),
            DatasetSpec("light_poses", ("T", None, 7), optional=True),
        ),
        check=_check,
    )
)


@dataclass
class Bake:
    """A loaded bake asset.

    Attributes
    ----------
    radiance : ndarray, shape (T, V, 3)
        Linear RGB outgoing radiance (white Lambertian receiver).
    vertices, normals : ndarray, shape (V, 3) or (T, V, 3)
    faces : ndarray, shape (F, 3)
    visibility : ndarray, shape (T, V, n*n), or None
    times : ndarray, shape (T,)
    frame_index : ndarray, shape (T,)
    albedo : ndarray, shape (V, 3), or None
    object_offsets : ndarray, shape (O+1,)
    object_names : list of str
    sh_order : int
    light_poses : ndarray, shape (T, S, 7), or None
    attrs : dict
        Root attributes (``parameters`` and ``inputs`` decoded).
    path : str
    """

    radiance: np.ndarray
    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    visibility: np.ndarray | None
    times: np.ndarray
    frame_index: np.ndarray
    albedo: np.ndarray | None
    object_offsets: np.ndarray
    object_names: list[str]
    sh_order: int
    light_poses: np.ndarray | None = None
    attrs: dict = field(default_factory=dict)
    path: str = ""

    @property
    def n_frames(self) -> int:
        return int(self.radiance.shape[0])

    @property
    def n_vertices(self) -> int:
        return int(self.radiance.shape[1])

    @property
    def parameters(self) -> dict:
        return self.attrs.get("parameters", {})

    def frame_position(self, frame: int) -> int:
        """Index into the asset's frames of scene frame number ``frame``.

        Raises :class:`~shtools.errors.InputError` naming the available range.
        """
        from shtools.errors import InputError

        hits = np.flatnonzero(self.frame_index == frame)
        if hits.size == 0:
            lo, hi = int(self.frame_index.min()), int(self.frame_index.max())
            raise InputError(
                f"frame {frame} is not in this bake (it holds frames {lo}..{hi}); "
                "pick one in that range",
                self.path,
            )
        return int(hits[0])

    def object_faces(self, o: int) -> np.ndarray:
        """Triangles ``(F_o, 3)`` of receiver object ``o``, indexing its own vertices.

        Object ``o`` owns vertices ``object_offsets[o]:object_offsets[o+1]``; a
        face belongs to the object of its first vertex (the baker never joins
        objects with a face).
        """
        lo, hi = int(self.object_offsets[o]), int(self.object_offsets[o + 1])
        first = self.faces[:, 0]
        return self.faces[(first >= lo) & (first < hi)] - lo

    def frame_vertices(self, t: int) -> np.ndarray:
        """Vertex positions ``(V, 3)`` of asset frame ``t`` (0-based position)."""
        return self.vertices if self.vertices.ndim == 2 else self.vertices[t]

    def frame_normals(self, t: int) -> np.ndarray:
        """Vertex normals ``(V, 3)`` of asset frame ``t``."""
        return self.normals if self.normals.ndim == 2 else self.normals[t]


def read_bake(path: str | os.PathLike) -> Bake:
    """Read and validate a bake asset.

    Raises
    ------
    AssetError
        Missing file, wrong kind, unknown version, bad shapes, NaN/inf.
    """
    asset = read_asset(path, "bake")
    return bake_from_data(asset, asset.data, path)


def bake_from_data(asset, d: dict, path) -> Bake:
    """The :class:`Bake` of a checked ``asset`` whose datasets are ``d`` (arrays, or h5py
    datasets of a still open file)."""
    T = d["radiance"].shape[0]
    V = d["radiance"].shape[1]
    names = asset.attrs.get("object_names")
    names = json.loads(names) if isinstance(names, str) else ["receivers"]
    return Bake(
        radiance=d["radiance"],
        vertices=d["vertices"],
        normals=d["normals"],
        faces=d["faces"].astype(np.int64),
        visibility=d.get("visibility"),
        times=d.get("times", np.arange(T, dtype=np.float64)),
        frame_index=d.get("frame_index", np.arange(T)).astype(np.int64),
        albedo=d.get("albedo"),
        object_offsets=d.get("object_offsets", np.array([0, V])).astype(np.int64),
        object_names=list(names),
        sh_order=int(asset.sh_order),
        light_poses=d.get("light_poses"),
        attrs=asset.attrs,
        path=os.fspath(path),
    )


def bake_size_bound(frames: int, vertices: int, *, static: bool = False,
                    visibility_size: int | None = None, fixed: int | None = None) -> int:
    """Upper bound of a bake asset's bytes: every dataset uncompressed, +1 % and 1 MiB.

    ``fixed``: bytes of the frame-independent datasets (default: two triangles
    per vertex, i.e. ``24 V``); ``static``: geometry stored once, not per frame.
    """
    T, V = int(frames), int(vertices)
    per_frame = V * 12 * (1 if static else 3) + V * 4 * (visibility_size or 0)
    fixed = V * 24 if fixed is None else fixed
    return int(1.01 * (T * per_frame + fixed + V * 36 + T * 12)) + (1 << 20)


class BakeWriter:
    """Stream a bake asset frame by frame into a temporary file, rename on success.

    Use as a context manager::

        with BakeWriter(path, n_frames=T, faces=F, ...) as w:
            for t in range(T):
                w.write_frame(t, radiance, vertices=..., normals=...)

    Parameters
    ----------
    path : path-like
        Target file.
    n_frames : int
        Number of frames ``T`` that will be written.
    faces : ndarray, shape (F, 3)
    sh_order : int
    static_vertices, static_normals : ndarray, shape (V, 3), optional
        Given when the receivers do not move; then ``write_frame`` takes no
        geometry.  Otherwise ``n_vertices`` must be given and every frame
        passes its vertices and normals.
    n_vertices : int, optional
    visibility_size : int, optional
        ``n*n`` to store visibility vectors per frame.
    times, frame_index : ndarray, shape (T,)
    albedo : ndarray, shape (V, 3), optional
    object_offsets : ndarray, shape (O+1,), optional
    object_names : list of str, optional
    parameters, inputs : mapping, optional
        Provenance, as for :func:`~shtools.data_formats.write_asset`.
    compression : str or None
        h5py filter for the per-frame geometry and radiance (deterministic);
        the visibility is stored without one.
    light_poses : ndarray, shape (T, S, 7), optional
        The spherical lights the frames were shaded with, posed per frame.
    copy : mapping of str to h5py.Dataset, optional
        Per-frame ``vertices``, ``normals`` or ``visibility`` ``(T, V, k)``
        taken whole from another bake's open file by HDF5's object copy (its
        stored chunks and filters as they are, nothing decompressed): the
        frame writes then leave them out.
    """

    def __init__(
        self,
        path,
        *,
        n_frames: int,
        faces,
        sh_order: int,
        static_vertices=None,
        static_normals=None,
        n_vertices: int | None = None,
        visibility_size: int | None = None,
        times=None,
        frame_index=None,
        albedo=None,
        object_offsets=None,
        object_names=None,
        parameters=None,
        inputs=None,
        fps: float | None = None,
        compression: str | None = "gzip",
        light_poses=None,
        copy=None,
    ):
        self.path = Path(path)
        self.copy = dict(copy or {})
        self.n_frames = int(n_frames)
        self.faces = np.asarray(faces, dtype=np.int32).reshape(-1, 3)
        self.sh_order = int(sh_order)
        self.static = static_vertices is not None
        if self.static:
            self.static_vertices = np.asarray(static_vertices, dtype=np.float32)
            self.static_normals = np.asarray(static_normals, dtype=np.float32)
            self.n_vertices = len(self.static_vertices)
        else:
            if n_vertices is None:
                raise ValueError("n_vertices is required when receivers move")
            self.n_vertices = int(n_vertices)
        self.visibility_size = visibility_size
        T = self.n_frames
        self.times = np.arange(T, dtype=np.float64) if times is None else np.asarray(times, float)
        self.frame_index = (
            np.arange(T, dtype=np.int32) if frame_index is None
            else np.asarray(frame_index, dtype=np.int32)
        )
        self.albedo = None if albedo is None else np.asarray(albedo, dtype=np.float32)
        self.object_offsets = (
            np.array([0, self.n_vertices], dtype=np.int64) if object_offsets is None
            else np.asarray(object_offsets, dtype=np.int64)
        )
        self.object_names = list(object_names or ["receivers"])
        self.light_poses = None if light_poses is None else np.asarray(light_poses, float)
        self.parameters = dict(parameters or {})
        self.inputs = {
            Path(p).name: sha256_file(p) for p in (inputs or {}).values() if p is not None
        }
        self.fps = fps
        self.compression = compression
        self._written = np.zeros(T, dtype=bool)
        self._stack: contextlib.ExitStack | None = None
        self._file: h5py.File | None = None
        self._datasets: dict[str, h5py.Dataset] = {}  # per-frame datasets, opened once
        self._direct: dict[int, bool] = {}  # id(source dataset) -> chunks copy as stored

    def size_bound(self) -> int:
        """Bytes the file can take at most (:func:`bake_size_bound`)."""
        return bake_size_bound(self.n_frames, self.n_vertices, static=self.static,
                               visibility_size=self.visibility_size,
                               fixed=self.faces.nbytes + self.object_offsets.nbytes
                               + (0 if self.light_poses is None else self.light_poses.nbytes))

    # -- context management -------------------------------------------------
    def __enter__(self) -> BakeWriter:
        from shtools.sh.basis import SH_CONVENTION

        stack = contextlib.ExitStack()
        try:
            tmp = stack.enter_context(atomic_path(self.path))
            f = h5py.File(tmp, "w", track_order=True)
            stack.callback(f.close)
            # a full disk must fail here, before HDF5 streams frames (see reserve_space)
            reserve_space(tmp, self.size_bound(), self.path)
        except BaseException as exc:
            # exit the contexts *with* the exception: a plain close() would commit
            # the (empty) temporary file over an existing output
            if not stack.__exit__(type(exc), exc, exc.__traceback__):
                raise
        self._stack, self._file = stack, f
        root = {
            "format": FORMAT_PREFIX + "bake",
            "format_version": np.int64(VERSION),
            "generator": generator_string(),
            "inputs": _json(self.inputs),
            "parameters": _json(self.parameters),
            "sh_order": np.int64(self.sh_order),
            "sh_convention": SH_CONVENTION,
            "object_names": json.dumps(self.object_names),
        }
        if self.fps is not None:
            root["fps"] = float(self.fps)
        for k in sorted(root):
            f.attrs[k] = root[k]
        T, V = self.n_frames, self.n_vertices
        plain = {"track_times": False}
        f.create_dataset("faces", data=self.faces, **plain)
        f.create_dataset("times", data=self.times, **plain)
        f.create_dataset("frame_index", data=self.frame_index, **plain)
        f.create_dataset("object_offsets", data=self.object_offsets, **plain)
        if self.albedo is not None:
            f.create_dataset("albedo", data=self.albedo, **plain)
        if self.light_poses is not None:
            f.create_dataset("light_poses", data=self.light_poses, **plain)
        frame = dict(plain, compression=self.compression, shuffle=bool(self.compression))
        for name, source in sorted(self.copy.items()):
            width = (self.visibility_size if name == "visibility" else 3)
            if source.shape != (T, V, width):
                raise ValueError(f"{name} to copy has shape {source.shape}, expected "
                                 f"({T}, {V}, {width})")
            f.copy(source, name)
        if self.static:
            f.create_dataset("vertices", data=self.static_vertices, **plain)
            f.create_dataset("normals", data=self.static_normals, **plain)
        else:
            for name in ("vertices", "normals"):
                if name not in self.copy:
                    f.create_dataset(name, (T, V, 3), "f4", chunks=(1, V, 3), **frame)
        f.create_dataset("radiance", (T, V, 3), "f4", chunks=(1, V, 3), **frame)
        if self.visibility_size and "visibility" not in self.copy:
            k = int(self.visibility_size)
            # stored plain: SH coefficients gain ~20 % from gzip, and decompressing them
            # would be most of the cost of relighting (shtools.scene.relight), which
            # reads them all
            f.create_dataset("visibility", (T, V, k), "f4", chunks=(1, V, k), **plain)
        self._datasets = {name: f[name] for name in ("radiance", "vertices", "normals",
                                                     "visibility")
                          if name in f and f[name].ndim == 3 and name not in self.copy}
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        stack, self._stack = self._stack, None
        if exc_type is None and not self._written.all():
            missing = np.flatnonzero(~self._written)
            exc = AssetError(f"bake ended with {missing.size} frame(s) unwritten", self.path)
            stack.__exit__(type(exc), exc, None)
            raise exc
        return bool(stack.__exit__(exc_type, exc, tb))

    # -- frames -------------------------------------------------------------
    def write_frame(self, t: int, radiance, *, vertices=None, normals=None, visibility=None):
        """Write asset frame ``t`` (0-based).

        Parameters
        ----------
        t : int
        radiance : ndarray, shape (V, 3)
        vertices, normals : ndarray, shape (V, 3)
            Required when the receivers move (and not copied).
        visibility : ndarray, shape (V, n*n), optional
            Required when the writer stores visibility (and does not copy it).

        ``vertices``, ``normals`` and ``visibility`` may also be another bake's
        per-frame dataset ``(T, V, k)`` (h5py): its frame ``t`` is copied.
        """
        f = self._file
        if f is None or self._stack is None:
            raise RuntimeError("BakeWriter.write_frame outside its context")
        radiance = np.asarray(radiance, dtype=np.float32)
        if radiance.shape != (self.n_vertices, 3):
            raise ValueError(
                f"radiance has shape {radiance.shape}, expected ({self.n_vertices}, 3)")
        if not np.all(np.isfinite(radiance)):
            raise AssetError(f"frame {int(self.frame_index[t])} produced NaN/inf radiance",
                             self.path)
        ds = self._datasets
        ds["radiance"][t] = radiance
        per_frame = {"vertices": vertices, "normals": normals} if not self.static else {}
        if self.visibility_size:
            per_frame["visibility"] = visibility
        for name, values in per_frame.items():
            if name in self.copy:
                continue
            if isinstance(values, h5py.Dataset):
                self._copy_chunk(values, ds[name], t)
            else:
                ds[name][t] = np.asarray(values, dtype=np.float32)
        self._written[t] = True

    def write_frames(self, start: int, radiance, *, vertices=None, normals=None,
                     visibility=None):
        """Write the consecutive asset frames ``start, start + 1, ...`` in one call each.

        As :meth:`write_frame` for ``len(radiance)`` frames at once (arrays only):
        one HDF5 write per dataset, not one per frame.

        Parameters
        ----------
        start : int
        radiance : ndarray, shape (K, V, 3)
        vertices, normals : ndarray, shape (K, V, 3)
            Required when the receivers move (and not copied).
        visibility : ndarray, shape (K, V, n*n), optional
            Required when the writer stores visibility (and does not copy it).
        """
        f = self._file
        if f is None or self._stack is None:
            raise RuntimeError("BakeWriter.write_frames outside its context")
        radiance = np.asarray(radiance, dtype=np.float32)
        k = len(radiance)
        if radiance.shape != (k, self.n_vertices, 3) or not 0 <= start <= self.n_frames - k:
            raise ValueError(f"radiance has shape {radiance.shape} from frame {start}, expected "
                             f"(K, {self.n_vertices}, 3) within {self.n_frames} frames")
        finite = np.isfinite(radiance).reshape(k, -1).all(axis=1)
        if not finite.all():
            bad = int(self.frame_index[start + int(np.argmin(finite))])
            raise AssetError(f"frame {bad} produced NaN/inf radiance", self.path)
        frames = slice(start, start + k)
        ds = self._datasets
        ds["radiance"][frames] = radiance
        per_frame = {"vertices": vertices, "normals": normals} if not self.static else {}
        if self.visibility_size:
            per_frame["visibility"] = visibility
        for name, values in per_frame.items():
            if name not in self.copy:
                ds[name][frames] = np.asarray(values, dtype=np.float32)
        self._written[frames] = True

    def _copy_chunk(self, source: h5py.Dataset, target: h5py.Dataset, t: int) -> None:
        """Frame ``t`` of a per-frame dataset of another bake, its stored bytes copied as
        they are when both store frames alike (one frame a chunk, the same filters): no
        decompression and compression again, the same values either way."""
        same = self._direct.get(id(source))
        if same is None:
            same = self._direct[id(source)] = (
                source.shape == target.shape and source.dtype == target.dtype
                and source.chunks == target.chunks == (1, *target.shape[1:])
                and source.compression == target.compression
                and source.compression_opts == target.compression_opts
                and source.shuffle == target.shuffle)
        if same:
            mask, chunk = source.id.read_direct_chunk((t, 0, 0))
            target.id.write_direct_chunk((t, 0, 0), chunk, mask)
        else:
            target[t] = np.asarray(source[t], dtype=np.float32)


def write_bake(
    path,
    *,
    vertices,
    normals,
    faces,
    radiance,
    sh_order: int,
    visibility=None,
    **kwargs,
) -> Path:
    """Write a whole bake asset at once (small bakes, tests).

    Parameters
    ----------
    vertices, normals : ndarray, shape (V, 3) or (T, V, 3)
    faces : ndarray, shape (F, 3)
    radiance : ndarray, shape (T, V, 3)
    sh_order : int
    visibility : ndarray, shape (T, V, n*n), optional
    **kwargs
        Passed to :class:`BakeWriter` (times, frame_index, albedo, ...).
    """
    radiance = np.asarray(radiance)
    vertices = np.asarray(vertices)
    normals = np.asarray(normals)
    T, V = radiance.shape[:2]
    static = vertices.ndim == 2
    writer = BakeWriter(
        path, n_frames=T, faces=faces, sh_order=sh_order,
        static_vertices=vertices if static else None,
        static_normals=normals if static else None,
        n_vertices=V,
        visibility_size=None if visibility is None else np.asarray(visibility).shape[-1],
        **kwargs,
    )
    with writer as w:
        for t in range(T):
            w.write_frame(
                t, radiance[t],
                vertices=None if static else vertices[t],
                normals=None if static else normals[t],
                visibility=None if visibility is None else visibility[t],
            )
    return Path(path)
