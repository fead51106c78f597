"""Batched ray casting against triangle meshes (Embree, via embreex).

One place for every ray query of the project: the ray-traced references, shadow
field sampling, deformable fields and precomputed self-visibility all call
:class:`RayCaster`.  It wraps an ``embreex`` scene directly (trimesh's
``RayMeshIntersector`` does the same but only exposes the slower ``INTERSECT``
query): ``OCCLUDED`` queries stop at the first hit found, which is what binary
visibility needs.

Embree works in float32.  The geometry is translated to its bounding-box
minimum and scaled to a unit diagonal before it is handed over (as trimesh
does), so the float32 resolution is relative to the mesh size and the same
code works for a mesh of size 1e-6 or 1e6.
"""

from __future__ import annotations

import numpy as np

#: Rays per call into Embree (bounds the float32 copies to ~50 MiB).
RAY_CHUNK = 1 << 21


class RayCaster:
    """Occlusion and first-hit queries against one triangle soup.

    Parameters
    ----------
    vertices : array_like, shape (P, 3)
    faces : array_like, shape (F, 3), integer
    robust : bool
        Embree's robust (watertight) traversal, embreex's default: no ray slips
        between two triangles sharing an edge.  Off, traversal is faster
        (``benchmarks/bench_fidelity.py --skinned`` measures it) and a ray may
        rarely miss through an edge; the per-frame traced self-visibility turns it off (its 32 rays
        per vertex carry far more quadrature error than such misses).

    Examples
    --------
    >>> import trimesh
    >>> sphere = trimesh.creation.icosphere(3)
    >>> rc = RayCaster(sphere.vertices, sphere.faces)
    >>> rc.occluded([[-3, 0, 0], [-3, 0, 0]], [[1, 0, 0], [-1, 0, 0]]).tolist()
    [True, False]
    """

    def __init__(self, vertices, faces, *, robust: bool = True):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
            raise ValueError("RayCaster needs vertices (P, 3) and at least one face (F, 3)")
        self.origin = v.min(axis=0)
        diagonal = float(np.linalg.norm(v.max(axis=0) - self.origin))
        #: Bounding-box diagonal of the geometry (world units).
        self.diagonal = diagonal
        #: World units -> Embree units (unit bounding-box diagonal).
        self.scale = 1.0 / diagonal if diagonal > 0 else 1.0
        self._scene = rtcore_scene.EmbreeScene(robust=bool(robust))
        # Embree keeps a reference to these buffers: hold them for the scene's lifetime.
        self._vertices = ((v - self.origin) * self.scale).astype(np.float32)
        self._faces = np.ascontiguousarray(f, dtype=np.int32)
        TriangleMesh(scene=self._scene, vertices=self._vertices, indices=self._faces)

    @classmethod
    def from_meshes(cls, meshes) -> RayCaster:
        """Caster over the union of ``trimesh.Trimesh`` objects (or one mesh)."""
        if not isinstance(meshes, list | tuple):
            meshes = [meshes]
        vertices, faces, base = [], [], 0
        for mesh in meshes:
            vertices.append(np.asarray(mesh.vertices, dtype=np.float64))
            faces.append(np.asarray(mesh.faces, dtype=np.int64) + base)
            base += len(mesh.vertices)
        return cls(np.concatenate(vertices), np.concatenate(faces))

    @classmethod
    def deferred(cls, vertices, faces, *, robust: bool = True) -> DeferredCaster:
        """A caster built on its first use (:class:`DeferredCaster`)."""
        return DeferredCaster(vertices, faces, robust=robust)

    def _prepare(self, origins, directions):
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        if o.shape != d.shape:
            o, d = np.broadcast_arrays(o, d)
        return o, d

    def occluded(self, origins, directions, t_far=None) -> np.ndarray:
        """Whether each ray hits any triangle.

        Parameters
        ----------
        origins, directions : array_like, shape (R, 3)
            Ray origins and directions (need not be unit; ``t_far`` is in units
            of the direction's length).
        t_far : float or array_like of shape (R,), optional
            Ignore hits beyond this parameter (default: unbounded).

        Returns
        -------
        ndarray of bool, shape (R,)
        """
        o, d = self._prepare(origins, directions)
        out = np.empty(o.shape[0], dtype=bool)
        far = None if t_far is None else np.broadcast_to(
            np.asarray(t_far, dtype=np.float64), (o.shape[0],))
        for s in range(0, o.shape[0], RAY_CHUNK):
            oo = ((o[s:s + RAY_CHUNK] - self.origin) * self.scale).astype(np.float32)
            dd = d[s:s + RAY_CHUNK].astype(np.float32)
            kwargs = {}
            if far is not None:
                # A world parameter t is t * scale in the scaled frame (origins
                # scaled, directions not).
                t_scaled = np.minimum(far[s:s + RAY_CHUNK] * self.scale, 1e30)
                kwargs["dists"] = t_scaled.astype(np.float32)
            # OCCLUDED returns 0 for a blocked ray and -1 for a free one.
            out[s:s + RAY_CHUNK] = self._scene.run(oo, dd, query="OCCLUDED", **kwargs) == 0
        return out

    def embree_points(self, points) -> np.ndarray:
        """Points in Embree's scaled float32 frame, ``(P, 3)``, for :meth:`occluded_embree`."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return ((p - self.origin) * self.scale).astype(np.float32)

    def occluded_embree(self, origins, directions) -> np.ndarray:
        """:meth:`occluded` for rays already in Embree's frame (no conversion pass).

        Parameters
        ----------
        origins : ndarray of float32, shape (R, 3)
            From :meth:`embree_points` (C-contiguous).
        directions : ndarray of float32, shape (R, 3)
            Unit directions (unchanged by the frame's uniform scale).

        Returns
        -------
        ndarray of bool, shape (R,)
            True where the ray hits a triangle.
        """
        out = np.empty(origins.shape[0], dtype=bool)
        for s in range(0, origins.shape[0], RAY_CHUNK):
            out[s:s + RAY_CHUNK] = self._scene.run(origins[s:s + RAY_CHUNK],
                                                   directions[s:s + RAY_CHUNK],
                                                   query="OCCLUDED") == 0
        return out

    def first_hit(self, origins, directions) -> tuple[np.ndarray, np.ndarray]:
        """Nearest hit along each ray.

        Parameters
        ----------
        origins, directions : array_like, shape (R, 3)

        Returns
        -------
        t : ndarray, shape (R,)
            Ray parameter of the hit (distance when directions are unit); inf on a miss.
        face : ndarray of int, shape (R,)
            Index of the hit triangle, -1 on a miss.
        """
        o, d = self._prepare(origins, directions)
        t = np.full(o.shape[0], np.inf)
        face = np.full(o.shape[0], -1, dtype=np.int64)
        for s in range(0, o.shape[0], RAY_CHUNK):
            oo = ((o[s:s + RAY_CHUNK] - self.origin) * self.scale).astype(np.float32)
            dd = d[s:s + RAY_CHUNK].astype(np.float32)
            res = self._scene.run(oo, dd, output=1)
            hit = res["primID"] >= 0
            # tfar is in the scaled frame; the direction was not scaled.
            t[s:s + RAY_CHUNK][hit] = res["tfar"][hit] / self.scale
            face[s:s + RAY_CHUNK] = res["primID"]
        return t, face

    def visibility(self, points, directions, *, normals=None, offset: float = 0.0,
                   mask=None, t_far: float | None = None) -> np.ndarray:
        """Binary visibility of points over a shared direction set.

        Parameters
        ----------
        points : array_like, shape (V, 3)
        directions : array_like, shape (Q, 3)
            Unit directions.
        normals : array_like, shape (V, 3), optional
            With normals, directions with ``s . N <= 0`` are not cast and count
            as visible (the convention of :mod:`shtools.reference.raytrace`),
            and origins are moved ``offset`` along the normal.
        offset : float
            Origin offset (world units) along the normal, against self-hits.
        mask : array_like of bool, shape (V, Q), optional
            Only these (point, direction) pairs are cast; the others count as
            visible (e.g. directions outside an object's bounding cone).
        t_far : float, optional
            Only hits closer than this (world units) occlude (local visibility).

        Returns
        -------
        ndarray of bool, shape (V, Q)
            True where the direction is unoccluded.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        dirs = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        vis = np.ones((p.shape[0], dirs.shape[0]), dtype=bool)
        nrm = None if normals is None else np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        step = max(1, RAY_CHUNK // max(dirs.shape[0], 1))
        for s in range(0, p.shape[0], step):
            cast = np.ones((min(step, p.shape[0] - s), dirs.shape[0]), dtype=bool)
            if nrm is not None:
                cast &= nrm[s:s + step] @ dirs.T > 0
            if mask is not None:
                cast &= np.asarray(mask[s:s + step], dtype=bool)
            vi, qi = np.nonzero(cast)
            if vi.size == 0:
                continue
            origins = p[s + vi]
            if nrm is not None and offset:
                origins = origins + offset * nrm[s + vi]
            blocked = self.occluded(origins, dirs[qi], t_far=t_far)
            vis[s + vi[blocked], qi[blocked]] = False
        return vis


class DeferredCaster:
    """A :class:`RayCaster` of the given triangles, built when a query first needs it.

    Building an Embree scene costs as much as tracing a few hundred thousand rays; a
    caster whose results may all come from the set-up cache
    (:func:`shtools.scene.traced_shadows.traced_ground` of a still object) is only
    built on a miss.  Every attribute of :class:`RayCaster` is forwarded.
    """

    def __init__(self, vertices, faces, *, robust: bool = True):
        self._args = (vertices, faces, bool(robust))
        self._caster: RayCaster | None = None

    def __getattr__(self, name: str):
        if name.startswith("_"):  # (pickling, copying: not the caster's)
            raise AttributeError(name)
        if self._caster is None:
            vertices, faces, robust = self._args
            self._caster = RayCaster(vertices, faces, robust=robust)
        return getattr(self._caster, name)

