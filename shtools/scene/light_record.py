"""The spherical lights a relight adds: recorded in the bake, or from a parsed scene.

A bake of a scene whose ``[[lights]]`` are all spheres (no source radiance
field) stores the lights it shaded with, posed at each frame's time
(:func:`~shtools.scene.pose.pose_lights`): the dataset ``light_poses (T, S, 7)``
float64, columns :data:`COLUMNS`, the scene's lights in order.  A relit bake
records the lights it was shaded with the same way (none: no dataset).

``shtools relight BAKE --lights SCENE`` with ``SCENE`` the very file those lights
came from (its sha256 is the one the bake recorded for it in ``inputs``) takes
them from the bake (:func:`own_lights`) instead of parsing the scene: the same
lights, without importing the parser (pydantic and every registered kind),
which costs more than relighting a small bake.  Every other case (an older bake,
another scene, a light shadowed another way than ``shexp``) parses the scene
(:func:`scene_lights`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shtools.errors import InputError

#: The columns of ``light_poses``: the centre, the radius and the RGB radiance of
#: :class:`~shtools.runtime.SphereLight`.
COLUMNS = ("x", "y", "z", "radius", "r", "g", "b")


def pose_table(frames: list) -> np.ndarray | None:
    """``light_poses (T, S, 7)`` of the posed lights of each frame, or None without lights.

    Parameters
    ----------
    frames : list of list of SphereLight
        Per frame, the same lights in the same order.
    """
    if not frames or not frames[0]:
        return None
    return np.array([[[*light.position, light.radius, *light.color] for light in lights]
                     for lights in frames], dtype=np.float64).reshape(len(frames), -1,
                                                                      len(COLUMNS))


def scene_pose_table(scene, times) -> np.ndarray | None:
    """``light_poses`` of a scene baked at ``times`` ``(T,)``; None when it has no
    lights or a field light (whose pose is not a sphere's)."""
    if not scene.lights or any(spec.srf is not None for spec in scene.lights):
        return None
    from shtools.scene.pose import pose_lights

    return pose_table([pose_lights(scene, float(t)) for t in times])


@dataclass
class PosedLights:
    """The spherical lights a relight adds, posed at each frame of the bake.

    Read from the bake (:func:`own_lights`) or posed from a parsed scene
    (:func:`posed`).

    Attributes
    ----------
    path : Path
        The scene file they come from.
    frames : list of list of SphereLight
        Per frame of the bake, its posed lights.
    inputs : list of str
        Read from the bake: the names of the files it recorded as its inputs (the
        scene names them); empty otherwise.
    """

    path: Path
    frames: list
    inputs: list

    @property
    def lights(self) -> list:
        return self.frames[0]

    def check_output(self, output: str | os.PathLike) -> None:
        """Refuse an existing ``output`` named as a file the bake's scene names.

        The parser path refuses any file the scene names
        (:func:`~shtools.scene.prepare.scene_files`); without the parser only their
        names are known (the bake's ``inputs``), so a file of one of those names is
        refused wherever it is.

        Raises
        ------
        InputError
        """
        out = Path(output)
        if out.name in self.inputs and out.exists():
            raise InputError(f"has the name of a file the scene {self.path.name} names (the "
                             "bake recorded it as an input); writing it could destroy that "
                             "input, choose another -o path", out)


def own_lights(bake, scene: str | os.PathLike) -> PosedLights | None:
    """The lights ``bake`` recorded, when ``scene`` is the file they came from; else None.

    None also when the bake recorded no lights (made before they were
    recorded, or with a field light) or some light is shadowed another way
    than ``shexp`` (``parameters.light_shadows``): relighting then parses the
    scene, which says what it cannot add.

    Parameters
    ----------
    bake : shtools.data_formats.bake.Bake
    scene : path-like
        A scene file (``--lights``).

    Returns
    -------
    PosedLights or None
    """
    from shtools.data_formats._base import sha256_file

    poses = getattr(bake, "light_poses", None)
    params = bake.parameters
    if poses is None or params.get("light_shadows") is not None:
        return None
    relit = params.get("relight")  # a relit bake: its lights came from its --lights scene
    source = relit.get("lights") if isinstance(relit, dict) else params.get("scene")
    inputs = bake.attrs.get("inputs") or {}
    recorded = inputs.get(source) if isinstance(source, str) else None
    try:
        if recorded is None or sha256_file(scene) != recorded:
            return None
    except OSError:  # unreadable: the parser says so
        return None
    from shtools.runtime.blockers import SphereLight

    poses = np.asarray(poses, dtype=np.float64)
    frames = [[SphereLight(position=p[:3], radius=float(p[3]), color=p[4:]) for p in frame]
              for frame in poses]
    return PosedLights(Path(scene), frames, sorted(inputs))


def bake_own_lights(bake: str | os.PathLike, scene: str | os.PathLike) -> PosedLights | None:
    """:func:`own_lights` of the bake file ``bake`` (None also when it is not a readable bake:
    relighting it says what is wrong)."""
    from shtools.data_formats.bake_stream import open_bake
    from shtools.errors import ShtoolsError

    try:
        with open_bake(bake) as b:
            return own_lights(b, scene)
    except (ShtoolsError, OSError):
        return None


def scene_lights(scene, bake=None):
    """The lights a relight adds for ``scene``, each shaded through the stored visibility.

    Parameters
    ----------
    scene : path-like, shtools.scene.scene.Scene or PosedLights
        A path is first tried as the bake's own scene (:func:`own_lights`), then parsed.
    bake : shtools.data_formats.bake.Bake, optional
        The bake relit.

    Returns
    -------
    PosedLights or shtools.scene.scene.Scene
        The latter checked: every light a sphere with ``shadows = "shexp"``.

    Raises
    ------
    InputError
        A field light, a light shadowed another way than ``shexp``, or none at all.
    """
    if isinstance(scene, PosedLights):
        return scene
    if bake is not None and isinstance(scene, str | os.PathLike):
        own = own_lights(bake, scene)
        if own is not None:
            return own
    from shtools.scene.scene import Scene, load_scene
    from shtools.scene.shadows import ShexpLight

    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    for spec in scene.lights:
        if spec.srf is not None:
            raise InputError(f"light '{spec.name}' is a field light (field = "
                             f"\"{spec.srf.name}\"); relighting adds spherical lights "
                             "(shadows = \"shexp\") only: bake the scene for it", scene.path)
        if spec.shadows != ShexpLight.name:
            raise InputError(f"light '{spec.name}' uses shadows = \"{spec.shadows}\", which "
                             "needs the posed blocker meshes a bake does not keep; relighting "
                             "shades spherical lights through the stored visibility (shadows = "
                             "\"shexp\") only", scene.path)
    if not scene.lights:
        raise InputError("has no [[lights]] to add; leave the scene out", scene.path)
    return scene


def posed(bake, scene) -> PosedLights:
    """:func:`scene_lights` of ``scene`` posed at each frame of ``bake``."""
    scene = scene_lights(scene, bake)
    if isinstance(scene, PosedLights):
        if len(scene.frames) != bake.n_frames:
            raise ValueError(f"{len(scene.frames)} frames of posed lights for a bake of "
                             f"{bake.n_frames}")
        return scene
    from shtools.scene.pose import pose_lights

    return PosedLights(Path(scene.path), [pose_lights(scene, float(t)) for t in bake.times], [])


def lamps_as_baked(bake, table: np.ndarray | None) -> bool | None:
    """Whether each lamp of ``table`` (the relit lamps' :func:`pose_table`, ``(T, S, 7)``
    or None for none) sits where one of the bake's recorded lamps sat, at its size, at
    every frame (in any order; a lamp left out is not a difference); None when the
    bake's record cannot say.

    A stored visibility keeps one thing of the bake's lamps: where they were.  A
    spherical light that a traced object may hide keeps the object's real mesh traced
    on the receivers behind it however far
    (:func:`~shtools.scene.traced_shadows.light_weights`), for the lamps the bake had;
    their colours do not enter it.  The record cannot say for a bake that recorded no
    lamps (it had none, or a field light, or it predates the record) and for a relit
    bake (its record holds the lamps it was relit with, its visibility the reach of
    the first bake's).  True when there is no relit lamp.
    """
    poses = getattr(bake, "light_poses", None)
    if poses is None or "relight" in bake.parameters:
        return None
    if table is None:
        return True
    recorded = np.asarray(poses[...], dtype=np.float64)[..., :4]
    if table.shape[0] != recorded.shape[0]:
        return False
    # (T, relit, recorded): a relit lamp matches a recorded one of the same frame
    same = np.isclose(table[:, :, None, :4], recorded[:, None, :, :], rtol=1e-9,
                      atol=0.0).all(axis=-1)
    return bool(same.any(axis=2).all())


def frame_lights(bake, scene=None) -> list:
    """The posed spherical lights of each frame of ``bake`` (:func:`posed`); empty lists
    without ``scene``."""
    if scene is None:
        return [[] for _ in range(bake.n_frames)]
    return posed(bake, scene).frames
