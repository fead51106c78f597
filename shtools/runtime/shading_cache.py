"""Per-vertex shading terms kept between frames: cosine transfer, lit transfer, light terms.

Static receivers (most of a scene) keep their normals, and a scene's light often
holds still: the runtime then reuses H(N), L_H = L * H(N) and the sphere lights'
lit transfer row by row instead of projecting them again each frame, as the paper
keeps L_H per normal, so a static row's shading is one dot product with ``g``.

Rows are refreshed a whole block of
:data:`~shtools.runtime.fast_exp.PRODUCT_BLOCK_ROWS` at a time, the blocks the
terms were first computed in: a row's matrix products then see the rows they saw
the first time, and the kept terms are the bytes of terms computed afresh
(:func:`~shtools.runtime.fast_exp.row_matmul`).
"""

from __future__ import annotations

import numpy as np

from shtools.runtime.fast_exp import PRODUCT_BLOCK_ROWS
from shtools.runtime.shading import (
    band_window,
    cosine_transfer,
    environment_matrices,
    lit_transfer,
    sphere_light_terms,
    sphere_light_transfer,
)


class ShadingCache:
    """H(N) and L_H of the last frame, refreshed where normals or the light changed.

    Parameters
    ----------
    order : int
        Shading SH order.
    settings : ShadowSettings
        The runtime's settings (their window, read at each light change).
    """

    def __init__(self, order: int, settings):
        self.order = order
        self.settings = settings
        self._transfer: tuple[np.ndarray, np.ndarray] | None = None
        self._lit: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._points: np.ndarray | None = None  # receivers of the kept light terms
        self._lights: list = []  # per light: (position, radius, zh, y)
        self._rows: tuple | None = None  # (key, lit rows, their receivers) of lit_rows

    def cosine_transfer(self, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """H(N) per vertex, recomputed only for vertices whose normal changed since last call.

        Static receivers (most of a scene) keep their tabulated transfer across
        frames, as the paper keeps L_H per normal.

        Returns
        -------
        transfer : ndarray, shape (V, n*n) float32
        changed : ndarray of int or None
            Rows recomputed by this call (None: all of them).
        """
        cached = self._transfer
        if cached is None or cached[0].shape != normals.shape:
            transfer = cosine_transfer(normals, self.order)
            self._transfer = (normals.copy(), transfer)
            return transfer, None
        old_n, transfer = cached
        changed = _changed_rows(old_n, normals)
        if changed.size:
            transfer[changed] = cosine_transfer(normals[changed], self.order)
            old_n[changed] = normals[changed]
        return transfer, changed

    def lit_transfer(self, env_sh, transfer: np.ndarray, changed: np.ndarray | None
                     ) -> np.ndarray:
        """L_H = L * H(N) per vertex (V, 3, n*n), kept while the light is unchanged.

        Rows are refreshed where the normal changed (``changed``), all of them
        when the light, the window or the receivers changed.
        """
        s = self.settings
        env = np.array(env_sh, dtype=np.float64)
        cached = self._lit
        if (cached is None or changed is None or cached[1].shape[0] != transfer.shape[0]
                or cached[0].shape != env.shape or not np.array_equal(cached[0], env)):
            mats = environment_matrices(env, self.order, s.resolved_window(), s.window_h)
            self._lit = (env, lit_transfer(transfer, mats), mats)
            return self._lit[1]
        _, l_h, mats = cached
        if changed.size:
            rows = _whole_blocks(changed, transfer.shape[0])
            l_h[rows] = lit_transfer(transfer[rows], mats)
        return l_h

    def light_terms(self, lights, points: np.ndarray) -> list:
        """:func:`~shtools.runtime.shading.sphere_light_terms` of each light, kept per row.

        Rows are refreshed where the receiver moved, all of them for a light that
        moved or changed size (or when the receivers or the lights changed).
        """
        points = np.asarray(points)
        if (self._points is None or self._points.shape != points.shape
                or len(self._lights) != len(lights)):
            self._points = points.copy()
            self._lights = [self._fresh(light, points) for light in lights]
            return [(zh, y) for _, _, zh, y in self._lights]
        moved = _changed_rows(self._points, points)
        if moved.size:
            self._points[moved] = points[moved]
        for k, light in enumerate(lights):
            position, radius, zh, y = self._lights[k]
            if radius != light.radius or not np.array_equal(position, light.position):
                self._lights[k] = self._fresh(light, points)
            elif moved.size:
                zh[moved], y[moved] = sphere_light_terms(light, points[moved], self.order)
        return [(zh, y) for _, _, zh, y in self._lights]

    def lit_rows(self, env_sh, lights, points: np.ndarray, transfer: np.ndarray,
                 changed: np.ndarray | None) -> np.ndarray:
        """Lit transfer of a shared environment and the sphere lights, ``(V, 3, n*n)``.

        :meth:`lit_transfer` plus
        :func:`~shtools.runtime.shading.sphere_light_transfer`, kept per row:
        refreshed where the normal changed (``changed``, None for all) or the
        receiver moved, all of them when the light, a sphere light (position,
        size, colour) or the window changed.
        """
        s = self.settings
        l_h = None if env_sh is None else self.lit_transfer(env_sh, transfer, changed)
        key = (None if env_sh is None else np.array(env_sh, dtype=np.float64),
               s.resolved_window(), s.window_h,
               tuple((light.position.copy(), light.radius, light.color.copy())
                     for light in lights))
        kept = self._rows
        if (kept is None or changed is None or kept[2].shape != points.shape
                or not _same(kept[0], key)):
            self._rows = (key, self._lit_part(l_h, lights, points, transfer, slice(None)),
                          points.copy())
            return self._rows[1]
        _, lit, old_points = kept
        refresh = np.zeros(points.shape[0], dtype=bool)
        refresh[changed] = True
        moved = _changed_rows(old_points, points)
        refresh[moved] = True
        old_points[moved] = points[moved]
        rows = _whole_blocks(np.flatnonzero(refresh), points.shape[0])
        if rows.size:
            lit[rows] = self._lit_part(l_h, lights, points, transfer, rows)
        return lit

    def _lit_part(self, l_h, lights, points, transfer, rows) -> np.ndarray:
        """The ``rows`` of :meth:`lit_rows` computed afresh (as ``shade`` does)."""
        s = self.settings
        lit = None if l_h is None else l_h[rows]
        if lights:
            win = band_window(self.order, s.resolved_window(), s.window_h)
            part = sphere_light_transfer(lights, points[rows], transfer[rows], self.order, win)
            lit = part if lit is None else lit + part
        if lit is None:
            lit = np.zeros((transfer[rows].shape[0], 3, self.order ** 2), np.float32)
        return lit

    def _fresh(self, light, points) -> tuple:
        zh, y = sphere_light_terms(light, points, self.order)
        return np.array(light.position, dtype=np.float64), float(light.radius), zh, y


def _same(a, b) -> bool:
    """Whether two :meth:`ShadingCache.lit_rows` keys are equal (arrays by value)."""
    if isinstance(a, tuple):
        return (isinstance(b, tuple) and len(a) == len(b)
                and all(_same(x, y) for x, y in zip(a, b, strict=True)))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray)
                and a.shape == b.shape and np.array_equal(a, b))
    return a == b


def _changed_rows(old: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Rows of ``(V, 3)`` arrays that differ (column by column: several times faster
    than a reduction over the short last axis)."""
    return np.flatnonzero((old[:, 0] != new[:, 0]) | (old[:, 1] != new[:, 1])
                          | (old[:, 2] != new[:, 2]))


def _whole_blocks(rows: np.ndarray, n_rows: int) -> np.ndarray:
    """Every row ``(R',)`` of the blocks of :data:`PRODUCT_BLOCK_ROWS` (from row 0 of
    ``n_rows``) that hold one of the sorted ``rows``, in order."""
    touched = np.zeros(-(-n_rows // PRODUCT_BLOCK_ROWS), dtype=bool)
    touched[rows // PRODUCT_BLOCK_ROWS] = True
    return np.flatnonzero(np.repeat(touched, PRODUCT_BLOCK_ROWS)[:n_rows])
