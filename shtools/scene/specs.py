"""The parts of a parsed scene as data classes: objects, their poses and blockers, lights.

Filled by the parser (:mod:`shtools.scene.scene`, which also holds the whole
:class:`~shtools.scene.scene.Scene` and its ``Settings``) and read by the
animation, the blocker kinds and the baker.  Nothing here imports another
module of :mod:`shtools.scene`, so every one of them may import these.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: Strata per receiver that ``shadows = "ssoc"`` traces where the occlusion camera finds
#: penumbra (0: none; :func:`shtools.scene.light_shadows.ssoc_radiance`).
#: ``benchmarks/bench_ssoc.py`` (docs/ssoc.md): on the bunny's dark ground 4.7-5.5 %
#: against 7.3-12.2 % for the camera alone (64-ray tracing of every receiver 3.7-4.3 %);
#: 256 rays: 1.6-3.4 %, at 2.5-3.9x the camera's time on 100k receivers at 0.01-0.02
#: rad (the bunny's own vertices are penumbra too), close to tracing them all.
PENUMBRA_RAYS = 64


@dataclass
class BlockerSpec:
    """How an object blocks light, as parsed from its blocker table.

    Attributes
    ----------
    kind : str
        A registered :class:`~shtools.scene.blockers.BlockerKind` name.
    path : Path or None
        The asset of an ``"asset"`` kind (resolved against the scene folder).
    count : int or None
        The value of a ``"count"`` kind (spheres to fit).
    options : dict
        The kind's other keys (defaults filled in).
    """

    kind: str
    path: Path | None = None
    count: int | None = None
    options: dict[str, Any] = field(default_factory=dict)


@dataclass
class Pose:
    """A rigid transform ``T * R * S``: translation, unit quaternion (x, y, z, w), scale."""

    translate: np.ndarray = field(default_factory=lambda: np.zeros(3))
    quaternion: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))


@dataclass
class Keyframe:
    """A pose at a time (seconds)."""

    time: float
    pose: Pose


@dataclass
class SkinSpec:
    """Skinned animation of a glTF mesh: clip index or name, speed, time offset."""

    animation: int | str = 0
    speed: float = 1.0
    offset: float = 0.0


@dataclass
class ObjectSpec:
    """One ``[[objects]]`` entry."""

    name: str
    index: int
    role: str
    mesh: Path | None = None
    primitive: tuple[str, dict] | None = None
    albedo: np.ndarray = field(default_factory=lambda: np.ones(3))
    parent: str | None = None
    pose: Pose = field(default_factory=Pose)
    keyframes: list[Keyframe] = field(default_factory=list)
    loop: bool = False
    blocker: BlockerSpec | None = None
    skin: SkinSpec | None = None
    #: exact self-shadowing: None (the settings' default), False, True or a transfer asset
    self_visibility: bool | Path | None = None

    @property
    def receives(self) -> bool:
        return self.role in ("receiver", "both")

    @property
    def blocks(self) -> bool:
        return self.role in ("blocker", "both")


@dataclass
class EnvironmentSpec:
    """``[environment]``: exactly one of a light asset, an HDR image or inline SH."""

    kind: str | None = None  # "light" | "image" | "coeffs" | None (no environment)
    path: Path | None = None
    coeffs: np.ndarray | None = None
    intensity: float = 1.0
    rotate: float = 0.0  # radians about +Y
    #: mid-range lighting: the environment lies on a sphere of this radius about
    #: ``center`` (None: at infinity); ``scaling`` an optional midrange table asset
    radius: float | None = None
    center: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scaling: Path | None = None


@dataclass
class LightKey:
    time: float
    position: np.ndarray
    radius: float
    color: np.ndarray


@dataclass
class SphereLightSpec:
    """One ``[[lights]]`` spherical light (RGB radiance ``color * intensity``)."""

    name: str
    keys: list[LightKey]
    loop: bool = False
    #: the registered light-shadow way (:mod:`shtools.scene.shadows`)
    shadows: str = "shexp"
    #: strata per receiver of ``shadows = "raytrace"`` (:mod:`shtools.scene.light_shadows`)
    samples: int = 64
    #: ``SSOCSettings`` of ``shadows = "ssoc"``/``"auto"`` (None: the defaults)
    ssoc: Any = None
    #: strata per penumbra receiver of ``"ssoc"``/``"auto"`` (``ssoc.rays``; light_shadows)
    ssoc_rays: int = PENUMBRA_RAYS
    #: a field light: its ``srf`` asset (``shadows`` is then ``"field"`` or
    #: ``"field-shexp"``, :mod:`shtools.scene.field_light`) ...
    srf: Path | None = None
    #: ... its keyed lamp poses (translate = position; rotation, uniform scale) ...
    poses: list[Keyframe] = field(default_factory=list)
    #: ... and the factor on the asset's radiance
    intensity: float = 1.0
