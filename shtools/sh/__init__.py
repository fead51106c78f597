"""SH algebra on arrays: basis, quadrature, projection, products, exp, log, rotation.

No I/O here. Every function is batched over leading axes ``(..., n*n)``.
"""

from shtools.sh.basis import (
    SH_CONVENTION,
    band_of,
    basis,
    check_order,
    n_coeffs,
    order_from_size,
    sh_index,
)

__all__ = [
    "SH_CONVENTION",
    "band_of",
    "basis",
    "check_order",
    "n_coeffs",
    "order_from_size",
    "sh_index",
]
