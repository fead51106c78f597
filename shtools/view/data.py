"""What the browser viewer shows of a bake: geometry, per-frame display colours, blocker spheres.

Colours are computed here, with the export's own functions
(:func:`shtools.export.quantity.display_linear`: albedo for ``radiance``, the
automatic exposure of :func:`~shtools.export.quantity.display_scale` over every
frame, the ACES tone curve, sRGB encoding), so the viewer shows what
``shtools export`` writes; the page only draws them.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from shtools.errors import InputError

#: The tone curve of the viewer (the export's default).
CURVE = "aces"


@dataclass
class SceneSpheres:
    """The blockers of a bake's scene, posed at each frame's time (the sphere-set overlay).

    Parameters
    ----------
    prepared : shtools.scene.prepare.PreparedScene
    times : ndarray, shape (T,)
        The bake's frame times, seconds.
    """

    prepared: object
    times: np.ndarray
    _cache: dict = field(default_factory=dict)

    def frame(self, t: int) -> np.ndarray:
        """Sphere centres and radii of asset frame ``t``, shape ``(N, 4)`` float32."""
        if t not in self._cache:
            from shtools.scene.pose import pose_frame

            state = pose_frame(self.prepared, float(self.times[t]), trace=False)
            rows = [np.column_stack([b.centers, b.radii]) for b in state.blockers
                    if hasattr(b, "centers") and hasattr(b, "radii")]
            self._cache[t] = (np.concatenate(rows) if rows else np.zeros((0, 4))
                              ).astype(np.float32)
        return self._cache[t]


class BakeView:
    """A bake as the viewer page reads it (little-endian binary arrays and a JSON summary).

    Parameters
    ----------
    path : path-like
        A bake asset.
    spheres : SceneSpheres, optional
        The sphere-set overlay.

    Raises
    ------
    AssetError
        Not a bake asset (one line naming the file).
    """

    def __init__(self, path: str | os.PathLike, spheres: SceneSpheres | None = None):
        from shtools.data_formats.bake import read_bake
        from shtools.export.quantity import QUANTITIES, display_scale

        self.bake = read_bake(path)
        self.spheres = spheres
        b = self.bake
        self.quantities = [q for q in QUANTITIES if q != "visibility" or b.visibility is not None]
        every = list(range(b.n_frames))
        #: automatic exposure per quantity, shared by all frames (as an exported sequence)
        self.scales = {q: display_scale(b, every, q) for q in self.quantities}
        self.path = os.fspath(path)

    def summary(self) -> dict:
        """The page's description of the bake: frames, fps, objects, quantities, bounds."""
        b = self.bake
        pts = b.vertices.reshape(-1, 3)
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        faces = 0
        objects = []
        for o, name in enumerate(b.object_names):
            n_faces = len(b.object_faces(o))
            objects.append({"name": name, "first_face": faces, "faces": n_faces,
                            "first_vertex": int(b.object_offsets[o]),
                            "vertices": int(b.object_offsets[o + 1] - b.object_offsets[o])})
            faces += n_faces
        return {
            "name": os.path.basename(self.path),
            "frames": b.frame_index.tolist(),
            "times": b.times.tolist(),
            "fps": float(b.attrs.get("fps") or 24.0),
            "vertices": b.n_vertices,
            "moving": b.vertices.ndim == 3,
            "objects": objects,
            "quantities": self.quantities,
            "center": ((lo + hi) / 2).tolist(),
            "radius": float(np.linalg.norm(hi - lo) / 2) or 1.0,
            "spheres": self.spheres is not None,
        }

    def frame_position(self, t) -> int:
        """Asset frame ``t`` (0-based) checked against the bake's frame count."""
        try:
            t = int(t)
        except (TypeError, ValueError):
            raise InputError(f"frame '{t}' is not a whole number") from None
        if not 0 <= t < self.bake.n_frames:
            raise InputError(f"frame {t} is outside 0..{self.bake.n_frames - 1}")
        return t

    def faces(self) -> bytes:
        """Triangles grouped by object (the order of :meth:`summary`), uint32 ``(F, 3)``."""
        b = self.bake
        parts = [b.object_faces(o) + b.object_offsets[o] for o in range(len(b.object_names))]
        return np.concatenate(parts).astype("<u4").tobytes()

    def positions(self, t: int) -> bytes:
        """Vertex positions of asset frame ``t``, float32 ``(V, 3)``."""
        return np.asarray(self.bake.frame_vertices(self.frame_position(t)), "<f4").tobytes()

    def colors(self, t: int, quantity: str, exposure: float = 0.0) -> bytes:
        """sRGB display colours of asset frame ``t``, uint8 ``(V, 3)``.

        ``exposure`` in stops on top of the automatic exposure.
        """
        from shtools.export.quantity import display_linear
        from shtools.export.tonemap import srgb_encode, to_uint8

        if quantity not in self.quantities:
            raise InputError(f"quantity '{quantity}' is not one of {', '.join(self.quantities)}")
        if not math.isfinite(exposure) or abs(exposure) > 60:
            raise InputError(f"exposure {exposure} is outside -60..60 stops")
        scale = self.scales[quantity] * 2.0 ** exposure
        linear = display_linear(self.bake, self.frame_position(t), quantity, scale, CURVE)
        return to_uint8(srgb_encode(linear)).tobytes()

    def sphere_bytes(self, t: int) -> bytes:
        """Blocker spheres of asset frame ``t``, float32 ``(N, 4)`` (empty without a scene)."""
        if self.spheres is None:
            return b""
        return np.asarray(self.spheres.frame(self.frame_position(t)), "<f4").tobytes()


def scene_spheres(scene: str | os.PathLike, bake) -> SceneSpheres:
    """The sphere-set overlay of ``bake`` from its scene file (prepared once, posed per frame).

    Raises
    ------
    InputError
        The scene has no sphere blockers.
    """
    from shtools.scene.prepare import prepare_scene
    from shtools.scene.scene import load_scene

    parsed = load_scene(scene)
    prepared = prepare_scene(parsed)
    spheres = SceneSpheres(prepared, np.asarray(bake.times, dtype=np.float64))
    if len(spheres.frame(0)) == 0:
        raise InputError("has no sphere blockers to overlay; leave --scene out", scene)
    return spheres
