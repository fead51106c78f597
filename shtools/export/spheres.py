"""Look at a sphere set over its mesh: a PNG preview and a GLB for a DCC viewport.

* :func:`render_spheres_png` -- two views side by side (the given azimuth and
  90 degrees round from it) of the mesh, opaque and grey-shaded, with every
  sphere drawn over it half-transparent in its own colour (a sphere shows even
  where the mesh hides it: the point is to see how the set bounds the mesh);
* :func:`write_spheres_glb` -- the mesh as one node and every sphere as a node
  ``sphere_<i>`` instancing one unit icosphere with ``translation = centre``
  and ``scale = radius``, in a half-transparent material (``alphaMode BLEND``),
  so a DCC can select, hide or measure spheres one by one.
"""

from __future__ import annotations

import os

import numpy as np
import pygltflib
import trimesh

from shtools.data_formats import atomic_path
from shtools.export.raster import fit_camera, rasterize

#: Sphere opacity over the mesh in the PNG and the GLB.
SPHERE_ALPHA = 0.4
MESH_GREY = np.array([0.45, 0.45, 0.43])
BACKGROUND = np.array([0.03, 0.035, 0.045])
OUTLINE = np.array([0.0, 0.0, 0.0])


def sphere_colors(n: int) -> np.ndarray:
    """Distinct saturated linear RGB colours (n, 3): golden-ratio steps round the hue circle."""
    import colorsys

    hues = (np.arange(n) * 0.618033988749895) % 1.0
    srgb = np.array([colorsys.hsv_to_rgb(h, 0.85, 1.0) for h in hues]).reshape(-1, 3)
    return srgb ** 2.2  # to linear


def _spheres_mesh(centers, radii, subdivisions=2):
    """All spheres as one icosphere mesh: vertices (N*K, 3), faces, sphere id per vertex."""
    ico = trimesh.creation.icosphere(subdivisions=subdivisions)
    unit_v, unit_f = np.asarray(ico.vertices), np.asarray(ico.faces)
    k = len(unit_v)
    verts = (centers[:, None, :] + radii[:, None, None] * unit_v[None]).reshape(-1, 3)
    faces = (unit_f[None] + (np.arange(len(centers)) * k)[:, None, None]).reshape(-1, 3)
    normals = np.broadcast_to(unit_v, (len(centers), k, 3)).reshape(-1, 3)
    return verts, faces, normals, np.repeat(np.arange(len(centers)), k)


def _shade(normals, base, light):
    """Half-Lambert shading (soft, no black backs) of ``base`` colours."""
    lam = 0.5 + 0.5 * (normals @ light)
    return base * (0.25 + 0.75 * lam[:, None])


def render_spheres_png(
    mesh: trimesh.Trimesh,
    centers: np.ndarray,
    radii: np.ndarray,
    *,
    width: int = 480,
    height: int = 360,
    elevation: float = 20.0,
    azimuth: float = 35.0,
) -> np.ndarray:
    """Two-panel preview image, uint8 ``(height, 2 * width, 3)``.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    centers : ndarray, shape (N, 3)
    radii : ndarray, shape (N,)
    width, height : int
        Size of one panel in pixels.
    elevation, azimuth : float
        Camera angles of the left panel, degrees; the right panel turns 90 degrees.
    """
    from shtools.export.tonemap import srgb_encode, to_uint8

    centers = np.asarray(centers, float)
    radii = np.asarray(radii, float)
    sv, sf, sn, sid = _spheres_mesh(centers, radii)
    mv, mf = np.asarray(mesh.vertices, float), np.asarray(mesh.faces)
    mn = np.asarray(mesh.vertex_normals, float)
    panels = []
    for az in (azimuth, azimuth + 90.0):
        # frame the spheres and the mesh together
        camera = fit_camera(np.vstack([mv, sv]), elevation=np.radians(elevation),
                            azimuth=np.radians(az), aspect=width / height)
        light = camera.eye - camera.target
        light = light / np.linalg.norm(light)
        bg = np.broadcast_to(BACKGROUND, (height, width, 3))
        base, _ = rasterize(mv, mf, _shade(mn, MESH_GREY, light), camera, width, height,
                            background=bg)
        colors = _shade(sn, sphere_colors(len(centers))[sid], light)
        over, cover = rasterize(sv, sf, colors, camera, width, height,
                                background=np.zeros((height, width, 3)))
        a = SPHERE_ALPHA * cover[..., None]
        # ``over`` is already weighted by coverage at the edges (premultiplied)
        img = base * (1 - a) + SPHERE_ALPHA * over
        # outline every sphere's visible silhouette: where the front-most sphere id
        # changes between neighbouring pixels (ids are constant per sphere, so
        # their interpolation is exact away from edges)
        ids, _ = rasterize(sv, sf, sid[:, None] + 1.0, camera, width, height, supersample=1,
                           background=np.zeros((height, width, 1)))
        ids = np.rint(ids[..., 0])
        edge = np.zeros(ids.shape, dtype=bool)
        edge[:, 1:] |= ids[:, 1:] != ids[:, :-1]
        edge[1:, :] |= ids[1:, :] != ids[:-1, :]
        img[edge] = 0.6 * img[edge] + 0.4 * OUTLINE
        panels.append(to_uint8(srgb_encode(img)))
    return np.concatenate(panels, axis=1)


def write_spheres_glb(path: str | os.PathLike, mesh: trimesh.Trimesh, centers: np.ndarray,
                      radii: np.ndarray, *, mesh_name: str = "mesh") -> None:
    """GLB: the mesh plus one node per sphere (unit icosphere, translated and scaled)."""
    from shtools.export.gltf import _ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER, _Buffer

    ico = trimesh.creation.icosphere(subdivisions=3)
    buf = _Buffer()

    def prim(v, n, f, material):
        attrs = pygltflib.Attributes(
            POSITION=buf.add(np.asarray(v, np.float32), kind="VEC3", target=_ARRAY_BUFFER,
                             bounds=True),
            NORMAL=buf.add(np.asarray(n, np.float32), kind="VEC3", target=_ARRAY_BUFFER))
        idx = buf.add(np.asarray(f, np.uint32).reshape(-1), kind="SCALAR",
                      target=_ELEMENT_ARRAY_BUFFER, bounds=True)
        return pygltflib.Primitive(attributes=attrs, indices=idx, material=material)

    colors = sphere_colors(len(radii))
    materials = [pygltflib.Material(
        name="mesh", pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
            baseColorFactor=[*MESH_GREY.tolist(), 1.0], metallicFactor=0.0,
            roughnessFactor=0.8))]
    materials += [pygltflib.Material(
        name=f"sphere_{k}", alphaMode="BLEND", doubleSided=False,
        pbrMetallicRoughness=pygltflib.PbrMetallicRoughness(
            baseColorFactor=[*colors[k].tolist(), SPHERE_ALPHA], metallicFactor=0.0,
            roughnessFactor=0.6))
        for k in range(len(radii))]
    mesh_prim = prim(mesh.vertices, mesh.vertex_normals, mesh.faces, 0)
    unit = prim(ico.vertices, ico.vertex_normals, ico.faces, 1)
    meshes = [pygltflib.Mesh(name=mesh_name, primitives=[mesh_prim])]
    # one mesh per colour (glTF binds materials to meshes, not nodes), sharing the accessors
    for k in range(len(radii)):
        meshes.append(pygltflib.Mesh(name=f"sphere_{k}", primitives=[pygltflib.Primitive(
            attributes=unit.attributes, indices=unit.indices, material=1 + k)]))
    nodes = [pygltflib.Node(name=mesh_name, mesh=0)]
    nodes += [pygltflib.Node(name=f"sphere_{k}", mesh=1 + k,
                             translation=[float(x) for x in centers[k]],
                             scale=[float(radii[k])] * 3)
              for k in range(len(radii))]
    gltf = pygltflib.GLTF2(
        asset=pygltflib.Asset(generator="shtools spheres preview", version="2.0"),
        scene=0, scenes=[pygltflib.Scene(nodes=list(range(len(nodes))))],
        nodes=nodes, meshes=meshes, materials=materials, accessors=buf.accessors,
        bufferViews=buf.views, buffers=[pygltflib.Buffer(byteLength=len(buf.blob))])
    gltf.set_binary_blob(bytes(buf.blob))
    with atomic_path(path) as tmp:
        gltf.save_binary(str(tmp))
