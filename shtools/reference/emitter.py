r"""Ray-traced direct light of an emissive mesh (the ground truth of source radiance fields).

Not a field, not SH: the emissive triangles are sampled by area (stratified
over triangles in proportion to their area, uniform within each), and every
receiver ``x`` with normal ``N`` gathers

.. math::

    R(x) = \frac1\pi \frac{A}{S} \sum_k L\,V(x, y_k)
           \frac{\max(0, N\cdot\omega_k)\max(0, -n_k\cdot\omega_k)}{|y_k - x|^2},
    \qquad \omega_k = \frac{y_k - x}{|y_k - x|},

the white-Lambertian outgoing radiance of docs/conventions.md ("Light and
radiance"), with a shadow ray from ``x`` (offset along ``N`` against
self-hits) to just short of ``y_k`` through the **real meshes**: the blockers,
the lamp's fixture and the emitter itself (so one part of a bulb hides another).
"""

from __future__ import annotations

import numpy as np

from shtools.geometry.visibility import END_FRACTION, RAY_OFFSET


def area_samples(vertices, faces, n_samples: int, seed: int = 0
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """Points on triangles, stratified by area: positions ``(S, 3)``, face ids ``(S,)``, area.

    Each triangle gets ``n_samples * area / total`` samples rounded by
    systematic sampling of the cumulative area (every triangle within one
    sample of its share), uniform barycentric positions inside it.
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    total = float(area.sum())
    rng = np.random.default_rng(seed)
    cum = np.cumsum(area) / total
    u = (np.arange(n_samples) + rng.random()) / n_samples
    face = np.minimum(np.searchsorted(cum, u, side="right"), len(f) - 1)
    r1, r2 = rng.random(n_samples), rng.random(n_samples)
    s = np.sqrt(r1)
    pts = (1 - s)[:, None] * a[face] + (s * (1 - r2))[:, None] * b[face] \
        + (s * r2)[:, None] * c[face]
    return pts, face, total


def emitter_radiance(points, normals, emitter_vertices, emitter_faces, emissive, radiance,
                     occluders, *, n_samples: int = 4096, seed: int = 0) -> np.ndarray:
    """Ray-traced outgoing radiance of receivers lit by an emissive mesh, shape ``(V, 3)``.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
        Receivers (unit normals).
    emitter_vertices : array_like, shape (P, 3)
        The lamp's vertices in the world (emitter and fixture).
    emitter_faces : array_like, shape (F, 3)
    emissive : array_like of bool, shape (F,)
    radiance : array_like, shape (3,)
        RGB radiance of the emitter's front side (the side its normals face).
    occluders : list of (vertices (Pb, 3), faces (Fb, 3))
        Blocker meshes in the world (the lamp itself is added).
    n_samples : int
        Area samples on the emitter (shared by every receiver).
    seed : int
    """
    from shtools.geometry.raycast import RayCaster

    x = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    ev = np.asarray(emitter_vertices, dtype=np.float64)
    ef = np.asarray(emitter_faces, dtype=np.int64)
    em = np.flatnonzero(np.asarray(emissive, dtype=bool))
    y, face, area = area_samples(ev, ef[em], n_samples, seed)
    tri = ev[ef[em]]
    n_face = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n_face /= np.linalg.norm(n_face, axis=1, keepdims=True)
    ny = n_face[face]
    verts, faces, base = [ev], [ef], len(ev)
    for v, f in occluders:
        verts.append(np.asarray(v, dtype=np.float64))
        faces.append(np.asarray(f, dtype=np.int64) + base)
        base += len(v)
    caster = RayCaster(np.concatenate(verts), np.concatenate(faces))
    offset = RAY_OFFSET * caster.diagonal
    out = np.zeros(x.shape[0])
    step = max(1, (1 << 20) // n_samples)
    for s in range(0, x.shape[0], step):
        xs, ns = x[s:s + step], nrm[s:s + step]
        delta = y[None, :, :] - xs[:, None, :]  # (B, S, 3)
        dist = np.linalg.norm(delta, axis=2)
        w = delta / dist[:, :, None]
        cos_x = np.einsum("bsi,bi->bs", w, ns)
        cos_y = -np.einsum("bsi,si->bs", w, ny)
        live = (cos_x > 0) & (cos_y > 0)
        bi, si = np.nonzero(live)
        contrib = np.zeros(live.shape)
        if bi.size:
            origin = xs[bi] + offset * ns[bi]
            seg = y[si] - origin
            length = np.linalg.norm(seg, axis=1)
            blocked = caster.occluded(origin, seg / length[:, None],
                                      t_far=length * (1 - END_FRACTION))
            ok = ~blocked
            contrib[bi[ok], si[ok]] = (cos_x[bi[ok], si[ok]] * cos_y[bi[ok], si[ok]]
                                       / dist[bi[ok], si[ok]] ** 2)
        out[s:s + step] = contrib.sum(axis=1)
    return (out * area / (n_samples * np.pi))[:, None] * np.asarray(radiance, float)[None, :]



def shadowed_and_free(points, normals, emitter, emitter_vertices, occluders, *,
                      n_samples: int = 4096) -> tuple[np.ndarray, np.ndarray]:
    """:func:`emitter_radiance` of a lamp with the occluders and without them.

    Parameters
    ----------
    points, normals : array_like, shape (V, 3)
    emitter
        The lamp: its ``faces``, ``emissive`` flags and ``radiance``.
    emitter_vertices : array_like, shape (P, 3)
        The lamp's vertices in the world.
    occluders : list of (vertices (Pb, 3), faces (Fb, 3))
    n_samples : int

    Returns
    -------
    shadowed, free : ndarray, shape (V, 3)
        The same area samples (the default seed) light both.
    """
    shadowed = emitter_radiance(points, normals, emitter_vertices, emitter.faces,
                                emitter.emissive, emitter.radiance, occluders,
                                n_samples=n_samples)
    free = emitter_radiance(points, normals, emitter_vertices, emitter.faces, emitter.emissive,
                            emitter.radiance, [], n_samples=n_samples)
    return shadowed, free

def shaded_lamp(bulb_radius: float = 0.13, shade_radii=(0.32, 0.14), shade_z=(-0.2, 0.15),
                sections: int = 48, subdivisions: int = 2):
    """A procedural shaded lamp (tests, benchmarks): a closed bulb inside an open conical shade.

    The bulb is an icosphere about the origin; the shade a truncated cone about
    ``+z``, open at both ends, wider at the bottom (``z = shade_z[0]``), so most
    light leaves downward (``-z``) and a narrower beam upward.

    Returns
    -------
    bulb, shade : trimesh.Trimesh
    """
    import trimesh

    a = np.linspace(0, 2 * np.pi, sections, endpoint=False)
    rings = [np.c_[r * np.cos(a), r * np.sin(a), np.full(sections, z)]
             for r, z in zip(shade_radii, shade_z, strict=True)]
    faces = []
    for i in range(sections):
        j = (i + 1) % sections
        faces += [[i, j, sections + j], [i, sections + j, sections + i]]
    shade = trimesh.Trimesh(np.vstack(rings), np.array(faces), process=False)
    bulb = trimesh.creation.icosphere(subdivisions, radius=bulb_radius)
    return bulb, shade
