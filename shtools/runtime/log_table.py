r"""Cap log table indexed by :math:`1 - \cos\theta` (no per-pair arcsin).

Eq. 34 needs :math:`F(\theta)` at :math:`\theta = \sin^{-1}(r/d)`.  The runtime
has :math:`r^2/d^2 = \sin^2\theta` for free, so
:math:`x = 1 - \cos\theta = 1 - \sqrt{1 - r^2/d^2}` costs one square root, and
the table is resampled uniformly in ``x``.  ``x`` is also the natural variable:
a small cap's log coefficients are proportional to its solid angle
:math:`2\pi x`, so linear interpolation in ``x`` is exact to first order.

The runtime kernel uses a second form of the same table that needs one
gather and one multiply per band and no interpolation weights: the *ratio*
:math:`G_l(x) = F_l(x)/x`, which is smooth and finite at ``x = 0`` (the
small-cap limit), tabulated at the midpoints of ``RATIO_SAMPLES`` cells, so
:math:`F_l(x) \approx x\,G_l(\text{cell of } x)`.  Its error is first order in
the cell width, ``|G'| x / (2K)``; at 16384 cells it stays below 6e-4 of each
band's largest coefficient and the median relative error is 5e-5 (against
the float64 table; tests/runtime/test_accumulate.py checks it).
"""

from __future__ import annotations

import numpy as np

from shtools.errors import InputError

#: Samples of the resampled table; linear interpolation error at 4096 samples is
#: below 1e-6 of the largest coefficient.
TABLE_SAMPLES = 4096
#: Cells of the ratio table F_l(x)/x (piecewise constant; error ~ 1/RATIO_SAMPLES).
RATIO_SAMPLES = 16384


class CapLogTable:
    """Scaled cap-log coefficients :math:`f^*_l` tabulated uniformly in ``1 - cos(theta)``.

    Parameters
    ----------
    tables : dict
        As returned by :func:`shtools.sh.tables.build_log_tables` or
        :func:`shtools.data_formats.tables.read_tables`: ``theta (T,)`` and
        ``log_zh (T, n)``.
    order : int
        Number of bands to keep (``<=`` the table's order).
    samples : int
        Resampled table size ``K``.

    Attributes
    ----------
    values : ndarray, shape (n, K) float32
        :math:`f^*_l` at ``x_k = k / (K - 1)``.
    slopes : ndarray, shape (n, K) float32
        ``values[:, k+1] - values[:, k]`` (0 in the last column).
    ratios : ndarray, shape (n, RATIO_SAMPLES + 1) float32
        :math:`F_l(x)/x` at the midpoints of ``RATIO_SAMPLES`` equal cells of
        ``[0, 1]`` (see :meth:`lookup_ratio`), the last repeated for ``x = 1``.
    """

    def __init__(self, tables: dict, order: int, samples: int = TABLE_SAMPLES):
        theta = np.asarray(tables["theta"], dtype=np.float64)
        log_zh = np.asarray(tables["log_zh"], dtype=np.float64)
        if log_zh.ndim != 2 or log_zh.shape[0] != theta.shape[0] or log_zh.shape[1] < order:
            raise InputError(
                f"log tables have {log_zh.shape[-1]} bands, fewer than the order {order} "
                "needed; build them with `shtools tables log --order N`"
            )
        self.order = int(order)
        self.samples = int(samples)
        # theta = 0 is an empty cap: log visibility exactly 0.
        x_src = np.concatenate([[0.0], 1.0 - np.cos(theta)])
        f_src = np.concatenate([np.zeros((1, order)), log_zh[:, :order]], axis=0)
        if np.any(np.diff(x_src) <= 0):
            raise InputError("log table theta must be strictly increasing in (0, pi/2]")
        x = np.linspace(0.0, 1.0, self.samples)
        values = np.stack([np.interp(x, x_src, f_src[:, l]) for l in range(order)])
        self.values64 = values
        self._rows64 = np.ascontiguousarray(values.T)  # (K, n): one row per sample
        # each sample's step to the next (the last row unused): one gather fewer a lookup
        self._steps64 = np.diff(self._rows64, axis=0, append=self._rows64[-1:])
        self.values = values.astype(np.float32)
        slopes = np.zeros_like(values)
        slopes[:, :-1] = np.diff(values, axis=1)
        self.slopes = slopes.astype(np.float32)
        self.scale = np.float32(self.samples - 1)
        mids = (np.arange(RATIO_SAMPLES) + 0.5) / RATIO_SAMPLES
        ratios = np.stack([np.interp(mids, x_src, f_src[:, l]) for l in range(order)]) / mids
        # one contiguous row per band: the kernel gathers each band separately;
        # x = 1 lands on index RATIO_SAMPLES, so the last cell is repeated there and
        # every index is in range (no clipping in the gather)
        self.ratios = np.ascontiguousarray(np.concatenate([ratios, ratios[:, -1:]], axis=1),
                                           dtype=np.float32)
        self.ratio_cells = np.float32(RATIO_SAMPLES)

    def lookup(self, one_minus_cos, out: np.ndarray | None = None) -> np.ndarray:
        """Interpolated :math:`f^*_l` for every band.

        Parameters
        ----------
        one_minus_cos : ndarray, shape (...)
            ``1 - cos(theta)`` in ``[0, 1]`` (values outside are clamped).
        out : ndarray, shape (n, ...), optional
            Destination (float32).

        Returns
        -------
        ndarray, shape (n, ...)
        """
        x = np.asarray(one_minus_cos)
        t = np.clip(x * self.scale, 0.0, self.scale).astype(np.float32, copy=False)
        idx = t.astype(np.intp)
        frac = t - idx
        if out is None:
            out = np.empty((self.order, *x.shape), dtype=np.float32)
        tmp = np.empty(x.shape, dtype=np.float32)
        for l in range(self.order):
            np.take(self.values[l], idx, out=out[l])
            np.take(self.slopes[l], idx, out=tmp)
            tmp *= frac
            out[l] += tmp
        return out

    def lookup_ratio(self, one_minus_cos) -> np.ndarray:
        r""":math:`f^*_l \approx x\,G_l` from the ratio table (the kernel's form).

        Parameters
        ----------
        one_minus_cos : ndarray, shape (...)
            ``x = 1 - cos(theta)`` in ``[0, 1]``.

        Returns
        -------
        ndarray, shape (n, ...) float32
        """
        x = np.clip(np.asarray(one_minus_cos, dtype=np.float32), 0.0, 1.0)
        cell = np.minimum(x * self.ratio_cells, self.ratio_cells - 1).astype(np.intp)
        return self.ratios[:, cell] * x

    def lookup64(self, theta) -> np.ndarray:
        """float64 :math:`f^*_l(\\theta)`, shape ``(..., n)`` (for per-cluster work)."""
        return self.lookup64_x(1.0 - np.cos(np.asarray(theta, dtype=np.float64)))

    def lookup64_x(self, one_minus_cos) -> np.ndarray:
        """float64 :math:`f^*_l` at ``1 - cos(theta)``, shape ``(..., n)``."""
        x = np.asarray(one_minus_cos, dtype=np.float64)
        t = np.clip(x * (self.samples - 1), 0.0, self.samples - 1)
        idx = np.minimum(t.astype(np.intp), self.samples - 2)
        frac = (t - idx)[..., None]
        # np.take gathers rows several times faster than fancy indexing
        out = np.take(self._steps64, idx, axis=0)  # (..., n)
        out *= frac
        out += np.take(self._rows64, idx, axis=0)
        return out
