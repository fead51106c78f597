r"""Log-space accumulation of sphere blockers at receiver points (eqs. 34 and 38).

For every receiver ``p`` and every sphere ``(P, r)`` of its list, with
:math:`d = |P - p|` and :math:`s = (P - p)/d`,

.. math::

    \mathbf f(p) \mathrel{+}= \mathbf W\,\mathbf F(\theta)\,\mathbf y(s),
    \qquad \sin\theta = r/d,

where ``W`` holds per-band ratio weights (eq. 38; ones for leaf spheres).

The kernel works in float32 on blocks laid out ``(S, K, T)`` — spheres x
tiles x receivers per tile (each tile has its own sphere list) — one array pass
per operation, in place, with scratch buffers kept between calls:

* no arcsin: the table is indexed by :math:`x = 1 - \cos\theta = 1 - \sqrt{1 - r^2/d^2}`,
  and each band is one gather of the ratio :math:`F_l(x)/x` times ``x``
  (:mod:`shtools.runtime.log_table`);
* the self-shadow rules (:mod:`shtools.runtime.self_shadow`) run on the
  leading ``rule_rows`` spheres only when the caller knows the others are in
  front of every receiver (:mod:`shtools.runtime.tiling`), on the gathered
  subset of pairs whose sphere straddles the tangent plane, or over those
  rows when that subset is large (receivers on the blocker itself);
* the SH basis is built by the Legendre/complex-power recurrence of
  :mod:`shtools.sh.basis`, and each coefficient is reduced over the spheres at
  once (``einsum("sr,sr->r")`` along contiguous receivers; zonal terms
  without forming the product), so the per-pair ``n*n`` vectors are never
  formed; the normalisation is applied per vertex.
"""

from __future__ import annotations

import numpy as np

from shtools.runtime.log_table import CapLogTable
from shtools.runtime.self_shadow import apply_self_shadow_rules, apply_self_shadow_rules_inplace
from shtools.sh.basis import double_factorial, legendre_recurrence, normalisation

#: d^2 floor (scene units^2): guards 1/d for a zero-radius sphere at the receiver.
MIN_DIST2 = 1e-20
#: Above this fraction of straddling pairs in a block the self-shadow rules run
#: over the whole block instead of gathering the straddling subset.
FULL_BLOCK_RULES_FRACTION = 0.1


def accumulate_log(points, normals, centers, radii, table: CapLogTable, *, weights=None,
                   self_shadow: bool = True, chunk_pairs: int = 1 << 15,
                   out: np.ndarray | None = None, kernel: BlockKernel | None = None
                   ) -> np.ndarray:
    """Sum of sphere log-visibility vectors at each receiver (float32), one sphere list.

    Parameters
    ----------
    points : array_like, shape (V, 3)
        Receiver positions.
    normals : array_like, shape (V, 3)
        Unit receiver normals (used by the self-shadow rules).
    centers : array_like, shape (S, 3)
        Sphere centres (the same list for every receiver).
    radii : array_like, shape (S,)
        Sphere radii; radius 0 contributes nothing.
    table : CapLogTable
        Cap log table of order ``n`` (the accumulation order).
    weights : array_like, shape (S, n), optional
        Per-band ratio weights ``w_l`` of eq. 38 (default ones).
    self_shadow : bool
        Apply the Sec. 6.2 rules.
    chunk_pairs : int
        Pairs per block (memory ~ ``(20 + n) * 4 * chunk_pairs`` bytes).
    out : ndarray, shape (V, n*n), optional
        float32 destination; the sums are *added* to it when given.
    kernel : BlockKernel, optional
        Reused kernel (keeps scratch buffers between calls).

    Returns
    -------
    ndarray, shape (V, n*n) float32
    """
    order = table.order
    pts = np.asarray(points, dtype=np.float32)
    nrm = np.asarray(normals, dtype=np.float32)
    cen = np.asarray(centers, dtype=np.float32)
    rad = np.asarray(radii, dtype=np.float32)
    n_v, n_s = pts.shape[0], cen.shape[0]
    if out is None:
        out = np.zeros((n_v, order * order), dtype=np.float32)
    if n_v == 0 or n_s == 0:
        return out
    w = None if weights is None else np.asarray(weights, dtype=np.float32)[None]
    step = max(1, chunk_pairs // n_s)
    if kernel is None or kernel.table is not table:
        kernel = BlockKernel(table)
    for start in range(0, n_v, step):
        stop = min(n_v, start + step)
        sel, rule_rows = _chunk_spheres(pts[start:stop], nrm[start:stop], cen, rad, self_shadow)
        if sel.size == 0:
            continue
        out[start:stop] += accumulate_blocks(
            pts[None, start:stop], nrm[None, start:stop], cen[None, sel], rad[None, sel], table,
            weights=None if w is None else w[:, sel], self_shadow=self_shadow, kernel=kernel,
            rule_rows=rule_rows)[0]
    return out


def _chunk_spheres(pts, nrm, cen, rad, self_shadow: bool) -> tuple[np.ndarray, int]:
    """Spheres a chunk of receivers needs, those needing the self-shadow rules first.

    Spheres behind the tangent plane of every receiver are dropped (rule 1 of
    Sec. 6.2 removes them); those in front of every plane need no rules.

    Returns
    -------
    sel : ndarray of int
        Sphere indices (rules first, then in front).
    rule_rows : int
        Leading entries of ``sel`` that may straddle or be behind a plane.
    """
    if not self_shadow:
        return np.arange(cen.shape[0]), 0
    h = nrm @ cen.T  # (V, S): N . P - N . p
    h -= np.einsum("vi,vi->v", pts, nrm)[:, None]
    behind = h.max(axis=0) <= -rad
    front = h.min(axis=0) >= rad
    key = np.where(behind, 2, np.where(front, 1, 0))
    sel = np.argsort(key, kind="stable")[: int(np.count_nonzero(~behind))]
    return sel, int(np.count_nonzero(key == 0))


def accumulate_blocks(points, normals, centers, radii, table: CapLogTable, *, weights=None,
                      self_shadow: bool = True, kernel: BlockKernel | None = None,
                      rule_rows: int | None = None) -> np.ndarray:
    """Log-visibility sums for ``K`` tiles of receivers, each with its own sphere list.

    Parameters
    ----------
    points, normals : ndarray, shape (K, T, 3) float32
        ``T`` receivers per tile.
    centers : ndarray, shape (K, S, 3) float32
        Sphere list of each tile (pad with radius-0 spheres).
    radii : ndarray, shape (K, S) float32
    table : CapLogTable
        Log table of the accumulation order ``n``.
    weights : ndarray, shape (K, S, n) float32, optional
        Per-band ratio weights (eq. 38).
    self_shadow : bool
        Apply the Sec. 6.2 rules.
    kernel : BlockKernel, optional
        Reused kernel (keeps its scratch buffers between calls).
    rule_rows : int, optional
        Only the first ``rule_rows`` spheres of each list can be behind or
        straddle a receiver's tangent plane (the others are in front of every
        receiver of their tile); the self-shadow rules skip the rest.  Default:
        all.

    Returns
    -------
    ndarray, shape (K, T, n*n) float32
    """
    if kernel is None or kernel.table is not table:
        kernel = BlockKernel(table)
    return kernel.run(np.asarray(points, np.float32), np.asarray(normals, np.float32),
                      np.asarray(centers, np.float32), np.asarray(radii, np.float32),
                      None if weights is None else np.asarray(weights, np.float32), self_shadow,
                      rule_rows)


#: Scratch arrays of the kernel (each ``K*T*S`` float32); bands need ``n`` more.
_N_SCRATCH = 12


class BlockKernel:
    """Accumulation over blocks of ``(K, T, S)`` pairs, every op in place.

    Scratch buffers are kept between calls: allocating fresh multi-100-KB arrays
    per block costs page faults (system time) comparable to the arithmetic.
    """

    def __init__(self, table: CapLogTable):
        self.order = table.order
        self.table = table
        self.norm = normalisation(self.order).astype(np.float32)
        self._gammas, self._coef = _recurrence_constants(self.order, self.norm)
        self._scratch = np.empty((_N_SCRATCH + self.order, 0), np.float32)
        # intp indices: np.take of 8-byte items with int32 indices spread over
        # the table takes a slow path (NumPy 2)
        self._idx = np.empty(0, np.intp)
        self._idx32 = np.empty(0, np.int32)
        self._sums = np.empty((self.order * self.order, 0), np.float32)
        self._masks = np.empty((2, 0), np.bool_)

    def _buffers(self, shape):
        size = int(np.prod(shape))
        if self._scratch.shape[1] < size:
            self._scratch = np.empty((_N_SCRATCH + self.order, size), np.float32)
            self._idx = np.empty(size, np.intp)
            self._idx32 = np.empty(size, np.int32)
        # one view of them all, split along its first axis (cheaper than a reshape each)
        views = list(self._scratch[:, :size].reshape(self._scratch.shape[0], *shape))
        return views, self._idx[:size].reshape(shape)

    def _bools(self, shape):
        size = int(np.prod(shape))
        if self._masks.shape[1] < size:
            self._masks = np.empty((2, size), np.bool_)
        return [self._masks[i, :size].reshape(shape) for i in range(2)]

    def run(self, pts, nrm, cen, rad, w, self_shadow, rule_rows=None):
        # Layout (S, K, T): spheres outermost, so the final reduction over the
        # spheres runs along contiguous rows of receivers (several times faster
        # in NumPy than reducing short rows of S).
        n_k, n_t, _ = pts.shape
        n_s = cen.shape[1]
        shape = (n_s, n_k, n_t)
        views, idx = self._buffers(shape)
        dx, dy, dz, r, t0, t1, t2, t3 = views[:8]
        extra = views[8:_N_SCRATCH]
        bands = views[_N_SCRATCH:]
        # contiguous components: NumPy broadcasts them in far fewer, longer inner
        # loops than strided views of the (..., 3) arrays
        for out, k in ((dx, 0), (dy, 1), (dz, 2)):
            np.subtract(np.ascontiguousarray(cen[:, :, k].T)[:, :, None],
                        np.ascontiguousarray(pts[:, :, k])[None], out=out)
        r[...] = np.ascontiguousarray(rad.T)[:, :, None]
        n_r = n_s if rule_rows is None else min(n_s, int(rule_rows))
        if self_shadow and n_r:
            # the rules on the sphere rows that may be behind or straddle (a
            # contiguous prefix of the (S, K, T) layout)
            pdx, pdy, pdz, pr = dx[:n_r], dy[:n_r], dz[:n_r], r[:n_r]
            h, a1, a2, a3 = t0[:n_r], t1[:n_r], t2[:n_r], t3[:n_r]
            nx, ny, nz = (np.ascontiguousarray(nrm[:, :, k])[None] for k in range(3))
            # h = (P - p) . N
            np.multiply(pdx, nx, out=h)
            np.multiply(pdy, ny, out=a1)
            h += a1
            np.multiply(pdz, nz, out=a1)
            h += a1
            bools = [b[:n_r] for b in self._bools(shape)]
            np.abs(h, out=a1)
            straddle = np.less(a1, pr, out=bools[1])  # straddling the plane (or p inside)
            count = int(np.count_nonzero(straddle))
            if count > FULL_BLOCK_RULES_FRACTION * pr.size:
                apply_self_shadow_rules_inplace(pdx, pdy, pdz, pr, h, nx, ny, nz,
                                                (a1, a2, a3, *(e[:n_r] for e in extra[:2])),
                                                (bools[0], bools[1]))
            else:
                np.negative(pr, out=a1)
                np.copyto(pr, 0.0, where=np.less_equal(h, a1, out=bools[0]))  # behind
                if count:
                    sel = np.flatnonzero(straddle)
                    rows = sel % (n_k * n_t)
                    nflat = nrm.reshape(-1, 3)
                    ndx, ndy, ndz, nr = apply_self_shadow_rules(
                        pdx.ravel()[sel], pdy.ravel()[sel], pdz.ravel()[sel], pr.ravel()[sel],
                        nflat[rows, 0], nflat[rows, 1], nflat[rows, 2])
                    pdx.ravel()[sel] = ndx
                    pdy.ravel()[sel] = ndy
                    pdz.ravel()[sel] = ndz
                    pr.ravel()[sel] = nr
        # inverse distance and unit direction (x, y, z overwrite dx, dy, dz)
        d2, inv = t0, t1
        np.multiply(dx, dx, out=d2)
        np.multiply(dy, dy, out=t2)
        d2 += t2
        np.multiply(dz, dz, out=t2)
        d2 += t2
        np.maximum(d2, MIN_DIST2, out=d2)
        np.sqrt(d2, out=inv)
        np.reciprocal(inv, out=inv)
        x, y, z = dx, dy, dz
        x *= inv
        y *= inv
        z *= inv
        # 1 - cos(theta) = 1 - sqrt(1 - (r/d)^2)
        u = r
        u *= inv
        np.multiply(u, u, out=u)
        np.subtract(1.0, u, out=u)
        np.maximum(u, 0.0, out=u)
        np.sqrt(u, out=u)
        np.subtract(1.0, u, out=u)
        self._lookup(u, bands, t0, idx)
        if w is not None:
            for l in range(self.order):
                bands[l] *= w[:, :, l].T[:, :, None]
        flat = (n_s, n_k * n_t)
        # (cos, sin) pairs of (x + i y)^m in adjacent scratch rows, reduced by one
        # einsum each: x, y; the recurrence's pair; its next pair
        size = n_s * n_k * n_t
        pairs = [self._scratch[i:i + 2, :size].reshape(2, *flat) for i in (0, 4, 10)]
        if self._sums.shape[1] < n_k * n_t:
            self._sums = np.empty((self.order * self.order, n_k * n_t), np.float32)
        sums = self._sums[:, :n_k * n_t]
        self._accumulate([b.reshape(flat) for b in bands], z.reshape(flat), pairs,
                         t2.reshape(flat), [a.reshape(flat) for a in (t3, *extra[:2])], sums)
        # scaled column by column into receiver-major rows: several times faster
        # than NumPy's copy of the transposed (n*n, R) array
        out = np.empty((n_k * n_t, self.order * self.order), np.float32)
        np.multiply(sums.T, self._coef, out=out)
        return out.reshape(n_k, n_t, -1)

    def _lookup(self, u, bands, cell, idx):
        """``bands[l] = u * G_l(cell of u)`` (the ratio table; no interpolation)."""
        tbl = self.table
        np.multiply(u, tbl.ratio_cells, out=cell)
        # truncation == floor since >= 0; through int32, which NumPy converts to
        # from float32 several times faster than to intp
        idx32 = self._idx32[:idx.size].reshape(idx.shape)
        np.copyto(idx32, cell, casting="unsafe")
        np.copyto(idx, idx32)
        for l in range(self.order):
            # 0 <= u <= 1 and the table has a cell for u = 1, so every index is in
            # range; "wrap" (a no-op here) gathers straight into ``out`` without a
            # buffer copy, as "clip" does, and faster
            np.take(tbl.ratios[l], idx, out=bands[l], mode="wrap")
            bands[l] *= u

    def _accumulate(self, bands, z, pairs, prod, q_buf, sums):
        """sums[lm] = sum_s bands[l] * R_lm(z) * Re/Im (x + i y)^m (unscaled: see _coef).

        ``pairs``: ``(2, S, R)`` views holding (x, y) and the two scratch pairs of
        the complex power recurrence; ``sums``: ``(n*n, R)``.
        """
        order = self.order
        xy, cs, cs_new = pairs
        x, y = xy
        for m in range(order):
            if m == 1:
                cs = xy  # read only: m = 2 writes into the scratch pairs
            elif m > 1:
                # (c + i s) * (x + i y)
                c_m, s_m = cs
                c_new, s_new = cs_new
                np.multiply(c_m, x, out=c_new)
                np.multiply(s_m, y, out=prod)
                c_new -= prod
                np.multiply(c_m, y, out=s_new)
                np.multiply(s_m, x, out=prod)
                s_new += prod
                if m == 2:
                    cs, cs_new = cs_new, pairs[1]
                else:
                    cs, cs_new = cs_new, cs
            # Q_lm = sigma_l R_l with sigma_l = a_l sigma_{l-1}, so the recurrence
            # Q_l = a_l z Q_{l-1} - c_l Q_{l-2} becomes R_l = z R_{l-1} - gamma_l
            # R_{l-2} (one pass fewer) and sigma_l joins the per-coefficient scale
            q_prev2 = q_prev1 = None
            for l, gamma in self._gammas[m]:
                if l == m:
                    q = None  # R_m = 1
                elif l == m + 1:
                    q = z  # R_{m+1} = z (read only)
                else:
                    q = q_buf[l % 3]
                    np.multiply(z, q_prev1, out=q)
                    if q_prev2 is None:  # R_m = 1
                        q -= gamma
                    else:
                        np.multiply(q_prev2, gamma, out=prod)
                        q -= prod
                base = l * l + l
                # reductions over the spheres (axis 0), the per-pair products formed
                # inside einsum only (one pass over its operands, no temporaries)
                if m == 0:
                    if q is None:
                        np.einsum("sr->r", bands[l], out=sums[base])
                    else:
                        np.einsum("sr,sr->r", bands[l], q, out=sums[base])
                elif q is None:
                    # rows base + m (cos) and base - m (sin) at once
                    np.einsum("sr,tsr->tr", bands[l], cs, out=sums[base + m:base - m - 1:-2 * m])
                else:
                    np.einsum("sr,sr,tsr->tr", bands[l], q, cs,
                              out=sums[base + m:base - m - 1:-2 * m])
                if l > m:
                    q_prev2, q_prev1 = q_prev1, q


def _recurrence_constants(order: int, norm: np.ndarray) -> tuple[list, np.ndarray]:
    """The kernel's Legendre recurrence constants and per-coefficient scales.

    Returns ``gammas[m] = [(l, gamma_l), ...]`` for ``l = m .. n-1`` (``gamma`` of
    :meth:`BlockKernel._accumulate`'s scaled recurrence, None where unused) and
    ``coef (n*n,)`` float32: ``sigma_l K_lm`` per coefficient.
    """
    gammas = []
    coef = np.empty(order * order, np.float32)
    for m in range(order):
        sigma_prev2 = sigma = float(double_factorial(2 * m - 1))  # Q_mm
        rows = []
        for l, (a_num, c_num, den) in legendre_recurrence(m, order):
            gamma = None
            if l == m + 1:
                sigma_prev2, sigma = sigma, sigma * a_num
            elif l > m + 1:
                a = a_num / den
                c = c_num / den
                gamma = c * sigma_prev2 / (a * sigma)
                sigma_prev2, sigma = sigma, sigma * a
            rows.append((l, gamma))
            base = l * l + l
            coef[base + m] = coef[base - m] = sigma * norm[l, m]
        gammas.append(rows)
    return gammas, coef
