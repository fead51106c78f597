r"""The traced shadow of a field light: the fraction of its emission each receiver sees.

Order-4 SH cannot hold the product of a compact lamp's radiance and a blocker's
visibility: the lamp covers a few degrees, the visibility's edge smears over
tens.  So, as the occlusion camera does for small spherical lights, the
blockers' shadow is taken out of SH: the receiver's unshadowed light from the
lamp (its RCV double-producted with its transfer, Tamura et al. Fig. 3) is
multiplied by

.. math::

    F(x) = \frac{\int L_e(x, \omega)\,V_B(x, \omega)\max(0, N\cdot\omega)\,d\omega}
                {\int L_e(x, \omega)\max(0, N\cdot\omega)\,d\omega},

the part of the lamp's emission that reaches ``x`` past the blockers ``B``.
``L_e`` is the emission the source radiance field samples: a ray carries it
when its nearest hit on the lamp's own triangles (emitter and fixture, stored
in the ``srf`` asset) is an emitter face seen from the front.  ``V_B`` is 1
when no blocker triangle lies between ``x`` and that hit, so only blockers
**nearer than the lamp** along the ray shadow it (the per-ray form of the
paper's distance sorting).

Both integrals use one stratified direction set per receiver: ``k x k``
strata of equal solid angle in the cone of the emitter's bounding sphere
(:func:`shtools.reference.light_fraction.cap_directions`), where all the
emission is; a receiver inside that sphere uses its upper hemisphere.  The
ratio shares its rays, so the noise of the estimate cancels where nothing
blocks (``F = 1`` exactly) and in a full umbra (``F = 0``).
"""

from __future__ import annotations

import numpy as np

from shtools.geometry.visibility import END_FRACTION, RAY_OFFSET

#: Widening of the emitter's bounding cone (the sphere is fitted to its vertices).
CONE_MARGIN = 1e-3
#: Receivers per batch (bounds the (B, k*k, 3) direction arrays).
BATCH = 4096


class LampCaster:
    """A lamp's triangles in its own frame, ready for emission queries.

    Parameters
    ----------
    vertices : array_like, shape (P, 3)
    faces : array_like, shape (F, 3)
    emissive : array_like of bool, shape (F,)
    emitter_center : array_like, shape (3,)
    emitter_radius : float
        Sphere bounding the emissive faces (lamp frame).
    """

    def __init__(self, vertices, faces, emissive, emitter_center, emitter_radius: float):
        from shtools.geometry.raycast import RayCaster

        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces, dtype=np.int64)
        self.caster = RayCaster(v, f)
        self.emissive = np.asarray(emissive, dtype=bool)
        cross = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        self.normals = cross / np.maximum(np.linalg.norm(cross, axis=1), 1e-300)[:, None]
        self.center = np.asarray(emitter_center, dtype=np.float64)
        self.radius = float(emitter_radius)

    def emission(self, origins, directions) -> tuple[np.ndarray, np.ndarray]:
        """Whether each lamp-frame ray gets the emitter's light, and where it hits.

        Returns
        -------
        lit : ndarray of bool, shape (R,)
        t : ndarray, shape (R,)
            Distance to the lamp hit (inf on a miss).
        """
        t, face = self.caster.first_hit(origins, directions)
        lit = face >= 0
        lit[lit] = self.emissive[face[lit]]
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        lit[lit] = np.einsum("ij,ij->i", self.normals[face[lit]], d[lit]) < 0
        return lit, t


class Blockers:
    """The posed blocker meshes of a frame: one caster and a bounding sphere per mesh.

    Parameters
    ----------
    meshes : list of (vertices (P_i, 3), faces (F_i, 3))
        World frame; meshes without faces are skipped.
    """

    def __init__(self, meshes):
        from shtools.geometry.raycast import RayCaster

        meshes = [(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64))
                  for v, f in meshes if len(f)]
        self.caster = None
        self.centers = np.zeros((0, 3))
        self.radii = np.zeros(0)
        if not meshes:
            return
        faces, base = [], 0
        for v, f in meshes:
            faces.append(f + base)
            base += len(v)
        self.caster = RayCaster(np.concatenate([v for v, _ in meshes]), np.concatenate(faces))
        used = [v[np.unique(f)] for v, f in meshes]
        self.centers = np.array([0.5 * (u.min(axis=0) + u.max(axis=0)) for u in used])
        self.radii = np.array([np.linalg.norm(u - c, axis=1).max() * (1 + CONE_MARGIN)
                               for u, c in zip(used, self.centers, strict=True)])

    def in_cone(self, points, axis, cos_alpha, length) -> np.ndarray:
        """``(V,)`` bool: some blocker's bounding sphere meets the cone from each point
        (unit ``axis``, half-angle ``acos(cos_alpha)``) within ``length`` of it."""
        hit = np.zeros(len(points), dtype=bool)
        sin_alpha = np.sqrt(np.maximum(1.0 - cos_alpha ** 2, 0.0))
        for c, r in zip(self.centers, self.radii, strict=True):
            rel = c - points
            d = np.linalg.norm(rel, axis=1)
            inside = d <= r
            cos_b = np.einsum("vi,vi->v", rel, axis) / np.maximum(d, 1e-300)
            # angle to the sphere's centre below alpha + its angular radius
            sin_r = np.minimum(r / np.maximum(d, 1e-300), 1.0)
            cos_r = np.sqrt(1.0 - sin_r ** 2)
            cos_limit = cos_alpha * cos_r - sin_alpha * sin_r
            hit |= inside | ((cos_b >= cos_limit) & (d - r < length))
        return hit


def emission_visible_fraction(lamp: LampCaster, rotation, translation, scale: float,
                              blockers, points, normals, *, n_samples: int = 64,
                              seed: int = 0) -> np.ndarray:
    """Fraction ``F`` of a posed lamp's emission each receiver sees past the blockers.

    Parameters
    ----------
    lamp : LampCaster
    rotation : array_like, shape (3, 3)
        Lamp-to-world rotation.
    translation : array_like, shape (3,)
    scale : float
        Uniform lamp scale.
    blockers : Blockers or None
        The posed blocker meshes (world frame); None: nothing blocks.  Only
        receivers whose cone toward the lamp meets a blocker's bounding sphere
        cast rays; the others see all of it (``F = 1``).
    points, normals : array_like, shape (V, 3)
        Receivers (world) and their unit normals.
    n_samples : int
        Strata per receiver (rounded down to a square ``k * k``).
    seed : int
        The jitter pattern, shared by every receiver and frame.

    Returns
    -------
    ndarray, shape (V,)
        In [0, 1]; 1 where no stratum reaches the emitter (nothing to shadow).
    """
    from shtools.reference.light_fraction import cap_directions

    R = np.asarray(rotation, dtype=np.float64).reshape(3, 3)
    tr = np.asarray(translation, dtype=np.float64).reshape(3)
    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    out = np.ones(x.shape[0])
    if blockers is None or blockers.caster is None:
        return out
    center = R @ lamp.center * scale + tr
    radius = lamp.radius * scale * (1 + CONE_MARGIN)
    rel = center - x
    dist = np.linalg.norm(rel, axis=1)
    inside = dist <= radius
    axis = np.where(inside[:, None], nrm, rel / np.maximum(dist, 1e-300)[:, None])
    alpha = np.where(inside, np.pi / 2,
                     np.arcsin(np.minimum(radius / np.maximum(dist, 1e-300), 1.0)))
    rows = np.flatnonzero(blockers.in_cone(x, axis, np.cos(alpha), dist + radius))
    offset = RAY_OFFSET * blockers.caster.diagonal
    for s in range(0, rows.size, BATCH):
        b = rows[s:s + BATCH]
        xs, ns = x[b], nrm[b]
        dirs = cap_directions(axis[b], alpha[b], n_samples, np.random.default_rng(seed))
        cos = np.einsum("bki,bi->bk", dirs, ns)
        bi, ki = np.nonzero(cos > 0)
        origin = xs[bi] + offset * ns[bi]
        d = dirs[bi, ki]
        # the lamp is queried in its own frame: its BVH is built once per bake
        lit, t_local = lamp.emission((origin - tr) @ R / scale, d @ R)
        w = np.zeros(cos.shape)
        w[bi[lit], ki[lit]] = cos[bi[lit], ki[lit]]
        free = np.zeros(cos.shape)
        if lit.any():
            hit_t = t_local[lit] * scale
            ok = ~blockers.caster.occluded(origin[lit], d[lit],
                                           t_far=hit_t * (1 - END_FRACTION))
            free[bi[lit][ok], ki[lit][ok]] = cos[bi[lit][ok], ki[lit][ok]]
        den = w.sum(axis=1)
        out[b] = np.where(den > 0, free.sum(axis=1) / np.maximum(den, 1e-300), 1.0)
    return out
