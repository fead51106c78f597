"""Procedural test meshes for the geometry tests (others may import these fixtures).

All are small (<= ~3k triangles) so that fits run in seconds:

* ``torus_mesh``           closed genus-1 surface, volume 2π²Rr² (polyhedral approx.)
* ``capsule_union_mesh``   two crossing capsules joined by a boolean union (pymeshlab)
* ``character_mesh``       a non-convex "character": torso, head, arms, legs (union)
* ``open_mesh``            a sphere with a hole cut in its top (open boundary)
* ``flat_sheet_mesh``      a flat square grid (encloses no volume)
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh


def boolean_union(parts: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """Boolean union of closed meshes with pymeshlab, cleaned by ``validate_mesh``."""
    import pymeshlab

    from shtools.geometry.mesh import validate_mesh

    vertices, faces = parts[0].vertices, parts[0].faces
    for part in parts[1:]:
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertices, faces))
        ms.add_mesh(pymeshlab.Mesh(part.vertices, part.faces))
        ms.generate_boolean_union(first_mesh=0, second_mesh=1)
        vertices, faces = ms.current_mesh().vertex_matrix(), ms.current_mesh().face_matrix()
    return _canonical(validate_mesh(trimesh.Trimesh(vertices, faces, process=False)))


def _canonical(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The same triangles in a fixed order: pymeshlab's boolean (multi-threaded)
    returns them in a different vertex and face order from run to run, and a fit's
    result depends on that order (sample indices, tie-breaks)."""
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    order = np.lexsort(v.T[::-1])  # vertices sorted by (x, y, z)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    f = rank[f]
    first = np.argmin(f, axis=1)  # rotate each face (keeping its winding) to its least index
    f = np.take_along_axis(f, (first[:, None] + np.arange(3)) % 3, axis=1)
    f = f[np.lexsort(f.T[::-1])]
    return trimesh.Trimesh(v[order], f, process=False)


def capsule(a, b, radius: float, sections: int = 16) -> trimesh.Trimesh:
    """A capsule from point ``a`` to point ``b``."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = b - a
    length = float(np.linalg.norm(axis))
    mesh = trimesh.creation.capsule(height=length, radius=radius, count=[sections, sections])
    # trimesh's capsule runs along +z centred at the origin
    transform = trimesh.geometry.align_vectors([0, 0, 1], axis / length)
    transform[:3, 3] = 0.5 * (a + b)
    mesh.apply_transform(transform)
    return mesh


def make_torus() -> trimesh.Trimesh:
    return trimesh.creation.torus(1.0, 0.35, major_sections=32, minor_sections=16)


def make_capsule_union() -> trimesh.Trimesh:
    return boolean_union([capsule([-1, 0, 0], [1, 0, 0], 0.3),
                          capsule([0, -0.2, -1], [0, 0.2, 1], 0.25)])


def make_character() -> trimesh.Trimesh:
    """Y-up figure about 2 units tall: torso, head, two arms, two legs."""
    head = trimesh.creation.icosphere(subdivisions=2, radius=0.25)
    head.apply_translation([0, 1.75, 0])
    parts = [
        capsule([0, 0.9, 0], [0, 1.4, 0], 0.3),            # torso
        head,
        capsule([-0.25, 1.35, 0], [-0.9, 0.9, 0], 0.1),     # arms, bent down
        capsule([0.25, 1.35, 0], [0.9, 0.9, 0], 0.1),
        capsule([-0.15, 0.8, 0], [-0.25, 0.1, 0.05], 0.12),  # legs
        capsule([0.15, 0.8, 0], [0.25, 0.1, -0.05], 0.12),
    ]
    return boolean_union(parts)


def make_open_mesh() -> trimesh.Trimesh:
    """A unit sphere with the triangles of its top cap removed (an open scan)."""
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    keep = sphere.triangles_center[:, 2] < 0.9
    return trimesh.Trimesh(sphere.vertices, sphere.faces[keep], process=True)


def make_flat_sheet() -> trimesh.Trimesh:
    """A 1 x 1 square in the plane z = 0, 8 x 8 quads."""
    g = np.linspace(0.0, 1.0, 9)
    x, y = np.meshgrid(g, g, indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(81).reshape(9, 9)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    return trimesh.Trimesh(vertices, faces, process=False)


@pytest.fixture(scope="session")
def torus_mesh() -> trimesh.Trimesh:
    return make_torus()


@pytest.fixture(scope="session")
def capsule_union_mesh() -> trimesh.Trimesh:
    return make_capsule_union()


@pytest.fixture(scope="session")
def character_mesh() -> trimesh.Trimesh:
    return make_character()


@pytest.fixture(scope="session")
def open_mesh() -> trimesh.Trimesh:
    return make_open_mesh()


@pytest.fixture(scope="session")
def flat_sheet_mesh() -> trimesh.Trimesh:
    return make_flat_sheet()


@pytest.fixture
def write_mesh(tmp_path):
    """Write a mesh to ``tmp_path/<name>`` and return the path."""

    def write(mesh: trimesh.Trimesh, name: str = "mesh.obj"):
        path = tmp_path / name
        mesh.export(path)
        return path

    return write
