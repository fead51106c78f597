"""All-frequency field blockers in a bake: ``blocker = { field = "x.haar.h5" }``.

The ``field`` kind (:mod:`shtools.scene.field_blocker`) reads the asset's kind
and hands a ``haar`` asset here: :func:`prepare_haar` loads it and
:func:`pose_haar` poses a :class:`shtools.runtime.haar_shading.HaarBlocker`.
Such a blocker is neutral in the frame's SH visibility, so every visibility
method (SHEXP, product) gives the visibility of the *other* blockers
(sphere sets, SH fields, deformable fields, traced shadows and the receivers'
self-visibility).  :func:`shade_all_frequency` then shades the environment in
the map basis: that SH visibility evaluated on the map's cells, times every
Haar blocker's world-frame map, against the environment averaged into the
same cells (an HDR image: its pixels binned; a light asset or inline SH: the
SH radiance at the cell centres, no window), by the cell-wise sum or Ng et
al.'s triple product (:data:`SCHEME`).  Spherical lights shaded with
the SH visibility see the Haar fields projected to SH at the shading order
and multiplied in (an SH product).  ``--method raytrace`` traces every
blocker's mesh, the Haar objects' too, so it shades in SH as usual (the
reference).  A mid-range environment is refused (the maps are directions at
infinity).
"""

from __future__ import annotations

import math

import numpy as np

from shtools.errors import InputError

#: Environment shading in the map basis: "cells" (pixel domain), "triple" (Ng et al.'s
#: wavelet triple product) or "auto": the same radiance to rounding, so the faster one
#: (:func:`_triple_is_faster`; benchmarks/bench_haar.py --part sun times both).
SCHEME = "auto"

#: Most distinct receiver normals for which "auto" picks the triple product.
TRIPLE_MAX_NORMALS = 64


def prepare_haar(spec, prep, ctx) -> None:
    """Load a ``haar`` asset as the object's blocker data."""
    from shtools.runtime.haar import HaarField

    prep.blocker_data = HaarField.from_asset(spec.path)
    ctx.inputs[f"{prep.spec.name}.field"] = spec.path


def pose_haar(prep, world):
    """The posed :class:`~shtools.runtime.haar_shading.HaarBlocker` of one frame."""
    from shtools.runtime.haar_shading import HaarBlocker

    try:
        return HaarBlocker.from_matrix(prep.blocker_data, world)
    except InputError as exc:
        raise InputError(f"objects '{prep.spec.name}': {exc.message}") from None


def haar_blockers(run, state) -> list:
    """The frame's all-frequency blockers that shade the environment (none under raytrace)."""
    if run.method == "raytrace":
        return []
    return [b for b in state.blockers if getattr(b, "all_frequency", False)]


def environment_cells(run, size: int) -> np.ndarray | None:
    """The scene's environment as mean radiance per world map cell ``(M*M, 3)`` (cached)."""
    key = ("haar_env", size)
    if key in run.cache:
        return run.cache[key]
    prepared = run.prepared
    env = prepared.scene.environment
    if prepared.midrange is not None:
        raise InputError("an all-frequency (haar) field blocker needs the environment at "
                         "infinity; remove [environment] radius or use an SH field",
                         prepared.scene.path)
    from shtools.runtime.haar_shading import cell_of, map_directions

    dirs, w = map_directions(size)
    if env.kind is None:
        cells = None
    elif env.kind == "image":
        from shtools.lighting.environment import environment_rotation
        from shtools.lighting.images import load_hdr_image
        from shtools.lighting.latlong import latlong_directions, pixel_solid_angles

        image = np.asarray(load_hdr_image(env.path), dtype=np.float64)[..., :3]
        # pixels binned into cells: split coarse pixels (the same piecewise-constant image)
        # until a cell row spans at least two pixel rows, so that no cell is left empty
        f = max(1, math.ceil(2 * size / image.shape[0]))
        if f > 1:
            image = np.repeat(np.repeat(image, f, axis=0), f, axis=1)
        H, W = image.shape[:2]
        d = latlong_directions(H, W).reshape(-1, 3) @ \
            environment_rotation(math.degrees(env.rotate)).T
        pw = pixel_solid_angles(H, W).reshape(-1)
        acc = np.zeros((size * size, 3))
        np.add.at(acc, cell_of(d, size), image.reshape(-1, 3) * pw[:, None])
        cells = acc / w[:, None] * env.intensity
    else:
        from shtools.sh import basis

        sh = np.asarray(prepared.env_sh, dtype=np.float64)
        cells = basis(dirs, math.isqrt(sh.shape[0])) @ sh
    run.cache[key] = cells
    return cells


def shade_all_frequency(run, state, visibility, haar: list, joined: list) -> np.ndarray:
    """Radiance ``(V, 3)`` of the environment and the SH-shaded lights with Haar blockers.

    Parameters
    ----------
    visibility : ndarray, shape (V, n*n)
        The frame's SH visibility (every blocker but the Haar ones).
    haar : list of HaarBlocker
    joined : list of SphereLight
        Lights shaded with the SH visibility.
    """
    from shtools.runtime.haar_shading import (
        TripleShader,
        combined_coefficients,
        combined_maps,
        map_directions,
        shade_cells,
    )

    M = haar[0].map_size
    if any(b.map_size != M for b in haar):
        raise InputError("the scene's haar field blockers have different map sizes; resample "
                         "them with one --map", run.prepared.scene.path)
    pts, nrm = state.vertices, state.normals
    radiance = np.zeros((len(pts), 3))
    env = environment_cells(run, M)
    if env is not None:
        others = None if _unoccluded(visibility) else visibility
        scheme = SCHEME
        if scheme == "auto":
            scheme = "triple" if _triple_is_faster(haar, others, nrm) else "cells"
        if scheme == "triple":
            key = ("haar_triple", M)
            if key not in run.cache:
                run.cache[key] = TripleShader(env)
            shader = run.cache[key]
            if len(haar) == 1 and others is None and haar[0].unrotated:
                radiance += shader.radiance_sparse(*haar[0].sparse_terms(pts), nrm)
            else:
                radiance += shader.radiance(combined_coefficients(haar, pts, others), nrm)
        else:
            radiance += shade_cells(combined_maps(haar, pts, others), env, nrm)
    if joined:
        from shtools.sh import basis, product

        order = run.settings.order
        dirs, w = map_directions(M)
        haar_sh = combined_maps(haar, pts) @ (basis(dirs, order) * w[:, None])
        radiance += run.runtime.shade(product(visibility, haar_sh, order), pts, nrm, None,
                                      sphere_lights=joined)
    return radiance


def _unoccluded(visibility) -> bool:
    """The SH visibility is the constant 1 everywhere (no other blocker reaches a receiver)."""
    if visibility is None:
        return True
    g = np.asarray(visibility, dtype=np.float64)
    return bool(np.allclose(g[:, 0], math.sqrt(4 * math.pi), atol=1e-6)
                and np.allclose(g[:, 1:], 0.0, atol=1e-6))


def _triple_is_faster(haar: list, others, normals) -> bool:
    """Whether ``"auto"`` shades by the triple product: one unrotated Haar field and no SH
    factor (the Haar coefficients are then the looked-up ones, with no Haar-domain
    product or resampling), on receivers with few distinct normals (their lit transfer is
    computed once and kept)."""
    return (len(haar) == 1 and others is None and haar[0].unrotated
            and len(np.unique(normals, axis=0)) <= TRIPLE_MAX_NORMALS)
