"""The set-up cache: what a bake computes before its frames, stored once by content.

A bake's set-up (the exact self-transfers of its rigid objects, sphere fits made
on the fly, the local visibility of skinned objects, environment images projected
to SH, mid-range scaling tables) depends only on its inputs, so it is computed once and read
back on every later bake of the same inputs (``docs/cache.md``).

* **Key.** The SHA-256 of everything the result depends on: the arrays the
  computation reads (a mesh as loaded from its file's bytes) or a file's bytes,
  every setting that changes the result, the computation's algorithm version,
  the versions of shtools and of the libraries that compute it, and a digest
  of shtools' own source files -- an edited checkout cannot read an entry an
  older code wrote.
* **Entries.** One file each: a header with the key and the SHA-256 of the
  payload, then the payload (NumPy arrays, ``np.savez`` without pickles).  A
  corrupt or truncated entry fails its checksum: it is removed, recomputed,
  and reported in one warning line, never used.
* **Writes.** A temporary file in the cache folder, then :func:`os.replace`:
  readers see a whole entry or none, and concurrent bakes (or Dask workers)
  writing the same entry write the same bytes.
* **Size.** At most ``max_bytes`` (:data:`DEFAULT_MAX_BYTES`,
  ``SHTOOLS_CACHE_SIZE``); a write past it removes the least recently used
  entries (a hit refreshes an entry's time).
* **Failures.** An unwritable folder or a full disk never fails a bake: the
  result is computed as without a cache, with one warning line.

The location is ``SHTOOLS_CACHE``, else ``$XDG_CACHE_HOME/shtools``, else
``~/.cache/shtools``; ``SHTOOLS_NO_CACHE=1`` turns the cache off.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import io
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

#: Largest total size of the cache folder's entries (2 GiB: about 150 self-transfers of
#: 100k-vertex meshes at accumulation order 6).
DEFAULT_MAX_BYTES = 2 * 2**30
#: Environment variables: the folder, its size bound, and the switch that turns it off.
ENV_LOCATION = "SHTOOLS_CACHE"
ENV_SIZE = "SHTOOLS_CACHE_SIZE"
ENV_OFF = "SHTOOLS_NO_CACHE"
#: First bytes of every entry (the format of the entry files, not of what they hold).
MAGIC = b"shtools-cache 1\n"
#: Suffix of entry files; temporary files start with a dot and are never read.
SUFFIX = ".entry"
#: A temporary file older than this is a dead writer's (removed by eviction and clear).
STALE_TEMP_SECONDS = 3600.0
#: Libraries whose versions are part of every key (they compute what is cached).
KEY_LIBRARIES = ("numpy", "scipy", "trimesh", "embreex", "h5py")


def default_location() -> Path:
    """``SHTOOLS_CACHE``, else ``$XDG_CACHE_HOME/shtools``, else ``~/.cache/shtools``."""
    if os.environ.get(ENV_LOCATION):
        return Path(os.environ[ENV_LOCATION]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "shtools"


def parse_size(text: str) -> int:
    """Bytes from ``"512M"``, ``"2G"``, ``"10000"`` (suffixes K, M, G, T: powers of 1024).

    Raises
    ------
    ValueError
        Not a size.
    """
    units = {"K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
    s = str(text).strip().upper().removesuffix("B").removesuffix("I")
    scale = units.get(s[-1:], 1)
    number = s[:-1] if s[-1:] in units else s
    try:
        value = float(number)
    except ValueError:
        raise ValueError(f"'{text}' is not a size (e.g. 500M, 2G)") from None
    if not value >= 0 or value == float("inf"):
        raise ValueError(f"'{text}' is not a size (e.g. 500M, 2G)")
    return int(value * scale)


@functools.lru_cache(maxsize=1)
def code_digest() -> str:
    """SHA-256 of shtools' version, its source files and the key libraries' versions."""
    from importlib import metadata

    from shtools import __version__

    h = hashlib.sha256(f"shtools {__version__}\n".encode())
    for name in KEY_LIBRARIES:
        try:
            version = metadata.version(name)
        except metadata.PackageNotFoundError:
            version = "absent"
        h.update(f"{name} {version}\n".encode())
    root = Path(__file__).resolve().parent
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


def file_digest(path) -> str:
    """SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _feed(h, value) -> None:
    """Hash one key part, typed, so that no two different parts hash alike."""
    if isinstance(value, np.ndarray):
        a = np.ascontiguousarray(value)
        h.update(f"array {a.dtype.str} {a.shape}\n".encode())
        h.update(a.tobytes())
    elif isinstance(value, Path):
        h.update(f"file {file_digest(value)}\n".encode())
    elif isinstance(value, dict):
        h.update(f"dict {len(value)}\n".encode())
        for k in sorted(value):
            h.update(f"{k}=".encode())
            _feed(h, value[k])
    elif isinstance(value, list | tuple):
        h.update(f"seq {len(value)}\n".encode())
        for v in value:
            _feed(h, v)
    else:  # str, numbers, bools, None: their JSON text
        h.update(f"value {json.dumps(value)}\n".encode())


def cache_key(kind: str, version: int, parts: dict) -> str:
    """The key of one computation.

    Parameters
    ----------
    kind : str
        What is computed (e.g. ``"self_log"``); also part of the entry's file name.
    version : int
        The computation's algorithm version (raise it when its results change).
    parts : dict
        Everything the result depends on: arrays (hashed with their dtype and
        shape), :class:`~pathlib.Path` (the file's bytes), and JSON values.

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    h = hashlib.sha256(f"{kind} {version} {code_digest()}\n".encode())
    _feed(h, parts)
    return h.hexdigest()


def _stderr_warning(message: str) -> None:
    print(f"warning: {message}", file=sys.stderr)


class SetupCache:
    """A content-addressed folder of set-up results (see the module docstring).

    Parameters
    ----------
    location : path-like, optional
        The folder (default :func:`default_location`); created on the first write.
    max_bytes : int, optional
        Size bound (default ``SHTOOLS_CACHE_SIZE`` or :data:`DEFAULT_MAX_BYTES`).
    enabled : bool
        False: every :meth:`fetch` computes, nothing is read or written.
    warn : callable, optional
        Receives each warning line (default: ``warning: ...`` on stderr).  At
        most one warning per cache object and kind of failure.

    Attributes
    ----------
    hits, misses : int
        Entries read back / computed (and stored) by :meth:`fetch`.
    kinds : dict
        The same per kind of entry: ``{kind: {"hits": int, "misses": int}}``.
    """

    def __init__(self, location=None, *, max_bytes: int | None = None, enabled: bool = True,
                 warn: Callable[[str], None] | None = None):
        self.location = Path(location).expanduser() if location is not None \
            else default_location()
        self.enabled = bool(enabled)
        self.hits = self.misses = 0
        self.kinds: dict[str, dict[str, int]] = {}
        self._warn = warn or _stderr_warning
        self._warned: set[str] = set()
        if max_bytes is None:
            max_bytes = DEFAULT_MAX_BYTES
            if os.environ.get(ENV_SIZE):
                try:
                    max_bytes = parse_size(os.environ[ENV_SIZE])
                except ValueError as exc:
                    self._warn_once("size", f"{ENV_SIZE}: {exc}; using the default "
                                            f"{DEFAULT_MAX_BYTES // 2**30}G")
        self.max_bytes = int(max_bytes)

    def __getstate__(self) -> dict:
        # a prepared scene travels to worker processes with its cache; a local warning
        # function need not (the workers warn on stderr)
        state = dict(self.__dict__)
        state["_warn"] = _stderr_warning
        return state

    @classmethod
    def from_environment(cls, warn=None) -> SetupCache:
        """The default cache: off when ``SHTOOLS_NO_CACHE`` is set (to anything but 0)."""
        off = os.environ.get(ENV_OFF, "").strip() not in ("", "0")
        return cls(enabled=not off, warn=warn)

    # ----------------------------------------------------------------- entries
    def path_of(self, kind: str, key: str) -> Path:
        """The entry file of ``key``."""
        return self.location / key[:2] / f"{key}-{kind}{SUFFIX}"

    def _warn_once(self, what: str, message: str) -> None:
        if what not in self._warned:
            self._warned.add(what)
            self._warn(message)

    def get(self, kind: str, key: str) -> dict[str, np.ndarray] | None:
        """The arrays of an entry, or None (absent, unreadable or corrupt: then removed)."""
        path = self.path_of(kind, key)
        try:
            with open(path, "rb") as fh:
                data = fh.read()
        except (FileNotFoundError, NotADirectoryError):
            return None
        except OSError as exc:
            self._warn_once("read", f"set-up cache {path}: cannot read it ({exc.strerror}); "
                                    "computing without the cache")
            return None
        arrays = _decode(data, key)
        if arrays is None:
            self._warn_once("corrupt", f"set-up cache entry {path} is corrupt or truncated; "
                                       "removed and recomputed")
            with contextlib.suppress(OSError):
                path.unlink()
            return None
        with contextlib.suppress(OSError):  # least recently used: a hit is a use
            os.utime(path)
        return arrays

    def put(self, kind: str, key: str, arrays: dict[str, np.ndarray]) -> bool:
        """Store an entry atomically, then evict past the size bound; False if not stored."""
        data = _encode(key, arrays)
        if len(data) > self.max_bytes:
            return False
        path = self.path_of(kind, key)
        tmp = None
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=path.parent)
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.replace(tmp, path)
            tmp = None
        except OSError as exc:
            reason = exc.strerror or type(exc).__name__
            self._warn_once("write", f"set-up cache {self.location}: cannot write to it "
                                     f"({reason}); the bake goes on without storing its set-up "
                                     "(set SHTOOLS_CACHE or pass --no-cache)")
            return False
        finally:
            if tmp is not None:
                with contextlib.suppress(OSError):
                    os.unlink(tmp)
        self.evict(keep=path)
        return True

    def fetch(self, kind: str, version: int, parts: dict,
              compute: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        """The stored result of ``compute()`` for these key parts, computing it on a miss.

        ``compute`` returns a dict of arrays; what is returned on a hit is
        identical to it (same dtypes, shapes and bytes).
        """
        if not self.enabled:
            return compute()
        key = cache_key(kind, version, parts)
        arrays = self.get(kind, key)
        counts = self.kinds.setdefault(kind, {"hits": 0, "misses": 0})
        if arrays is not None:
            self.hits += 1
            counts["hits"] += 1
            return arrays
        self.misses += 1
        counts["misses"] += 1
        arrays = {k: np.asarray(v) for k, v in compute().items()}
        self.put(kind, key, arrays)
        return arrays

    # --------------------------------------------------------------- the folder
    def _files(self) -> list[tuple[Path, os.stat_result]]:
        out = []
        if not self.location.is_dir():
            return out
        for sub in self.location.iterdir():
            if not sub.is_dir() or not _is_entry_folder(sub.name):
                continue
            for path in sub.iterdir():
                # only what the cache writes: --cache may name a folder holding other
                # files, which clear and eviction must never remove
                if not _is_cache_file(sub.name, path.name):
                    continue
                with contextlib.suppress(OSError):  # removed meanwhile by another process
                    out.append((path, path.stat()))
        return out

    def evict(self, keep: Path | None = None) -> int:
        """Remove the least recently used entries past ``max_bytes`` (and dead temp files).

        Returns the number of entries removed.  ``keep`` (the entry just
        written) goes last.
        """
        now = time.time()
        entries, removed = [], 0
        for path, st in self._files():
            if path.name.startswith(".tmp-"):
                if now - st.st_mtime > STALE_TEMP_SECONDS:
                    with contextlib.suppress(OSError):
                        path.unlink()
            elif path.name.endswith(SUFFIX):
                entries.append((path == keep, st.st_mtime, path, st.st_size))
        total = sum(e[3] for e in entries)
        for _, _, path, size in sorted(entries):
            if total <= self.max_bytes:
                break
            with contextlib.suppress(OSError):
                path.unlink()
                removed += 1
            total -= size
        return removed

    def info(self) -> dict:
        """``location``, ``entries``, ``bytes``, ``max_bytes``, ``enabled`` and entries by kind."""
        kinds: dict[str, int] = {}
        size = 0
        for path, st in self._files():
            if path.name.endswith(SUFFIX):
                kind = path.name[:-len(SUFFIX)].partition("-")[2]
                kinds[kind] = kinds.get(kind, 0) + 1
                size += st.st_size
        return {"location": os.fspath(self.location), "entries": sum(kinds.values()),
                "bytes": size, "max_bytes": self.max_bytes, "enabled": self.enabled,
                "kinds": dict(sorted(kinds.items()))}

    def clear(self) -> int:
        """Remove every entry and temporary file; returns the number of entries removed."""
        removed = 0
        for path, _ in self._files():
            with contextlib.suppress(OSError):
                path.unlink()
                removed += path.name.endswith(SUFFIX)
        if self.location.is_dir():
            for sub in self.location.iterdir():
                if sub.is_dir() and _is_entry_folder(sub.name):
                    with contextlib.suppress(OSError):
                        sub.rmdir()
        return removed

    def summary(self) -> dict:
        """What a bake reports (``bake --json``): location, enabled, hits, misses (in all
        and per kind of entry)."""
        return {"location": os.fspath(self.location), "enabled": self.enabled,
                "hits": self.hits, "misses": self.misses,
                "kinds": {k: dict(v) for k, v in sorted(self.kinds.items())}}


_HEX = frozenset("0123456789abcdef")


def _is_entry_folder(name: str) -> bool:
    """A folder of entries: the first two hex digits of their keys."""
    return len(name) == 2 and set(name) <= _HEX


def _is_cache_file(folder: str, name: str) -> bool:
    """An entry ``KEY-KIND.entry`` (KEY: 64 hex digits starting with ``folder``) or a
    writer's temporary file ``.tmp-*``."""
    if name.startswith(".tmp-"):
        return True
    key, dash, kind = name.partition("-")
    return (bool(dash) and name.endswith(SUFFIX) and len(key) == 64 and set(key) <= _HEX
            and key.startswith(folder) and len(kind) > len(SUFFIX))


def _encode(key: str, arrays: dict[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **{k: np.asarray(v) for k, v in arrays.items()})
    payload = buf.getvalue()
    digest = hashlib.sha256(payload).hexdigest()
    return MAGIC + f"{key} {digest} {len(payload)}\n".encode() + payload


def _decode(data: bytes, key: str) -> dict[str, np.ndarray] | None:
    """The arrays of an entry's bytes; None when its header, size or checksum is wrong."""
    if not data.startswith(MAGIC):
        return None
    header, sep, payload = data[len(MAGIC):].partition(b"\n")
    fields = header.decode("ascii", "replace").split()
    if not sep or len(fields) != 3 or fields[0] != key or fields[2] != str(len(payload)):
        return None
    if hashlib.sha256(payload).hexdigest() != fields[1]:
        return None
    try:
        with np.load(io.BytesIO(payload), allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except (ValueError, OSError, EOFError):
        return None
