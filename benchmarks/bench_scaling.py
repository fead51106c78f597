"""SH scaling (Wang et al. 2005): throughput, deformable fields, mid-range lighting.

Four tables, side by side in one run:

1. **Scaling throughput** -- ``ScalingTable.apply`` (interpolate M(k), rotate,
   scale, rotate back) per receiver x entity at orders 4 and 6.
2. **Skinned character over a ground grid** (Fox, CesiumMan from
   ``../shared/data/skinned``; several frames of one clip; a 100 x 100 grid, 10k
   receivers like the planes of Wang et al.'s Table 1): relative RMSE of
   per-vertex radiance against ray tracing of the posed mesh, on the ground and
   on the character itself, for (a) the deformable shadow field (re-sampled on
   the bounding sphere every frame, scaled per receiver; log space with one exp
   at several samplings and both logs, and product space) and (b) today's bound
   sphere set (the 48-sphere ``spheres fit`` + ``spheres bind`` sets of
   ``bench_fidelity``, cached in ``build/bench_fidelity``), through the runtime
   at its defaults in one process.  The character's own vertices are also given
   other self paths (nothing, the local visibility ``g_p``, the sphere set, a
   per-frame ray-traced self-visibility), combined with the field on the
   ground in log space.  Frame time = the sum of the per-frame components
   (sampling, lookups, self path, one exp), wall and CPU (this process), with
   the components listed; ratios are of CPU time.  The cone model's
   half-angle alpha is swept, and the log/product commutation difference of
   the field is reported.
3. **Mid-range lighting** -- a teapot on a plane inside an environment sphere
   (the set-up of Wang et al.'s Fig. 11, probe ``uffizi.hdr``): radiance error against
   per-vertex ray-traced environment lighting (rays hit the sphere, the probe --
   band-limited to order 12 -- is seen in the hit point's direction), for the
   scaled environment and for
   the distant-light assumption; unshadowed and shadowed by the teapot.
4. Wang et al.'s Table 1 (GPU frame rates, 2005) quoted as printed.

``python benchmarks/bench_scaling.py [--quick]``
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
ORDER = 4


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} / {five:.2f} (1 / 5 min) on {os.cpu_count()} cores"


def _timed(fn, repeat=3):
    best = math.inf
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


# -- 1. throughput --------------------------------------------------------------------


def throughput(quick: bool) -> list[str]:
    from shtools.runtime.scaling import ScalingTable
    from shtools.sh.scaling import build_scaling_table

    rows = ["| order | receivers x entities | apply (s) | vertex.entities / s | table build (s) |",
            "|---:|---:|---:|---:|---:|"]
    count = 2000 if quick else 20000
    rng = np.random.default_rng(0)
    for order in (4, 6):
        t0 = time.perf_counter()
        table = ScalingTable(build_scaling_table(order, "cone"))
        build = time.perf_counter() - t0
        f = rng.normal(size=(count, order * order))
        k = np.exp(rng.uniform(math.log(0.2), math.log(6), count))
        axes = rng.normal(size=(count, 3))
        _, seconds = _timed(lambda t=table, f=f, k=k, a=axes: t.apply(f, k, a))
        rows.append(f"| {order} | {count} | {seconds:.3f} | {count / seconds:,.0f} | "
                    f"{build:.2f} |")
    return rows


def accuracy() -> list[str]:
    """Quadrature convergence and interpolation error of the tables (spec section 6)."""
    from shtools.runtime.scaling import ScalingTable
    from shtools.sh.scaling import build_scaling_table, quadrature_error, scaling_values

    rows = ["| map, k | 100 nodes | 200 nodes | 400 nodes | 800 nodes |",
            "|---|---:|---:|---:|---:|"]
    for fn, k in (("cone", 1 / 8), ("cone", 8.0), ("midrange", 0.95), ("midrange", 0.99)):
        errs = [quadrature_error([k], ORDER, fn, nodes=q) for q in (100, 200, 400, 800)]
        rows.append(f"| {fn}, {k:g} | " + " | ".join(f"{e:.1e}" for e in errs) + " |")
    rows += ["", "| table (order 4) | interpolation | K = 20 | K = 40 | K = 80 |",
             "|---|---|---:|---:|---:|"]
    for fn, rng, rule in (("cone", (1 / 8, 8), "linear"), ("cone", (1 / 8, 8), "linear-log-k"),
                          ("cone", (1 / 16, 16), "linear"), ("midrange", (0, 0.95), "linear")):
        cells = []
        for count in (20, 40, 80):
            t = build_scaling_table(ORDER, fn, samples=count, k_range=rng, interpolation=rule)
            k = t["k"]
            mid = np.sqrt(k[:-1] * k[1:]) if fn == "cone" else 0.5 * (k[:-1] + k[1:])
            err = np.abs(ScalingTable(t).values_at(mid) - scaling_values(mid, ORDER, fn)).max()
            cells.append(f"{err:.4f}")
        rows.append(f"| {fn} [{rng[0]:g}, {rng[1]:g}] | {rule} | " + " | ".join(cells) + " |")
    return rows


# -- 2. skinned characters ----------------------------------------------------------------


CHARACTERS = {"Fox": ("Fox.glb", "Walk"), "CesiumMan": ("CesiumMan.glb", 0)}
#: bound sphere sets shared with bench_fidelity (48 spheres, `spheres fit` + `spheres bind`)
SPHERE_CACHE = REPO / "build" / "bench_fidelity"
SPHERES = 48
#: field samplings compared: (label, layout, rays, log method)
SAMPLINGS = (("384 x 512 rays, naive log", (16, 24), (16, 32), "naive"),
             ("384 x 512 rays, eigen log", (16, 24), (16, 32), "eigen"),
             ("384 x 128 rays, naive log", (16, 24), (8, 16), "naive"),
             ("192 x 128 rays, naive log", (12, 16), (8, 16), "naive"))
#: ray-traced per-frame self-visibility of the character's own vertices (an estimate
#: of the per-frame self path): key "traced <directions> <log>", label
SELF_TRACED = (("traced 256 eigen", "ray-traced self (256 dirs, eigen log)"),
               ("traced 96 naive", "ray-traced self (96 dirs, naive log)"))


def _vertex_normals(vertices, faces):
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    return np.asarray(mesh.vertex_normals, dtype=np.float64)


def _bound_spheres(name: str, file: str):
    """The bench_fidelity bound sphere set of a character (built with the CLI if missing)."""
    import subprocess
    import sys

    from shtools.data_formats.bound import read_bound

    rig = DATA / "skinned" / file
    sph = SPHERE_CACHE / f"{name.lower()}{SPHERES}.spheres.h5"
    bound = SPHERE_CACHE / f"{name.lower()}{SPHERES}.bound.h5"
    t0 = time.perf_counter()
    SPHERE_CACHE.mkdir(parents=True, exist_ok=True)
    if not sph.exists():
        subprocess.run([sys.executable, "-m", "shtools", "spheres", "fit", str(rig), "-n",
                        str(SPHERES), "-o", str(sph)], check=True)
    if not bound.exists():
        subprocess.run([sys.executable, "-m", "shtools", "spheres", "bind", str(sph), str(rig),
                        "-o", str(bound)], check=True)
    return read_bound(bound), time.perf_counter() - t0


def _timed2(fn, repeat=2):
    """Result, best wall seconds and best CPU seconds (this process) over ``repeat`` runs."""
    wall = cpu = math.inf
    out = None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return out, wall, cpu


class _Frame:
    """One posed frame: receivers, the ray-traced truth and the shading."""

    def __init__(self, rt, env, model, joints, ground, gnorm):
        import trimesh

        from shtools.reference.raytrace import raytrace_visibility

        self.rt, self.env = rt, env
        self.verts = model.skin(joints)
        self.n_g = len(ground)
        self.pts = np.concatenate([ground, self.verts])
        self.nrm = np.concatenate([gnorm, _vertex_normals(self.verts, model.faces)])
        self.mesh = trimesh.Trimesh(self.verts, model.faces, process=False)
        self.truth = rt.shade(raytrace_visibility(self.pts, self.nrm, [self.mesh], ORDER, 1024),
                              self.pts, self.nrm, env)

    def errors(self, g):
        """(ground, self) relative RMSE of radiance shaded with visibility ``g``."""
        from shtools.reference.metrics import relative_rmse

        rad = self.rt.shade(g, self.pts, self.nrm, self.env)
        return (relative_rmse(rad[:self.n_g], self.truth[:self.n_g]),
                relative_rmse(rad[self.n_g:], self.truth[self.n_g:]))


def _skinned_frame(fr: _Frame, model, joints, bound, local_log, clusters, tables, table4,
                   acc, err, secs, runtimes):
    """Every method and self path of one frame against ray tracing.

    Appends (ground, self) relative RMSEs to ``err[key]`` and (wall, CPU) seconds
    of each per-frame component to ``secs[key]``; returns the commutation
    difference (mean, max) of the field.
    """
    from shtools.fields.deformable import sample_deformable_field
    from shtools.geometry.visibility import (
        HEMISPHERE_DIRECTIONS,
        self_visibility,
        self_visibility_log,
    )
    from shtools.runtime import SelfVisibility, SphereBlocker
    from shtools.runtime.deformable import DeformableBlocker, deformable_visibility
    from shtools.runtime.spheres import pose_bound_spheres
    from shtools.scene.transfer import posed_local_log, traced_self_visibility
    from shtools.sh import exp as sh_exp
    from shtools.sh import log as sh_log

    rt, pts, n_g = fr.rt, fr.pts, fr.n_g
    size = acc * acc

    def put(key, value):
        g, wall, cpu = value
        secs.setdefault(key, []).append((wall, cpu))
        return g

    def spheres_blocker():
        return SphereBlocker(pose_bound_spheres(bound.bone_index, bound.bone_vectors, joints),
                             bound.radii)

    # (b) the bound sphere set through the SHEXP runtime (all rows, its own exp)
    g = put("spheres", _timed2(lambda: rt.visibility(pts, fr.nrm, [spheres_blocker()],
                                                     clusters=clusters["all"])))
    err.setdefault("spheres", []).append(fr.errors(g))
    # the scenes' defaults: the character's posed mesh traced on its own
    # vertices every frame, multiplied in after the exp, its own blocker skipped there
    own = slice(n_g, None)

    def with_traced(blocker, runtime=rt):
        traced = traced_self_visibility(fr.verts, fr.nrm[n_g:], model.faces, ORDER,
                                        HEMISPHERE_DIRECTIONS)
        return runtime.visibility(pts, fr.nrm, [blocker()], clusters=clusters["all"],
                                  self_visibility=[SelfVisibility(None, own, blocker=0,
                                                                  visibility=traced)])

    _, layout0, rays0, method0 = SAMPLINGS[0]

    def field_blocker():
        return DeformableBlocker(sample_deformable_field(
            fr.verts, model.faces, acc, layout=layout0, rays=rays0, log_method=method0),
            tables[45.0])

    # the scene defaults (traced own vertices), field in log and in product space;
    # one process (CPU) and the runtime's default processes (wall); "calling process":
    # the field hidden from the runtime behind a plain log blocker, evaluated in the
    # calling process only (the runtime without worker processes)
    for key, blocker, space in (("default spheres", spheres_blocker, "log"),
                                ("default field", field_blocker, "log"),
                                ("default field product", field_blocker, "product"),
                                ("default field calling process",
                                 lambda: _PlainLog(field_blocker()), "log")):
        # 4 repeats (fastest kept): wall times on the shared box swing by 30 %
        g = put(key, _timed2(lambda b=blocker, s=space: with_traced(b, runtimes[s, 1]), 4))
        err.setdefault(key, []).append(fr.errors(g))
        put(f"{key} | default processes", _timed2(
            lambda b=blocker, s=space: with_traced(b, runtimes[s, None]), 4))
    # components of the combined paths
    logs = {}
    for label, layout, rays, method in SAMPLINGS:
        field = put(f"sample {label}", _timed2(lambda la=layout, ra=rays, me=method:
                                               sample_deformable_field(
                                                   fr.verts, model.faces, acc, layout=la,
                                                   rays=ra, log_method=me)))
        logs[f"ground {label}"] = put(f"ground {label}", _timed2(
            lambda f=field: (f._local.clear(),
                             deformable_visibility(f, tables[45.0], pts[:n_g], log=True))[1]))
        logs[f"self {label}"] = put(f"self {label}", _timed2(
            lambda f=field: deformable_visibility(f, tables[45.0], pts[n_g:], log=True)))
        if label == SAMPLINGS[0][0]:
            field0 = field  # the default sampling: the alpha sweep
        if method == "eigen":
            field_eigen = field  # the log that inverts exp: the commutation check
    logs["self none"] = np.zeros((len(pts) - n_g, size))
    logs["self g_p"] = put("self g_p", _timed2(
        lambda: posed_local_log(local_log, model.blend_matrices(joints), np.eye(4))))
    logs["self spheres"] = put("self spheres", _timed2(
        lambda: rt.log_visibility(pts[n_g:], fr.nrm[n_g:], [spheres_blocker()],
                                  clusters=clusters["self"])))
    for key, _ in SELF_TRACED:  # "traced <dirs> <log>"
        _, dirs, method = key.split()

        def traced(dirs=int(dirs), method=method):
            g = self_visibility(fr.verts, fr.nrm[n_g:], fr.mesh, acc, n_dirs=dirs)
            return self_visibility_log(g) if method == "eigen" else sh_log(g, "naive")

        logs[f"self {key}"] = put(f"self {key}", _timed2(traced, repeat=1))

    def combined_log(ground_key, self_keys):
        return np.concatenate([logs[ground_key], sum(logs[k] for k in self_keys)]
                              ).astype(np.float32)

    def combined(ground_key, self_keys):
        return rt.exponentiate(combined_log(ground_key, self_keys))

    first = SAMPLINGS[0][0]
    one = combined_log(f"ground {first}", [f"self {first}"])
    put("exp", _timed2(lambda: rt.exponentiate(one)))

    for label, *_ in SAMPLINGS:
        err.setdefault(f"field {label} | field k<1", []).append(
            fr.errors(combined(f"ground {label}", [f"self {label}"])))
    for key, selfs in (("none", ["self none"]), ("g_p", ["self g_p"]),
                       ("field k<1 + g_p", [f"self {first}", "self g_p"]),
                       ("spheres", ["self spheres"]),
                       ("spheres + g_p", ["self spheres", "self g_p"]),
                       *[(key, [f"self {key}"]) for key, _ in SELF_TRACED]):
        for label, *_ in SAMPLINGS:
            if label == first or key not in ("none", "field k<1 + g_p", "spheres + g_p"):
                err.setdefault(f"field {label} | {key}", []).append(
                    fr.errors(combined(f"ground {label}", selfs)))
    # product space: the order-4 field's visibility on every row
    fld4 = put("sample product", _timed2(lambda: sample_deformable_field(
        fr.verts, model.faces, ORDER, log=False)))
    g = put("lookup product", _timed2(lambda: (fld4._local.clear(),
                                              deformable_visibility(fld4, table4, pts))[1]))
    err.setdefault("product | field k<1", []).append(fr.errors(g))
    for a, table in tables.items():
        err.setdefault(f"alpha {a:g}", []).append(fr.errors(rt.exponentiate(
            deformable_visibility(field0, table, pts, log=True).astype(np.float32))))
    # commutation: exp(scale(log S)) against scale(S), both at the accumulation order
    # (receivers within 8 bounding radii, a subset of at most 2000)
    near = np.flatnonzero(np.linalg.norm(pts - field_eigen.center, axis=1) < 8 * field_eigen.radius)
    near = near[:: max(1, len(near) // 2000)]
    scaled = deformable_visibility(field_eigen, tables[45.0], pts[near])
    via_log = sh_exp(deformable_visibility(field_eigen, tables[45.0], pts[near], log=True), "exact")
    diff = np.linalg.norm(via_log[:, :16] - scaled[:, :16], axis=1) / math.sqrt(4 * math.pi)
    return float(np.mean(diff)), float(np.max(diff))


class _PlainLog:
    """A log blocker the runtime knows nothing else about (evaluated in the calling process)."""

    def __init__(self, inner):
        self.inner = inner

    def log_visibility(self, points, normals, order):
        return self.inner.log_visibility(points, normals, order)


def _frame_time(secs, parts):
    """Mean (wall, CPU) of a frame made of the given components."""
    per = np.array([[sum(secs[p][f][c] for p in parts) for c in (0, 1)]
                    for f in range(len(secs[parts[0]]))])
    return per.mean(axis=0)


def _character_rows(name: str, n_v: str, err: dict, secs: dict) -> list[str]:
    """Table rows of one character: every (ground, self) combination with its frame time."""
    from shtools.geometry.visibility import HEMISPHERE_DIRECTIONS

    rows = []
    sph = _frame_time(secs, ["spheres"])

    def row(label, key, parts, base=sph):
        e = np.mean(err[key], axis=0)
        wall, cpu = _frame_time(secs, parts)
        rows.append(f"| {name} | {n_v} | {label} | {100 * e[0]:.1f} % | {100 * e[1]:.1f} % | "
                    f"{wall:.3f} | {cpu:.3f} | {cpu / base[1]:.2f}x |")

    row(f"bound sphere set ({SPHERES}) / the same", "spheres", ["spheres"])
    row(f"**scene default**: bound sphere set ({SPHERES}) / traced posed mesh "
        f"({HEMISPHERE_DIRECTIONS} rays, after the exp)", "default spheres", ["default spheres"])
    row(f"**scene default**: field, log, {SAMPLINGS[0][0]} / traced posed mesh "
        f"({HEMISPHERE_DIRECTIONS} rays) (ratio to the sphere set's scene default)",
        "default field", ["default field"], base=_frame_time(secs, ["default spheres"]))
    first = SAMPLINGS[0][0]
    for label, *_ in SAMPLINGS:
        base = [f"sample {label}", f"ground {label}", "exp"]
        row(f"field, log, {label} / field k<1", f"field {label} | field k<1",
            [*base, f"self {label}"])
        if label == first:
            row(f"field, log, {label} / nothing", f"field {label} | none", base)
            row(f"field, log, {label} / field k<1 + g_p", f"field {label} | field k<1 + g_p",
                [*base, f"self {label}", "self g_p"])
            row(f"field, log, {label} / spheres + g_p", f"field {label} | spheres + g_p",
                [*base, "self spheres", "self g_p"])
        row(f"field, log, {label} / g_p", f"field {label} | g_p", [*base, "self g_p"])
        row(f"field, log, {label} / spheres", f"field {label} | spheres",
            [*base, "self spheres"])
        for key, what in SELF_TRACED:
            row(f"field, log, {label} / {what}", f"field {label} | {key}",
                [*base, f"self {key}"])
    row("field, product (order 4, 384 x 512) / field k<1", "product | field k<1",
        ["sample product", "lookup product"])
    return rows


def _defaults_rows(name: str, n_v: str, err: dict, secs: dict) -> list[str]:
    """The scene defaults (own vertices traced) with spheres, field log / product space:
    errors, CPU per frame with one process, wall per frame with the default processes."""
    rows = []
    base = None
    for label, key in (("bound sphere set (48)", "default spheres"),
                       ("deformable field, log space", "default field"),
                       ("deformable field, product space", "default field product"),
                       ("deformable field, log space, in the calling process only (before)",
                        "default field calling process")):
        e = np.mean(err[key], axis=0)
        wall1, cpu1 = _frame_time(secs, [key])
        wall_p, _ = _frame_time(secs, [f"{key} | default processes"])
        base = base or (cpu1, wall_p)
        rows.append(f"| {name} | {n_v} | {label} | {100 * e[0]:.1f} % | {100 * e[1]:.1f} % | "
                    f"{1e3 * cpu1:.0f} ({cpu1 / base[0]:.2f}x) | {1e3 * wall1:.0f} | "
                    f"{1e3 * wall_p:.0f} ({wall_p / base[1]:.2f}x) |")
    return rows


DEFAULTS_HEAD = ["| character | receivers (ground + own) | blocker (scene defaults: own vertices "
                 "traced) | ground | own | CPU ms/frame, 1 process | wall ms, 1 process | "
                 "wall ms/frame, default processes ({p}) |",
                 "|---|---:|---|---:|---:|---:|---:|---:|"]


def skinned(quick: bool) -> tuple[list[str], list[str]]:
    import types

    from shtools.geometry.skin import load_skinned_gltf
    from shtools.lighting import load_hdr_image, project_latlong
    from shtools.reference.scenes import ground_grid
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.runtime.scaling import ScalingTable
    from shtools.scene.transfer import object_local_log
    from shtools.sh.scaling import build_scaling_table

    # the runtime's defaults (hierarchy on), one process: CPU time is comparable
    settings = ShadowSettings(order=ORDER, processes=1)
    acc = settings.resolved_acc_order()
    env = project_latlong(load_hdr_image(DATA / "probes" / "uffizi.hdr"), ORDER)
    frames = 2 if quick else 4
    alphas = (45.0,) if quick else (30.0, 45.0, 60.0)
    tables = {a: ScalingTable(build_scaling_table(acc, "cone", alpha=math.radians(a)))
              for a in alphas}
    table4 = ScalingTable(build_scaling_table(ORDER, "cone"))
    head = ["| character | receivers (ground + self) | method: ground / self | ground rel. RMSE "
            "| self rel. RMSE | frame s wall | frame s CPU | CPU ratio to spheres |",
            "|---|---:|---|---:|---:|---:|---:|---:|"]
    rows, alpha_rows = [], ["| character | alpha (deg) | ground rel. RMSE | self rel. RMSE |",
                            "|---|---:|---:|---:|"]
    commutation = []
    from dataclasses import replace

    from shtools.runtime.parallel import resolve_processes

    runtimes = {(space, p): ShadowRuntime(replace(settings, field_space=space, processes=p))
                for space in ("log", "product") for p in (1, None)}
    defaults = [DEFAULTS_HEAD[0].format(p=resolve_processes(None)), DEFAULTS_HEAD[1]]
    with ShadowRuntime(settings) as rt:
        for name, (file, clip) in CHARACTERS.items():
            path = DATA / "skinned" / file
            if not path.exists():
                rows.append(f"| {name} | - | (missing {path}) | | | | | |")
                continue
            model = load_skinned_gltf(path)
            bound, fit_s = _bound_spheres(name, file)
            rest = types.SimpleNamespace(vertices=model.rest_vertices, faces=model.faces,
                                         normals=_vertex_normals(model.rest_vertices,
                                                                 model.faces))
            t0 = time.perf_counter()
            local_log = object_local_log(rest, acc)
            local_s = time.perf_counter() - t0
            duration = model.duration(clip)
            times = np.linspace(0.1, 0.9, frames) * duration
            posed0 = model.skin(model.joint_matrices(times[0], clip))
            lo, hi = posed0.min(axis=0), posed0.max(axis=0)
            size = float(np.max(hi - lo))
            ground, gnorm = ground_grid(24 if quick else 100, 0.5 * (lo + hi)[[0, 2]],
                                        0.9 * size, y=float(lo[1]) - 1e-3 * size)
            n_g = len(ground)
            clusters = {"all": rt.clusters(np.concatenate([ground, posed0]),
                                           groups=np.r_[np.zeros(n_g), np.ones(len(posed0))]),
                        "self": rt.clusters(posed0)}
            err, secs = {}, {}
            for t in times:
                joints = model.joint_matrices(t, clip)
                fr = _Frame(rt, env, model, joints, ground, gnorm)
                commutation.append((name, *_skinned_frame(fr, model, joints, bound, local_log,
                                                          clusters, tables, table4, acc,
                                                          err, secs, runtimes)))
            rows += _character_rows(name, f"{n_g} + {len(posed0)}", err, secs)
            defaults += _defaults_rows(name, f"{n_g} + {len(posed0)}", err, secs)
            rows.append(f"| {name} | | (one-off: sphere fit + bind {fit_s:.0f} s if not "
                        f"cached; local g_p {local_s:.1f} s) | | | | | |")
            for a in alphas:
                e = np.mean(err[f"alpha {a:g}"], axis=0)
                alpha_rows.append(f"| {name} | {a:g} | {100 * e[0]:.1f} % | {100 * e[1]:.1f} % |")
            parts = ["| component | wall s | CPU s |", "|---|---:|---:|"]
            for key in secs:
                wall, cpu = _frame_time(secs, [key])
                parts.append(f"| {key} | {wall:.4f} | {cpu:.4f} |")
            print(f"\nPer-frame components, {name} (mean of {frames} frames; {_load()}):\n")
            print("\n".join(parts), flush=True)
    comm = ["| character | mean ‖exp(M log S) − M S‖ / √(4π) (order-4 part) | max |",
            "|---|---:|---:|"]
    for name in dict.fromkeys(c[0] for c in commutation):
        vals = [c for c in commutation if c[0] == name]
        comm.append(f"| {name} | {np.mean([v[1] for v in vals]):.4f} | "
                    f"{np.max([v[2] for v in vals]):.4f} |")
    for r in runtimes.values():
        r.close()
    print(f"\nScene defaults, one process (CPU) vs the default processes (wall); {_load()}:\n")
    print("\n".join(defaults), flush=True)
    return head + rows, [*alpha_rows, "", *comm, "", *defaults]


# -- 3. mid-range lighting ------------------------------------------------------------------


def midrange(quick: bool) -> list[str]:

    from shtools.geometry.mesh import load_mesh
    from shtools.geometry.raycast import RayCaster
    from shtools.geometry.visibility import direction_quadrature
    from shtools.lighting import load_hdr_image, project_latlong
    from shtools.reference.metrics import relative_rmse
    from shtools.runtime import ShadowRuntime, ShadowSettings
    from shtools.runtime.scaling import ScalingTable, midrange_lighting
    from shtools.sh import basis, project
    from shtools.sh.scaling import build_scaling_table

    img = load_hdr_image(DATA / "probes" / "uffizi.hdr")
    teapot = load_mesh(DATA / "meshes" / "teapot.obj")
    ext = teapot.bounds[1] - teapot.bounds[0]
    teapot.apply_translation(-np.array([teapot.bounds.mean(axis=0)[0], teapot.bounds[0][1],
                                        teapot.bounds.mean(axis=0)[2]]))
    teapot.apply_scale(1.0 / float(ext[1]))  # unit height, standing on y = 0
    grid = 24 if quick else 48
    t = np.linspace(-1.5, 1.5, grid)
    xx, zz = np.meshgrid(t, t, indexing="ij")
    plane_pts = np.stack([xx.ravel(), np.zeros(xx.size), zz.ravel()], axis=1)
    pot_pts = np.asarray(teapot.vertices)
    pot_nrm = np.asarray(teapot.vertex_normals)
    pts = np.concatenate([plane_pts, pot_pts])
    nrm = np.concatenate([np.tile([0.0, 1.0, 0.0], (len(plane_pts), 1)), pot_nrm])
    dirs, w = direction_quadrature(600 if quick else 1200)
    caster = RayCaster.from_meshes([teapot])
    occl = caster.visibility(pts, dirs, normals=nrm, offset=1e-4 * caster.diagonal)
    # the reference sees the probe band-limited to order 12 (a smooth integrand, so
    # the direction rule converges; the order-4 methods are compared with it)
    ref_order = 12
    probe = project_latlong(img, ref_order)  # (144, 3)
    rows = ["| R (env radius) | max k | receivers | method | unshadowed rel. RMSE | "
            "shadowed rel. RMSE | s |", "|---:|---:|---:|---|---:|---:|---:|"]
    center = np.array([0.0, 0.5, 0.0])
    settings = ShadowSettings(order=ORDER, processes=1, window="none")
    with ShadowRuntime(settings) as rt:
        g_one = np.zeros((len(pts), ORDER * ORDER))
        g_one[:, 0] = math.sqrt(4 * math.pi)
        g_sh = project(occl.astype(float), dirs, w, ORDER)
        for radius in (2.5, 4.0, 8.0):
            # reference: each ray hits the sphere; the probe is seen in the hit direction
            truth = {}
            cosine = np.maximum(nrm @ dirs.T, 0.0) / math.pi
            for start in range(0, len(pts), 512):
                p = pts[start:start + 512] - center
                b = p @ dirs.T
                tt = -b + np.sqrt(b * b - (np.sum(p * p, axis=1)[:, None] - radius**2))
                hit = (p[:, None, :] + tt[..., None] * dirs[None]) / radius
                lum = basis(hit, ref_order) @ probe  # (B, Q, 3)
                wt = cosine[start:start + 512] * w
                truth.setdefault("free", []).append(np.einsum("bq,bqc->bc", wt, lum))
                truth.setdefault("shadow", []).append(
                    np.einsum("bq,bqc->bc", wt * occl[start:start + 512], lum))
            free, shadow = (np.concatenate(truth[key]) for key in ("free", "shadow"))
            kmax = float(np.max(np.linalg.norm(pts - center, axis=1)) / radius)
            methods = {}
            for label, scale_order in (("distant (captured at the centre)", None),
                                       ("mid-range, scaled at order 4", ORDER),
                                       ("mid-range, scaled at order 8 -> 4", 8)):
                t0 = time.perf_counter()
                if scale_order is None:
                    light = env_c = project_latlong(img, ORDER)
                else:
                    table = ScalingTable(build_scaling_table(scale_order, "midrange",
                                                             k_range=(0.0, max(0.95, kmax))))
                    env_c = project_latlong(img, scale_order)
                    light = midrange_lighting(env_c, pts, center, radius, table, ORDER)
                seconds = time.perf_counter() - t0
                methods[label] = (rt.shade(g_one, pts, nrm, light),
                                  rt.shade(g_sh, pts, nrm, light), seconds)
            for label, (r_free, r_shadow, seconds) in methods.items():
                rows.append(f"| {radius:g} | {kmax:.2f} | {len(pts)} | {label} | "
                            f"{100 * relative_rmse(r_free, free):.1f} % | "
                            f"{100 * relative_rmse(r_shadow, shadow):.1f} % | {seconds:.2f} |")
    return rows


TABLE1 = """| scene (seed Table 1, GPU, 2005) | model / plane vertices | FPS as printed |
|---|---|---|
| Flying Dragon | 1.1k / 10k | "354" (almost surely 35.4) |
| Egg + Deform Light | 0.5k / 10k | 14.2 |
| Bending Sponge | 8.4k / 10k | "134" (almost surely 13.4) |
| Teapot Plane (mid-range) | 10k / 10k | 26.8 |"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--sections", default="throughput,skinned,midrange",
                        help="comma-separated subset of throughput, skinned, midrange")
    args = parser.parse_args()
    sections = set(args.sections.split(","))
    print("## SH scaling\n")
    print(_load())
    if "throughput" in sections:
        print("\n### 1. Scaling throughput (interpolate M(k), D^T M D f per receiver)\n")
        print("\n".join(throughput(args.quick)))
        print("\nQuadrature error (max entry change against twice the nodes) and "
              "interpolation error (max entry error at the midpoints between samples):\n")
        print("\n".join(accuracy()))
    if not (DATA / "skinned").is_dir():
        print(f"\n(no {DATA}; the skinned and mid-range tables need the shared data)")
        return
    if "skinned" in sections:
        print("\n### 2. Skinned character over a ground grid (vs ray tracing of the posed "
              "mesh)\n")
        main_rows, extra = skinned(args.quick)
        print("\n".join(main_rows))
        print("\nCone half-angle (deformable field, log space):\n")
        print("\n".join(extra))
    if "midrange" in sections:
        print("\n### 3. Mid-range lighting: teapot on a plane inside an environment sphere\n")
        print("\n".join(midrange(args.quick)))
    print("\n### 4. Wang et al.'s Table 1, as printed (not comparable: GPU, 2005)\n")
    print(TABLE1)
    print("\n" + _load())


if __name__ == "__main__":
    main()
