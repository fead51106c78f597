"""Fidelity against the real meshes: shadow settings compared with ray tracing.

Scenes built from ``../shared/data`` (never committed):

* ``bunny`` — the scanned (open) bunny, 48 spheres, on a ground grid under the
  Uffizi probe;
* ``dragon+armadillo`` — two large closed meshes (64 spheres each) shadowing
  each other under the Mondello beach probe (a hard sun);
* ``cesiumman`` — the skinned CesiumMan (48 bound spheres) walking under Grace;
* ``fox`` — the skinned Fox (48 bound spheres, walk clip) under Grace.

Every scene is baked with each variant (:data:`VARIANTS`, ``--variants``; the
assets are shared): the **old default** (``self_visibility = false``: every
blocker, the objects' own included, as spheres with the self-shadow rules),
**self+spheres** (exact self-shadowing from a ``transfer`` asset, sphere trees as the
objects' blockers, whose real meshes near them are traced on the other receivers as
by default, ``traced_shadows``) and **new**: every rigid object a shadow-field
blocker (``blocker = { field = ... }``) whose asset also holds its O_v, so the
real mesh shadows the other receivers and the object itself (skinned objects
keep their bound spheres for the other receivers and, with ``self_visibility``
on as in self+spheres and new, trace their posed mesh on their own vertices every
frame: the rest-pose ``g_p`` is a ``--skinned`` row).  The reference is the project's
ray tracer of the posed **real meshes**
(:func:`shtools.reference.raytrace_visibility`, >= 3,200 directions, projected
to the same order and shaded the same way; cached per scene, it depends on no
variant); the sphere union (:func:`~shtools.reference.sphere_union_visibility`,
with the rules) splits the error into "sphere approximation" and "SHEXP".
References are evaluated on a random subset of each receiver's vertices (an
unbiased estimate of the relative RMSE; the bakes cover every vertex).  Per
frame bake times of the variants come from the same run, alternated, the fastest
repeat kept; the one-off precompute (``shtools transfer``, ``shtools field
sample``) is reported separately.  Negative vertices: vertices with any radiance
channel < 0 over every baked frame.  ``--variant NAME=BASE;key = value;...``
adds an experiment (e.g. ``field_space = "product"``, ``field=--resolution 128``).

Assets (sphere fits, trees, bound sets, transfers, fields) are cached in
``build/bench_fidelity``.

``python benchmarks/bench_fidelity.py [--quick]`` (quick: the small ``spot``
mesh on a coarse ground only, fewer directions).  ``--skinned [--scene fox]``:
skinned characters tracing their posed mesh every frame (own vertices, and the ground
in the cone of their bounding sphere): the old default, "spheres on ground"
(the characters' spheres shade the ground) and the ground's ray counts, accuracy and
frame time (wall and CPU) side by side, negatives (``--skinned-variants``; ``--skinned-sections
quadrature,interpolation`` adds the own vertices' direction sets and every-k-th-frame
tracing).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
CACHE = REPO / "build" / "bench_fidelity"
SHTOOLS = [sys.executable, "-m", "shtools"]
#: Alternating repeats of the two variants' bakes for the frame times (min kept).
REPEATS = 2


def _run(*args) -> float:
    """Run a shtools stage (cached by the caller); returns its wall seconds."""
    t0 = time.perf_counter()
    subprocess.run([*SHTOOLS, *map(str, args)], check=True, env={**os.environ,
                                                                 "OPENBLAS_NUM_THREADS": "1"})
    return time.perf_counter() - t0


#: What a cached asset of each stage holds, raised when shtools changes it (a cached
#: asset of another version is built again; no stamp: 1).  2: the O_v of a field and
#: a transfer asset by the bake's hemisphere estimator; field 3: its ray counts recorded.
ASSET_VERSIONS = {"field": 3, "transfer": 2}


def _ensure(path: Path, *args) -> float:
    """Build ``path`` with ``shtools args`` unless cached at its stage's
    :data:`ASSET_VERSIONS`; seconds spent (0 when cached)."""
    version = ASSET_VERSIONS.get(str(args[0]), 1)
    stamp = path.with_name(path.name + ".version")
    try:
        held = int(stamp.read_text()) if stamp.exists() else 1
    except ValueError:  # an unreadable stamp: built again
        held = None
    if path.exists() and held == version:
        return 0.0
    seconds = _run(*args, "-o", path)  # (a failed build raises: no stamp is written)
    stamp.write_text(f"{version}\n")
    return seconds


def placement(mesh_path: Path, height: float, x: float, z: float, yaw: float = 0.0):
    """TOML transform lines putting a mesh of the given height on the ground at (x, z)."""
    from shtools.geometry.mesh import load_mesh

    lo, hi = load_mesh(mesh_path).bounds
    s = height / (hi[1] - lo[1])
    cx, cz = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[2] + hi[2])
    c, sn = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    # world = T + R_y (s v): centre the footprint at (x, z) and the lowest point at y = 0
    tx = x - s * (c * cx + sn * cz)
    tz = z - s * (-sn * cx + c * cz)
    return (f"scale = {s:.6g}\ntranslate = [{tx:.6g}, {-s * lo[1]:.6g}, {tz:.6g}]\n"
            f"rotate = [0.0, {yaw:.6g}, 0.0]\n")


def _rigid(name, mesh_key, spheres, height, x, z, yaw, pre: dict) -> str:
    """A rigid ``role = "both"`` object with sphere-tree blocker and transfer asset.

    Variants that cast with the real mesh swap the tree for the object's field
    (:func:`_field_for`, built only when such a variant runs).
    """
    mesh = DATA / "meshes" / mesh_key
    sph = CACHE / f"{name}{spheres}.spheres.h5"
    tree = CACHE / f"{name}{spheres}.tree.h5"
    tr = CACHE / f"{name}.transfer.h5"
    pre[f"{name} fit"] = _ensure(sph, "spheres", "fit", mesh, "-n", spheres)
    _ensure(tree, "spheres", "tree", sph)
    pre[f"{name} transfer"] = _ensure(tr, "transfer", mesh)
    _MESH_OF_TREE[str(tree)] = (name, mesh)
    return (f'[[objects]]\nname = "{name}"\nmesh = "{mesh}"\nrole = "both"\n'
            f'blocker = {{ tree = "{tree}" }}\nself_visibility = "{tr}"\n'
            + placement(mesh, height, x, z, yaw))


#: tree asset -> (object name, mesh), filled by :func:`_rigid`
_MESH_OF_TREE: dict[str, tuple[str, Path]] = {}


def _field_for(match, pre: dict, field_options: tuple) -> str:
    """``blocker = { field = ... }`` replacing a rigid object's tree (``re`` match).

    The field holds the object's O_v (``shtools field sample``'s default, the estimate
    the bake would trace): the one asset shadows the other receivers and the object
    itself.
    """
    name, mesh = _MESH_OF_TREE[match.group(1)]
    tag = "".join(str(o).lstrip("-") for o in field_options)
    fld = CACHE / f"{name}{'.' + tag if tag else ''}.field.h5"
    pre[f"{name} field{' ' + tag if tag else ''}"] = _ensure(
        fld, "field", "sample", mesh, *field_options)
    return f'blocker = {{ field = "{fld}" }}'


def _skinned(name, glb, spheres, pre: dict, extra: str = "", animation: int = 0) -> str:
    rig = DATA / "skinned" / glb
    sph = CACHE / f"{name}{spheres}.spheres.h5"
    bound = CACHE / f"{name}{spheres}.bound.h5"
    pre[f"{name} fit"] = _ensure(sph, "spheres", "fit", rig, "-n", spheres)
    if not bound.exists():
        _run("spheres", "bind", sph, rig, "-o", bound)
    return (f'[[objects]]\nname = "{name}"\nmesh = "{rig}"\nrole = "both"\n'
            f'blocker = {{ bound = "{bound}" }}\nskin = {{ animation = {animation} }}\n{extra}')


def _ground(size, subdivisions) -> str:
    return (f'[[objects]]\nname = "ground"\nprimitive = {{ type = "plane", size = [{size}, '
            f'{size}], subdivisions = {subdivisions} }}\nrole = "receiver"\n')


def scenes(quick: bool, only=None) -> dict[str, dict]:
    """Scene texts and the seconds spent building their assets (only the ``only`` ones)."""
    CACHE.mkdir(parents=True, exist_ok=True)
    out = {}

    def wanted(name):
        return not only or name in only

    if quick:
        pre = {}
        text = (_ground(3.0, 40) + _rigid("spot", "spot.obj", 24, 1.0, 0.0, 0.0, 30.0, pre))
        out["spot"] = {"text": text, "env": DATA / "probes" / "uffizi.hdr", "frames": 1,
                       "pre": pre}
        return out
    if wanted("bunny"):
        pre = {}
        text = (_ground(3.0, 64)
                + _rigid("bunny", "stanford-bunny.obj", 48, 1.0, 0.0, 0.0, 0.0, pre))
        out["bunny"] = {"text": text, "env": DATA / "probes" / "uffizi.hdr", "frames": 2,
                        "pre": pre}
    if wanted("dragon+armadillo"):
        pre = {}
        text = (_ground(5.0, 96)
                + _rigid("dragon", "dragon.obj", 64, 1.1, -0.9, 0.0, 20.0, pre)
                + _rigid("armadillo", "armadillo.obj", 64, 1.4, 0.9, 0.2, -30.0, pre))
        out["dragon+armadillo"] = {"text": text, "env": DATA / "probes" /
                                   "spiaggia_di_mondello_1k.hdr", "frames": 2, "pre": pre}
    if wanted("cesiumman"):
        pre = {}
        text = _ground(3.0, 64) + _skinned("cesiumman", "CesiumMan.glb", 48, pre)
        out["cesiumman"] = {"text": text, "env": DATA / "probes" / "grace.hdr", "frames": 3,
                            "fps": 4, "pre": pre}
    if wanted("fox"):  # the glTF is in centimetres: 1.5 long after scaling
        pre = {}
        text = _ground(3.0, 64) + _skinned("fox", "Fox.glb", 48, pre, "scale = 0.01\n", 1)
        out["fox"] = {"text": text, "env": DATA / "probes" / "grace.hdr", "frames": 3,
                      "fps": 4, "pre": pre}
    return out


#: Bake variants: how rigid objects cast on other receivers ("tree": their spheres,
#: "field": their real mesh through a shadow field, which also holds their
#: self-visibility unless "transfer" keeps the transfer asset) and the settings.  "old" has no
#: self-visibility and no traced shadows, "self+spheres" exact self-shadowing over sphere
#: trees (the ground traced near them, as by default), "new" the current default.
VARIANTS = {
    "old": {"blocker": "tree", "settings": 'self_visibility = false\nlocal_visibility = false\n'
                                           'deringing = "none"\ntraced_shadows = false\n'},
    "self+spheres": {"blocker": "tree", "settings": 'self_visibility = true\n'
                                               'local_visibility = true\n'
                                               'deringing = "desaturate"\n'},
    "new": {"blocker": "field", "settings": ""},  # the current defaults
    # the default with sphere trees (no precomputed field), without and with the
    # rigid objects' real meshes trace their shadow on the ground (``traced_shadows``)
    "tree": {"blocker": "tree", "settings": "traced_shadows = false\n"},
    "traced": {"blocker": "tree", "settings": ""},
}


def describe_variant(variant: dict) -> str:
    """What a variant bakes, from its own entry: its blockers, the settings it sets (the
    last of a repeated key, as its scene file takes it) and its assets' options."""
    last = {}
    for line in variant.get("settings", "").splitlines():
        if line.strip():
            last[line.split("=", 1)[0].strip()] = line.strip()
    kind = {"tree": "sphere-tree blockers", "field": "shadow-field blockers"}.get(
        variant.get("blocker"), f"{variant.get('blocker')} blockers")
    parts = [f"`{x}`" for x in last.values()] or ["the defaults"]
    if variant.get("field_options"):
        parts.append("fields sampled with `" + " ".join(map(str, variant["field_options"])) + "`")
    if variant.get("transfer"):
        parts.append("transfer assets")
    return kind + ", " + ", ".join(parts)


def parse_variant(text: str) -> tuple[str, dict]:
    """``NAME=BASE[;setting line;...;field=--opt value ...]`` -> (name, variant).

    An extra variant for experiments: BASE's blocker and settings plus the given
    ``[settings]`` lines (later keys win); ``field=...`` passes options to
    ``shtools field sample`` (a separate cached field); ``transfer`` keeps the
    objects' transfer assets with a field blocker.
    """
    name, _, rest = text.partition("=")
    base, *lines = rest.split(";")
    v = dict(VARIANTS[base])
    v["settings"] = v["settings"] + "".join(line.strip() + "\n" for line in lines
                                            if "=" in line and not line.startswith("field="))
    v["field_options"] = tuple(o for line in lines if line.startswith("field=")
                               for o in line[len("field="):].split())
    v["transfer"] = "transfer" in lines
    return name, v


def _scene_file(name: str, spec: dict, variant: str, v: dict) -> Path:
    import re

    lines = {}  # later keys win
    for line in v["settings"].splitlines():
        if line.strip():
            lines[line.split("=")[0].strip()] = line.strip()
    settings = "".join(line + "\n" for line in lines.values())
    head = (f'[settings]\norder = 4\nframes = {spec["frames"]}\nfps = {spec.get("fps", 24)}\n'
            + settings)
    # experiments may replace the environment or add lights (e.g. an extracted sun)
    env = v.get("environment", f'[environment]\nimage = "{spec["env"]}"\n')
    path = CACHE / f"{name.replace('+', '_')}.{variant}.toml"
    text = spec["text"]
    if "self_visibility = false" in settings:  # the objects' own transfers off too
        text = re.sub(r'self_visibility = "[^"]*"', "self_visibility = false", text)
    if v["blocker"] == "field":
        text = re.sub(r'blocker = \{ tree = "([^"]*)" \}',
                      lambda m: _field_for(m, spec["pre"], v.get("field_options", ())), text)
        if not v.get("transfer"):  # the field's own O_v shadows the object
            text = re.sub(r'self_visibility = "[^"]*"\n', "", text)
    path.write_text(head + "\n" + env + "\n" + text + v.get("append", ""))
    return path


def evaluate(name: str, spec: dict, *, n_dirs: int, subset: int, variants: dict,
             repeats: int = REPEATS) -> dict:
    """Bake each variant, ray-trace the references on vertex subsets, tabulate.

    ``variants`` maps names to :data:`VARIANTS` entries (posing the same geometry);
    the references are posed and shaded from the "old" variant's scene.  The
    references' visibilities are cached in ``CACHE`` per scene, direction count
    and subset size (they depend on neither the variant nor the code under test).
    """
    import trimesh

    from shtools.reference import raytrace_visibility, relative_rmse, sphere_union_visibility
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.runtime.hierarchy import leaf_spheres
    from shtools.scene.bake import bake_scene, pose_frame, prepare_scene
    from shtools.scene.scene import load_scene

    names = list(variants)
    baked, times, cpu, preps = {}, {}, {}, {}
    for variant in names:
        scene = load_scene(_scene_file(name, spec, variant, variants[variant]))
        preps[variant] = (scene, prepare_scene(scene))
    # frames in this process (the runtime's worker processes share each frame), the
    # variants alternated and the fastest repeat kept: the machine is shared
    for _ in range(repeats):
        for variant in names:
            scene, prepared = preps[variant]
            frames = list(bake_scene(scene, prepared=prepared, scheduler="inline"))
            baked[variant] = [f.radiance.astype(np.float64) for f in frames]
            ms = 1e3 * float(np.mean([f.seconds for f in frames][1:] or frames[0].seconds))
            times[variant] = min(times.get(variant, ms), ms)
            # CPU with one runtime process (robust to the other jobs on a shared box)
            t0 = time.process_time()
            count = sum(1 for _ in bake_scene(scene, prepared=prepared, scheduler="inline",
                                              processes=1))
            ms = 1e3 * (time.process_time() - t0) / count
            cpu[variant] = min(cpu.get(variant, ms), ms)
    # the references pose the scene with sphere trees (for the sphere-union split) and
    # the probe as given, whatever the variants do
    ref_scene = _scene_file(name, spec, "reference", VARIANTS["old"])
    scene = load_scene(ref_scene)
    prepared = prepare_scene(scene)
    preps["reference"] = (scene, prepared)
    # the references are shaded raw (no de-ringing): what order-4 shading of the real
    # visibility gives, negative lobes included
    shader = ShadowRuntime(ShadowSettings(order=4, processes=1, deringing="none"))
    # keyed by the scene text too: another placement or mesh is another reference
    digest = hashlib.sha256(ref_scene.read_bytes()).hexdigest()[:12]
    ref_path = CACHE / f"{name.replace('+', '_')}.ref{n_dirs}x{subset}.{digest}.npz"
    refs = dict(np.load(ref_path)) if ref_path.exists() else {}
    rng = np.random.default_rng(0)
    offsets = np.cumsum([0] + [len(o.vertices) for o in prepared.receivers])
    rows = []
    acc = {}
    for k, t in enumerate(scene.frame_times()):
        state = pose_frame(prepared, float(t), with_meshes=True)
        meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
        centers, radii = leaf_spheres(state.blockers)
        for o, obj in enumerate(prepared.receivers):
            a, b = offsets[o], offsets[o + 1]
            sel = np.sort(rng.choice(np.arange(a, b), min(subset, b - a), replace=False))
            v, n = state.vertices[sel], state.normals[sel]
            key = f"{k}.{obj.spec.name}"
            if key + ".mesh" not in refs:
                refs[key + ".sel"] = sel
                refs[key + ".mesh"] = raytrace_visibility(v, n, meshes, 4, n_dirs)
                refs[key + ".sph"] = sphere_union_visibility(v, n, centers, radii, 4, n_dirs)
                np.savez(ref_path, **refs)
            r_mesh = shader.shade(refs[key + ".mesh"], v, n, prepared.env_sh, state.lights)
            r_sph = shader.shade(refs[key + ".sph"], v, n, prepared.env_sh, state.lights)
            entry = acc.setdefault(obj.spec.name, {"mesh": [], "sph": [], "neg_ref": 0,
                                                   **{vv: [] for vv in names}})
            entry["neg_ref"] += int((r_mesh.min(axis=1) < 0).sum())
            entry["mesh"].append(r_mesh)
            entry["sph"].append(r_sph)
            for variant in names:
                entry[variant].append(baked[variant][k][sel])
    for obj_name, e in acc.items():
        mesh, sph = np.concatenate(e["mesh"]), np.concatenate(e["sph"])
        row = {"scene": name, "receiver": obj_name,
               "spheres vs mesh": relative_rmse(sph, mesh)}
        for variant in names:
            r = np.concatenate(e[variant])
            row[f"{variant} vs mesh"] = relative_rmse(r, mesh)
            row[f"{variant} vs spheres"] = relative_rmse(r, sph)
            row[f"{variant} neg (subset)"] = int((r.min(axis=1) < 0).sum())
        row["mesh neg (subset)"] = e["neg_ref"]
        rows.append(row)
    summary = {"scene": name}
    for variant in names:
        rad = np.stack(baked[variant])
        summary[f"{variant} ms/frame"] = round(times[variant], 1)
        summary[f"{variant} CPU ms/frame (1 process)"] = round(cpu[variant], 1)
        summary[f"{variant} CPU ratio"] = round(cpu[variant] / cpu[names[0]], 2)
        summary[f"{variant} negative vertices"] = int((rad.min(axis=2) < 0).sum())
    summary[f"ratio {names[-1]}/{names[0]}"] = times[names[-1]] / times[names[0]]
    summary["load"] = round(os.getloadavg()[0], 1)
    summary["vertex-frames"] = int(np.stack(baked[names[0]]).shape[0] *
                                   np.stack(baked[names[0]]).shape[1])
    # what an experiment needs to score other references: baked radiance per variant
    # and frame, the posed scene per frame, the cached reference visibilities
    details = {"baked": baked, "refs": refs, "prepared": preps}
    return {"rows": rows, "summary": summary, "details": details}


def _markdown(rows: list[dict]) -> str:
    keys = list(rows[0])
    out = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        out.append("| " + " | ".join(
            (f"{100 * r[k]:.1f} %" if "vs" in k else f"{r[k]:.4g}")
            if isinstance(r[k], float) else str(r[k]) for k in keys) + " |")
    return "\n".join(out)


# -- the characters as deformable shadow fields ---------------------------------------------


#: field variants of :func:`deformable_variants`: label -> (blocker table, settings lines).
#: The field and the bound spheres shade the ground only with ``traced_shadows = false``
#: (by default a traced character's posed mesh is traced on the ground instead).
DEFORMABLE_FIELDS = {
    "deformable field, log space": ("{ deformable = true }",
                                    'field_space = "log"\ntraced_shadows = false\n'),
    "deformable field (default: product space)": ("{ deformable = true }",
                                                  "traced_shadows = false\n"),
}


def deformable_variants(name: str, spec: dict, *, n_dirs: int, subset: int,
                        methods=("default", "product"), fields=None) -> list[dict]:
    """The skinned scene with its bound spheres vs a deformable shadow field, per method.

    ``fields``: label -> blocker table, or (blocker table, ``[settings]`` lines), of
    each field variant (default :data:`DEFORMABLE_FIELDS`).

    Same scene, settings (the new default) and frames; only the character's
    blocker (``bound`` -> ``deformable = true``) and the variant's settings lines
    change.  Each bake runs in this process, the variants alternated
    :data:`REPEATS` times (fastest kept): with one runtime process (CPU ms per
    frame, robust to the load) and, for the default method, with the runtime's
    default processes (wall ms per frame: what a user waits).  The product method
    is not run for variants whose settings set ``field_space`` (it multiplies
    anyway).  The reference is the ray tracer of the posed real meshes on random
    vertex subsets, as :func:`evaluate`.
    """
    import re

    import trimesh

    from shtools.reference import raytrace_visibility, relative_rmse
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.scene.bake import bake_scene, pose_frame, prepare_scene
    from shtools.scene.scene import load_scene

    fields = fields or DEFORMABLE_FIELDS
    texts = {"bound spheres": (spec["text"], "traced_shadows = false\n"),
             "bound spheres, ground traced (the default)": (spec["text"], "")}
    for label, table in fields.items():  # label -> blocker table of the field variant
        table, lines = (table, "") if isinstance(table, str) else table
        texts[label] = (re.sub(r"blocker = \{ bound = \"[^\"]*\" \}",
                               f"blocker = {table}", spec["text"]), lines)
    preps = {}
    for label, (text, lines) in texts.items():
        for method in methods:
            if method == "product" and ("field_space" in lines or "traced" in label):
                continue
            variant = f"{label}, {method}"
            tag = re.sub(r"\W+", "_", label)
            # the current defaults; only the method set
            v = {"blocker": "tree", "settings": f'method = "{method}"\n{lines}'}
            scene = load_scene(_scene_file(f"{name}.{tag}.{method}",
                                           {**spec, "text": text}, "new", v))
            preps[variant] = (scene, prepare_scene(scene))
    baked, times = {}, {}
    for _ in range(REPEATS):
        for variant, (scene, prepared) in preps.items():
            for processes in (1, None) if variant.endswith(", default") else (1,):
                c0, w0 = time.process_time(), time.perf_counter()
                frames = list(bake_scene(scene, prepared=prepared, scheduler="inline",
                                         processes=processes))
                cpu = 1e3 * (time.process_time() - c0) / len(frames)
                wall = 1e3 * (time.perf_counter() - w0) / len(frames)
                baked[variant] = [f.radiance.astype(np.float64) for f in frames]
                key = "ms/frame CPU, 1 process" if processes == 1 else \
                    "ms/frame wall, default processes"
                got = cpu if processes == 1 else wall
                best = times.setdefault(variant, {})
                best[key] = min(best.get(key, math.inf), got)
    scene, prepared = next(iter(preps.values()))
    shader = ShadowRuntime(ShadowSettings(order=4, processes=1, deringing="none"))
    rng = np.random.default_rng(0)
    offsets = np.cumsum([0] + [len(o.vertices) for o in prepared.receivers])
    acc = {}
    for k, t in enumerate(scene.frame_times()):
        state = pose_frame(prepared, float(t), with_meshes=True)
        meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
        for o, obj in enumerate(prepared.receivers):
            a, b = offsets[o], offsets[o + 1]
            sel = np.sort(rng.choice(np.arange(a, b), min(subset, b - a), replace=False))
            v, n = state.vertices[sel], state.normals[sel]
            ref = shader.shade(raytrace_visibility(v, n, meshes, 4, n_dirs), v, n,
                               prepared.env_sh, state.lights)
            e = acc.setdefault(obj.spec.name, {"ref": [], **{var: [] for var in preps}})
            e["ref"].append(ref)
            for variant in preps:
                e[variant].append(baked[variant][k][sel])
    rows = []
    for variant in preps:
        row = {"scene": name, "blocker, method": variant}
        for obj_name, e in acc.items():
            role = "ground" if obj_name == "ground" else "character"
            row[f"{role} vs mesh"] = relative_rmse(np.concatenate(e[variant]),
                                                   np.concatenate(e["ref"]))
        row["ms/frame CPU, 1 process"] = times[variant]["ms/frame CPU, 1 process"]
        row["ms/frame wall, default processes"] = times[variant].get(
            "ms/frame wall, default processes", float("nan"))
        rows.append(row)
    return rows


# --------------------------------------------------------------------------- skinned
#: Variants of the skinned comparison (``--skinned``): [settings] lines of each.
#: "traced N": the character's own vertices traced with N rays (the ground traced too,
#: the default); "spheres on ground": own vertices traced with 32 rays, the
#: ground shaded by the character's bound spheres; "ground N": the defaults with N rays
#: for a ground vertex whose hemisphere the character's bounding sphere fills (64: the
#: default).
SKINNED_VARIANTS = {
    "old": 'self_visibility = false\nlocal_visibility = false\nderinging = "none"\n',
    "g_p": 'self_visibility = false\nlocal_visibility = true\nderinging = "desaturate"\n',
    **{f"traced {q}": (f'self_visibility = true\nself_visibility_directions = {q}\n'
                       'deringing = "desaturate"\n') for q in (16, 24, 32, 48)},
    "spheres on ground": 'traced_shadows = false\n',
    **{f"ground {q}": f"traced_shadow_directions = {q}\n"
       for q in (32, 48, 64, 96, 128)},
}
#: The default traced variant as the first shift built it, for the before/after figures
#: (:func:`_previous_tracing`); same settings as "spheres on ground".
PREVIOUS = "traced 32, previous"
SKINNED_VARIANTS[PREVIOUS] = SKINNED_VARIANTS["spheres on ground"]
#: The variants ``--skinned`` runs unless ``--skinned-variants`` names others: the old
#: default (the baseline), "spheres on ground" and the ground's ray counts (96: the
#: current default, ``CONE_DIRECTIONS``).
SKINNED_RUN = ("old", "spheres on ground",
               "ground 32", "ground 48", "ground 64", "ground 96", "ground 128")


@contextlib.contextmanager
def _previous_tracing(active: bool):
    """While active, trace as the first shift did: Embree's robust traversal on, the
    receivers' clustering posing frame 0 with its trace (one more trace a bake), and
    the traced visibility multiplied by quadrature on every row (also where the
    other blockers give the constant 1)."""
    if not active:
        yield
        return
    import shtools.scene.bake as bake
    import shtools.scene.transfer as transfer
    from shtools.geometry.raycast import RayCaster
    from shtools.geometry.visibility import hemisphere_visibility
    from shtools.runtime.evaluator import ShadowRuntime
    from shtools.runtime.fast_exp import QuadratureProducts
    from shtools.scene.pose import pose_frame
    from shtools.scene.shadows import receiver_clusters

    def clusters(prepared, method, t):
        return receiver_clusters(prepared, pose_frame(prepared, float(t)).vertices)

    def traced(vertices, normals, faces, order, n_dirs):
        return hemisphere_visibility(vertices, normals, RayCaster(vertices, faces), order,
                                     n_dirs=n_dirs).astype(np.float32)

    def multiply(runtime, g, self_visibility):
        terms = runtime._self  # the runtime's SelfTerms keeps the products between frames
        if terms.products is None:
            terms.products = QuadratureProducts(runtime.order, np.float32)
        for sv in self_visibility or ():
            if sv.visibility is not None:
                rows = np.arange(g.shape[0])[sv.rows]
                g[rows] = terms.products.product(g[rows], sv.visibility[:, :g.shape[1]])
        return g

    saved = bake.bake_clusters, transfer.traced_self_visibility, ShadowRuntime._multiply_self
    bake.bake_clusters, transfer.traced_self_visibility = clusters, traced
    ShadowRuntime._multiply_self = multiply
    try:
        yield
    finally:
        bake.bake_clusters, transfer.traced_self_visibility, ShadowRuntime._multiply_self = saved


def skinned_quadrature(name: str, spec: dict, *, n_ref: int = 3200) -> list[dict]:
    """Quadrature error of the per-frame traced self-visibility on the posed character.

    Direction sets, each against the project's ray tracer at ``n_ref`` directions of
    the same posed mesh (own vertices, every frame of the scene): the default
    hemisphere Fibonacci set in each vertex's tangent frame, the same turned by a
    random azimuth per vertex, and one spherical Fibonacci set shared by all
    vertices (one matrix product; half its rays fall below the tangent plane).
    Relative error of ``g`` at orders 4 and 6, and of the order-4 radiance.
    """
    import trimesh

    from shtools.geometry.raycast import RayCaster
    from shtools.geometry.visibility import (
        hemisphere_directions,
        hemisphere_visibility,
        tangent_frames,
    )
    from shtools.reference import raytrace_visibility, relative_rmse
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.scene.bake import pose_frame, prepare_scene
    from shtools.scene.scene import load_scene
    from shtools.sh import basis

    scene = load_scene(_skinned_scene_file(name, spec, "old", SKINNED_VARIANTS["old"]))
    prepared = prepare_scene(scene)
    shader = ShadowRuntime(ShadowSettings(order=4, processes=1, deringing="none"))
    rng = np.random.default_rng(0)
    acc: dict = {}
    own = slice(len(prepared.receivers[0].vertices), None)  # the ground comes first

    def frames_visibility(v, n, rc, q, kind):
        if kind == "hemisphere":
            return hemisphere_visibility(v, n, rc, 6, n_dirs=q)
        if kind == "hemisphere, random azimuth":
            t1, t2 = tangent_frames(n)
            a = rng.uniform(0.0, 2 * math.pi, len(v))[:, None]
            frames = np.stack([np.cos(a) * t1 + np.sin(a) * t2,
                               -np.sin(a) * t1 + np.cos(a) * t2, n], axis=1)
            dirs = hemisphere_directions(q) @ frames  # (V, Q, 3)
            o = np.repeat(rc.embree_points(v + 1e-5 * rc.diagonal * n), q, axis=0)
            blocked = rc.occluded_embree(o, dirs.reshape(-1, 3).astype(np.float32))
            g = np.zeros((len(v), 36))
            g[:, 0] = math.sqrt(4 * math.pi)
            y = basis(dirs, 6) * blocked.reshape(len(v), q, 1)
            return g - (2 * math.pi / q) * y.sum(axis=1)
        i = np.arange(2 * q) + 0.5  # full sphere: 2q directions, about q above the plane
        z = 1.0 - i / q
        phi = i * math.pi * (3.0 - math.sqrt(5.0))
        r = np.sqrt(1.0 - z * z)
        d = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
        vis = rc.visibility(v, d, normals=n, offset=1e-5 * rc.diagonal)
        g = -(~vis).astype(np.float64) @ (basis(d, 6) * (2 * math.pi / q))
        g[:, 0] += math.sqrt(4 * math.pi)
        return g

    for t in scene.frame_times():
        state = pose_frame(prepared, float(t), with_meshes=True)
        v, n = state.vertices[own], state.normals[own]
        mv, mf = state.blocker_meshes[0]
        ref = raytrace_visibility(v, n, [trimesh.Trimesh(mv, mf, process=False)], 6, n_ref)
        r_ref = shader.shade(ref[:, :16], v, n, prepared.env_sh, state.lights)
        rc = RayCaster(mv, mf)
        for kind in ("hemisphere", "hemisphere, random azimuth", "sphere (2x rays cast)"):
            for q in (16, 24, 32, 48, 64, 128):
                g = frames_visibility(v, n, rc, q, kind)
                r = shader.shade(g[:, :16], v, n, prepared.env_sh, state.lights)
                e = acc.setdefault((kind, q), {"g4": [], "ref4": [], "g6": [], "ref6": [],
                                               "r": [], "rref": []})
                e["g4"].append(g[:, :16])
                e["ref4"].append(ref[:, :16])
                e["g6"].append(g)
                e["ref6"].append(ref)
                e["r"].append(r)
                e["rref"].append(r_ref)
    rows = []
    for (kind, q), e in acc.items():
        cat = {k: np.concatenate(x) for k, x in e.items()}
        rows.append({"scene": name, "set": kind, "rays per vertex": q,
                     "g order 4 vs 3,200": relative_rmse(cat["g4"], cat["ref4"]),
                     "g order 6 vs 3,200": relative_rmse(cat["g6"], cat["ref6"]),
                     "radiance vs 3,200": relative_rmse(cat["r"], cat["rref"])})
    return rows


def skinned_interpolation(name: str, spec: dict, *, n_ref: int = 3200,
                          times=(0.2, 0.45, 0.7), fps: float = 24.0) -> list[dict]:
    """Would tracing every k-th frame do?  The worst case of linear interpolation.

    At each time, the traced visibility (the default 32 rays) against the mean of
    the traces ``k/2`` frames before and after (at ``fps``): the midpoint between
    two traced frames, where interpolation is furthest from a trace.  Order-4
    radiance of the character's own vertices vs the ray tracer at ``n_ref``.
    """
    import trimesh

    from shtools.reference import raytrace_visibility, relative_rmse
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.scene.bake import pose_frame, prepare_scene
    from shtools.scene.scene import load_scene
    from shtools.scene.transfer import traced_self_visibility

    scene = load_scene(_skinned_scene_file(name, spec, "old", SKINNED_VARIANTS["old"]))
    prepared = prepare_scene(scene)
    own = slice(len(prepared.receivers[0].vertices), None)
    shader = ShadowRuntime(ShadowSettings(order=4, processes=1, deringing="none"))

    def traced(t):
        state = pose_frame(prepared, t, with_meshes=True)
        return traced_self_visibility(state.vertices[own], state.normals[own],
                                      state.blocker_meshes[0][1], 4, 32)

    got: dict = {}
    for t in times:
        state = pose_frame(prepared, t, with_meshes=True)
        v, n = state.vertices[own], state.normals[own]
        mv, mf = state.blocker_meshes[0]
        ref = raytrace_visibility(v, n, [trimesh.Trimesh(mv, mf, process=False)], 4, n_ref)
        r_ref = shader.shade(ref, v, n, prepared.env_sh, state.lights)
        got.setdefault(1, []).append((traced(t), r_ref, v, n, state.lights))
        for k in (2, 4, 8):
            dt = 0.5 * k / fps
            got.setdefault(k, []).append((0.5 * (traced(t - dt) + traced(t + dt)), r_ref, v, n,
                                          state.lights))
    rows = []
    for k, items in got.items():
        r = np.concatenate([shader.shade(g, v, n, prepared.env_sh, lights)
                            for g, _, v, n, lights in items])
        ref = np.concatenate([r_ref for _, r_ref, *_ in items])
        rows.append({"scene": name, "traced every k-th frame (24 fps), midpoint": k,
                     "radiance vs 3,200": relative_rmse(r, ref)})
    return rows


def _skinned_scene_file(name: str, spec: dict, variant: str, settings: str) -> Path:
    path = CACHE / f"{name}.skinned.{variant.replace(' ', '')}.toml"
    path.write_text(f'[settings]\norder = 4\nframes = {spec["frames"]}\n'
                    f'fps = {spec.get("fps", 24)}\n{settings}\n'
                    f'[environment]\nimage = "{spec["env"]}"\n\n{spec["text"]}')
    return path


def evaluate_skinned(name: str, spec: dict, *, n_dirs: int = 3200, subset: int = 2500,
                     repeats: int = 3, variants=SKINNED_RUN) -> tuple[list[dict], list[dict]]:
    """The ``variants`` (of :data:`SKINNED_VARIANTS`) of a skinned scene against the real
    posed mesh.

    Accuracy as in :func:`evaluate` (reference: the ray tracer of the posed meshes on
    a vertex subset, shaded raw).  Frame time, the variants alternated ``repeats``
    times and the fastest kept: **wall** ms per frame with the runtime's default
    processes (frames in this process, as :func:`evaluate`), and **CPU** ms per
    frame with one process (``time.process_time``: robust to the other jobs): the
    whole bake over its frames, and the frames after the first alone (the bake's
    set-up left out, as in a long animation).  :data:`PREVIOUS` is the default
    traced variant as the first shift built it (:func:`_previous_tracing`).  Negative
    vertices: vertex-frames with a channel < 0 over the whole bake (every vertex).
    """
    import trimesh

    from shtools.reference import raytrace_visibility, relative_rmse
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.scene.bake import bake_scene, pose_frame, prepare_scene
    from shtools.scene.scene import load_scene

    preps, baked, wall, cpu, steady = {}, {}, {}, {}, {}
    for variant in variants:
        settings = SKINNED_VARIANTS[variant]
        scene = load_scene(_skinned_scene_file(name, spec, variant, settings))
        t0 = time.process_time()
        preps[variant] = (scene, prepare_scene(scene))
        cpu[variant + " set-up"] = time.process_time() - t0
    for _ in range(repeats):
        for variant, (scene, prepared) in preps.items():
            with _previous_tracing(variant == PREVIOUS):
                frames = list(bake_scene(scene, prepared=prepared, scheduler="inline"))
                baked[variant] = [f.radiance.astype(np.float64) for f in frames]
                ms = 1e3 * float(np.mean([f.seconds for f in frames][1:]))
                wall[variant] = min(wall.get(variant, ms), ms)
                marks = [time.process_time()]
                for _ in bake_scene(scene, prepared=prepared, scheduler="inline", processes=1):
                    marks.append(time.process_time())
                ms = 1e3 * (marks[-1] - marks[0]) / len(frames)
                cpu[variant] = min(cpu.get(variant, ms), ms)
                # frames after the first: without the bake's set-up (clustering), as in
                # a long animation
                ms = 1e3 * float(np.mean(np.diff(marks)[1:]))
                steady[variant] = min(steady.get(variant, ms), ms)
    scene, prepared = preps["old"]
    shader = ShadowRuntime(ShadowSettings(order=4, processes=1, deringing="none"))
    rng = np.random.default_rng(0)
    offsets = np.cumsum([0] + [len(o.vertices) for o in prepared.receivers])
    ref, got = {}, {}
    for k, t in enumerate(scene.frame_times()):
        state = pose_frame(prepared, float(t), with_meshes=True)
        meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
        for o, obj in enumerate(prepared.receivers):
            a, b = offsets[o], offsets[o + 1]
            sel = np.sort(rng.choice(np.arange(a, b), min(subset, b - a), replace=False))
            v, n = state.vertices[sel], state.normals[sel]
            g = raytrace_visibility(v, n, meshes, 4, n_dirs)
            ref.setdefault(obj.spec.name, []).append(
                shader.shade(g, v, n, prepared.env_sh, state.lights))
            for variant in preps:
                got.setdefault((obj.spec.name, variant), []).append(baked[variant][k][sel])
    load = os.getloadavg()[0]
    accuracy = []
    for receiver, r in ref.items():
        row = {"scene": name, "receiver": receiver}
        for variant in preps:
            row[variant] = relative_rmse(np.concatenate(got[(receiver, variant)]),
                                         np.concatenate(r))
        accuracy.append(row)
    timing = []
    for variant in preps:
        timing.append({"scene": name, "variant": variant,
                       "wall ms/frame": round(wall[variant], 1),
                       "wall ratio": round(wall[variant] / wall["old"], 2),
                       "CPU ms/frame (1 process)": round(cpu[variant], 1),
                       "CPU ratio": round(cpu[variant] / cpu["old"], 2),
                       "CPU ratio, frames 2..": round(steady[variant] / steady["old"], 2),
                       "set-up CPU s": round(cpu[variant + " set-up"], 2),
                       "negative vertex-frames": int(sum((f.min(axis=1) < 0).sum()
                                                         for f in baked[variant])),
                       "load": round(load, 1)})
    return accuracy, timing


def skinned_main(names, variants=SKINNED_RUN, sections=("variants",)) -> int:
    """``--skinned``: the variants' table (and, asked for, the quadrature of the per-frame
    tracing of the own vertices and frame-to-frame interpolation)."""
    specs = scenes(False, names or ["cesiumman", "fox"])
    print(f"load at the start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    for name, spec in specs.items():
        if "quadrature" in sections:
            quad = skinned_quadrature(name, spec)
            print(f"\n### Per-frame tracing quadrature, {name} (load {os.getloadavg()[0]:.2f} "
                  f"on {os.cpu_count()} cores)\n\n" + _markdown(quad), flush=True)
        if "interpolation" in sections:
            print("\n" + _markdown(skinned_interpolation(name, spec)), flush=True)
        if "variants" in sections:
            a, t = evaluate_skinned(name, spec, variants=variants)
            print(f"\n### {name}: radiance vs the real posed mesh (order 4, 3,200 "
                  "directions)\n\n" + _markdown(a) + "\n\n" + _markdown(t), flush=True)
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="spot only, coarse")
    parser.add_argument("--scene", action="append", help="only these scenes")
    parser.add_argument("--variants", default="old,new",
                        help=f"comma-separated, of {', '.join(VARIANTS)} (default old,new; "
                             "the time ratio is last/first)")
    parser.add_argument("--variant", action="append", default=[], metavar="NAME=BASE;...",
                        help="an extra variant for experiments (parse_variant)")
    parser.add_argument("--repeats", type=int, default=REPEATS,
                        help="alternating repeats of the bakes (the fastest is kept)")
    parser.add_argument("--deformable", action="store_true",
                        help="the skinned scenes with a deformable shadow field instead of "
                             "their bound spheres")
    parser.add_argument("--skinned", action="store_true",
                        help="skinned objects' per-frame tracing: the variants' table")
    parser.add_argument("--skinned-variants", default=",".join(SKINNED_RUN),
                        help=f"with --skinned: comma-separated, of {', '.join(SKINNED_VARIANTS)}")
    parser.add_argument("--skinned-sections", default="variants",
                        help="with --skinned: comma-separated, of variants, quadrature, "
                             "interpolation")
    args = parser.parse_args(argv)
    known = dict(VARIANTS)
    known.update(parse_variant(v) for v in args.variant)
    variants = {n: known[n] for n in args.variants.split(",")}
    if not (DATA / "meshes").is_dir():
        print(f"bench_fidelity: {DATA} not present; nothing to measure")
        return 0
    if args.skinned:
        return skinned_main(args.scene, tuple(args.skinned_variants.split(",")),
                            tuple(args.skinned_sections.split(",")))
    n_dirs, subset = (1600, 600) if args.quick else (3200, 2500)
    if args.deformable:
        from shtools.runtime.parallel import resolve_processes

        print(f"load at the start: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
        rows = []
        for name, spec in scenes(False, args.scene or ["cesiumman", "fox"]).items():
            rows += deformable_variants(name, spec, n_dirs=n_dirs, subset=subset)
            print(_markdown(rows), flush=True)
        load = os.getloadavg()
        print(f"\n### Skinned characters: bound spheres vs deformable shadow field (order 4, "
              f"{n_dirs} directions, {subset} vertices per receiver and frame; CPU with one "
              f"runtime process, wall with the default processes ({resolve_processes(None)}); "
              f"load {load[0]:.2f} at the end on {os.cpu_count()} cores)\n")
        print(_markdown(rows))
        return 0
    all_rows, sums, pre = [], [], {}
    for name, spec in scenes(args.quick, args.scene).items():
        out = evaluate(name, spec, n_dirs=n_dirs, subset=subset, variants=variants,
                       repeats=args.repeats)
        all_rows += out["rows"]
        sums.append(out["summary"])
        pre.update(spec["pre"])
    load = os.getloadavg()
    cpu = os.times()
    print(f"\nCPU seconds of this run: {cpu.user + cpu.system:.0f} (this process), "
          f"{cpu.children_user + cpu.children_system:.0f} (finished children)")
    print(f"\n### Fidelity vs the real meshes (order 4, {n_dirs}+ directions, "
          f"{subset} vertices per receiver and frame; load {load[0]:.2f} on "
          f"{os.cpu_count()} cores)\n")
    legend = [f"**{name}**: {describe_variant(v)}" for name, v in variants.items()]
    print("Variants: " + "; ".join(legend) + ". \"vs mesh\": against the ray tracer of the "
          "real meshes; \"vs spheres\": against ray tracing of the sphere union.\n")
    print(_markdown(all_rows))
    print("\n" + _markdown(sums))
    built = {k: round(v, 1) for k, v in pre.items() if v}
    if built:
        print(f"\nprecompute this run (s): {built}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
