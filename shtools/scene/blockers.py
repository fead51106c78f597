"""Blocker kinds: how an object of a scene blocks light (one small protocol, registered by name).

A scene object with ``role = "blocker"`` or ``"both"`` names its kind in its
blocker table, e.g. ``blocker = { tree = "bunny.tree.h5" }``.  A kind is a
:class:`BlockerKind` registered with :func:`register_blocker_kind`; it says

* ``name`` — its key in the blocker table (and ``BlockerSpec.kind``);
* ``value`` — what that key holds: ``"asset"`` (an ``.h5`` file), ``"count"``
  (an integer >= 1) or ``"flag"`` (``true``);
* ``options`` — further keys of the table it accepts (pydantic annotation, default);
* :meth:`~BlockerKind.check` — rules that need the object (e.g. a skinned mesh);
* :meth:`~BlockerKind.prepare` — load or build its data once, before frame 0;
* :meth:`~BlockerKind.pose` — the runtime blocker of one frame: a
  :class:`shtools.runtime.SphereBlocker` or any object with
  ``log_visibility(points, normals, order)`` (:class:`shtools.runtime.LogBlocker`),
  which the runtime adds to the log sum before the exp.

The scene schema (:func:`shtools.scene.schema.blocker_model`), the parser and
the baker read the registry; nothing else lists the kinds.  Built in: sphere
sets from assets (``spheres``, ``tree``, ``bound``), fitted on the fly
(``fit``) and the exact sphere of a sphere primitive (``exact``).  Adding a
kind is one module with a subclass and a :func:`register_blocker_kind` call,
imported by :mod:`shtools.scene.kinds` (see ``docs/architecture.md``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from shtools.errors import AssetError
from shtools.registry import Registry
from shtools.scene.specs import BlockerSpec


@dataclass
class PrepareContext:
    """What :meth:`BlockerKind.prepare` may use.

    Attributes
    ----------
    settings : shtools.scene.scene.Settings
    model : shtools.geometry.skin.SkinnedModel or None
        The object's skinned model (skinned objects only).
    inputs : dict
        ``name -> path`` of the files read; a kind adds its assets for provenance.
    progress : callable or None
        Progress factory (:mod:`shtools.progress`) for long preparations (fits, trees).
    cache : shtools.cache.SetupCache or None
        The set-up cache, for what a kind computes from its inputs alone (fits).
    """

    settings: Any
    model: Any = None
    inputs: dict[str, Path] = field(default_factory=dict)
    progress: Any = None
    cache: Any = None


class BlockerKind(ABC):
    """A kind of blocker (see the module docstring).  Subclass and register."""

    name: ClassVar[str]
    value: ClassVar[str]  # "asset" | "count" | "flag"
    #: one phrase for "give exactly one of ..." messages and docs
    hint: ClassVar[str] = ""
    #: further table keys: name -> (pydantic annotation, default)
    options: ClassVar[dict[str, tuple[Any, Any]]] = {}
    #: the blocker *is* the object's shape (a sphere primitive): a rigid object's real
    #: mesh is then not traced in its place on the ground (``traced_shadows``)
    exact: ClassVar[bool] = False

    def check(self, spec: BlockerSpec, obj) -> tuple[str, str] | None:
        """A rule the object breaks, as ``(key, message)``, or None.

        ``obj`` is the :class:`shtools.scene.scene.ObjectSpec` (its skin, primitive).
        """
        return None

    @abstractmethod
    def prepare(self, spec: BlockerSpec, prep, ctx: PrepareContext) -> None:
        """Load or build what :meth:`pose` needs into ``prep`` (a ``PreparedObject``)."""

    @abstractmethod
    def pose(self, prep, world: np.ndarray, joints: np.ndarray | None):
        """The runtime blocker at one frame.

        Parameters
        ----------
        prep : PreparedObject
        world : ndarray, shape (4, 4)
            Object-to-world transform this frame.
        joints : ndarray, shape (J, 4, 4) or None
            Skinning matrices this frame (skinned objects).
        """


class SphereSetKind(BlockerKind):
    """A blocker represented by a sphere set (optionally a tree, optionally skin-bound).

    Subclasses implement :meth:`load`, which sets ``prep.centers`` / ``prep.radii``
    (and ``prep.tree`` or the skin binding when the asset has them); the rest
    (a tree for the hierarchy, the skin binding, posing) is shared here.
    """

    #: branching of the tree built when the asset has none
    def branching(self, spec: BlockerSpec) -> int:
        return 4

    @abstractmethod
    def load(self, spec: BlockerSpec, prep, ctx: PrepareContext) -> None:
        """Set ``prep.centers``/``prep.radii`` (and a tree) from the blocker's value."""

    def prepare(self, spec, prep, ctx):
        self.load(spec, prep, ctx)
        if prep.centers is None:  # e.g. an exact sphere set filled from the primitive
            return
        if prep.tree is None and ctx.settings.hierarchy and len(prep.radii) > 1:
            from shtools.geometry.sphere_tree import build_tree

            t = build_tree(prep.centers, prep.radii, branching=self.branching(spec), seed=0,
                           progress=ctx.progress)
            prep.tree = (np.asarray(t.parent), np.asarray(t.leaf))
        if ctx.model is not None and prep.bone_index is None:
            from shtools.geometry.binding import bind_spheres

            binding = bind_spheres(prep.centers, ctx.model)
            prep.bone_index = np.asarray(binding.bone_index)
            prep.bone_vectors = np.asarray(binding.bone_vectors)

    def pose(self, prep, world, joints):
        from shtools.runtime import SphereBlocker
        from shtools.scene.animation import transform_spheres

        centers = prep.centers
        if joints is not None:
            from shtools.runtime.spheres import pose_bound_spheres

            centers = pose_bound_spheres(prep.bone_index, prep.bone_vectors, joints)
        c, r = transform_spheres(world, centers, prep.radii)
        # the runtime refits inner spheres from the leaves every frame
        return SphereBlocker(c, r, tree=prep.tree) if prep.tree is not None \
            else SphereBlocker(c, r)


class SpheresAsset(SphereSetKind):
    name, value, hint = "spheres", "asset", "'spheres' (a spheres asset)"

    def load(self, spec, prep, ctx):
        from shtools.data_formats.spheres import read_spheres

        s = read_spheres(spec.path)
        prep.centers, prep.radii = s.centers, s.radii
        ctx.inputs[f"{prep.spec.name}.spheres"] = spec.path


class TreeAsset(SphereSetKind):
    name, value, hint = "tree", "asset", "'tree' (a tree asset)"

    def load(self, spec, prep, ctx):
        from shtools.data_formats.tree import read_tree

        t = read_tree(spec.path)
        leaves = np.flatnonzero(t.leaf >= 0)
        n = int(t.leaf[leaves].max()) + 1
        centers, radii = np.empty((n, 3)), np.empty(n)
        centers[t.leaf[leaves]] = t.centers[leaves]
        radii[t.leaf[leaves]] = t.radii[leaves]
        prep.centers, prep.radii = centers, radii
        prep.tree = (np.asarray(t.parent), np.asarray(t.leaf))
        ctx.inputs[f"{prep.spec.name}.tree"] = spec.path


class BoundAsset(SphereSetKind):
    name, value, hint = "bound", "asset", "'bound' (a skin-bound sphere set)"

    def check(self, spec, obj):
        if obj.skin is None:
            return ("bound", "a bound sphere set needs a skinned object; add 'skin = {}' or "
                             "use 'spheres'/'tree'")
        return None

    def load(self, spec, prep, ctx):
        from shtools.data_formats.bound import read_bound

        b = read_bound(spec.path)
        n_joints = len(ctx.model.inverse_bind)
        if b.joint_count != n_joints:
            raise AssetError(f"is bound to a rig with {b.joint_count} joints but "
                             f"'{prep.spec.mesh.name}' has {n_joints}; rebind with "
                             "'shtools spheres bind'", spec.path)
        prep.centers, prep.radii = b.centers, b.radii
        prep.bone_index, prep.bone_vectors = b.bone_index, b.bone_vectors
        ctx.inputs[f"{prep.spec.name}.bound"] = spec.path


def _fit_options() -> dict[str, tuple[Any, Any]]:
    from typing import Annotated

    from pydantic import Field

    from shtools.geometry.fit_methods import FitMethod
    from shtools.scene.schema import choice

    return {
        "method": (choice(tuple(m.value for m in FitMethod)), "variational"),
        "seed": (Annotated[int, Field(strict=True, ge=0)], 0),
        "branching": (Annotated[int, Field(strict=True, ge=2)], 4),
    }


class FitSpheres(SphereSetKind):
    name, value, hint = "fit", "count", "'fit' (number of spheres to fit)"
    options = _fit_options()
    #: algorithm version of a cached fit (:mod:`shtools.cache`)
    version = 1

    def branching(self, spec):
        return spec.options["branching"]

    def load(self, spec, prep, ctx):
        def fit():
            import trimesh

            from shtools.geometry.sphere_fit import fit_spheres

            mesh = trimesh.Trimesh(prep.vertices, prep.faces, process=False)
            # the bake uses the spheres only: no E or coverage measured
            s = fit_spheres(mesh, spec.count, method=spec.options["method"],
                            seed=spec.options["seed"], progress=ctx.progress,
                            diagnostics=False, _desc=f"fit {prep.spec.name}")
            return {"centers": np.asarray(s.centers), "radii": np.asarray(s.radii)}

        if ctx.cache is None:
            got = fit()
        else:
            parts = {"vertices": np.asarray(prep.vertices), "faces": np.asarray(prep.faces),
                     "count": int(spec.count), "method": str(spec.options["method"]),
                     "seed": int(spec.options["seed"])}
            got = ctx.cache.fetch("fit", self.version, parts, fit)
        prep.centers, prep.radii = got["centers"], got["radii"]


class ExactSphere(SphereSetKind):
    name, value, hint = "exact", "flag", "'exact = true' (a sphere primitive)"
    exact = True

    def check(self, spec, obj):
        if obj.primitive is None or obj.primitive[0] != "sphere":
            return ("exact", "only a 'sphere' primitive is exactly a sphere set; use "
                             "'fit = N' or a spheres asset")
        return None

    def load(self, spec, prep, ctx):
        pass  # the primitive's own spheres, set when its mesh was generated


def _check_kind(kind: BlockerKind) -> None:
    if not getattr(kind, "name", None) or kind.value not in ("asset", "count", "flag"):
        raise ValueError(f"blocker kind {kind!r} needs a name and a value of asset, count "
                         "or flag")


#: name -> kind; read by the scene schema, the parser and the baker, complete once
#: :mod:`shtools.scene.kinds` (which imports the kinds in modules of their own) is
BLOCKER_KINDS: Registry[BlockerKind] = Registry("blocker kind", check=_check_kind)
#: add a blocker kind (its ``name`` becomes a blocker-table key); returns it
register_blocker_kind = BLOCKER_KINDS.register

for _kind in (SpheresAsset(), TreeAsset(), BoundAsset(), FitSpheres(), ExactSphere()):
    register_blocker_kind(_kind)
