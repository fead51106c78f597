"""The bundled demo: ``python -m shtools.demo OUTDIR`` (what ``make demo`` runs).

Everything is generated here — no downloaded data.  A character built from
primitives (capsule torso, limbs swinging on hip and shoulder pivots, a sphere
head) walks across a ground plane past a column while a ball rolls the other
way, under a procedural lat-long HDR sky (bright warm sun region, blue sky,
dark ground) and one warm spherical light.

The demo runs the real stages, in-process through the ``shtools`` command line:

1. writes the part meshes (OBJ) and the sky (``sky.hdr``);
2. ``shtools spheres fit`` per distinct mesh and ``shtools spheres tree``;
3. ``shtools tables log`` at the accumulation order;
4. ``shtools light project sky.hdr``;
5. writes ``scene.toml`` and runs ``shtools bake``;
6. ``shtools export`` to ``demo.glb``, ``frame.png``, ``sheet.png`` and ``demo.gif``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

#: Scene timing: frames at FPS; one walk cycle (two steps) per STRIDE_SECONDS.
FRAMES = 48
FPS = 24.0
STRIDE_SECONDS = 1.0
ORDER = 4
#: Sphere fitting method of the demo's `spheres fit` stage, and its round cap: 12
#: rounds reach within ~30 % of the 40-round outside volume at a quarter of the time
#: (torso: E = 0.145 vs 0.113), which keeps the demo near a minute.
FIT_METHOD = "variational"
FIT_ITERATIONS = 12


def sky_image(height: int = 64, width: int = 128) -> np.ndarray:
    """A procedural lat-long HDR sky (H, W, 3), linear RGB, Y up (image centre = -z).

    Blue sky brightening towards the horizon, a broad warm sun region about 40
    degrees above the horizon behind the scene as the preview camera sees it
    (wide enough for a 4th-order SH to carry its direction, so shadows fall
    towards the camera), and a dim brown ground below the horizon.
    """
    from shtools.lighting.latlong import latlong_directions

    d = latlong_directions(height, width)
    up = d[..., 1]
    zenith = np.array([0.10, 0.2, 0.45])
    horizon = np.array([0.4, 0.45, 0.55])
    t = np.clip(up, 0.0, 1.0)[..., None]
    sky = (1 - t) ** 2 * horizon + (1 - (1 - t) ** 2) * zenith
    sun_dir = np.array([-0.6, 0.65, -0.25])
    sun_dir /= np.linalg.norm(sun_dir)
    cos_sun = d @ sun_dir
    sun = 40.0 * np.exp((cos_sun - 1.0) / 0.03)[..., None] * np.array([1.0, 0.85, 0.6])
    ground = np.array([0.18, 0.15, 0.12])
    image = np.where(up[..., None] > 0, sky + sun, ground)
    return image.astype(np.float32)


def write_hdr(path: Path, image: np.ndarray) -> None:
    """Write a Radiance RGBE ``.hdr`` (OpenCV's writer; BGR channel order)."""
    import cv2

    from shtools.data_formats import atomic_path

    with atomic_path(path) as tmp:
        ok, buf = cv2.imencode(".hdr", np.ascontiguousarray(image[..., ::-1], np.float32))
        if not ok:
            raise RuntimeError("OpenCV could not encode the HDR image")
        tmp.write_bytes(buf.tobytes())


def part_meshes() -> dict[str, object]:
    """Meshes (trimesh) of the parts that get fitted sphere sets, in their local frames.

    Limbs hang below their pivot (the local origin) so that keyframed
    rotations swing them about the hip or shoulder.
    """
    from shtools.scene.primitives import make_primitive

    return {
        "torso": make_primitive("capsule", {"radius": 0.17, "length": 0.42, "count": 20}).mesh,
        "leg": make_primitive("capsule", {"radius": 0.085, "length": 0.55, "count": 16,
                                          "center": [0.0, -0.36, 0.0]}).mesh,
        "arm": make_primitive("capsule", {"radius": 0.06, "length": 0.42, "count": 14,
                                          "center": [0.0, -0.26, 0.0]}).mesh,
        "column": make_primitive("cylinder", {"radius": 0.22, "height": 2.2, "sections": 32,
                                              "subdivisions": 12}).mesh,
    }


#: sphere count fitted per part mesh
SPHERES = {"torso": 6, "leg": 5, "arm": 4, "column": 8}


def _walk_keys(duration: float) -> str:
    """TOML keyframes of the torso: across the ground with a bob at every step."""
    lines = []
    steps = max(1, round(2 * duration / STRIDE_SECONDS))
    for k in range(steps + 1):
        t = k * duration / steps
        x = -2.0 + 4.0 * t / duration
        y = 0.95 if k % 2 == 0 else 0.99
        lines.append(f"[[objects.keyframes]]\ntime = {t:.4f}\ntranslate = [{x:.4f}, {y}, 0.35]")
    return "\n".join(lines)


def _swing_keys(amplitude: float, phase: int) -> str:
    """Looping pendulum keyframes (rotation about z) for a limb."""
    sign = 1 if phase == 0 else -1
    q = STRIDE_SECONDS / 4
    angles = [0, sign * amplitude, 0, -sign * amplitude, 0]
    return "\n".join(
        f"[[objects.keyframes]]\ntime = {k * q:.4f}\nrotate = [0.0, 0.0, {a:.2f}]"
        for k, a in enumerate(angles)
    )


def _roll_keys(duration: float, radius: float) -> str:
    """A ball rolling along -x at z = -1.1 without slipping (keys every ~50 degrees)."""
    x0, x1 = 2.2, -2.2
    total_angle = np.degrees((x0 - x1) / radius)
    n = int(np.ceil(total_angle / 50.0))
    lines = []
    for k in range(n + 1):
        u = k / n
        lines.append(
            f"[[objects.keyframes]]\ntime = {u * duration:.4f}\n"
            f"translate = [{x0 + u * (x1 - x0):.4f}, {radius}, -1.1]\n"
            f"rotate = [0.0, 0.0, {u * total_angle:.3f}]"
        )
    return "\n".join(lines)


def scene_toml(frames: int = FRAMES, fps: float = FPS) -> str:
    """The demo scene file (assets referenced relative to it)."""
    duration = (frames - 1) / fps
    ball_r = 0.35
    limbs = []
    for name, mesh, pivot, amp, phase in (
        ("leg_left", "leg", [0.0, -0.22, 0.1], 28.0, 0),
        ("leg_right", "leg", [0.0, -0.22, -0.1], 28.0, 1),
        ("arm_left", "arm", [0.0, 0.27, 0.25], 32.0, 1),
        ("arm_right", "arm", [0.0, 0.27, -0.25], 32.0, 0),
    ):
        limbs.append(f"""
[[objects]]
name = "{name}"
mesh = "meshes/{mesh}.obj"
role = "both"
parent = "torso"
translate = {pivot}
loop = true
blocker = {{ tree = "spheres/{mesh}_tree.h5" }}
{_swing_keys(amp, phase)}
""")
    return f"""# shtools demo scene (generated by shtools.demo)
[settings]
order = {ORDER}
frames = {frames}
fps = {fps}
tables = "tables.h5"
vertices_per_cluster = 400

[environment]
light = "sky.h5"

[[lights]]
name = "lamp"
position = [-1.6, 1.9, 1.5]
radius = 0.3
color = [40.0, 30.0, 18.0]

[[objects]]
name = "ground"
primitive = {{ type = "plane", size = [6.0, 4.2], subdivisions = 112 }}
role = "receiver"
albedo = [0.8, 0.8, 0.78]

[[objects]]
name = "column"
mesh = "meshes/column.obj"
role = "both"
translate = [0.9, 1.1, -0.35]
albedo = [0.85, 0.8, 0.7]
blocker = {{ tree = "spheres/column_tree.h5" }}

[[objects]]
name = "ball"
primitive = {{ type = "sphere", radius = {ball_r}, subdivisions = 3 }}
role = "both"
albedo = [0.9, 0.35, 0.25]
{_roll_keys(duration, ball_r)}

[[objects]]
name = "torso"
mesh = "meshes/torso.obj"
role = "both"
albedo = [0.3, 0.5, 0.85]
blocker = {{ tree = "spheres/torso_tree.h5" }}
{_walk_keys(duration)}

[[objects]]
name = "head"
primitive = {{ type = "sphere", radius = 0.14, subdivisions = 3 }}
role = "both"
parent = "torso"
translate = [0.0, 0.48, 0.0]
albedo = [0.95, 0.8, 0.65]
{''.join(limbs)}"""


def _fit_part(job) -> None:
    """Fit then tree for one part (in a worker process), as `spheres fit` + `spheres tree`."""
    from shtools.geometry.assets import fit_to_file, tree_to_file

    out, name, n, method = job
    iterations = FIT_ITERATIONS if method == "variational" else None
    fit_to_file(out / "meshes" / f"{name}.obj", n, out / "spheres" / f"{name}.h5",
                method=method, iterations=iterations)
    tree_to_file(out / "spheres" / f"{name}.h5", out / "spheres" / f"{name}_tree.h5")


def run_demo(outdir: str | Path, *, frames: int = FRAMES, quiet: bool = False,
             fit_method: str | None = None) -> dict:
    """Generate, bake and export the demo scene into ``outdir``; returns timings (seconds).

    Every stage is a library call (the same functions the ``shtools`` commands run),
    so the outputs equal those of the command-line pipeline in ``examples/``.
    """
    out = Path(outdir)
    (out / "meshes").mkdir(parents=True, exist_ok=True)
    (out / "spheres").mkdir(exist_ok=True)
    timings: dict[str, float] = {}
    say = (lambda *_: None) if quiet else (lambda msg: print(msg, flush=True))

    def stage(name, fn):
        start = time.perf_counter()
        say(f"[demo] {name}")
        fn()
        timings[name] = time.perf_counter() - start

    def meshes():
        from shtools.data_formats import atomic_path

        for name, mesh in part_meshes().items():
            with atomic_path(out / "meshes" / f"{name}.obj") as tmp:
                tmp.write_text(mesh.export(file_type="obj", include_normals=False))
        write_hdr(out / "sky.hdr", sky_image())

    def spheres():
        # one fit -> tree chain per part, two at a time (like `make -j2`)
        from concurrent.futures import ProcessPoolExecutor

        from shtools.tasks import blas_threads, use_blas_threads, worker_context

        jobs = [(out, name, n, fit_method or FIT_METHOD) for name, n in SPHERES.items()]
        # biggest fits first so the two workers finish together
        jobs.sort(key=lambda job: -job[2])
        # workers from the fork server, as the library's pools (shtools.tasks.worker_context)
        with ProcessPoolExecutor(max_workers=2, mp_context=worker_context(),
                                 initializer=use_blas_threads,
                                 initargs=(blas_threads(),)) as pool:
            list(pool.map(_fit_part, jobs))  # a failure re-raises here

    def tables():
        from shtools.data_formats.tables import write_log_tables
        from shtools.runtime.settings import ShadowSettings

        write_log_tables(out / "tables.h5", ShadowSettings(order=ORDER).resolved_acc_order())

    def light():
        from shtools.lighting.environment import project_environment_to_file

        project_environment_to_file(out / "sky.hdr", ORDER, out / "sky.h5")

    def bake():
        from shtools.scene.bake import bake_to_file
        from shtools.scene.scene import load_scene

        (out / "scene.toml").write_text(scene_toml(frames))
        bake_to_file(load_scene(out / "scene.toml"), out / "baked.h5", processes=None)

    def export():
        from shtools.data_formats.bake import read_bake
        from shtools.export.png import View
        from shtools.export.writer import export_bake

        baked = read_bake(out / "baked.h5")
        view = View()
        mid = frames * 5 // 8  # mid-stride for the default 48 frames
        export_bake(baked, out / "demo.glb", frame=mid, view=view)
        export_bake(baked, out / "frame.png", frame=mid, view=view)
        step = max(frames // 12, 1)
        if step == 1:
            export_bake(baked, out / "sheet.png", frames_text=f"0:{frames}", view=view,
                        columns=4)
        else:
            _sheet(out, frames, step)  # 12 tiles: every step-th frame
        export_bake(baked, out / "demo.gif", view=view, size=(400, 300))

    start = time.perf_counter()
    stage("meshes and sky", meshes)
    stage("spheres fit + tree", spheres)
    stage("tables log", tables)
    stage("light project", light)
    stage("bake", bake)
    stage("export", export)
    timings["total"] = time.perf_counter() - start
    return timings


def _sheet(out: Path, frames: int, step: int) -> None:
    """Contact sheet of every ``step``-th frame (library call: the CLI takes ranges)."""
    from shtools.data_formats.bake import read_bake
    from shtools.export.png import View, contact_sheet, render_frames, save_png

    bake = read_bake(out / "baked.h5")
    positions = list(range(0, frames, step))
    images = render_frames(bake, positions, View(width=320, height=240))
    labels = [f"frame {int(bake.frame_index[t])}" for t in positions]
    save_png(contact_sheet(images, labels, columns=4), out / "sheet.png")


def main(argv: list[str] | None = None) -> int:
    import argparse

    from shtools.geometry.fit_methods import FIT_METHODS

    parser = argparse.ArgumentParser(prog="python -m shtools.demo",
                                     description="Generate, bake and export the demo scene.")
    parser.add_argument("outdir", help="output folder (created)")
    parser.add_argument("--frames", type=int, default=FRAMES, help=f"default {FRAMES}")
    parser.add_argument("--fit-method", default=FIT_METHOD,
                        choices=FIT_METHODS,
                        help=f"sphere fitting method (default {FIT_METHOD})")
    args = parser.parse_args(argv)
    if args.frames < 2:
        parser.error("--frames must be at least 2")
    out = Path(args.outdir)
    from shtools.cli._common import one_blas_thread

    with one_blas_thread():  # unless the user set a BLAS thread count
        timings = run_demo(out, frames=args.frames, fit_method=args.fit_method)
    stages = ", ".join(f"{k} {v:.1f} s" for k, v in timings.items() if k != "total")
    print(f"[demo] stages: {stages}")
    print(f"[demo] done in {timings['total']:.1f} s:")
    for name in ("baked.h5", "demo.glb", "frame.png", "sheet.png", "demo.gif", "scene.toml"):
        print(f"  {out / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
