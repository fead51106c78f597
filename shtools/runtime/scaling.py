r"""Runtime SH scaling: interpolate M(k) from a ``scaling`` table and apply it per receiver.

For a receiver whose scaling axis is the unit vector ``a`` (towards an entity's
centre, or away from the environment sphere's centre) and scale ``k``:

.. math::  f_d = D^T\, M(k)\, D\, f ,

where ``D = rotation_matrix(R, n)`` and ``R`` takes ``a`` to ``+z``
(:mod:`shtools.sh.rotation`).  The scaling is symmetric about ``+z``, so the
spin of ``R`` about ``a`` does not matter.  ``M(k)`` is interpolated between the
table's samples by the rule the table names (linear in ``k`` or in ``log k``);
outside the sampled range the table's ``out_of_range`` policy applies
(``clamp`` or ``error``).

NumPy only (the runtime's import rule).
"""

from __future__ import annotations

import numpy as np

from shtools.sh.rotation import rotation_matrix

#: Receivers closer than this (relative) to ``k = 1`` of a mid-range table's
#: sphere, or with a ``k`` outside an ``error`` table's range by more, are refused.
RANGE_TOL = 1e-9


class ScalingTable:
    """M(k) sampled in k, ready for interpolation.

    Parameters
    ----------
    table : dict
        As :func:`shtools.data_formats.scaling.read_scaling` or
        :func:`shtools.sh.scaling.build_scaling_table` return: ``k (K,)``,
        ``rows (P,)``, ``cols (P,)``, ``values (K, P)``, ``order``,
        ``function``, ``interpolation``, ``out_of_range`` (and the rest of the
        metadata, kept in :attr:`info`).
    """

    def __init__(self, table: dict):
        self.order = int(table["order"])
        self.k = np.asarray(table["k"], dtype=np.float64)
        self.rows = np.asarray(table["rows"], dtype=np.intp)
        self.cols = np.asarray(table["cols"], dtype=np.intp)
        self.values = np.asarray(table["values"], dtype=np.float64)
        self.function = str(table["function"])
        self.interpolation = str(table["interpolation"])
        self.out_of_range = str(table["out_of_range"])
        if self.interpolation not in ("linear", "linear-log-k"):
            raise ValueError(f"unknown interpolation {self.interpolation!r}")
        if self.out_of_range not in ("clamp", "error"):
            raise ValueError(f"unknown out_of_range policy {self.out_of_range!r}")
        self._x_k = np.log(self.k) if self.interpolation == "linear-log-k" else self.k
        n = self.order
        l = np.repeat(np.arange(n), 2 * np.arange(n) + 1)
        m = np.arange(n * n) - (l * l + l)
        self._abs_m = np.abs(m).astype(np.float64)
        self._sign_m = np.sign(m).astype(np.float64)
        self._partner = l * l + l - m
        # X = D(Q), Q the quarter-turn about x taking +y to +z: R_y(b) = Q^T R_z(b) Q
        quarter = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
        self._x = rotation_matrix(quarter, n)
        # the pattern is sorted by (m, l_out): each output coefficient is one segment
        change = np.flatnonzero(np.diff(self.rows)) + 1
        self._group_starts = np.concatenate([[0], change]).astype(np.intp)
        self._group_rows = self.rows[self._group_starts]
        if np.unique(self._group_rows).size != self._group_rows.size:
            raise ValueError("scaling pattern rows are not grouped (expected the canonical "
                             "order m, l_out, l_in)")
        self._by_dtype = {}  # the fixed arrays of apply per precision (_typed)
        #: every metadata entry of the table (function, alpha, energy_preserving, ...)
        self.info = {key: v for key, v in table.items()
                     if key not in ("k", "rows", "cols", "values")}

    @property
    def k_range(self) -> tuple[float, float]:
        """Lowest and highest sampled ``k``."""
        return float(self.k[0]), float(self.k[-1])

    def values_at(self, k, dtype=np.float64) -> np.ndarray:
        """Interpolated pattern values.

        Parameters
        ----------
        k : array_like, shape (V,)
        dtype : float64 or float32
            Of the result (the table is interpolated in it).

        Returns
        -------
        ndarray, shape (V, P)

        Raises
        ------
        ValueError
            With ``out_of_range = "error"``, when a ``k`` is outside the table.
        """
        k = np.asarray(k, dtype=np.float64).reshape(-1)
        lo, hi = self.k_range
        if self.out_of_range == "error":
            bad = (k < lo - RANGE_TOL) | (k > hi + RANGE_TOL) | ~np.isfinite(k)
            if np.any(bad):
                worst = float(k[bad][np.argmax(np.abs(k[bad] - 0.5 * (lo + hi)))])
                raise ValueError(f"k = {worst:.6g} is outside the scaling table's range "
                                 f"[{lo:g}, {hi:g}]")
        k = np.clip(k, lo, hi)
        x = np.log(k) if self.interpolation == "linear-log-k" else k
        xs = self._x_k
        i = np.clip(np.searchsorted(xs, x, side="right") - 1, 0, self.k.size - 2)
        t = ((x - xs[i]) / (xs[i + 1] - xs[i])).astype(dtype)[:, None]
        values = self._typed(dtype)["values"]
        return (1 - t) * values[i] + t * values[i + 1]

    def matrix(self, k) -> np.ndarray:
        """Interpolated dense ``M(k)``, shape ``(V, n*n, n*n)``."""
        vals = self.values_at(k)
        size = self.order * self.order
        out = np.zeros((vals.shape[0], size, size))
        out[:, self.rows, self.cols] = vals
        return out

    def apply(self, f, k, axes, *, shared: bool = False) -> np.ndarray:
        """Scale SH vectors about per-receiver axes: ``D^T M(k) D f``.

        The rotation taking the axis (polar angle ``beta``, azimuth ``alpha``)
        to ``+z`` is ``R_y(-beta) R_z(-alpha)``, and ``R_y(b) = Q^T R_z(b) Q``
        with ``Q`` the fixed quarter-turn about ``x``; so
        ``D = X^T Z(-beta) X Z(-alpha)`` with one fixed block-diagonal matrix
        ``X = D(Q)`` (a BLAS product for all receivers) and z-rotations
        ``Z`` (a cosine/sine per coefficient).  ``M(k)`` is applied sparsely
        (one segment sum per output coefficient).

        Parameters
        ----------
        f : array_like, shape (V, n*n) or (V, n*n, C); with ``shared``, (n*n,) or (n*n, C)
            SH vectors (C channels, e.g. RGB) in the world frame.
        k : array_like, shape (V,)
        axes : array_like, shape (V, 3)
            Unit axes; for ``k`` at the identity any unit vector will do.
        shared : bool
            ``f`` is one vector (or one set of C channels) for every receiver.

        Returns
        -------
        ndarray, shape (V, n*n) or (V, n*n, C)
        """
        f = np.asarray(f, dtype=np.float64)
        k = np.asarray(k, dtype=np.float64).reshape(-1)
        size = self.order * self.order
        coeff_axis = 0 if shared else 1
        if f.ndim <= coeff_axis or f.shape[coeff_axis] != size:
            raise ValueError(f"SH vectors of shape {f.shape} do not match the scaling "
                             f"table's order {self.order} ({size} coefficients)")
        vec = f.ndim == coeff_axis + 1
        g = f[..., None] if vec else f  # (V, n^2, C) or (n^2, C)
        if shared:
            g = np.broadcast_to(g, (k.size, *g.shape))
        a = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
        alpha = np.arctan2(a[:, 1], a[:, 0])
        beta = np.arctan2(np.hypot(a[:, 0], a[:, 1]), a[:, 2])
        n_c = g.shape[-1]
        out = np.empty((k.size, n_c, size))
        vals = self.values_at(k)
        ops = self._typed(np.float64)
        for s in range(0, k.size, APPLY_CHUNK):
            sl = slice(s, min(s + APPLY_CHUNK, k.size))
            rows = sl.stop - sl.start
            # (receiver, channel) rows, coefficients last: X is one GEMM for all rows
            x = np.swapaxes(g[sl], 1, 2).reshape(rows * n_c, size)
            trig = (*self._trig(np.repeat(alpha[sl], n_c)), *self._trig(np.repeat(beta[sl], n_c)))
            x = self._scale(np.repeat(vals[sl], n_c, axis=0), self._to_z(x, trig, ops))
            out[sl] = self._from_z(x, trig, ops).reshape(rows, n_c, size)
        out = np.swapaxes(out, 1, 2)
        return out[..., 0] if vec else out

    def to_axis_frame(self, f, axes) -> np.ndarray:
        """``D f``: SH vectors ``(V, n*n)`` re-expressed in the frame whose ``+z`` is each axis.

        The frame of the axis with polar angle ``beta`` and azimuth ``alpha`` is
        ``R_z(alpha) R_y(beta)`` (the spin :meth:`apply` uses); :meth:`from_axis_frame`
        inverts it, and ``apply(f, k, a) = from_axis_frame(scale(to_axis_frame(f, a), k), a)``.

        Parameters
        ----------
        f : array_like, shape (V, n*n)
            SH vectors in the world frame (float32 rows stay float32).
        axes : array_like, shape (V, 3)
            Each row's axis (any length > 0).

        Returns
        -------
        ndarray, shape (V, n*n)
            ``f`` in each axis' frame, in ``f``'s precision.
        """
        return self._frame_pass(f, axes, self._to_z)

    def from_axis_frame(self, x, axes) -> np.ndarray:
        """``D^T x``: SH vectors ``(V, n*n)`` given in each axis' frame, back to the world.

        Parameters
        ----------
        x : array_like, shape (V, n*n)
            SH vectors in the frames of ``axes`` (float32 rows stay float32).
        axes : array_like, shape (V, 3)
            Each row's axis, as given to :meth:`to_axis_frame`.

        Returns
        -------
        ndarray, shape (V, n*n)
            ``x`` in the world frame, in ``x``'s precision.
        """
        return self._frame_pass(x, axes, self._from_z)

    def scale(self, x, k) -> np.ndarray:
        """``M(k) x`` per row: SH vectors ``(V, n*n)`` already in their axis' frame.

        Parameters
        ----------
        x : array_like, shape (V, n*n)
            SH vectors in their axis' frame (:meth:`to_axis_frame`; float32 rows stay
            float32).
        k : array_like, shape (V,)
            The scaling parameter per row (interpolated between the table's samples).

        Returns
        -------
        ndarray, shape (V, n*n)
            The scaled vectors, in ``x``'s precision.
        """
        dtype = _work_dtype(x)
        x = np.asarray(x, dtype=dtype).reshape(-1, self.order * self.order)
        k = np.asarray(k, dtype=np.float64).reshape(-1)
        out = np.empty_like(x)
        for s in range(0, k.size, APPLY_CHUNK):
            sl = slice(s, min(s + APPLY_CHUNK, k.size))
            out[sl] = self._scale(self.values_at(k[sl], dtype), x[sl])
        return out

    def _frame_pass(self, x, axes, step) -> np.ndarray:
        """``step`` (:meth:`_to_z` / :meth:`_from_z`) over chunks of rows, in ``x``'s
        precision (float32 rows stay float32: half the memory traffic)."""
        dtype = _work_dtype(x)
        x = np.asarray(x, dtype=dtype).reshape(-1, self.order * self.order)
        a = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
        alpha = np.arctan2(a[:, 1], a[:, 0])
        beta = np.arctan2(np.hypot(a[:, 0], a[:, 1]), a[:, 2])
        ops = self._typed(dtype)
        out = np.empty_like(x)
        for s in range(0, x.shape[0], APPLY_CHUNK):
            sl = slice(s, min(s + APPLY_CHUNK, x.shape[0]))
            trig = (*self._trig(alpha[sl], dtype), *self._trig(beta[sl], dtype))
            out[sl] = step(x[sl], trig, ops)
        return out

    def _typed(self, dtype) -> dict:
        """The fixed arrays of the factored apply in ``dtype`` (made once per dtype)."""
        dtype = np.dtype(dtype)
        if dtype not in self._by_dtype:
            self._by_dtype[dtype] = {
                "x": self._x.astype(dtype), "xt": np.ascontiguousarray(self._x.T, dtype=dtype),
                "sign_m": self._sign_m.astype(dtype), "values": self.values.astype(dtype)}
        return self._by_dtype[dtype]

    def _to_z(self, x, trig, ops):
        """Rows ``x`` to the axis frame: ``D = X^T Z(-beta) X Z(-alpha)`` (``trig`` =
        cos/sin of ``|m| alpha`` and of ``|m| beta``; ``ops`` from :meth:`_typed`)."""
        ca, sa, cb, sb = trig
        x = self._zrot(x, ca, -sa, ops) @ ops["xt"]
        return self._zrot(x, cb, -sb, ops) @ ops["x"]

    def _from_z(self, x, trig, ops):
        """Rows ``x`` back from the axis frame: ``D^T = Z(alpha) X^T Z(beta) X``."""
        ca, sa, cb, sb = trig
        x = self._zrot(x @ ops["xt"], cb, sb, ops) @ ops["x"]
        return self._zrot(x, ca, sa, ops)

    def _trig(self, angle, dtype=np.float64):
        """``cos(|m| angle)``, ``sin(|m| angle)`` per coefficient, shape ``(R, n*n)``."""
        ma = angle[:, None] * np.arange(self.order, dtype=np.float64)[None, :]
        m = self._abs_m.astype(np.intp)
        return np.cos(ma).astype(dtype)[:, m], np.sin(ma).astype(dtype)[:, m]

    def _zrot(self, x, cos_m, sin_m, ops):
        """Rotation about +z of rows ``x (R, n*n)`` by the angle whose
        ``cos(|m| a)``, ``sin(|m| a)`` are given:
        ``out[l,m] = cos(|m| a) x[l,m] - sign(m) sin(|m| a) x[l,-m]``."""
        return cos_m * x - ops["sign_m"] * sin_m * x[:, self._partner]

    def _scale(self, vals, x):
        """Sparse ``M x`` per row: ``vals (R, P)``, ``x (R, n*n)``."""
        out = np.zeros_like(x)
        out[:, self._group_rows] = np.add.reduceat(vals * x[:, self.cols],
                                                   self._group_starts, axis=1)
        return out

    def operator(self, k, axes) -> np.ndarray:
        """Per-receiver dense operator ``D^T M(k) D``, shape ``(V, n*n, n*n)``.

        Built with :func:`shtools.sh.rotation_matrix` (quadrature), independently
        of the factored rotations of :meth:`apply`; for checks and small batches.
        """
        d = rotation_matrix(rotation_to_z(axes), self.order)  # (V, n^2, n^2)
        return np.einsum("vji,vjk,vkl->vil", d, self.matrix(k), d, optimize=True)


#: Receivers per pass of :meth:`ScalingTable.apply` (bounds the temporaries).
APPLY_CHUNK = 1024


def _work_dtype(x):
    """float32 for float32 input, else float64."""
    return np.float32 if getattr(x, "dtype", None) == np.float32 else np.float64


def rotation_to_z(axes) -> np.ndarray:
    """Rotations taking unit ``axes`` to ``+z``, shape ``(V, 3, 3)``.

    The minimal rotation (about ``a x z``); ``a = -z`` gives a half-turn about ``x``.
    """
    a = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
    a = a / np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300)
    c = a[:, 2]
    v = np.stack([a[:, 1], -a[:, 0], np.zeros_like(c)], axis=1)  # a x z
    vx = np.zeros((a.shape[0], 3, 3))
    vx[:, 0, 1], vx[:, 0, 2] = -v[:, 2], v[:, 1]
    vx[:, 1, 0], vx[:, 1, 2] = v[:, 2], -v[:, 0]
    vx[:, 2, 0], vx[:, 2, 1] = -v[:, 1], v[:, 0]
    flip = c < -1 + 1e-12
    scale = np.where(flip, 0.0, 1.0 / np.where(flip, 1.0, 1.0 + c))
    r = np.eye(3) + vx + np.einsum("vij,vjk->vik", vx, vx) * scale[:, None, None]
    r[flip] = np.diag([1.0, -1.0, -1.0])
    return r


def midrange_lighting(env_sh, points, center, radius: float, table: ScalingTable,
                      out_order: int | None = None) -> np.ndarray:
    """Environment radiance seen from points inside a finite environment sphere.

    The environment was captured at the sphere's centre (``env_sh``); a point
    at distance ``d`` from it sees the sphere's points along other directions,
    ``L_p = D^T M_mid(d/R) D L_c`` with the axis from the centre to the point
    (Wang et al. 2005, Sec. 3.2; plain scaling: radiance is invariant
    along rays, so the warp alone is exact up to truncation).

    The warp moves the environment's bands ``>= n`` into the bands below, so
    scale at a higher order than the shading order: ``env_sh`` and ``table`` at
    ``n + 4`` with ``out_order = n`` took the error against ray-sphere tracing of
    a sharp probe from 8–19 % to 0.04–0.43 % (``tests/runtime/test_scaling_apply.py``).

    Parameters
    ----------
    env_sh : array_like, shape (n'*n', C)
        Radiance SH captured at the centre (C colours); truncated or zero-padded
        to the table's order.
    points : array_like, shape (V, 3)
    center : array_like, shape (3,)
    radius : float
        Sphere radius ``R``.
    table : ScalingTable
        A ``midrange`` table; ``out_of_range = "error"`` refuses receivers past
        its ``kmax``.

    out_order : int, optional
        Order of the result (at most the table's); default the table's.

    Returns
    -------
    ndarray, shape (V, out_order**2, C)

    Raises
    ------
    ValueError
        A point on or outside the sphere, or beyond the table's ``kmax``.
    """
    if table.function != "midrange":
        raise ValueError(f"mid-range lighting needs a 'midrange' scaling table, got "
                         f"'{table.function}'")
    if table.info.get("energy_preserving"):
        raise ValueError("mid-range lighting needs a plain (not energy-preserving) table: "
                         "radiance is invariant along rays")
    offset = np.asarray(points, dtype=np.float64).reshape(-1, 3) - np.asarray(center, float)
    dist = np.linalg.norm(offset, axis=1)
    k = dist / float(radius)
    if np.any(k >= 1.0):
        i = int(np.argmax(k))
        raise ValueError(f"receiver {i} is at {dist[i]:.6g} from the environment centre, "
                         f"outside the sphere of radius {radius:g}")
    axes = np.where(dist[:, None] > 0, offset, [0.0, 0.0, 1.0])
    size = table.order * table.order
    env = np.asarray(env_sh, dtype=np.float64)
    padded = np.zeros((size, *env.shape[1:]))
    padded[:min(size, env.shape[0])] = env[:size]
    out_size = size if out_order is None else int(out_order) ** 2
    if out_size > size:
        raise ValueError(f"out_order {out_order} exceeds the scaling table's order {table.order}")
    return table.apply(padded, k, axes, shared=True)[:, :out_size]
