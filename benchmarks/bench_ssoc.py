"""Small spherical lights: SSOC vs SHEXP's cap light vs ray tracing, side by side.

Scene: a mesh (the 69k-triangle bunny of ``../shared/data``; a procedural blob
without the data) standing on a 256 x 256 ground grid, lit by one spherical
light whose angular radius (seen from the ground under the mesh) sweeps
0.01-0.3 rad.  Receivers are the ground vertices and the mesh's own vertices.

Ground truth: the directly ray-traced visible fraction ``S`` and the
cosine-weighted light (``shtools.reference.light_fraction.light_visible_fraction``, 256
stratified rays per receiver).  Per method and radius:

* ``S`` MAE and max over true-penumbra receivers (``0.02 < S_ref < 0.98``, light
  wholly above the receiver's horizon), misclassification rate
  (``|S - S_ref| > 0.5``, all such receivers);
* relative RMSE of the light's radiance over every receiver;
* time per light per frame (CPU seconds, one process).

Methods: SSOC (``shtools.runtime.ssoc``, defaults), SHEXP's cap light at order
4 and 6 (the runtime's visibility of a 48-sphere variational fit, then the
light's SH shading; ``S`` read back as radiance / unshadowed), ray tracing at
16 and 64 strata.  For SHEXP the time is visibility + light shading (the
visibility is shared with the environment in a real bake; the light's own
shading is given separately).  Then the crossover radius, the goal, the
options beyond the paper at 0.05 rad, and the paper's Table 1 columns (CPU) on the
bunny and the dragon.  First, :func:`penumbra`: the error over the ground vertices
in the penumbra and umbra of a 0.05 rad light, next to the whole ground's.

The penumbra table is repeated with spot and the cow in the bunny's place (held out:
the defaults were tuned on the bunny; ``--penumbra-mesh NAME`` for others).

``python benchmarks/bench_ssoc.py [--quick] [--penumbra-only] [--penumbra-mesh NAME]``
"""

from __future__ import annotations

import argparse
import itertools
import os
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: the shared meshes next to the repository (or next to the folder of its worktrees)
DATA = next((d / "shared" / "data" / "meshes" for d in (REPO.parent, REPO.parent.parent)
             if (d / "shared" / "data" / "meshes").is_dir()),
            REPO.parent / "shared" / "data" / "meshes")
RADII = (0.01, 0.02, 0.05, 0.1, 0.2, 0.3)
#: Mo et al.'s Table 1 (GeForce 8800 GTX, 512^2 screen), quoted as printed (ms).
SEED_TABLE1 = {
    "Bunny (70k)": (8.0, 0.8, 1.7, 8.2),
    "Dragon and Sphere (270k)": (27.7, 1.8, 5.3, 16.5),
}


def _load(name: str, quick: bool):
    import trimesh

    path = DATA / name
    if path.exists():
        from shtools.geometry.mesh import load_mesh

        mesh = load_mesh(path)
    else:  # procedural stand-in (a lumpy blob)
        mesh = trimesh.creation.icosphere(5 if not quick else 3)
        mesh.vertices *= 1.0 + 0.15 * np.sin(4 * mesh.vertices[:, :1])
    # unit height, standing on y = 0, centred at the origin in x, z
    lo, hi = mesh.bounds
    mesh.apply_translation([-(lo[0] + hi[0]) / 2, -lo[1], -(lo[2] + hi[2]) / 2])
    mesh.apply_scale(1.0 / (hi[1] - lo[1]))
    return mesh


def _scene(mesh, grid: int):
    half = 1.5
    x = np.linspace(-half, half, grid)
    X, Z = np.meshgrid(x, x, indexing="ij")
    ground = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], axis=1)
    pts = np.concatenate([ground, mesh.vertices])
    nrm = np.concatenate([np.tile([0.0, 1.0, 0.0], (len(ground), 1)), mesh.vertex_normals])
    return pts, nrm, len(ground)


def _timed(fn, *args, **kw):
    t = time.process_time()
    out = fn(*args, **kw)
    return out, time.process_time() - t


def _metrics(S, rad, ref, mask_above, n_ground) -> dict:
    pen = mask_above & (ref.fraction > 0.02) & (ref.fraction < 0.98)
    err = np.abs(S - ref.fraction)
    rmse = np.sqrt(np.mean((rad - ref.radiance) ** 2) / np.mean(ref.radiance ** 2))
    ground = np.arange(len(S)) < n_ground
    return {"S MAE": float(err[pen].mean()) if pen.any() else float("nan"),
            "S MAE ground": float(err[pen & ground].mean()) if (pen & ground).any() else 0.0,
            "S MAE mesh": float(err[pen & ~ground].mean()) if (pen & ~ground).any() else 0.0,
            "S max": float(err[pen].max()) if pen.any() else float("nan"),
            "miscl %": 100.0 * float(np.mean(err[mask_above] > 0.5)),
            "rad RMSE %": 100.0 * float(rmse)}


def accuracy(mesh, quick: bool):
    from shtools.geometry.sphere_fit import fit_spheres
    from shtools.reference.light_fraction import light_visible_fraction
    from shtools.runtime import ShadowRuntime, ShadowSettings, SphereBlocker, SphereLight
    from shtools.runtime.shading import sphere_light_unshadowed
    from shtools.runtime.ssoc import OcclusionCamera, SSOCSettings
    from shtools.scene.light_shadows import ssoc_radiance

    pts, nrm, ng = _scene(mesh, 96 if quick else 256)
    fit = fit_spheres(mesh, 16 if quick else 48, seed=0)
    blockers = [SphereBlocker(fit.centers, fit.radii)]
    center = np.array([0.35, 2.5, 0.25])
    dist = float(np.linalg.norm(center))  # to the ground under the mesh
    meshes = [(np.asarray(mesh.vertices), np.asarray(mesh.faces))]
    from shtools.geometry.raycast import RayCaster

    caster = RayCaster(*meshes[0])
    rows, extra = [], []
    radii = RADII[::2] if quick else RADII
    runtimes = {n: ShadowRuntime(ShadowSettings(order=n, hierarchy=False, processes=1))
                for n in (4, 6)}
    vis = {}
    for n, rt in runtimes.items():  # the SHEXP visibility does not depend on the light
        vis[n] = _timed(rt.visibility, pts, nrm, blockers)
    for alpha in radii:
        r = dist * np.sin(alpha)
        light = SphereLight(center, r, (1.0, 1.0, 1.0))
        ref = light_visible_fraction(pts, nrm, caster, center, r, n_samples=256, seed=1)
        d = center - pts
        dd = np.linalg.norm(d, axis=1)
        cos_b = np.einsum("ij,ij->i", nrm, d) / dd
        above = np.arccos(np.clip(cos_b, -1, 1)) + np.arcsin(r / dd) < np.pi / 2 - 0.02
        free, t_free = _timed(sphere_light_unshadowed, light, pts, nrm)
        oc = OcclusionCamera([meshes[0][1]], SSOCSettings())
        S, t = _timed(oc.visible_fraction, [meshes[0][0]], center, r, pts, nrm)
        rows.append({"alpha": alpha, "method": "SSOC", **_metrics(S, S * free, ref, above, ng),
                     "ms/light/frame": 1e3 * (t + t_free)})
        for rays in HYBRID_RAYS:  # the scene's "ssoc" light: rays where the camera sees penumbra
            lit, t = _timed(ssoc_radiance, oc, [meshes[0][0]], caster, light, pts, nrm, rays)
            S_h = np.where(free > 1e-12, lit / np.maximum(free, 1e-12), 1.0)
            rows.append({"alpha": alpha, "method": f"SSOC + {rays} rays",
                         **_metrics(S_h, lit, ref, above, ng), "ms/light/frame": 1e3 * t})
        for n, rt in runtimes.items():
            (g, t_vis) = vis[n]
            rad, t_sh = _timed(rt.shade, g, pts, nrm, None, sphere_lights=[light])
            rad = rad[:, 0]
            S_sh = np.where(free > 1e-12, rad / np.maximum(free, 1e-12), 1.0)
            rows.append({"alpha": alpha, "method": f"SHEXP o{n}",
                         **_metrics(S_sh, rad, ref, above, ng),
                         "ms/light/frame": 1e3 * (t_vis + t_sh),
                         "shade only ms": 1e3 * t_sh})
        for spp in (16, 64):
            rt_ref, t = _timed(light_visible_fraction, pts, nrm, caster, center, r,
                               n_samples=spp, seed=7)
            rows.append({"alpha": alpha, "method": f"RT {spp} spp",
                         **_metrics(rt_ref.fraction, rt_ref.radiance, ref, above, ng),
                         "ms/light/frame": 1e3 * t})
        if abs(alpha - 0.05) < 1e-9 or (quick and alpha == radii[1]):
            for label, st in (("steps 1 (naive, Fig. 5)", SSOCSettings(max_steps=1)),
                              ("steps 2", SSOCSettings(max_steps=2)),
                              ("smoothstep falloff (paper)", SSOCSettings(falloff="smoothstep")),
                              ("quads (seed corners)", SSOCSettings(corners="quads")),
                              ("product overlap (paper)", SSOCSettings(overlap="product")),
                              ("covered silhouettes kept", SSOCSettings(drop_covered=False)),
                              ("both (98bedba-0b3d1da rules)",
                               SSOCSettings(overlap="product", drop_covered=False)),
                              ("resolution 512", SSOCSettings(resolution=512)),
                              ("resolution 2048", SSOCSettings(resolution=2048)),
                              ("frustum camera", SSOCSettings(camera="frustum"))):
                oc = OcclusionCamera([meshes[0][1]], st)
                S, t = _timed(oc.visible_fraction, [meshes[0][0]], center, r, pts, nrm)
                extra.append({"alpha": alpha, "variant": label,
                              **_metrics(S, S * free, ref, above, ng),
                              "ms/light/frame": 1e3 * (t + t_free), "camera": oc.camera.mode})
    for rt in runtimes.values():
        rt.close()
    return rows, extra, len(pts)


#: Rays per penumbra receiver of the hybrid rows (the scene's ``ssoc.rays``).
HYBRID_RAYS = (64, 256)
#: Meshes of the penumbra table held out from the tuning (the bunny's), scaled likewise.
HELD_OUT = ("spot.obj", "cow.obj")
#: Light centres of the small-light penumbra scenes (bunny of unit height at the origin).
PENUMBRA_LIGHTS = ((0.35, 2.5, 0.25), (1.5, 1.6, 0.8), (-0.8, 1.2, -1.0))


def penumbra(mesh, quick: bool) -> list[dict]:
    """The bunny on a 3 x 3 ground under one light of angular radius 0.05 rad (from the
    origin), per light of :data:`PENUMBRA_LIGHTS`: relative RMSE of the light's radiance
    over the ground vertices that see less than 98 % of it (penumbra and umbra) and over
    the whole ground, SSOC (defaults; alone, and with :data:`HYBRID_RAYS` rays on the
    receivers it finds in penumbra) and 64-ray tracing against 1,024 rays."""
    from shtools.geometry.raycast import RayCaster
    from shtools.reference.light_fraction import light_visible_fraction
    from shtools.runtime import SphereLight
    from shtools.runtime.shading import sphere_light_unshadowed
    from shtools.runtime.ssoc import OcclusionCamera
    from shtools.scene.light_shadows import ssoc_radiance

    pts, nrm, ng = _scene(mesh, 49 if quick else 97)
    pts, nrm = pts[:ng], nrm[:ng]
    caster = RayCaster(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    rows = []
    for pos in PENUMBRA_LIGHTS[:1] if quick else PENUMBRA_LIGHTS:
        center = np.asarray(pos, dtype=np.float64)
        r = float(np.linalg.norm(center)) * np.sin(0.05)
        ref = light_visible_fraction(pts, nrm, caster, center, r,
                                     n_samples=256 if quick else 1024, seed=1)
        dark = ref.fraction < 0.98

        def rel(x, y):
            return 100.0 * float(np.sqrt(np.mean((x - y) ** 2) / np.mean(y ** 2)))

        free = sphere_light_unshadowed(SphereLight(center, r, (1.0, 1.0, 1.0)), pts, nrm)
        oc = OcclusionCamera([np.asarray(mesh.faces)])
        S, t = _timed(oc.visible_fraction, [np.asarray(mesh.vertices)], center, r, pts, nrm)
        rt, t_rt = _timed(light_visible_fraction, pts, nrm, caster, center, r, n_samples=64,
                          seed=7)
        hyb = {}
        for rays in HYBRID_RAYS:
            lit, t_h = _timed(ssoc_radiance, oc, [np.asarray(mesh.vertices)], caster,
                              SphereLight(center, r, (1.0, 1.0, 1.0)), pts, nrm, rays)
            hyb.update({f"+{rays} rays dark %": rel(lit[dark], ref.radiance[dark]),
                        f"+{rays} rays ground %": rel(lit, ref.radiance),
                        f"+{rays} rays ms": 1e3 * t_h})
        rows.append({"light": str(pos), "dark vertices": int(dark.sum()),
                     "SSOC dark %": rel(S[dark] * free[dark], ref.radiance[dark]),
                     "SSOC ground %": rel(S * free, ref.radiance), **hyb,
                     "RT64 dark %": rel(rt.radiance[dark], ref.radiance[dark]),
                     "RT64 ground %": rel(rt.radiance, ref.radiance),
                     "SSOC ms": 1e3 * t, "RT64 ms": 1e3 * t_rt})
    return rows


def crossover(rows) -> str:
    """Angular radius where SSOC's radiance error meets SHEXP order 6's (log-linear)."""
    alphas = sorted({r["alpha"] for r in rows})
    diff = []
    for a in alphas:
        e = {r["method"]: r["rad RMSE %"] for r in rows if r["alpha"] == a}
        diff.append(np.log(e["SSOC"]) - np.log(e["SHEXP o6"]))
    pairs = list(zip(alphas, diff, strict=True))
    for (a0, d0), (a1, d1) in itertools.pairwise(pairs):
        if d0 < 0 <= d1:
            la = np.log(a0) + (np.log(a1) - np.log(a0)) * (-d0) / (d1 - d0)
            return f"{np.exp(la):.3g} rad (SSOC better below)"
    if all(d < 0 for d in diff):
        return f"> {alphas[-1]} rad (SSOC better at every radius measured)"
    return f"< {alphas[0]} rad (SHEXP order 6 better at every radius measured)"


def stages(quick: bool):
    """Mo et al.'s Table 1 columns, CPU, one process, on the bunny and the dragon."""
    from shtools.runtime.ssoc import OcclusionCamera, SSOCSettings

    out = []
    for name, file in (("bunny", "stanford-bunny.obj"), ("dragon", "dragon.obj")):
        mesh = _load(file, quick)
        pts, nrm, _ = _scene(mesh, 96 if quick else 256)
        center = np.array([0.35, 2.5, 0.25])
        for res in (512, 1024):
            oc = OcclusionCamera([mesh.faces], SSOCSettings(resolution=res))
            oc.visible_fraction([mesh.vertices], center, 0.12, pts, nrm)  # warm-up
            best = None
            for _ in range(1 if quick else 3):
                oc.visible_fraction([mesh.vertices], center, 0.12, pts, nrm)
                st = oc.last_stats
                tot = st.silhouettes + st.shadow_map + st.ssoc + st.receivers
                if best is None or tot < best[1]:
                    best = (st, tot)
            st = best[0]
            out.append({"mesh": f"{name} ({len(mesh.faces) // 1000}k)", "map": f"{res}²",
                        "receivers": len(pts), "silhouettes ms": 1e3 * st.silhouettes,
                        "shadow map ms": 1e3 * st.shadow_map, "SSOC ms": 1e3 * st.ssoc,
                        "receivers ms": 1e3 * st.receivers, "edges": st.n_silhouettes,
                        "camera": f"{st.camera} ({st.faces} face)"})
    return out


def _markdown(rows: list[dict]) -> str:
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    out = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for r in rows:
        out.append("| " + " | ".join(
            (f"{r[k]:.4g}" if isinstance(r.get(k), float) else str(r.get(k, "")))
            for k in keys) + " |")
    return "\n".join(out)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--skip-stages", action="store_true")
    parser.add_argument("--stages-only", action="store_true")
    parser.add_argument("--penumbra-only", action="store_true",
                        help="only the small-light penumbra tables (bunny on a 3 x 3 ground)")
    parser.add_argument("--penumbra-mesh", action="append", metavar="NAME",
                        help="a mesh of the shared data for another penumbra table, in the "
                             "bunny's place (again for more; default without --quick: "
                             + ", ".join(HELD_OUT) + ")")
    args = parser.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    load = os.getloadavg()
    print(f"# bench_ssoc — {os.cpu_count()} cores, load average {load[0]:.1f} {load[1]:.1f} "
          f"{load[2]:.1f} (CPU process time per method; side by side in one run)")
    if args.stages_only:
        print(_markdown(stages(args.quick)))
        return
    mesh = _load("stanford-bunny.obj", args.quick)
    print("\n## Small light (0.05 rad), bunny on a 3 x 3 ground: the vertices seeing "
          "< 98 % of it\n")
    print(_markdown(penumbra(mesh, args.quick)))
    for name in args.penumbra_mesh or (() if args.quick else HELD_OUT):
        if not (DATA / name).exists():
            continue
        print(f"\n## Small light (0.05 rad), {name} in the bunny's place (held out)\n")
        print(_markdown(penumbra(_load(name, args.quick), args.quick)))
    if args.penumbra_only:
        return
    t0 = time.perf_counter()
    rows, extra, n = accuracy(mesh, args.quick)
    print(f"\n## Accuracy and time, bunny over a plane ({n} receivers; "
          f"{time.perf_counter() - t0:.0f} s)\n")
    print(_markdown(rows))
    print(f"\nCrossover SSOC vs SHEXP order 6 (radiance RMSE): {crossover(rows)}")
    goal_rows = [r for r in rows if r["alpha"] <= 0.05]
    for a in sorted({r["alpha"] for r in goal_rows}):
        e = {r["method"]: r for r in goal_rows if r["alpha"] == a}
        ok_err = e["SSOC"]["rad RMSE %"] <= 0.5 * e["SHEXP o6"]["rad RMSE %"]
        ok_t = e["SSOC"]["ms/light/frame"] < e["RT 64 spp"]["ms/light/frame"]
        print(f"goal at {a} rad: SSOC {e['SSOC']['rad RMSE %']:.3g} % vs half of SHEXP o6 "
              f"{0.5 * e['SHEXP o6']['rad RMSE %']:.3g} % -> {'met' if ok_err else 'MISSED'}; "
              f"time {e['SSOC']['ms/light/frame']:.0f} ms vs RT64 "
              f"{e['RT 64 spp']['ms/light/frame']:.0f} ms -> {'met' if ok_t else 'MISSED'}")
    print("\n## SSOC variants (beyond the paper, and its naive form)\n")
    print(_markdown(extra))
    if not args.skip_stages:
        print("\n## Per-stage CPU times (Mo et al.'s Table 1 columns)\n")
        print(_markdown(stages(args.quick)))
        print("\nSeed (GeForce 8800 GTX, 512² screen, as printed): "
              + "; ".join(f"{k}: silhouette {v[0]} ms, shadow map {v[1]} ms, create SSOC "
                          f"{v[2]} ms, render from eye {v[3]} ms" for k, v in SEED_TABLE1.items()))


if __name__ == "__main__":
    main()
