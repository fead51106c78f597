r"""Source-radiance-field lights: RCV lookup and shading (NumPy + h5py only).

A :class:`FieldLight` is a lamp carrying a source radiance field
(:class:`shtools.data_formats.srf.RadianceField`), posed by a rotation, a
translation and a uniform scale.  Per receiver point:

1. the point in the lamp's frame, ``p_loc = R^T (p - t) / s`` (radiance is
   invariant under a uniform scale of the whole lamp);
2. the RCV looked up like an occlusion field's OCV
   (:class:`shtools.runtime.fields.FieldTable`: two nearest shells, bilinear on
   each, theta clamped, phi wrapped; inside the first shell, clamped);
3. **beyond the last shell** the last shell's RCV in the point's direction,
   times ``(r_last / d)^2``: the lamp's solid angle, hence every coefficient
   of its radiance, falls off with the square of the distance once the lamp
   looks small (at the default 6.4 V_r it subtends 9 degrees);
4. each channel's SH vector rotated to the world (one rotation matrix per lamp).

Shading (Tamura et al. Fig. 3): the receiver's transfer, multiplied by a
visibility, double-producted with the world RCV: :func:`field_light_radiance`
passes the RCVs as a per-vertex environment to
:func:`shtools.runtime.shading.shade`.  Which visibility -- that of only the
blockers nearer than the lamp, or none, the blockers' shadow then traced -- is
the scene's choice (:mod:`shtools.scene.field_light`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from shtools.errors import InputError
from shtools.runtime.fields import SCALE_TOL, FieldTable
from shtools.sh import rotation_matrix


class RadianceTable(FieldTable):
    """A radiance field laid out for lookups (:class:`FieldTable` with three channels)."""

    def __init__(self, fld):
        super().__init__(fld)
        self.radiance = np.asarray(fld.radiance, dtype=np.float64)
        self.emitter_center = np.asarray(fld.emitter_center, dtype=np.float64)
        self.emitter_radius = float(fld.emitter_radius)

    def radiance_lookup(self, points) -> np.ndarray:
        """RCVs at lamp-frame points (no rotation), shape ``(P, 3, n*n)`` float32."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        rel = p - self.center
        d = np.linalg.norm(rel, axis=1)
        r_last = float(self.radii[-1])
        far = d > r_last
        q = p.copy()
        q[far] = self.center + rel[far] * (r_last / d[far])[:, None]
        out = self.lookup(q, "ocv").reshape(p.shape[0], 3, self.order ** 2)
        out[far] *= ((r_last / d[far]) ** 2).astype(np.float32)[:, None, None]
        return out


@dataclass
class FieldLight:
    """A lamp with a source radiance field, posed for one frame.

    Parameters
    ----------
    table : RadianceTable or RadianceField
    rotation : array_like, shape (3, 3)
        Lamp-to-world rotation (proper).
    translation : array_like, shape (3,)
    scale : float
        Uniform scale (> 0).
    intensity : float
        Multiplies the stored radiance (>= 0).
    """

    table: Any
    rotation: Any = field(default_factory=lambda: np.eye(3))
    translation: Any = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0
    intensity: float = 1.0

    def __post_init__(self):
        if not isinstance(self.table, RadianceTable):
            self.table = RadianceTable(self.table)
        self.rotation = np.asarray(self.rotation, dtype=np.float64).reshape(3, 3)
        self.translation = np.asarray(self.translation, dtype=np.float64).reshape(3)
        R = self.rotation
        if not (np.allclose(R.T @ R, np.eye(3), atol=1e-6) and np.linalg.det(R) > 0):
            raise InputError("a field light needs a proper rotation (no mirror, no shear)")
        if not (self.scale > 0 and math.isfinite(self.scale)):
            raise InputError(f"a field light needs a scale > 0, got {self.scale!r}")
        if not (self.intensity >= 0 and math.isfinite(self.intensity)):
            raise InputError(f"a field light needs an intensity >= 0, got {self.intensity!r}")
        if not np.isfinite(self.translation).all():
            raise InputError("a field light's position contains NaN or inf")

    @classmethod
    def from_matrix(cls, table, matrix, intensity: float = 1.0) -> FieldLight:
        """Pose from a 4x4 lamp-to-world matrix; refuses non-uniform scale and shear."""
        m = np.asarray(matrix, dtype=np.float64)
        scales = np.linalg.norm(m[:3, :3], axis=0)
        s = float(scales.mean())
        if not s > 0 or np.ptp(scales) > SCALE_TOL * s:
            raise InputError("a field light needs a rigid pose with a uniform scale; got "
                             f"scales {np.round(scales, 6).tolist()}")
        return cls(table, m[:3, :3] / s, m[:3, 3], s, intensity)

    def world_point(self, local) -> np.ndarray:
        """A lamp-frame point in the world, shape (3,)."""
        return self.rotation @ np.asarray(local, dtype=np.float64) * self.scale \
            + self.translation

    @property
    def world_center(self) -> np.ndarray:
        """The emitter's bounding-sphere centre in the world, shape (3,): the light's
        distance for the nearer-blocker rule."""
        return self.world_point(self.table.emitter_center)

    @property
    def world_emitter_radius(self) -> float:
        return self.table.emitter_radius * self.scale

    def world_rcv(self, points) -> np.ndarray:
        """World-frame RCVs at world points, shape ``(P, n*n, 3)`` float32 (a per-vertex
        environment for :func:`shtools.runtime.shading.shade`)."""
        local = (np.asarray(points, dtype=np.float64) - self.translation) @ self.rotation \
            / self.scale
        rcv = self.table.radiance_lookup(local)
        D = rotation_matrix(self.rotation, self.table.order).astype(np.float32)
        world = rcv @ D.T  # (P, 3, n*n): every channel rotated
        return np.ascontiguousarray(np.swapaxes(world, 1, 2)) * np.float32(self.intensity)


def field_light_radiance(light: FieldLight, visibility, points, normals, *, order: int,
                         window_kind: str | None = "cosine", window_h: float | None = None
                         ) -> np.ndarray:
    """Outgoing radiance of white Lambertian receivers lit by one field light, ``(V, 3)``.

    ``(H(N) * g) . L_v`` with ``L_v`` the lamp's world RCV at each receiver
    (:func:`shtools.runtime.shading.shade` with a per-vertex environment).

    Parameters
    ----------
    light : FieldLight
    visibility : array_like, shape (V, n*n)
        The receivers' visibility (of the blockers nearer than the lamp, or of
        none).
    points, normals : array_like, shape (V, 3)
    order : int
        Shading order; the field must have it.
    window_kind, window_h
        As :func:`shtools.runtime.shading.shade`.
    """
    from shtools.runtime.shading import shade

    if light.table.order != order:
        raise InputError(f"a radiance field has SH order {light.table.order} but the scene "
                         f"shades at order {order}; resample it with `shtools field sample "
                         f"--radiance ... --order {order}`")
    rcv = light.world_rcv(points)
    return shade(visibility, points, normals, rcv, order=order, window_kind=window_kind,
                 window_h=window_h)
