"""What a person sees: seams, rings and noise, and the error where the shadows are.

Per receiver of each scene, at the default settings, against the project's ray
tracer of the posed real meshes (:func:`shtools.reference.raytrace_visibility`,
3,200 directions, then 25,600 on every vertex some direction found blocked and two
rings of mesh neighbours around them, ``--ref-dirs``: :func:`converged`; 800 and no
second trace with ``--quick``), shaded raw at the scene's order (:mod:`shtools.reference.look`):

* the **smoothness ratio** (mean |graph Laplacian| of luminance, bake over truth;
  target 0.85-1.15): at 3,200 the reference's own steps inflate a ground's energy
  1.6-2.2x,
* the **error over the shadowed vertices** (reference darkened by > 2 %) next to
  the whole receiver's, and the error within 2 bounding radii of the blockers; the
  reference as shown, with the scene's de-ringing (``deringing = "desaturate"``, the
  default: negative radiance, the order-n truncation's ringing, cannot be displayed),
  and the raw reference's shadowed error beside (``shadowed raw``); at 3,200
  directions alone the reference's own quadrature error is a few tenths of a percent
  on a self-shadowed surface (where an estimator on the same rule of an unturned
  object scored 0.00 %); at 25,600 it is expected several times smaller (not
  measured),
* CPU per frame (one process and one frame baker, as a bake's worker; the set-up
  frame left out) and its ratio to the baseline, and the CPU of that set-up frame
  (receiver clusters, runtime, the first frame's per-bake state; the set-up cache off,
  so every code computes it).

Scenes from ``../shared/data`` (never committed; the assets are built with
``benchmarks/bench_fidelity.py``'s helpers and cached there): the bunny under the
Uffizi probe and CesiumMan walking under Grace, each on a 4 x 4 ground of 96
subdivisions; the glTF Fox running under the Mondello probe on a 3 x 3 ground of 96
(a low-poly quadruped whose thin legs stand in loose spheres); the cow and the human
side by side under Uffizi on the 4 x 4 ground; ``--demo DIR`` adds frames 10-13 of
``make demo``'s scene in DIR (default ``out/`` when ``make demo`` has written it);
``--scenes dragon`` (only when named: two large transfers and references) the dragon
and the armadillo side by side under Grace on the same ground, each shadowing the
other (objects that both receive and block).
``--scenes heldout`` (only when named, or each by its name) the held-out scenes of
:data:`HELDOUT`.
``--field ASSET`` adds the teapot with a shadow field on a 14 x 14 and a 3 x 3 ground
(default: the teapot's field at ``field sample`` defaults, built once into the cache).
``--quick``: spot on a 3 x 3 ground of 40 subdivisions, one frame.

``--baseline DIR`` (or ``SHTOOLS_BASELINE=DIR``) bakes the same scenes with the code in
DIR (e.g. the worktree of the previous release) in the same run, each bake in its own
process (the codes alternated, the fastest repeat kept), and prints them side by side;
given again, it adds more codes (the CPU ratios are against the first).

``--set KEY=VALUE`` (again for more) bakes this tree's code with those ``[settings]``
(TOML values, e.g. ``--set self_visibility_directions=64``) and the baselines at
their defaults, scored against the same reference: what a setting costs and buys.

``python benchmarks/bench_look.py [--quick] [--baseline DIR] [--demo DIR] [--set KEY=VALUE]``
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import math
import os
import re
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: the shared data next to the repository (or next to the folder of its worktrees)
DATA = next((d / "shared" / "data" for d in (REPO.parent, REPO.parent.parent)
             if (d / "shared" / "data").is_dir()), REPO.parent / "shared" / "data")
CACHE = REPO / "build" / "bench_look"
#: Receivers per block of the reference ray tracer.
REF_BLOCK = 8192
#: Directions of the first trace of the reference.
REF_DIRECTIONS = 3200
#: Directions of the reference where the first trace found something blocked
#: (:func:`converged`).
CONVERGED_DIRECTIONS = 25600
#: Alternating repeats of each code's bake (the fastest CPU kept: the machine is shared).
REPEATS = 2


def _fidelity():
    spec = importlib.util.spec_from_file_location("_bench_fidelity",
                                                  Path(__file__).with_name("bench_fidelity.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def scenes(quick: bool, demo: Path | None, field: Path | None = None,
           only: set | None = None) -> dict[str, dict]:
    """Scene files (written to ``CACHE``) and the frames to measure (``only`` of the
    teapot scenes: the other scenes' assets are not built)."""
    fid = _fidelity()
    fid.DATA = DATA
    fid.CACHE.mkdir(parents=True, exist_ok=True)
    CACHE.mkdir(parents=True, exist_ok=True)
    out = {}
    pre: dict = {}

    def write(name, body, env, frames, fps=24):
        path = CACHE / f"{name}.toml"
        path.write_text(f"[settings]\norder = 4\nframes = {frames}\nfps = {fps}\n\n"
                        f'[environment]\nimage = "{env}"\n\n{body}')
        return path

    if field is not None and only and only <= set(FIELD_SCENES):
        return field_scenes(write, Path(field).resolve())

    if quick:
        body = fid._ground(3.0, 40) + fid._rigid("spot", "spot.obj", 24, 1.0, 0.0, 0.0, 30.0,
                                                 pre)
        out["spot"] = {"path": write("spot", body, DATA / "probes" / "uffizi.hdr", 2),
                       "frames": range(0, 2)}
        return out
    body = fid._ground(4.0, 96) + fid._rigid("bunny", "stanford-bunny.obj", 48, 1.0, 0.0, 0.0,
                                             0.0, pre)
    out["bunny"] = {"path": write("bunny", body, DATA / "probes" / "uffizi.hdr", 2),
                    "frames": range(0, 2)}
    body = fid._ground(4.0, 96) + fid._skinned("cesiumman", "CesiumMan.glb", 48, pre)
    out["cesiumman"] = {"path": write("cesiumman", body, DATA / "probes" / "grace.hdr", 3, 4),
                        "frames": range(0, 3)}
    # a low-poly quadruped (576 faces) under a third probe: a skinned character unlike
    # CesiumMan, whose thin legs stand in loose spheres
    body = fid._ground(3.0, 96) + fid._skinned(
        "fox", "Fox.glb", 32, pre, extra="scale = 0.012\ntranslate = [0.0, 0.0, 0.2]\n",
        animation=2)
    out["fox"] = {"path": write("fox", body, DATA / "probes" / "spiaggia_di_mondello_1k.hdr",
                                3, 4),
                  "frames": range(0, 3)}
    body = (fid._ground(4.0, 96)
            + fid._rigid("cow", "cow.obj", 48, 0.9, -0.8, 0.1, 25.0, pre)
            + fid._rigid("human", "human_man.obj", 48, 1.7, 0.7, -0.2, -20.0, pre))
    out["cowman"] = {"path": write("cowman", body, DATA / "probes" / "uffizi.hdr", 1),
                     "frames": range(0, 1)}
    if only and "dragon" in only:  # opt-in: two large transfers and references
        body = (fid._ground(4.0, 96)
                + fid._rigid("dragon", "dragon.obj", 64, 1.1, -0.9, 0.0, 20.0, pre)
                + fid._rigid("armadillo", "armadillo.obj", 64, 1.4, 0.9, 0.2, -30.0, pre))
        out["dragon"] = {"path": write("dragon", body, DATA / "probes" / "grace.hdr", 1),
                         "frames": range(0, 1)}
    if only and only & set(HELDOUT):
        out.update(heldout_scenes(write, only, pre))
    if demo is not None:
        out["demo"] = {"path": Path(demo) / "scene.toml", "frames": range(10, 14)}
    if field is not None:
        out.update(field_scenes(write, Path(field).resolve()))
    return out


#: Held-out scenes (only when named, or all with ``--scenes heldout``): the kind the
#: look issue is judged on, with grounds, probes and placements none of the default
#: scenes use.
HELDOUT = ("spottea", "bunnywide", "cmcoarse", "foxwalk", "spotfield")


def heldout_scenes(write, only: set, pre: dict) -> dict[str, dict]:
    """The :data:`HELDOUT` scenes named in ``only``: spot and the teapot a bounding
    radius or two apart on a 4 x 4 ground of 128 under Mondello (each shadows the
    other at mid-range); the bunny on a wide 8 x 8 ground of 160 under Mondello (the
    sun's long shadow); CesiumMan on a coarse 3 x 3 ground of 48 under Uffizi; the Fox
    walking (animation 1) on a fine 2 x 2 ground of 128 under Grace; spot with a shadow
    field of its own (sampled at ``field sample`` defaults, order 4, built once into the
    cache) on a 4 x 4 ground of 48 under Mondello (a field object's own surface)."""
    fid = _fidelity()
    mondello = DATA / "probes" / "spiaggia_di_mondello_1k.hdr"
    out = {}
    if "spottea" in only:
        body = (fid._ground(4.0, 128)
                + fid._rigid("spot", "spot.obj", 48, 1.0, -0.9, 0.0, 30.0, pre)
                + fid._rigid("teapot", "teapot.obj", 48, 0.6, 0.9, 0.2, -40.0, pre))
        out["spottea"] = {"path": write("spottea", body, mondello, 1), "frames": range(0, 1)}
    if "bunnywide" in only:
        body = fid._ground(8.0, 160) + fid._rigid("bunny", "stanford-bunny.obj", 48, 1.0,
                                                  0.0, 0.0, 0.0, pre)
        out["bunnywide"] = {"path": write("bunnywide", body, mondello, 1),
                            "frames": range(0, 1)}
    if "cmcoarse" in only:
        body = fid._ground(3.0, 48) + fid._skinned("cesiumman", "CesiumMan.glb", 48, pre)
        out["cmcoarse"] = {"path": write("cmcoarse", body, DATA / "probes" / "uffizi.hdr", 3,
                                         4), "frames": range(0, 3)}
    if "foxwalk" in only:
        body = fid._ground(2.0, 128) + fid._skinned(
            "fox", "Fox.glb", 32, pre, extra="scale = 0.012\ntranslate = [0.0, 0.0, 0.2]\n",
            animation=1)
        out["foxwalk"] = {"path": write("foxwalk", body, DATA / "probes" / "grace.hdr", 3, 4),
                          "frames": range(0, 3)}
    if "spotfield" in only:
        field, mesh = CACHE / "spot.field.h5", DATA / "meshes" / "spot.obj"
        pre["spot field"] = fid._ensure(field, "field", "sample", mesh, "--order", 4)
        body = fid._ground(4.0, 48) + f"""
[[objects]]
name = "spot"
mesh = "{mesh}"
role = "both"
{fid.placement(mesh, 1.0, 0.0, 0.0, 30.0)}blocker = {{ field = "{field}" }}
"""
        out["spotfield"] = {"path": write("spotfield", body, mondello, 1), "frames": range(0, 1)}
    return out


#: The teapot field scenes: ground size and subdivisions.
FIELD_SCENES = {"teapot14": (14.0, 112), "teapot3": (3.0, 48)}


def field_scenes(write, field: Path) -> dict[str, dict]:
    """The teapot with a shadow field (``field``, sampled from ``teapot.obj`` at order 4)
    under Grace: on a 14 x 14 ground and on a 3 x 3 ground under it."""
    teapot = f"""
[[objects]]
name = "teapot"
mesh = "{DATA / 'meshes' / 'teapot.obj'}"
role = "both"
scale = 0.25
translate = [0.0, 0.01, 0.0]
rotate = [0.0, 30.0, 0.0]
blocker = {{ field = "{field}" }}
"""
    fid = _fidelity()
    out = {}
    for name, (size, subdivisions) in FIELD_SCENES.items():
        out[name] = {"path": write(name, fid._ground(size, subdivisions) + teapot,
                                   DATA / "probes" / "grace.hdr", 1),
                     "frames": range(0, 1)}
    return out


def bake_worker(scene_path: str, first: int, stop: int, out_path: str) -> None:
    """Bake frames ``first..stop-1`` in this process as a bake's worker does: radiance, CPU.

    One :class:`~shtools.scene.bake.FrameBaker` for all frames, the receiver clusters
    computed once (what ``bake_scene`` does once per bake, not per frame).  The set-up
    (clusters, runtime and a first frame, which builds the per-bake state: casters,
    kept traces) is timed apart, its frame posed half a frame before ``first``: a
    pose none of the measured frames repeats (a repeated pose would find a moving
    object's trace kept and time nothing).
    """
    from shtools.scene.bake import FrameBaker, bake_clusters, prepare_scene
    from shtools.scene.scene import load_scene

    scene = load_scene(scene_path)
    prepared = prepare_scene(scene)
    method = scene.settings.method
    times = scene.frame_times(range(first, stop))
    cpu = []
    radiance = []
    setup_start = time.process_time()
    baker = FrameBaker(prepared, method, bake_clusters(prepared, method, 0.0), processes=1)
    baker.frame(first, float(times[0]) - 0.5 / scene.settings.fps)
    setup = time.process_time() - setup_start
    for k, t in zip(range(first, stop), times, strict=True):
        t0 = time.process_time()
        frame = baker.frame(k, float(t))
        cpu.append(time.process_time() - t0)
        radiance.append(frame.radiance.astype(np.float64))
    baker.close()
    np.savez(out_path, radiance=np.stack(radiance), cpu=np.array(cpu), setup=setup)


#: A ``[settings]`` table header line (spaces and a comment allowed).
_SETTINGS_HEADER = re.compile(r"^\s*\[\s*settings\s*\]\s*(#.*)?$")


def with_settings(path: Path, settings: list[str]) -> Path:
    """A copy of the scene file ``path`` with ``settings`` (``"key = value"`` lines; the
    last of a repeated key wins) in its ``[settings]`` table, in the same folder (its
    relative asset paths hold), never over an existing file; the caller deletes it.

    Raises ``ValueError`` when the copy does not hold them, before any bake.  The
    scene's ``[settings]`` lines are edited as single lines (the scenes benchmarked have
    no multi-line setting; one makes the copy fail that check, never pass it wrongly).
    """
    wanted = {}
    for line in settings:
        key, _, value = line.partition("=")
        wanted[key.strip()] = value.strip()
    lines, table, placed = [], None, False
    for line in path.read_text().splitlines():
        if line.lstrip().startswith("["):
            table = "settings" if _SETTINGS_HEADER.match(line) else line.strip()
        elif table == "settings":
            key = line.split("=", 1)[0].strip().strip('"').strip("'")
            if "=" in line and key in wanted:
                continue  # replaced below
        lines.append(line)
        if table == "settings" and not placed:
            lines.extend(f"{k} = {v}" for k, v in wanted.items())
            placed = True
    if not placed:  # a table of its own at the end (before it, a dotted key would move)
        lines += ["", "[settings]", *(f"{k} = {v}" for k, v in wanted.items())]
    text = "\n".join(lines) + "\n"
    try:
        held = tomllib.loads(text).get("settings", {})
        want = {k: tomllib.loads(f"x = {v}")["x"] for k, v in wanted.items()}
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: --set {', '.join(settings)} does not make a TOML scene "
                         f"({exc})") from None
    if any(held.get(k) != v and v == v for k, v in want.items()):  # (nan != nan)
        raise ValueError(f"{path}: --set {', '.join(settings)} did not land in its [settings] "
                         "table (a dotted or inline settings key?)")
    digest = hashlib.sha256("\n".join(settings).encode()).hexdigest()[:8]
    out = path.with_name(f"{path.stem}.set-{digest}.toml")
    try:  # a new file only: never over one of the user's (a left-over copy included)
        with open(out, "x") as f:
            f.write(text)
    except FileExistsError:
        raise ValueError(f"{out} exists (a copy a stopped run left?); remove it and run "
                         "again") from None
    return out


def _bake(code: Path, scene: dict, tag: str) -> dict:
    tag = "".join(c if c.isalnum() else "_" for c in tag)  # a file name's
    out = CACHE / f"{scene['path'].stem}.{tag}.npz"
    # the bytecode kept out of the code's folder: a set-up frame's imports compile no
    # source after the first repeat (an installed package has its bytecode)
    # the set-up cache off: every code's set-up frame is computed, not read back
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": str(code),
           "PYTHONPYCACHEPREFIX": str(CACHE / "pycache" / tag), "SHTOOLS_NO_CACHE": "1"}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker",
                    str(scene["path"]), str(scene["frames"].start), str(scene["frames"].stop),
                    str(out)], check=True, env=env, cwd=str(code))
    return dict(np.load(out))


def references(scene: dict, n_dirs: int, ref_dirs: int | None = None) -> dict:
    """Ray-traced (real meshes) and unshadowed radiance per frame, receivers' faces, spheres.

    At ``n_dirs`` directions, and with ``ref_dirs`` at that many where the first trace
    found something blocked (:func:`converged`)."""
    import trimesh

    from shtools.reference import raytrace_visibility
    from shtools.reference.look import bounding_sphere
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.runtime.shading import desaturate_negative
    from shtools.scene.bake import prepare_scene
    from shtools.scene.pose import pose_frame
    from shtools.scene.scene import load_scene

    sc = load_scene(scene["path"])
    prepared = prepare_scene(sc)
    order = sc.settings.order
    digest = hashlib.sha256(scene["path"].read_bytes()).hexdigest()[:12]
    cache = CACHE / f"{scene['path'].stem}.ref{n_dirs}.{digest}.npz"
    stored = dict(np.load(cache)) if cache.exists() else {}
    shader = ShadowRuntime(ShadowSettings(order=order, processes=1, deringing="none"))
    blocking = [o.spec.name for o in prepared.objects if o.spec.blocks]
    ref, shown, free, spheres = [], [], [], []
    for k in scene["frames"]:
        state = pose_frame(prepared, k / sc.settings.fps, with_meshes=True, trace=False)
        if f"g{k}" not in stored:
            meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
            # in blocks of receivers: a (V, n_dirs) visibility of a large scene (the
            # dragon's and armadillo's 93k vertices) would not fit in memory at once
            stored[f"g{k}"] = np.concatenate([
                raytrace_visibility(state.vertices[i:i + REF_BLOCK],
                                    state.normals[i:i + REF_BLOCK], meshes, order, n_dirs)
                for i in range(0, len(state.vertices), REF_BLOCK)])
            np.savez(cache, **stored)
        one = np.zeros((len(state.vertices), order * order))
        one[:, 0] = math.sqrt(4 * math.pi)
        g = stored[f"g{k}"] if ref_dirs is None else converged(
            scene, prepared, state, k, stored[f"g{k}"], ref_dirs, digest)
        ref.append(shader.shade(g, state.vertices, state.normals, prepared.env_sh,
                                state.lights))
        # what a viewer is shown of it: the bake's own de-ringing (negative radiance,
        # the order-n truncation's ringing, cannot be displayed)
        shown.append(desaturate_negative(ref[-1]) if sc.settings.deringing == "desaturate"
                     else ref[-1])
        free.append(shader.shade(one, state.vertices, state.normals, prepared.env_sh,
                                 state.lights))
        spheres.append({name: bounding_sphere(v)
                        for name, (v, _) in zip(blocking, state.blocker_meshes, strict=True)})
        last = state
    offsets = np.cumsum([0] + [len(o.vertices) for o in prepared.receivers])
    receivers = [(o.spec.name, o.faces, slice(offsets[i], offsets[i + 1]))
                 for i, o in enumerate(prepared.receivers)]
    return {"ref": np.stack(ref), "shown": np.stack(shown), "free": np.stack(free),
            "spheres": spheres, "receivers": receivers, "points": last.vertices}


def converged(scene: dict, prepared, state, k: int, g, n_dirs: int, digest: str
              ) -> np.ndarray:
    """The visibility ``g`` ``(V, n*n)`` with every receiver's shadowed vertices traced
    again at ``n_dirs`` directions: the reference of the figures.

    The reference's own steps (a silhouette crossing one of its fixed directions moves
    a receiver's visibility by a whole direction's weight) add to its Laplacian energy
    as the bake's do, and its quadrature error to the errors (on a self-shadowed surface
    a few tenths of a percent at 3,200: a product-rule transfer asset of an unturned
    bunny, the same rule, scored 0.00 % against it, the hemisphere estimator 0.39 %,
    though it is the nearer of the two to a 51,200-direction rule, bench_transfer).
    CesiumMan's ground (3 frames): 8.7 / 5.1 / 3.9 / 3.5e-4 at
    3,200 / 12,800 / 25,600 / 51,200 directions; the demo's (frames 10-13): 5.6 / 3.9 /
    3.4e-3 at the first three.  At 25,600 the energy is within some 10 % of the next
    doubling's, at a cost a benchmark can pay: only the vertices some direction found
    blocked at the first count, and two rings of mesh neighbours around them, are
    traced again (the others are exactly unblocked at any count below a direction's
    solid angle; equal to a full trace at 25,600 on CesiumMan's and the demo's grounds).
    """
    import trimesh

    from shtools.reference import raytrace_visibility
    from shtools.reference.look import mesh_adjacency
    from shtools.sh.basis import SQRT_4PI

    cache = CACHE / f"{scene['path'].stem}.conv{n_dirs}.{digest}.npz"
    stored = dict(np.load(cache)) if cache.exists() else {}
    out = np.array(g, dtype=np.float64, copy=True)
    offsets = np.cumsum([0] + [len(o.vertices) for o in prepared.receivers])
    take = []
    for i, o in enumerate(prepared.receivers):
        rows = slice(offsets[i], offsets[i + 1])
        part = out[rows]
        blocked = np.abs(part[:, 0] - SQRT_4PI) + np.abs(part[:, 1:]).sum(axis=1) > 1e-9
        adj = mesh_adjacency(o.faces, len(part))
        for _ in range(2):  # two rings: a penumbra's edge between two of the fixed directions
            blocked = blocked | (adj @ blocked.astype(np.float64) > 0)
        take.append(offsets[i] + np.flatnonzero(blocked))
    take = np.concatenate(take) if take else np.zeros(0, dtype=np.int64)
    # the first trace's memory a block: (receivers, directions) of the ray tracer
    block = max(1, REF_BLOCK * REF_DIRECTIONS // n_dirs)
    if f"s{k}" not in stored or len(stored[f"s{k}"]) != len(take):
        meshes = [trimesh.Trimesh(v, f, process=False) for v, f in state.blocker_meshes]
        stored[f"s{k}"] = np.concatenate([
            raytrace_visibility(state.vertices[take[i:i + block]],
                                state.normals[take[i:i + block]], meshes,
                                prepared.scene.settings.order, n_dirs)
            for i in range(0, len(take), block)] or [out[:0]])
        np.savez(cache, **stored)
    out[take] = stored[f"s{k}"]
    return out


def score(radiance: np.ndarray, refs: dict) -> list[dict]:
    """:func:`shtools.reference.look.look_metrics` per receiver, frames pooled (errors) or
    averaged (smoothness)."""
    from shtools.reference.look import (
        luminance,
        near_blockers,
        relative_rmse,
        shadowed,
        smoothness_ratio,
    )

    rows = []
    for name, faces, rows_of in refs["receivers"]:
        x, raw, ref, free = (a[:, rows_of] for a in (radiance, refs["ref"], refs["shown"],
                                                     refs["free"]))
        smooth = float(np.mean([smoothness_ratio(luminance(x[k]), luminance(ref[k]), faces)
                                for k in range(len(x))]))
        dark = np.stack([shadowed(ref[k], free[k]) for k in range(len(x))])
        near = np.stack([near_blockers(refs["points"][rows_of],
                                       [s for n, s in refs["spheres"][k].items() if n != name])
                         for k in range(len(x))])
        rows.append({"receiver": name, "smoothness": smooth,
                     "error": relative_rmse(x, ref),
                     "shadowed": relative_rmse(x[dark], ref[dark]) if dark.any() else None,
                     "shadowed raw": relative_rmse(x[dark], raw[dark]) if dark.any() else None,
                     "near": relative_rmse(x[near], ref[near]) if near.any() else None})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="spot, one small ground")
    parser.add_argument("--baseline", type=Path, action="append",
                        help="code to compare with (a worktree; default $SHTOOLS_BASELINE); "
                             "again for more codes, the ratios against the first")
    parser.add_argument("--demo", type=Path,
                        help="make demo's output folder (its scene.toml; default out/ when "
                             "make demo has written it)")
    parser.add_argument("--scenes", help="comma-separated scene names (default all)")
    parser.add_argument("--field", type=Path, help="a field asset of teapot.obj (order 4): "
                        "adds the teapot scenes 'teapot14' and 'teapot3'")
    parser.add_argument("--ref-dirs", "--smooth-dirs", type=int,
                        default=CONVERGED_DIRECTIONS,
                        help="directions of the reference on the vertices the first trace "
                             f"found shadowed (default {CONVERGED_DIRECTIONS}; 0: the first "
                             "trace's)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="a [settings] value for this tree's bakes (TOML, e.g. "
                             "self_visibility_directions=64); again for more")
    parser.add_argument("--worker", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.baseline is None and os.environ.get("SHTOOLS_BASELINE"):
        args.baseline = [Path(os.environ["SHTOOLS_BASELINE"])]
    if args.worker:
        bake_worker(args.worker[0], int(args.worker[1]), int(args.worker[2]), args.worker[3])
        return 0
    if not (DATA / "meshes").is_dir():
        print(f"no data in {DATA}: nothing to measure")
        return 0
    wanted = None if not args.scenes else set(args.scenes.split(","))
    if wanted and "heldout" in wanted:
        wanted = (wanted - {"heldout"}) | set(HELDOUT)
    if args.demo is None and not args.quick and (REPO / "out" / "scene.toml").is_file():
        args.demo = REPO / "out"
    if args.demo is not None:  # each code's bake runs in that code's folder
        args.demo = args.demo.resolve()
    if args.field is None and not args.quick and (wanted is None or wanted & set(FIELD_SCENES)):
        # the teapot's field at `field sample` defaults (order 4), built once (~10 s CPU)
        args.field = CACHE / "teapot.field.h5"
        CACHE.mkdir(parents=True, exist_ok=True)
        _fidelity()._ensure(args.field, "field", "sample", DATA / "meshes" / "teapot.obj",
                            "--order", 4)
    settings = []
    for item in args.set:  # each checked alone, before any work
        key, sep, value = (x.strip() for x in item.partition("="))
        if not sep or not re.fullmatch(r"[A-Za-z0-9_-]+", key) or not value:
            parser.error(f"--set {item!r}: expected KEY=VALUE with a bare key, e.g. "
                         "self_visibility_directions=64")
        try:
            tomllib.loads(f"x = {value}")
        except tomllib.TOMLDecodeError as exc:
            parser.error(f"--set {item!r}: {value!r} is not a TOML value ({exc})")
        settings.append(f"{key} = {value}")
    this = "this" if not settings else "this (" + ", ".join(args.set) + ")"
    codes = {this: REPO}
    if args.baseline:
        codes = {("baseline" if i == 0 else f"baseline {i + 1} ({b.name})"): b.resolve()
                 for i, b in enumerate(args.baseline)} | codes
    n_dirs = 800 if args.quick else REF_DIRECTIONS
    ref_dirs = 0 if args.quick else args.ref_dirs
    again = f", {ref_dirs} where it finds a shadow" if ref_dirs else ""
    print(f"\n### Look at the default settings vs a {n_dirs}-direction ray tracer of the real "
          f"meshes{again} (smoothness target 0.85-1.15; errors relative RMSE of radiance)\n")
    keys = ["scene", "receiver", "code", "smoothness", "error", "shadowed", "shadowed raw", "near",
            "CPU ms/frame", "CPU ratio", "set-up ms"]
    print("| " + " | ".join(keys) + " |\n|" + "---|" * len(keys))
    for name, scene in scenes(args.quick, args.demo, args.field, wanted).items():
        if wanted is not None and name not in wanted:
            continue
        baked = {}
        try:
            variant = (dict(scene, path=with_settings(scene["path"], settings)) if settings
                       else scene)
        except ValueError as exc:
            parser.error(str(exc))
        try:
            for _ in range(REPEATS):
                for tag, code in codes.items():
                    run = _bake(code, variant if tag == this else scene, tag)
                    cpu = float(np.mean(run["cpu"]))
                    if tag not in baked or cpu < baked[tag]["cpu"]:
                        baked[tag] = {"radiance": run["radiance"], "cpu": cpu,
                                      "setup": baked.get(tag, {}).get("setup", math.inf)}
                    # the fastest set-up frame too, kept apart from the frames'
                    baked[tag]["setup"] = min(baked[tag]["setup"], float(run["setup"]))
        finally:
            if settings:
                variant["path"].unlink(missing_ok=True)
        refs = references(scene, n_dirs, ref_dirs or None)
        first = next(iter(codes))
        for tag in codes:
            for row in score(baked[tag]["radiance"], refs):
                cells = [name, row["receiver"], tag] + [
                    "-" if row[k] is None else f"{row[k]:.3f}" if k == "smoothness"
                    else f"{100 * row[k]:.2f} %" for k in ("smoothness", "error", "shadowed",
                                                           "shadowed raw", "near")] + [
                    f"{1e3 * baked[tag]['cpu']:.0f}",
                    f"{baked[tag]['cpu'] / baked[first]['cpu']:.2f}",
                    f"{1e3 * baked[tag]['setup']:.0f}"]
                print("| " + " | ".join(cells) + " |", flush=True)
    print(f"\nload {os.getloadavg()[0]:.1f}; " + json.dumps({"n_dirs": n_dirs,
                                                             "ref_dirs": ref_dirs,
                                                             "set": settings}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
