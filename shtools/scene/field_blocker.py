"""The ``field`` blocker kind: ``blocker = { field = "x.field.h5" }`` (Tamura et al.).

A ``haar`` asset (an all-frequency field) is handed to :mod:`shtools.scene.haar_blocker`.

A rigid object carries a precomputed adaptive shadow field (``shtools field
sample``).  The kind checks that the object can use one (no skin, one uniform
scale in every pose), loads the asset once (its SH order must be the scene's)
and poses a :class:`shtools.runtime.FieldBlocker` per frame from the object's
world matrix.  The runtime combines it as ``settings.field_space`` says (log
space by default, or product space).  The baker gives the posed blocker the
object's own receiver rows (``skip_rows``: a surface point lies inside the
field's innermost shells); on those rows the object is shadowed by its own
real mesh: the O_v stored in the asset (the estimate the bake would trace),
rotated with the object and multiplied in after the exp at the shading order, or
the ``transfer`` asset the scene names with ``self_visibility``
(:func:`shtools.scene.transfer.object_self_log`, :func:`shtools.scene.pose.pose_frame`).
So one asset gives a rigid object real-mesh shadows both on the other receivers and
on itself.  On the receiver-only objects near it (``traced_shadows``) its real mesh
is traced instead, handed over per vertex to the field
(:mod:`shtools.scene.traced_shadows`); the field skips the rows traced too.
"""

from __future__ import annotations

import numpy as np

from shtools.errors import AssetError, InputError
from shtools.scene.blockers import BlockerKind, register_blocker_kind


class FieldKind(BlockerKind):
    """``blocker = { field = "x.field.h5" }``: a rigid object's adaptive shadow field."""

    name = "field"
    value = "asset"
    hint = "'field' (a field asset)"

    def check(self, spec, obj):
        if obj.skin is not None:
            return ("field", "a shadow field is for rigid objects; a skinned object needs "
                             "'bound' or 'fit' spheres")
        for pose in [obj.pose] + [k.pose for k in obj.keyframes]:
            scale = np.asarray(pose.scale, dtype=float)
            if np.ptp(scale) > 1e-9 * np.max(scale):
                return ("field", f"a shadow field needs a uniform scale, got "
                                 f"{scale.tolist()}; use a sphere-set blocker for a stretched "
                                 "object")
        return None

    def prepare(self, spec, prep, ctx):
        from shtools.data_formats.field import read_field
        from shtools.data_formats.haar import asset_kind
        from shtools.runtime import FieldTable

        if asset_kind(spec.path) == "haar":  # an all-frequency field (shtools.scene.haar_blocker)
            from shtools.scene.haar_blocker import prepare_haar

            prepare_haar(spec, prep, ctx)
            return
        fld = read_field(spec.path)
        order = ctx.settings.order
        if fld.order != order:
            raise AssetError(f"field is SH order {fld.order} but the scene's settings.order is "
                             f"{order}; resample it with `shtools field sample --order "
                             f"{order}` or change the order", spec.path)
        if fld.self_visibility is not None and prep.spec.receives and \
                len(fld.self_visibility) != len(prep.vertices):
            raise AssetError(f"field holds self-visibility for {len(fld.self_visibility)} "
                             f"vertices but '{prep.spec.name}' has {len(prep.vertices)}; "
                             "resample it from this mesh", spec.path)
        table = FieldTable(fld)
        if fld.self_visibility is not None and prep.spec.receives:
            # the stored O_v, (V, self_order^2): the object's exact self-shadowing unless
            # the scene names a transfer asset (shtools.scene.transfer.object_self_log)
            table.self_visibility = np.asarray(fld.self_visibility, dtype=np.float32)
            table.self_order = fld.self_order
            # the estimate the bake would trace (geometry.transfer.FIELD_ESTIMATE);
            # fields sampled before hold the product rule's, which the bake traces again
            from shtools.geometry.transfer import FIELD_ESTIMATE

            recorded = fld.attrs.get("parameters", {})
            table.self_estimate = {k: recorded.get(k) for k in FIELD_ESTIMATE}
        prep.blocker_data = table
        ctx.inputs[f"{prep.spec.name}.field"] = spec.path

    def pose(self, prep, world, joints):
        from shtools.runtime import FieldBlocker
        from shtools.runtime.haar import HaarField

        if isinstance(prep.blocker_data, HaarField):
            from shtools.scene.haar_blocker import pose_haar

            return pose_haar(prep, world)

        try:
            return FieldBlocker.from_matrix(prep.blocker_data, world)
        except InputError as exc:
            raise InputError(f"objects '{prep.spec.name}': {exc.message}") from None


register_blocker_kind(FieldKind())
