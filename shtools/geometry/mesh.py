"""Load and validate triangle meshes; clean what can be cleaned, refuse what cannot.

Every stage that reads a mesh goes through :func:`load_mesh`, so the errors a user
sees for a bad file are the same everywhere.  Problems a mesh can carry without
being unusable — duplicate vertices, degenerate (zero-area) triangles, open
boundaries, several components — are repaired or tolerated here; missing,
unreadable, unsupported, empty and non-finite meshes raise :class:`InputError`.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import trimesh

from shtools.errors import InputError

#: File extensions trimesh can read as triangle meshes (lower case, with dot).
SUPPORTED_EXTENSIONS = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")

#: Relative area below which a triangle counts as degenerate (fraction of the
#: squared bounding-box diagonal); such triangles carry no surface and break
#: normals, so they are dropped.
DEGENERATE_AREA_FRACTION = 1e-14


def load_mesh(path: str | os.PathLike) -> trimesh.Trimesh:
    """Read a triangle mesh and validate it.

    Scenes (glTF, multi-object OBJ) are flattened into one mesh in world space.
    Exact duplicate vertices are merged, degenerate and duplicate triangles and
    unreferenced vertices are removed; open boundaries and several components
    are kept as they are (the solid is defined by generalized winding numbers
    downstream, which tolerate both).

    Parameters
    ----------
    path : path-like
        Mesh file (``.obj``, ``.ply``, ``.stl``, ``.off``, ``.glb``, ``.gltf``).

    Returns
    -------
    trimesh.Trimesh
        Cleaned mesh with ``vertices (V, 3) float64`` and ``faces (F, 3) int64``.

    Raises
    ------
    InputError
        The file is missing, not a supported format, unreadable, has no
        triangles, or has NaN/inf vertex coordinates.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("mesh file not found; check the path", path)
    if path.is_dir():
        raise InputError("is a folder, expected a mesh file", path)
    if not path.is_file():  # reading a pipe or device would block or never end
        raise InputError("is not a regular file (a pipe or device?); give a mesh file", path)
    ext = path.suffix.lower()
    if ext not in SUPPORTED_EXTENSIONS:
        raise InputError(
            f"unsupported mesh format '{ext or '(no extension)'}'; use one of "
            f"{', '.join(SUPPORTED_EXTENSIONS)}",
            path,
        )
    source = _checked_source(path, ext)
    try:
        if source is None:
            loaded = trimesh.load(str(path), force="mesh", process=False)
        else:  # text we decoded ourselves (trimesh would guess the charset)
            loaded = trimesh.load(source, file_type=ext[1:], force="mesh", process=False,
                                  resolver=trimesh.resolvers.FilePathResolver(str(path)))
    except InputError:
        raise
    except Exception as exc:  # trimesh raises many types for corrupt files
        raise InputError(
            f"cannot read the mesh ({type(exc).__name__}: {' '.join(str(exc).split())[:120]}); "
            "check that the file is a valid triangle mesh",
            path,
        ) from None
    if not isinstance(loaded, trimesh.Trimesh):
        raise InputError("the file holds no triangle mesh (points or lines only?)", path)
    return validate_mesh(loaded, path)


#: Bytes of a binary STL: an 80-byte header, a uint32 triangle count, 50 bytes each.
STL_HEADER, STL_TRIANGLE = 84, 50


def _checked_source(path: Path, ext: str):
    """Format checks trimesh does not make, with the honest reason; the text to load.

    * OBJ: binary data is refused; text that is not UTF-8 (a Latin-1 comment or
      material name) is decoded as Latin-1, which maps every byte, instead of
      letting trimesh guess the charset; a face index 0 (OBJ counts from 1) is
      refused instead of silently wrapping to the last vertex.
    * STL: a binary STL whose size disagrees with its triangle count is
      truncated; an ASCII STL without ``endsolid`` too.
    * glTF: the JSON must parse.

    Returns
    -------
    io.BytesIO or None
        UTF-8 text of an OBJ to load, or None to let trimesh read the file.
    """
    import io

    if ext not in (".obj", ".stl", ".gltf"):
        return None
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror})", path) from None
    if ext == ".stl":
        if len(data) >= STL_HEADER:
            count = int.from_bytes(data[80:84], "little")
            if len(data) == STL_HEADER + STL_TRIANGLE * count:
                return None  # a complete binary STL
        if data.lstrip()[:5].lower() == b"solid" and b"\0" not in data:
            if b"endsolid" not in data[-4096:].lower():
                raise InputError("truncated ASCII STL (no 'endsolid' at the end); re-export "
                                 "the mesh", path)
            return None
        if len(data) < STL_HEADER:
            raise InputError(f"not an STL file ({len(data)} bytes, shorter than a binary STL "
                             "header)", path)
        raise InputError(
            f"truncated or damaged binary STL: the header announces {count} triangles "
            f"({STL_HEADER + STL_TRIANGLE * count} bytes) but the file has {len(data)} bytes; "
            "re-export the mesh", path)
    if ext == ".gltf":
        import json

        try:
            json.loads(data)
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            where = (f" (line {exc.lineno}, column {exc.colno})"
                     if isinstance(exc, json.JSONDecodeError) else "")
            raise InputError(f"not valid glTF: the JSON does not parse{where}; re-export it "
                             "or use .glb", path) from None
        return None
    # OBJ
    if b"\0" in data:
        raise InputError("not an OBJ file: it holds binary data (OBJ is text with 'v' and "
                         "'f' lines)", path)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    if not _plain_obj_faces(text):
        faces = 0
        for number, line in enumerate(text.splitlines(), 1):
            fields = line.split()
            faces += fields[:1] == ["f"]
            if fields[:1] == ["f"] and any(
                    part in ("0", "-0") for item in fields[1:] for part in item.split("/")):
                raise InputError(f"line {number}: face index 0 (OBJ indices start at 1); fix "
                                 "the exporter or the file", path)
        if not faces:
            raise InputError("the OBJ has no faces (no 'f' lines): empty, or not an OBJ mesh",
                             path)
    return io.BytesIO(text.encode("utf-8"))


#: Line breaks and blanks other than space, tab, "\n" and "\r\n", under which the
#: patterns of :func:`_plain_obj_faces` would not split lines and fields as
#: ``str.splitlines`` and ``str.split`` do.
_OTHER_BREAKS = re.compile(r"[\x0b\x0c\x1c-\x1f\x85\u2028\u2029]|\r(?!\n)|[^\x00-\x7f]")
#: A line whose first field is "f".
_FACE_LINE = re.compile(r"^[ \t]*f(?:[ \t\r]|$)", re.MULTILINE)
#: A face line with a field part (between blanks and "/") that is "0" or "-0".
_ZERO_INDEX = re.compile(r"^[ \t]*f[ \t][^\n]*?(?<![^ \t/])-?0(?![^ \t/\r\n])", re.MULTILINE)


def _plain_obj_faces(text: str) -> bool:
    """Whether an OBJ's text has face lines and no face index 0, by two regular-expression
    scans (the line-by-line check of :func:`_checked_source` costs ~2 s on a 100k-face
    file).  False also when the text has other line breaks or blanks than the patterns
    know, or non-ASCII characters: the caller then checks line by line."""
    if _OTHER_BREAKS.search(text):
        return False
    return _FACE_LINE.search(text) is not None and _ZERO_INDEX.search(text) is None


def validate_mesh(mesh: trimesh.Trimesh, path: str | os.PathLike | None = None) -> trimesh.Trimesh:
    """Validate and clean an in-memory mesh (see :func:`load_mesh`).

    Parameters
    ----------
    mesh : trimesh.Trimesh
    path : path-like, optional
        Named in error messages.

    Returns
    -------
    trimesh.Trimesh
        A new cleaned mesh.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if len(faces) == 0 or len(vertices) == 0:
        raise InputError("the mesh is empty (no triangles); export it with its faces", path)
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise InputError("the mesh is not made of triangles; triangulate it first", path)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError("faces refer to vertices that do not exist; re-export the mesh", path)
    used = np.unique(faces)
    if not np.all(np.isfinite(vertices[used])):
        raise InputError(
            "vertex coordinates contain NaN or inf; fix or re-export the mesh", path
        )
    # Merge exact duplicates so that shared edges are recognised (UV seams split
    # vertices in OBJ files).
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    tri = unique[faces]
    diag = float(np.linalg.norm(np.ptp(tri.reshape(-1, 3), axis=0)))
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    keep = (area > DEGENERATE_AREA_FRACTION * max(diag, 1e-300) ** 2)
    keep &= (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2])
    keep &= faces[:, 0] != faces[:, 2]
    faces = faces[keep]
    if len(faces) == 0:
        raise InputError("every triangle is degenerate (zero area); the mesh is empty", path)
    # Identical triangles (same vertex set) would be counted twice by winding numbers.
    _, first = np.unique(np.sort(faces, axis=1), axis=0, return_index=True)
    faces = faces[np.sort(first)]
    used, compact = np.unique(faces, return_inverse=True)
    return trimesh.Trimesh(unique[used], compact.reshape(-1, 3), process=False, validate=False)


def boundary_edges(mesh: trimesh.Trimesh) -> np.ndarray:
    """Edges used by exactly one triangle, oriented as in that triangle.

    Returns
    -------
    ndarray, shape (B, 2), int64
    """
    edges = np.asarray(mesh.edges)  # (3F, 2) oriented
    key = np.sort(edges, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return edges[counts[inverse.reshape(-1)] == 1]


def thicken(mesh: trimesh.Trimesh, thickness: float) -> trimesh.Trimesh:
    """Turn a surface into a closed shell of the given thickness.

    Each vertex is offset by ``±thickness/2`` along its (area-weighted) normal;
    the outer layer keeps the orientation, the inner layer is flipped, and
    boundary edges are closed by quads, so a flat sheet becomes a slab that
    encloses volume.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    thickness : float
        Shell thickness in mesh units, > 0.

    Returns
    -------
    trimesh.Trimesh
        Closed shell (watertight when the input is edge-manifold).
    """
    if not thickness > 0:
        raise InputError(f"--thickness must be > 0 (got {thickness})")
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    normals = np.asarray(mesh.vertex_normals, dtype=np.float64)
    half = 0.5 * thickness
    nv = len(v)
    vertices = np.vstack([v + half * normals, v - half * normals])
    faces = [f, f[:, ::-1] + nv]
    edges = boundary_edges(mesh)
    if len(edges):
        a, b = edges[:, 0], edges[:, 1]
        # outer edge a->b is matched by the side quad (b, a, a', b') oriented outward
        faces.append(np.stack([b, a, a + nv], axis=1))
        faces.append(np.stack([b, a + nv, b + nv], axis=1))
    return trimesh.Trimesh(vertices, np.vstack(faces), process=False, validate=False)
