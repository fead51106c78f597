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
from shtools.sh.exponential import EXP_METHODS, ExpMethod, exp, squaring_weights, squarings
from shtools.sh.logarithm import LOG_EPS, log
from shtools.sh.quadrature import project, reconstruct, sphere_quadrature
from shtools.sh.rotation import rotate, rotation_matrix
from shtools.sh.triple import TripleTensor, product, product_matrix, square, triple, triple_tensor
from shtools.sh.zonal import (
    WINDOW_KINDS,
    WindowKind,
    apply_window,
    cap,
    cap_zh,
    cap_zh_cos,
    clamped_cosine_zh,
    window,
    zonal_to_sh,
)

__all__ = [
    "EXP_METHODS",
    "LOG_EPS",
    "SH_CONVENTION",
    "WINDOW_KINDS",
    "ExpMethod",
    "TripleTensor",
    "WindowKind",
    "apply_window",
    "band_of",
    "basis",
    "cap",
    "cap_zh",
    "cap_zh_cos",
    "check_order",
    "clamped_cosine_zh",
    "exp",
    "log",
    "n_coeffs",
    "order_from_size",
    "product",
    "product_matrix",
    "project",
    "reconstruct",
    "rotate",
    "rotation_matrix",
    "sh_index",
    "sphere_quadrature",
    "square",
    "squaring_weights",
    "squarings",
    "triple",
    "triple_tensor",
    "window",
    "zonal_to_sh",
]
