"""The settings schema: one declaration per setting gives the checks, the scene keys and the CLI."""

from __future__ import annotations

import math
from dataclasses import fields

import click
import pytest

from shtools.cli._common import setting_type
from shtools.errors import InputError
from shtools.runtime.settings import (
    MAX_ACC_ORDER,
    MAX_ORDER,
    ShadowSettings,
    limits_of,
    scene_fields,
    setting_fields,
)
from shtools.scene.scene import Settings


def test_every_field_is_declared_with_limits():
    declared = {name for name, _, _ in setting_fields(Settings)}
    assert declared == {f.name for f in fields(Settings)}
    for name, limits, _ in setting_fields(Settings):
        assert limits.doc, name
        if limits.kind in ("int", "float"):  # every number has a range
            assert (limits.lo is not None or limits.lo_field is not None), name


@pytest.mark.parametrize("name", [n for n, lim, _ in setting_fields(ShadowSettings)
                                  if lim.kind in ("int", "float")])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_every_number_refuses_non_finite_values(name, bad):
    with pytest.raises(InputError, match=f"^{name} must be finite"):
        ShadowSettings(**{name: bad})


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"order": 0}, "order must be an integer in 1..8, got 0"),
    ({"order": MAX_ORDER + 1}, f"order must be an integer in 1..{MAX_ORDER}"),
    ({"order": 2.5}, "order must be an integer in 1..8, got 2.5"),
    ({"order": True}, "order must be an integer"),
    ({"order": 4, "acc_order": 3}, "acc_order must be an integer in order (4)..10"),
    ({"acc_order": MAX_ACC_ORDER + 1}, "acc_order must be"),
    ({"exp_method": "psx"}, "exp_method must be one of auto, hyb, ps*, ps, ol, exact, volterra"),
    ({"window": "hamming"}, "window must be one of cosine, hann, lanczos, none"),
    ({"window_h": 0.0}, "window_h must be a number > 0"),
    ({"theta_max": math.pi / 2}, "theta_max must be a number in (0, 1.57"),
    ({"theta_min": 0.5, "theta_max": 0.4}, "theta_min must be a number in [0, theta_max (0.4))"),
    ({"hierarchy": 1}, "hierarchy must be true or false"),
    ({"vertices_per_cluster": 0}, "vertices_per_cluster must be an integer >= 1"),
    ({"chunk_pairs": 10}, "chunk_pairs must be an integer >= 256"),
    ({"threads": 65}, "threads must be an integer in 1..64"),
    ({"processes": 0}, "processes must be an integer in 1..64 (or None: one per core)"),
])
def test_bad_values_name_the_setting_and_its_range(kwargs, message):
    with pytest.raises(InputError) as info:
        ShadowSettings(**kwargs)
    assert message in info.value.one_line()


def test_none_means_a_derived_default():
    s = ShadowSettings(order=3)
    assert s.resolved_acc_order() == 5 and s.resolved_exp_method() == "ps*"
    assert s.resolved_theta_min() == pytest.approx(math.radians(1.0))
    assert ShadowSettings(order=7).resolved_acc_order() == 7
    assert ShadowSettings(acc_order=4).resolved_exp_method() == "hyb"


def test_scene_keys_come_from_the_schema():
    keys = {key: name for key, name, _, _ in scene_fields(Settings)}
    # angles are written in degrees; execution settings are not scene keys
    assert keys["theta_max_deg"] == "theta_max" and keys["theta_min_deg"] == "theta_min"
    assert {"processes", "threads", "chunk_pairs"}.isdisjoint(keys)
    assert {"frames", "fps", "tables", "method", "order", "acc_order"} <= set(keys)


def test_cli_types_come_from_the_schema():
    order = setting_type("order")
    assert isinstance(order, click.IntRange) and (order.min, order.max) == (1, MAX_ORDER)
    acc = setting_type("acc_order")
    assert (acc.min, acc.max) == (1, MAX_ACC_ORDER)
    assert tuple(setting_type("window").choices) == limits_of(ShadowSettings,
                                                             "window").choice_values()
    assert "raytrace" in setting_type("method", Settings).choices
