"""``blocker = { deformable = true }``: deformable shadow fields for skinned objects.

Wang et al. 2005, Sec. 3.1: every frame the posed character's visibility is
sampled on its bounding sphere (:func:`shtools.fields.deformable.sample_deformable_field`)
and each receiver gets the sample in its direction scaled to its distance by
the cone SH scaling (``alpha_deg``, default 45, the map Wang et al. print).  By
default its scaled visibility is multiplied in after the exp (``field_space``,
product space for deformable fields: closer to ray tracing on the ground at
about the same frame time, ``benchmarks/bench_scaling.py``); with ``field_space = "log"`` its SH log
joins the runtime's log accumulation (one exp for all blockers).

Options: ``alpha_deg`` (cone half-angle in (0, 90) degrees), ``samples``
(``[rings, azimuths]`` of the polar layout, default ``[16, 24]`` = 384 like
Wang et al.'s), ``rays`` (``[cos nodes, azimuths]`` of the inward-hemisphere rule per
sample, default ``[16, 32]`` = 512), ``log`` (``"naive"``, the default, or
``"eigen"``: how each sample's SH log is taken, used in log space; ``benchmarks/bench_scaling.py``
finds the same accuracy on Fox and CesiumMan, and the eigen logs of the 384
samples cost more than the rest of the field's frame).

The object's own vertices: by default its posed mesh is traced there every
frame (``self_visibility``; :mod:`shtools.scene.transfer`) and that
:class:`shtools.runtime.SelfVisibility` names this blocker, so the runtime does
not evaluate the field on those rows (the cone model's ``k < 1`` is far less
accurate on a character's own limbs, ``benchmarks/bench_scaling.py``); with
``self_visibility = false`` they get the field's ``k < 1`` scaling.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import Field

from shtools.scene.blockers import BlockerKind, register_blocker_kind
from shtools.scene.schema import choice


def _pair():
    return Annotated[list[Annotated[int, Field(strict=True, ge=2, le=256)]],
                     Field(min_length=2, max_length=2)]


class DeformableKind(BlockerKind):
    """Re-sampled every frame on the bounding sphere of the posed skinned mesh."""

    name, value = "deformable", "flag"
    hint = "'deformable = true' (a deformable shadow field, skinned objects)"

    def __init__(self):
        self.options = {
            "alpha_deg": (Annotated[float, Field(gt=0, lt=90)], 45.0),
            "samples": (_pair(), (16, 24)),
            "rays": (_pair(), (16, 32)),
            "log": (choice(("naive", "eigen")), "naive"),
        }

    def check(self, spec, obj):
        if obj.skin is None:
            return ("deformable", "a deformable shadow field needs a skinned object "
                                  "(add 'skin = {}'); rigid objects use spheres or a tree")
        return None

    def prepare(self, spec, prep, ctx):
        from shtools.runtime import ShadowSettings
        from shtools.runtime.scaling import ScalingTable
        from shtools.sh.scaling import build_scaling_table

        st = ctx.settings
        acc = ShadowSettings(order=st.order, acc_order=st.acc_order).resolved_acc_order()
        table = build_scaling_table(acc, "cone", alpha=math.radians(spec.options["alpha_deg"]))
        prep.blocker_data = {"order": acc, "table": ScalingTable(table),
                             "samples": tuple(spec.options["samples"]),
                             "rays": tuple(spec.options["rays"]),
                             "log": spec.options["log"]}

    def pose(self, prep, world, joints):
        from shtools.fields.deformable import sample_deformable_field
        from shtools.runtime.deformable import DeformableBlocker
        from shtools.scene.animation import transform_points

        data = prep.blocker_data
        local = prep.motion.model.skin(joints) if joints is not None else prep.vertices
        posed = transform_points(world, np.asarray(local, dtype=float))
        field = sample_deformable_field(posed, prep.faces, data["order"],
                                        layout=data["samples"], rays=data["rays"],
                                        log_method=data["log"])
        return DeformableBlocker(field, data["table"])


register_blocker_kind(DeformableKind())
