"""Shared machinery for every asset kind: atomic writes, provenance, validated reads.

Each asset kind has its own module (``spheres.py``, ``tables.py``, ...) that
declares a :class:`Schema` and thin ``write_*``/``read_*`` functions on top of
:func:`write_asset` and :func:`read_asset`.

Determinism: datasets are written without HDF5 object timestamps
(``track_times=False``), attributes in a fixed order, and nothing
time-dependent is stored, so the same inputs give byte-identical datasets.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from shtools.errors import AssetError, disk_error_reason

FORMAT_PREFIX = "shtools/"

#: Root attributes every asset carries (docs/formats.md, "Root attributes").
PROVENANCE_ATTRS = ("generator", "inputs", "parameters")
#: Elements read at once when a dataset is validated without being loaded
#: (``read_asset(load=False)``: ``shtools info``, ``check``, ``diff``), so memory stays
#: bounded however large the asset.
BLOCK_ELEMENTS = 1 << 22


@dataclass(frozen=True)
class DatasetSpec:
    """Expected layout of one dataset.

    Parameters
    ----------
    name : str
        Path inside the file (``"centers"``, ``"shells/0/ocv"``).
    shape : tuple
        Expected shape; each entry an int (exact), a str (a named dimension
        that must agree across datasets of the same asset, e.g. ``"N"``) or
        ``None`` (any length).
    dtype_kind : str
        Allowed numpy dtype kinds, e.g. ``"f"`` for floats, ``"iu"`` for ints.
    finite : bool
        Reject NaN/inf (floats only).
    optional : bool
        The dataset may be absent.
    ndim_options : tuple of tuple, optional
        Alternative shapes (e.g. ``(("V", 3), ("T", "V", 3))``); used instead of
        ``shape`` when given.
    """

    name: str
    shape: tuple = ()
    dtype_kind: str = "f"
    finite: bool = True
    optional: bool = False
    ndim_options: tuple = ()


@dataclass(frozen=True)
class Schema:
    """One asset kind: its name, current version, known versions and datasets."""

    kind: str
    version: int
    datasets: tuple[DatasetSpec, ...] = ()
    known_versions: tuple[int, ...] = ()
    required_attrs: tuple[str, ...] = ()
    has_sh: bool = False
    #: extra validation on the open file, after the generic checks; raise AssetError
    check: Callable[[h5py.File, dict], None] | None = None

    def versions(self) -> tuple[int, ...]:
        return self.known_versions or (self.version,)


@dataclass
class Asset:
    """A validated, fully-loaded asset.

    Attributes
    ----------
    kind : str
    version : int
    attrs : dict
        Root attributes (``parameters`` and ``inputs`` decoded from JSON).
    data : dict
        Dataset path -> ndarray, every dataset in the file.
    dims : dict
        Named dimensions resolved during validation (e.g. ``{"N": 64}``).
    path : str
    """

    kind: str
    version: int
    attrs: dict
    data: dict[str, np.ndarray]
    dims: dict[str, int] = field(default_factory=dict)
    path: str = ""

    def __getitem__(self, name: str) -> np.ndarray:
        return self.data[name]

    @property
    def sh_order(self) -> int | None:
        v = self.attrs.get("sh_order")
        return None if v is None else int(v)

    @property
    def parameters(self) -> dict:
        return self.attrs.get("parameters", {})


SCHEMAS: dict[str, Schema] = {}


def register(schema: Schema) -> Schema:
    """Register an asset kind so ``read_asset``/``shtools check`` know it."""
    SCHEMAS[schema.kind] = schema
    return schema


#: Every asset kind (docs/formats.md); each has a module ``shtools.data_formats.<kind>``
#: that registers its :class:`Schema` on import.
KINDS = ("spheres", "tree", "bound", "tables", "scaling", "field", "srf", "light", "bake",
         "transfer", "haar")


def get_schema(kind: str) -> Schema | None:
    """The registered schema of ``kind``, importing its module on first use."""
    if kind not in SCHEMAS and kind in KINDS:
        import importlib

        try:
            importlib.import_module(f"shtools.data_formats.{kind}")
        except ModuleNotFoundError:
            return None
    return SCHEMAS.get(kind)


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 16) -> str:
    """Hex sha256 of a file's bytes, read ``chunk`` bytes at a time (a small buffer: a
    writer hashes its inputs beside streaming work whose memory stays bounded)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def generator_string() -> str:
    from shtools import __version__

    return f"shtools {__version__}"


def _json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=_json_default)


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, os.PathLike):
        return os.fspath(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _host() -> str:
    """This machine's name as it appears in temporary names (no dots or slashes)."""
    if hasattr(os, "uname"):  # socket.gethostname()'s answer, without importing socket
        name = os.uname().nodename
    else:  # Windows
        import socket

        name = socket.gethostname()
    return re.sub(r"[^A-Za-z0-9_-]", "_", name)[:32] or "host"


def temporary_prefix(target: str | os.PathLike) -> str:
    """Prefix of the temporaries :func:`atomic_path` makes for ``target``.

    ``.NAME.PID@HOST.`` + 8 random characters + ``.tmp``: the owner's process id
    and host name make a temporary left by a killed run recognisable.  A NAME
    too long to leave room for the rest (file names stop at 255 bytes) is cut and
    tagged with a hash of the whole name.
    """
    return f".{_temp_stem(Path(target).name)}.{os.getpid()}@{_host()}."


def _temp_stem(name: str) -> str:
    if len(name.encode()) <= 150:
        return name
    digest = hashlib.sha1(name.encode()).hexdigest()[:8]
    return name.encode()[:120].decode(errors="ignore") + "~" + digest


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists but is someone else's (EPERM)
        return True
    return True


def remove_stale_temporaries(target: str | os.PathLike) -> list[Path]:
    """Remove temporaries of ``target`` whose owner process is gone.

    Only files named like :func:`temporary_prefix` by a process of *this* host
    that no longer runs are removed (a temporary being written by a running
    process, or by another machine sharing the folder, is left alone).

    Returns
    -------
    list of pathlib.Path
        The removed files.
    """
    target = Path(target)
    directory = target.parent if str(target.parent) else Path(".")
    stem = re.escape(_temp_stem(target.name))
    pattern = re.compile(rf"^\.{stem}\.(\d+)@([A-Za-z0-9_-]+)\.\w{{8}}\.tmp$")
    removed = []
    host = _host()
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        m = pattern.match(name)
        if m is None or m.group(2) != host or _pid_alive(int(m.group(1))):
            continue
        with contextlib.suppress(OSError):
            (directory / name).unlink()
            removed.append(directory / name)
    return removed
def _create_temporary(directory: Path, name: str) -> Path:
    """Create an empty, new ``.<name>.<pid>@<host>.<random>.tmp`` in ``directory``.

    The name is :func:`temporary_prefix` plus 8 random hex digits; returns the path.

    The file is created with mode 0666, which the kernel masks by the process
    umask -- the mode any output gets -- without reading (or changing) the
    process-wide umask, which other threads of an embedding program may rely on.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
    for _ in range(100):
        path = directory / f"{temporary_prefix(name)}{os.urandom(4).hex()}.tmp"
        try:
            os.close(os.open(path, flags, 0o666))
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"could not create a temporary file for {name} in {directory}")


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True when ``a`` and ``b`` name one file (hard links and symlinks included), so
    that writing one would destroy the other."""
    a, b = Path(a), Path(b)
    with contextlib.suppress(OSError):  # unreadable: compare the resolved names instead
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    return os.path.realpath(a) == os.path.realpath(b)


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; rename it into place on success.

    On any exception (including KeyboardInterrupt and SIGTERM, which the CLI turns
    into an exception) the temporary file is removed and ``target`` is left
    untouched, so ``make`` never sees a half-written file.  Temporaries of
    ``target`` left by killed runs (``kill -9``, power loss) are removed first
    (:func:`remove_stale_temporaries`).
    """
    target = Path(target)
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise AssetError("output folder does not exist; create it first", target)
    if target.exists() and not target.is_file():
        # os.replace would put a file where a device (/dev/null), pipe or folder was
        raise AssetError("is not a regular file (a folder, device, pipe or socket); give a "
                         "file path", target)
    remove_stale_temporaries(target)
    try:
        tmp_path = _create_temporary(directory, target.name)
    except OSError as exc:
        raise _output_error(exc, target) from exc
    try:
        yield tmp_path
        os.replace(tmp_path, target)
    except BaseException as exc:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        if disk_error_reason(exc) is not None:
            raise _output_error(exc, target) from exc
        raise


def _output_error(exc: OSError, target: Path) -> Exception:
    """A one-line AssetError for a full disk / read-only folder, else ``exc`` itself."""
    reason = disk_error_reason(exc)
    if reason is None:
        if isinstance(exc, PermissionError):
            return AssetError("cannot create a file in the output folder (no permission); "
                              "choose a writable folder", target)
        return exc
    return AssetError(f"{reason}; free space or write elsewhere (nothing was written, an "
                      "older file of that name is unchanged)", target)


def write_asset(
    path: str | os.PathLike,
    kind: str,
    datasets: Mapping[str, Any],
    *,
    attrs: Mapping[str, Any] | None = None,
    sh_order: int | None = None,
    inputs: Mapping[str, str | os.PathLike] | None = None,
    parameters: Mapping[str, Any] | None = None,
    dataset_attrs: Mapping[str, Mapping[str, Any]] | None = None,
    compression: str | None = None,
) -> Path:
    """Write an asset atomically, with provenance, deterministically.

    Parameters
    ----------
    path : path-like
        Target file.  Written to a temporary file beside it, then renamed.
    kind : str
        Asset kind (a registered :class:`Schema`), e.g. ``"spheres"``.
    datasets : mapping of str to array_like
        Dataset path (``"/"``-separated groups allowed) to data.
    attrs : mapping, optional
        Extra root attributes (scalars, strings, small arrays).
    sh_order : int, optional
        Recorded with ``sh_convention`` when the asset holds SH data.
    inputs : mapping of str to path-like, optional
        Input files; their names and sha256 are recorded in ``inputs``.
    parameters : mapping, optional
        The stage's parameters, recorded as JSON.
    dataset_attrs : mapping, optional
        Dataset path -> attributes for that dataset.
    compression : str, optional
        h5py compression filter (e.g. ``"gzip"``); deterministic.

    Returns
    -------
    pathlib.Path
        The written path.
    """
    from shtools.sh.basis import SH_CONVENTION

    schema = get_schema(kind)
    if schema is None:
        raise ValueError(f"unknown asset kind {kind!r}")
    input_hashes = {
        Path(p).name: sha256_file(p) for p in (inputs or {}).values() if p is not None
    }
    root = {
        "format": FORMAT_PREFIX + kind,
        "format_version": np.int64(schema.version),
        "generator": generator_string(),
        "inputs": _json(input_hashes),
        "parameters": _json(dict(parameters or {})),
    }
    if sh_order is not None:
        root["sh_order"] = np.int64(sh_order)
        root["sh_convention"] = SH_CONVENTION
    for k, v in (attrs or {}).items():
        root[k] = v
    # The file is built in memory and written with plain Python I/O: HDF5 failing a
    # write on a full disk leaves its file half-closed (tracebacks from h5py's
    # __dealloc__, a crash at exit), Python raises one clean OSError instead.
    with h5py.File(f"{os.fspath(path)}.{os.getpid()}.mem", "w", driver="core",
                   backing_store=False, track_order=True) as f:
        for k in sorted(root):
            f.attrs[k] = root[k]
        for name in sorted(datasets):
            arr = np.asarray(datasets[name])
            kwargs = {"track_times": False}
            if compression and arr.size > 1024:
                kwargs.update(compression=compression, shuffle=True)
            ds = f.create_dataset(name, data=arr, **kwargs)
            for k, v in sorted((dataset_attrs or {}).get(name, {}).items()):
                ds.attrs[k] = v
        f.flush()
        image = f.id.get_file_image()
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(image)
        fh.flush()
        os.fsync(fh.fileno())
    return Path(path)


def reserve_space(path: str | os.PathLike, nbytes: int, target: str | os.PathLike) -> None:
    """Allocate ``nbytes`` of disk for the file ``path`` now, so a full disk fails here.

    Used before HDF5 streams into a file (see :func:`write_asset` for why HDF5
    must not meet a full disk).  HDF5 truncates the file to its real size when it
    closes it.  File systems without ``fallocate`` are left alone.

    Raises
    ------
    AssetError
        The disk (or quota) cannot take ``nbytes``; the message names ``target``.
    """
    if not hasattr(os, "posix_fallocate") or nbytes <= 0:
        return
    fd = os.open(path, os.O_WRONLY)
    try:
        os.posix_fallocate(fd, 0, int(nbytes))
    except OSError as exc:
        if disk_error_reason(exc) is not None:
            raise AssetError(f"needs up to {nbytes / 2**20:,.1f} MiB: "
                             f"{disk_error_reason(exc)}; free space or write elsewhere "
                             "(nothing was written, an older file of that name is unchanged)",
                             target) from None
        # EOPNOTSUPP/EINVAL: this file system cannot preallocate; write and see
    finally:
        os.close(fd)


def _decode(v):
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.generic):
        return v.item()
    return v


def read_asset(path: str | os.PathLike, kind: str | None = None, *, load: bool = True,
               lazy: tuple[str, ...] = ()) -> Asset:
    """Open, validate and (by default) load an asset.

    Parameters
    ----------
    path : path-like
    kind : str, optional
        Required kind; ``None`` accepts any registered kind.
    load : bool
        Read every dataset into memory (default).  With ``False`` nothing is kept:
        the attributes and the datasets' shapes and dtypes are validated, and float
        datasets are checked for NaN/inf block by block (:data:`BLOCK_ELEMENTS`), so
        an asset larger than memory can be checked.
    lazy : tuple of str
        Datasets whose shapes and dtypes are checked but whose values are
        neither read nor checked for NaN/inf (a streaming reader checks them
        as it reads them).

    Returns
    -------
    Asset

    Raises
    ------
    AssetError
        With a one-line reason naming the file: missing, not HDF5, wrong kind,
        unknown version, missing dataset, wrong shape or dtype, NaN/inf.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise AssetError("file not found; check the path or build it first", path)
    if not os.path.isfile(path):
        raise AssetError("is not a regular file (a folder, pipe or device); give an asset "
                         "file", path)
    try:
        f = h5py.File(path, "r")
    except OSError:
        raise AssetError(
            "not a readable HDF5 file (truncated or another format); rebuild it", path
        ) from None
    with f:
        attrs = {k: _decode(v) for k, v in f.attrs.items()}
        fmt = attrs.get("format")
        if not isinstance(fmt, str) or not fmt.startswith(FORMAT_PREFIX):
            raise AssetError("not an shtools asset (no 'format' attribute)", path)
        file_kind = fmt[len(FORMAT_PREFIX):]
        if kind is not None and file_kind != kind:
            raise AssetError(f"is a '{file_kind}' asset, expected a '{kind}' asset", path)
        schema = get_schema(file_kind)
        if schema is None:
            raise AssetError(f"unknown asset kind '{file_kind}'; upgrade shtools", path)
        version = attrs.get("format_version")
        if not isinstance(version, int) or isinstance(version, bool):
            raise AssetError(f"attribute 'format_version' is {version!r} "
                             f"({type(version).__name__}), expected an integer; rebuild the "
                             "asset with shtools", path)
        if version not in schema.versions():
            raise AssetError(
                f"'{file_kind}' format version {version} is not supported by this shtools "
                f"(knows {', '.join(map(str, schema.versions()))}); rebuild the asset or upgrade",
                path,
            )
        for key in ("inputs", "parameters"):
            if isinstance(attrs.get(key), str):
                try:
                    attrs[key] = json.loads(attrs[key])
                except json.JSONDecodeError:
                    raise AssetError(f"attribute '{key}' is not valid JSON", path) from None
        for key in schema.required_attrs + (("sh_order",) if schema.has_sh else ()):
            if key not in attrs:
                raise AssetError(f"missing root attribute '{key}'", path)
        if schema.has_sh:
            order = attrs["sh_order"]
            if isinstance(order, bool) or not isinstance(order, int) or not 1 <= order <= 64:
                raise AssetError(f"attribute 'sh_order' is {order!r}, expected an integer SH "
                                 "order in 1..64; rebuild the asset", path)
        dims: dict[str, int] = {}
        data: dict[str, np.ndarray] = {}
        for spec in schema.datasets:
            _check_dataset(f, spec, dims, path, load and spec.name not in lazy, data,
                           read=spec.name not in lazy)
        if schema.check is not None:
            schema.check(f, {"attrs": attrs, "dims": dims, "path": path})
        if load:
            def visit(name, obj):
                if isinstance(obj, h5py.Dataset) and name not in data and name not in lazy:
                    data[name] = obj[()]
            f.visititems(visit)
    return Asset(file_kind, int(version), attrs, data, dims, path)


def _check_dataset(f, spec: DatasetSpec, dims, path, load, data, read: bool = True) -> None:
    if spec.name not in f:
        if spec.optional:
            return
        raise AssetError(f"missing dataset '{spec.name}'; the file is incomplete, rebuild it", path)
    ds = f[spec.name]
    if not isinstance(ds, h5py.Dataset):
        raise AssetError(f"'{spec.name}' is not a dataset", path)
    if ds.dtype.kind not in spec.dtype_kind:
        raise AssetError(f"dataset '{spec.name}' has dtype {ds.dtype}, expected kind "
                         f"'{spec.dtype_kind}'", path)
    options = spec.ndim_options or (spec.shape,)
    matched = None
    for shape in options:
        if len(shape) != ds.ndim:
            continue
        trial = dict(dims)
        ok = True
        for want, got in zip(shape, ds.shape, strict=True):
            if want is None:
                continue
            if isinstance(want, str):
                if trial.setdefault(want, got) != got:
                    ok = False
                    break
            elif want != got:
                ok = False
                break
        if ok:
            matched = trial
            break
    if matched is None:
        want = " or ".join(str(tuple(s)) for s in options)
        raise AssetError(f"dataset '{spec.name}' has shape {ds.shape}, expected {want}", path)
    dims.update(matched)
    if not read:  # a lazy dataset: its streaming reader checks the values it reads
        return
    check_finite = spec.finite and ds.dtype.kind == "f"
    if load:
        arr = ds[()]
        if check_finite and not np.all(np.isfinite(arr)):
            raise AssetError(f"dataset '{spec.name}' contains NaN or inf; rebuild it", path)
        data[spec.name] = arr
    elif check_finite:
        # block by block: a dataset larger than memory is validated without loading it
        for block in row_blocks(ds.shape, BLOCK_ELEMENTS):
            if not np.all(np.isfinite(ds[block])):
                raise AssetError(f"dataset '{spec.name}' contains NaN or inf; rebuild it",
                                 path)


def row_blocks(shape: tuple, elements: int) -> list:
    """Slices along the first axis of about ``elements`` elements each (at least one
    row), covering a dataset of ``shape``; ``[()]`` for a scalar."""
    if len(shape) == 0:
        return [()]
    size = int(np.prod(shape))
    row = max(1, size // max(shape[0], 1))
    step = max(1, elements // row)
    return [slice(i, i + step) for i in range(0, shape[0], step)] or [slice(0, 0)]
