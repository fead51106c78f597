"""The kept results of :func:`shtools.scene.traced_shadows.traced_ground`, per process.

A still object over still receivers is traced once per bake: the result of the
same inputs (the caster by identity, the arrays by value) comes back as copies.  A
scene's moving objects add a trace each frame, with a new caster each (their Embree
scenes are rebuilt when they move), so the kept results are dropped least recently
used first: a still column beside a walker, found again every frame, stays kept for
the whole bake.  (Dropping the freed casters' results first instead cost CesiumMan's
frame 5 % more: their arrays freed and allocated again every frame.)
"""

from __future__ import annotations

import weakref

import numpy as np

#: Per process: the last results of :func:`traced_ground`, by caster and call (a weak
#: reference to it and copies of the other inputs kept beside them).  A rigid object's
#: Embree scene is reused while it stays put, so an object and receivers that do not move
#: are traced once per bake, not once per frame.
_GROUND: dict = {}
#: Casters whose last result :data:`_GROUND` keeps (a scene's traced objects).
GROUND_KEPT = 16


def _same(a, b) -> bool:
    """Equal inputs of :func:`traced_ground` (arrays by value, the caster by identity)."""
    if a is b:
        return True
    if isinstance(a, tuple | list) and isinstance(b, tuple | list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b)
    if isinstance(a, int | float | np.number) and isinstance(b, int | float | np.number):
        return a == b
    return False


def _slot(key: tuple) -> tuple:
    """Where :data:`_GROUND` keeps the result of the inputs ``key`` (caster, points,
    normals, ..., n_dirs at 6, strata at 9): one caster may serve several calls a frame
    (a rigid group's scene traced on the ground and on its own parts)."""
    return id(key[0]), len(key[1]), key[6], key[9]


def kept(key: tuple):
    """Copies of the kept result of the same inputs ``key`` (caster first), or None."""
    entry = _GROUND.get(_slot(key))
    if entry is None or entry[0][0]() is not key[0] or not _same(entry[0][1:], key[1:]):
        return None
    _GROUND[_slot(key)] = _GROUND.pop(_slot(key))  # the least recently used go first
    return tuple(x.copy() for x in entry[1])


def keep(key: tuple, result: tuple) -> tuple:
    """Keep copies of ``result`` (the inputs as copies too: a caller may reuse its arrays)."""
    if len(_GROUND) >= GROUND_KEPT:
        _GROUND.pop(next(iter(_GROUND)))
    try:
        ref = weakref.ref(key[0])  # a skinned mesh's per-frame caster is not kept alive
    except TypeError:
        return result
    _GROUND.pop(_slot(key), None)
    _GROUND[_slot(key)] = ((ref, *(_copied(x) for x in key[1:])),
                           tuple(x.copy() for x in result))
    return result


def _copied(x):
    """Nested tuples/lists of arrays, the arrays copied."""
    if isinstance(x, tuple | list):
        return tuple(_copied(y) for y in x)
    return np.array(x, copy=True) if isinstance(x, np.ndarray) else x
