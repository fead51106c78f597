"""Cached functions hand out nothing a caller can change for the next caller."""

from __future__ import annotations

import numpy as np
import pytest

from shtools.sh import sphere_quadrature, triple_tensor
from shtools.sh._kernels import _cp_factors, _sparse_factors
from shtools.sh.exponential import _volterra_operators
from shtools.sh.quadrature import quarter_sphere_quadrature
from shtools.sh.tables import default_tables


def _arrays(value):
    if isinstance(value, np.ndarray):
        yield value
    elif isinstance(value, tuple | list):
        for v in value:
            yield from _arrays(v)
    elif isinstance(value, dict):
        for v in value.values():
            yield from _arrays(v)
    elif hasattr(value, "__dataclass_fields__"):
        for name in value.__dataclass_fields__:
            yield from _arrays(getattr(value, name))


@pytest.mark.parametrize("call", [
    lambda: sphere_quadrature(6),
    lambda: quarter_sphere_quadrature(9),
    lambda: triple_tensor(3, 4),
    lambda: _cp_factors(3, 3, "<f8"),
    lambda: _sparse_factors(3, 3, "<f4"),
    lambda: _volterra_operators(3, 3, 12, "float32"),
    lambda: default_tables(3),
])
def test_cached_arrays_are_read_only(call):
    arrays = list(_arrays(call()))
    assert arrays
    for a in arrays:
        with pytest.raises(ValueError, match="read-only"):
            a[...] = 0


def test_default_tables_returns_a_new_dict_each_call():
    first = default_tables(3)
    first["ol_a"] = None  # a caller's own change ...
    assert isinstance(default_tables(3)["ol_a"], np.ndarray)  # ... stays its own


def test_runtime_split_operators_are_read_only():
    from shtools.runtime.fast_exp import _split_operators

    for a in _arrays(_split_operators(6, "float32")):
        assert not a.flags.writeable
