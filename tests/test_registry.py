"""The one registry mechanism (shtools.registry) and the registries built on it."""

from __future__ import annotations

import sys

import pytest

from shtools.registry import Registry, UnknownName


class _Entry:
    def __init__(self, name):
        self.name = name


def test_register_keeps_order_and_returns_the_entry():
    reg = Registry("widget")
    b, a = _Entry("b"), _Entry("a")
    assert reg.register(b) is b
    assert reg.register(a) is a
    reg.register("plain", "c")  # an entry without a name attribute, named explicitly
    assert reg.names() == ("b", "a", "c")
    assert list(reg) == ["b", "a", "c"] and len(reg) == 3
    assert reg["a"] is a and "b" in reg and "z" not in reg
    assert reg.get("z") is None


def test_a_taken_name_is_refused():
    reg = Registry("widget")
    reg.register(_Entry("a"))
    with pytest.raises(ValueError, match=r"^widget 'a' is already registered$"):
        reg.register(_Entry("a"))
    assert len(reg) == 1


def test_an_unknown_name_lists_the_choices():
    reg = Registry("widget")
    reg.register(_Entry("a"))
    reg.register(_Entry("b"))
    with pytest.raises(UnknownName) as info:
        reg["c"]
    assert str(info.value) == "unknown widget 'c'; use one of ('a', 'b')"
    # both a KeyError (mapping protocol) and a ValueError (a bad value)
    assert isinstance(info.value, KeyError) and isinstance(info.value, ValueError)


def test_check_runs_before_the_entry_is_added():
    def check(entry):
        if not entry.name.islower():
            raise ValueError("lower-case names only")

    reg = Registry("widget", check=check)
    with pytest.raises(ValueError, match="lower-case"):
        reg.register(_Entry("A"))
    assert reg.names() == ()


def test_setitem_and_delitem_go_through_register():
    """``monkeypatch.setitem`` on a registry registers and later removes the entry."""
    reg = Registry("widget")
    reg["x"] = _Entry("x")
    with pytest.raises(ValueError, match="already registered"):
        reg["x"] = _Entry("x")
    del reg["x"]
    assert reg.names() == ()


def test_the_scene_registries_are_complete_from_kinds():
    """Every plugin module registers itself once shtools.scene.kinds is imported; the
    choices are the documented ones (docs/scenes.md), in the order --help lists them."""
    from shtools.scene.kinds import BLOCKER_KINDS, LIGHT_SHADOWS, bake_method_names

    assert BLOCKER_KINDS.names() == ("spheres", "tree", "bound", "fit", "exact",
                                     "deformable", "field")
    assert set(LIGHT_SHADOWS) == {"shexp", "field", "field-shexp", "ssoc", "raytrace", "auto"}
    assert bake_method_names()[0] == "default"
    assert {"product", "raytrace", "exact", "hyb"} <= set(bake_method_names())


def test_product_kernels_are_a_registry():
    import numpy as np

    from shtools.sh._kernels import PRODUCT_KERNELS, run_product

    assert isinstance(PRODUCT_KERNELS, Registry)
    f = np.ones((1, 4))
    with pytest.raises(ValueError, match=r"unknown product kernel 'nope'; use one of "
                                         r"\('cp', 'sparse'"):
        run_product(f, None, 2, 2, kernel="nope")


def test_lazy_attributes_import_on_first_use_and_bind_once(monkeypatch):
    import json
    import types

    from shtools.registry import lazy_attributes

    pkg = types.ModuleType("lazy_pkg")
    monkeypatch.setitem(sys.modules, "lazy_pkg", pkg)
    pkg.__getattr__, pkg.__dir__ = lazy_attributes("lazy_pkg", {"dumps": "json"})
    assert "dumps" not in vars(pkg)  # nothing loaded before the first use
    assert "dumps" in dir(pkg)
    assert pkg.dumps is json.dumps
    assert vars(pkg)["dumps"] is json.dumps  # bound: later reads skip __getattr__
    with pytest.raises(AttributeError, match="'lazy_pkg' has no attribute 'loads'"):
        _ = pkg.loads
