r"""The SH triple-product tensor Γ (SHEXP, Ren et al. 2006, eq. 4), exact and sparse.

:math:`\Gamma_{ijk} = \int_S y_i y_j y_k\,ds` is computed once per
``(order, out_order)`` by the quadrature of :mod:`shtools.sh.quadrature` of
degree ``(n_out - 1) + 2 (n - 1)``, which is *exact* because the integrand is a
polynomial of that degree; entries below :data:`GAMMA_ZERO` (round-off of
entries that vanish by the selection rules) are dropped.  The products that use
it are in :mod:`shtools.sh.triple` and :mod:`shtools.sh._kernels`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from shtools.sh.basis import basis, check_order
from shtools.sh.quadrature import sphere_quadrature

GAMMA_ZERO = 1e-10
"""|Γ| below this is round-off of a structural zero (true nonzeros exceed 4e-3 up to n = 8)."""


@dataclass(frozen=True, eq=False)
class TripleTensor:
    """Sparse triple-product tensor ``Γ[i, j, k]`` with ``i < out_order**2``, ``j, k < order**2``.

    Attributes
    ----------
    order, out_order : int
        Input and output SH orders.
    i, j, k : ndarray, shape (N,)
        Indices of every (ordered) nonzero entry.
    values : ndarray, shape (N,)
        Their values.
    pair_j, pair_k : ndarray, shape (P,)
        Unordered input pairs ``j <= k`` that carry at least one nonzero.
    pair_coef : ndarray, shape (P, out_order**2)
        ``Γ[i, j, k]`` per pair and output, for products.
    square_coef : ndarray, shape (P, out_order**2)
        The same with ``j < k`` doubled, for squares.
    """

    order: int
    out_order: int
    i: np.ndarray
    j: np.ndarray
    k: np.ndarray
    values: np.ndarray
    pair_j: np.ndarray
    pair_k: np.ndarray
    pair_coef: np.ndarray
    square_coef: np.ndarray

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(out_order**2, order**2, order**2)``."""
        return (self.out_order**2, self.order**2, self.order**2)

    @property
    def nnz(self) -> int:
        """Number of ordered nonzero entries."""
        return int(self.values.size)

    def todense(self) -> np.ndarray:
        """Dense tensor, shape ``(out_order**2, order**2, order**2)``."""
        dense = np.zeros(self.shape)
        dense[self.i, self.j, self.k] = self.values
        return dense


@functools.lru_cache(maxsize=32)
def _triple_tensor_cached(order: int, out_order: int) -> TripleTensor:
    dirs, w = sphere_quadrature((out_order - 1) + 2 * (order - 1))
    y_out = basis(dirs, out_order)  # (Q, n_out^2)
    y_in = basis(dirs, order)  # (Q, n^2)
    dense = np.einsum("qi,qj,qk->ijk", y_out * w[:, None], y_in, y_in, optimize=True)
    # Make Γ exactly symmetric (quadrature round-off differs between permutations):
    # every entry takes the value stored at its sorted index triple.
    if out_order == order:
        idx = np.sort(np.indices(dense.shape).reshape(3, -1), axis=0)
    else:
        i_, j_, k_ = np.indices(dense.shape).reshape(3, -1)
        idx = (i_, np.minimum(j_, k_), np.maximum(j_, k_))
    dense = dense[tuple(idx)].reshape(dense.shape)
    dense[np.abs(dense) < GAMMA_ZERO] = 0.0
    i, j, k = np.nonzero(dense)
    values = dense[i, j, k]
    upper = np.triu(np.any(dense != 0.0, axis=0))  # (n^2, n^2), pairs j <= k
    pair_j, pair_k = np.nonzero(upper)
    pair_coef = dense[:, pair_j, pair_k].T.copy()  # (P, n_out^2)
    square_coef = pair_coef * np.where(pair_j < pair_k, 2.0, 1.0)[:, None]
    arrays = (i, j, k, values, pair_j, pair_k, pair_coef, square_coef)
    for a in arrays:
        a.setflags(write=False)
    return TripleTensor(order, out_order, *arrays)


def triple_tensor(order: int, out_order: int | None = None) -> TripleTensor:
    """Sparse SH triple-product tensor (eq. 4), exact, cached per orders.

    Parameters
    ----------
    order : int
        SH order ``n`` of the two inputs ``j, k``.
    out_order : int, optional
        SH order of the output index ``i`` (default ``order``).

    Returns
    -------
    TripleTensor
        Ordered nonzeros and the pair grouping used by :func:`product`.
    """
    order = check_order(order)
    out_order = order if out_order is None else check_order(out_order)
    return _triple_tensor_cached(order, out_order)
