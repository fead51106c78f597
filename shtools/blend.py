"""The smoothstep of every continuous transition in shtools (one formula, one place).

Hand-overs between representations, ray densities, squaring counts, cluster cuts and
the occlusion camera's falloff all blend with the same weight, so that each is
continuous with a continuous slope:

.. math::

    S(t) = t^2 (3 - 2t), \\qquad S(0) = 0,\\ S(1) = 1,\\ S'(0) = S'(1) = 0,
    \\qquad \\max S' = S'(1/2) = 3/2 .
"""

from __future__ import annotations


def smoothstep(t):
    """:math:`S(t) = t^2 (3 - 2t)` of ``t`` already clipped to [0, 1], elementwise.

    Parameters
    ----------
    t : float or ndarray, shape (...)

    Returns
    -------
    float or ndarray, shape (...)
        Of ``t``'s dtype (a float32 array stays float32: the constants are Python
        scalars).
    """
    return t * t * (3.0 - 2.0 * t)
