"""Frames as tasks: the same bytes inline, on local worker processes and on Dask; faults.

The reference for "correct" here is the one-process bake itself: spreading
frames over workers must not change a single byte of the asset (the frames
are pure functions of the scene; only the place they run changes).
"""

from __future__ import annotations

import filecmp
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import processes

from shtools.errors import InputError
from shtools.scene.bake import bake_to_file
from shtools.scene.scene import load_scene
from shtools.tasks import task_pool

# The same tiny scene as the bake tests: a ball rolling over a ground plane.
from .test_bake import scene_text


def _square(shared, item):
    return shared * item * item


def _die_once(marker, item):
    """Kill this worker process the first time any worker runs item 3."""
    if item == 3 and not os.path.exists(marker):
        Path(marker).write_text("died")
        os._exit(1)
    return item


def _slow_echo(_shared, item):
    time.sleep(0.02)
    return item


@pytest.mark.parametrize("scheduler, workers", [("inline", 1), (None, 2)])
def test_results_come_back_in_order(scheduler, workers):
    with task_pool(scheduler, workers) as pool:
        out = list(pool.map_ordered(_square, range(20), shared=3))
    assert out == [3 * i * i for i in range(20)]
    assert sum(s.tasks for s in pool.stats.values()) == 20


def test_window_bounds_tasks_in_flight():
    pulled = []

    def items():
        for i in range(12):
            pulled.append(i)
            yield i

    with task_pool(None, 2) as pool:
        for k, result in enumerate(pool.map_ordered(_slow_echo, items(), window=3)):
            # At most `window` items were taken before result k was handed out:
            # the caller never holds more than the window.
            assert result == k
            assert len(pulled) <= k + 1 + 3
    assert len(pulled) == 12


def test_killed_local_worker_is_replaced_and_nothing_is_lost(tmp_path):
    marker = str(tmp_path / "died")
    with task_pool(None, 2) as pool:
        out = list(pool.map_ordered(_die_once, range(8), shared=marker))
    assert out == list(range(8))  # no duplicate, no missing result
    assert Path(marker).exists()  # a worker really died


_SET_UP: list = []


def _note_setup(shared):
    _SET_UP.append(shared)


def _setup_seen(shared, item):
    """This process's pid and how many times its set-up ran before this task."""
    return os.getpid(), len(_SET_UP)


@pytest.mark.parametrize("scheduler, workers", [("inline", 1), (None, 2)])
def test_setup_runs_once_per_worker_before_its_tasks(scheduler, workers):
    _SET_UP.clear()
    with task_pool(scheduler, workers) as pool, pool.share("state", setup=_note_setup) as shared:
        first = list(pool.map_ordered(_setup_seen, range(8), shared=shared))
        again = list(pool.map_ordered(_setup_seen, range(8), shared=shared))
    # every task ran after its own process's one set-up (local workers count their own)
    assert {count for _, count in first + again} == {1}
    assert len({pid for pid, _ in first}) <= workers


def _failing_setup(shared):
    raise ValueError(f"cannot set up {shared}")


def _task_with_failing_setup(shared, item):
    _failing_setup(shared)  # a task repeats its (cached) set-up, as the bake's do


@pytest.mark.parametrize("scheduler, workers", [("inline", 1), (None, 2)])
def test_failing_setup_reports_its_own_error(scheduler, workers):
    """Not "a worker died": the set-up's own error, from the set-up or the first task."""
    with pytest.raises(ValueError, match="cannot set up state"), \
            task_pool(scheduler, workers) as pool:
        list(pool.map_ordered(_task_with_failing_setup, range(4), shared="state",
                              setup=_failing_setup))


def test_bad_scheduler_values():
    with pytest.raises(InputError, match="neither 'local'"), task_pool("no-such-file.json"):
        pass
    with pytest.raises(InputError, match="--workers"), task_pool(None, 0):
        pass
    with pytest.raises(InputError, match="--workers"), task_pool(None, 100_000):
        pass


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("dist")
    path = d / "scene.toml"
    path.write_text(scene_text(order=3, frames=6))
    return path


@pytest.fixture(scope="module")
def inline_bake(scene_file):
    out = scene_file.parent / "inline.h5"
    bake_to_file(load_scene(scene_file), out, scheduler="inline", processes=1)
    return out


def test_local_workers_give_identical_bytes(scene_file, inline_bake, tmp_path):
    out = tmp_path / "pool.h5"
    summary = bake_to_file(load_scene(scene_file), out, workers=2)
    assert summary["pool"]["scheduler"] == "processes"
    assert sum(w["tasks"] for w in summary["pool"]["per_worker"].values()) == 6
    assert filecmp.cmp(out, inline_bake, shallow=False)


def test_local_workers_moving_receivers_identical_bytes(tmp_path):
    """Moving receivers: the workers send float32 vertices and normals (what the
    asset stores), and the asset is still the in-process bytes."""
    scene = tmp_path / "moving.toml"
    scene.write_text(scene_text(order=3, frames=4, moving_ground=True))
    inline, pool = tmp_path / "inline.h5", tmp_path / "pool.h5"
    bake_to_file(load_scene(scene), inline, scheduler="inline", processes=1)
    bake_to_file(load_scene(scene), pool, workers=2)
    assert filecmp.cmp(pool, inline, shallow=False)


@pytest.fixture
def split_every_frame(monkeypatch):
    """Cut even these small frames into FRAME_PARTS parts (as a large frame is),
    wherever they are evaluated: the split is decided where the frame is posed."""
    import shtools.runtime.evaluator as evaluator

    monkeypatch.setattr(evaluator, "MIN_PARALLEL_PAIRS", 0)


@pytest.mark.parametrize("scheduler, workers", [("inline", 1), (None, 2)])
def test_frame_parts_as_pool_tasks_give_identical_radiance(scene_file, split_every_frame,
                                                           scheduler, workers):
    from shtools.scene.bake import FrameBaker, bake_clusters, prepare_scene

    prepared = prepare_scene(load_scene(scene_file))
    clusters = bake_clusters(prepared, "default", 0.0)
    with FrameBaker(prepared, "default", clusters, processes=1) as alone:
        want = [alone.frame(f, f / 2).radiance for f in range(3)]
    with task_pool(scheduler, workers) as pool, \
            FrameBaker(prepared, "default", clusters, processes=1, part_pool=pool) as baker:
        got = [baker.frame(f, f / 2).radiance for f in range(3)]
        parts = baker.runtime.last_stats["processes"]
    for a, b in zip(got, want, strict=True):
        assert a.tobytes() == b.tobytes()
    assert sum(s.tasks for s in pool.stats.values()) > 3  # parts, not frames, were the tasks
    assert parts == min(workers, sum(s.tasks for s in pool.stats.values()) // 3)


#: distributed leaves sockets for the garbage collector when a cluster closes (its
#: own ResourceWarning, not ours); the tests that start a cluster let it pass.
DASK_LEAKS = (pytest.mark.filterwarnings("ignore::ResourceWarning"),
              pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning"))


@pytest.mark.slow
@DASK_LEAKS[0]
@DASK_LEAKS[1]
def test_dask_local_cluster_gives_identical_bytes(scene_file, inline_bake, tmp_path):
    pytest.importorskip("distributed", reason="the distributed extra is not installed")
    out = tmp_path / "dask.h5"
    summary = bake_to_file(load_scene(scene_file), out, scheduler="local", workers=2)
    assert summary["pool"]["scheduler"] == "dask"
    assert filecmp.cmp(out, inline_bake, shallow=False)


@pytest.mark.slow
@DASK_LEAKS[0]
@DASK_LEAKS[1]
def test_dask_frame_parts_identical_bytes_for_1_2_3_workers(scene_file, split_every_frame,
                                                            tmp_path):
    """One frame's parts as Dask tasks (split_frames): the in-process bytes on 1, 2, 3 workers."""
    pytest.importorskip("distributed", reason="the distributed extra is not installed")
    frames = range(2)
    want = tmp_path / "inline.h5"
    bake_to_file(load_scene(scene_file), want, frames=frames, scheduler="inline", processes=1)
    for workers in (1, 2, 3):
        out = tmp_path / f"parts{workers}.h5"
        summary = bake_to_file(load_scene(scene_file), out, frames=frames, scheduler="local",
                               workers=workers, split_frames=None if workers == 3 else True)
        tasks = sum(w["tasks"] for w in summary["pool"]["per_worker"].values())
        assert tasks > len(frames), summary["pool"]  # parts were the tasks
        assert filecmp.cmp(out, want, shallow=False), workers


@pytest.mark.slow
@DASK_LEAKS[0]
@DASK_LEAKS[1]
def test_cli_split_frames_runs_parts_on_the_cluster(scene_file, split_every_frame, run_cli,
                                                    tmp_path):
    import json

    pytest.importorskip("distributed", reason="the distributed extra is not installed")
    want, out = tmp_path / "inline.h5", tmp_path / "cli.h5"
    code, _, err = run_cli("bake", scene_file, "-o", want, "--frames", "0:3", "--workers", 1,
                           "--processes", 1)
    assert code == 0, err
    code, stdout, err = run_cli("bake", scene_file, "-o", out, "--frames", "0:3",
                                "--scheduler", "local", "--workers", 2, "--split-frames",
                                "--json")
    assert code == 0, err
    pool = json.loads(stdout)["pool"]
    assert sum(w["tasks"] for w in pool["per_worker"].values()) > 3  # 3 frames, in parts
    assert filecmp.cmp(out, want, shallow=False)


@pytest.mark.slow
@DASK_LEAKS[0]
@DASK_LEAKS[1]
def test_dask_frames_grouped_in_tasks_moving_receivers_identical_bytes(tmp_path):
    """17 frames on 1 worker: tasks of 2 frames (the last of 1), float32 poses back."""
    pytest.importorskip("distributed", reason="the distributed extra is not installed")
    from shtools.scene.bake import frames_per_task

    scene = tmp_path / "moving.toml"
    scene.write_text(scene_text(order=2, frames=17, moving_ground=True))
    inline, dask = tmp_path / "inline.h5", tmp_path / "dask.h5"
    bake_to_file(load_scene(scene), inline, scheduler="inline", processes=1)
    summary = bake_to_file(load_scene(scene), dask, scheduler="local", workers=1)
    assert frames_per_task("dask", 17, 1) == 2
    assert sum(w["tasks"] for w in summary["pool"]["per_worker"].values()) == 9
    assert summary["frames"] == 17
    assert filecmp.cmp(dask, inline, shallow=False)


@pytest.mark.slow
@DASK_LEAKS[0]
@DASK_LEAKS[1]
def test_dask_worker_killed_mid_bake_still_completes_identically(scene_file, inline_bake,
                                                                 tmp_path):
    distributed = pytest.importorskip("distributed",
                                      reason="the distributed extra is not installed")

    class KillOnce(distributed.WorkerPlugin):
        """Kills the worker process that starts the third task (once: a marker file)."""

        def __init__(self, marker):
            self.marker = marker

        def setup(self, worker):
            self.started = 0

        def transition(self, key, start, finish, **kwargs):
            if finish == "executing":
                self.started += 1
                if self.started == 2 and not os.path.exists(self.marker):
                    Path(self.marker).write_text("killed")
                    os._exit(1)

    marker = str(tmp_path / "killed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", silence_logs=50) as cluster, \
            distributed.Client(cluster) as client:
        client.register_plugin(KillOnce(marker))
        out = tmp_path / "killed.h5"
        bake_to_file(load_scene(scene_file), out, scheduler=cluster.scheduler_address)
    assert Path(marker).exists()
    assert filecmp.cmp(out, inline_bake, shallow=False)


def test_dask_shared_state_lost_with_its_workers_is_scattered_again():
    """Every worker of the cluster restarted mid-run: the shared state, scattered
    data the scheduler cannot recompute, is lost with them (as when the one worker
    a cluster's active memory manager left its replica on dies).  The run scatters
    it again, and every result still comes back, in order."""
    distributed = pytest.importorskip("distributed",
                                      reason="the distributed extra is not installed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0", silence_logs=50) as cluster, \
            distributed.Client(cluster) as client, \
            task_pool(cluster.scheduler_address) as pool:
        out = []
        for result in pool.map_ordered(_square, range(12), shared=3, window=4):
            out.append(result)
            if len(out) == 2:
                client.restart()
    assert out == [3 * i * i for i in range(12)]


def _cli(*args, **kwargs):
    return subprocess.run([sys.executable, "-m", "shtools", *args], capture_output=True,
                          text=True, **kwargs)


@pytest.mark.slow
def test_unreachable_scheduler_is_one_line_and_no_output(scene_file, tmp_path):
    pytest.importorskip("distributed", reason="the distributed extra is not installed")
    out = tmp_path / "x.h5"
    # Port 9 (discard) on loopback: nothing listens, the connection is refused.
    proc = _cli("bake", str(scene_file), "-o", str(out), "--scheduler", "tcp://127.0.0.1:9")
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "cannot reach the Dask scheduler" in lines[0], proc.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_stops_workers_and_leaves_no_file(tmp_path, sig):
    scene = tmp_path / "long.toml"
    # ~40k ground vertices: each frame takes long enough that the bake is mid-way.
    scene.write_text(scene_text(order=4, frames=400).replace("subdivisions = 24",
                                                           "subdivisions = 200"))
    out = tmp_path / "long.h5"
    # Test runners (xdist workers) may ignore SIGINT, and a child inherits that:
    # give the CLI the default disposition, as a shell would.
    with subprocess.Popen([sys.executable, "-m", "shtools", "bake", str(scene), "-o", str(out),
                           "--workers", "2"], stderr=subprocess.PIPE, text=True,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL)
                          ) as proc:
        deadline = time.monotonic() + 120
        children: list[int] = []
        while len(children) < 2 and time.monotonic() < deadline:  # workers started
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.5)
            # forked by the fork server, a child of the bake (as its resource tracker is)
            children = [w for c in processes.children(proc.pid)
                        for w in processes.children(c)]
        children += processes.children(proc.pid)  # the fork server and tracker must go too
        time.sleep(1.0)
        os.kill(proc.pid, sig)
        _, err = proc.communicate(timeout=120)
    assert proc.returncode != 0
    assert len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.toml"]  # no file, no temp
    time.sleep(0.5)
    assert children and [pid for pid in children if processes.alive(pid)] == []


def _two_meshes(folder: Path) -> list[Path]:
    """A box and a capsule as OBJ files: two small meshes for batch fits."""
    import trimesh

    meshes = []
    for name, mesh in [("box", trimesh.creation.box(extents=[2, 1, 1])),
                       ("capsule", trimesh.creation.capsule(height=1.0, radius=0.4))]:
        path = folder / f"{name}.obj"
        mesh.export(path)
        meshes.append(path)
    return meshes


def test_batch_fit_writes_one_asset_per_mesh_identically(tmp_path):
    from shtools.geometry.assets import fit_many, fit_to_file

    meshes = _two_meshes(tmp_path)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    pool: dict = {}
    rows = list(fit_many(meshes, out_dir, 6, method="kmeans", workers=2, pool_summary=pool))
    assert [r["mesh"] for r in rows] == [str(m) for m in meshes]
    assert pool["scheduler"] == "processes"
    for mesh, row in zip(meshes, rows, strict=True):
        # The same fit in this process, written by the single-mesh stage.
        alone = tmp_path / f"{mesh.stem}.alone.h5"
        fit_to_file(mesh, 6, alone, method="kmeans")
        assert filecmp.cmp(row["output"], alone, shallow=False)


def test_batch_fit_refuses_clashing_names_and_missing_folder(tmp_path):
    from shtools.geometry.assets import batch_outputs, fit_many

    with pytest.raises(InputError, match=r"would both write a\.spheres\.h5"):
        batch_outputs([tmp_path / "x" / "a.obj", tmp_path / "y" / "a.obj"], tmp_path)
    with pytest.raises(InputError, match="is not a folder"):
        list(fit_many([tmp_path / "a.obj"], tmp_path / "missing", 4))


def test_partial_bake_clusters_receivers_at_frame_0(tmp_path, monkeypatch):
    """Clusters come from the scene's frame 0 whatever range is baked, so frames
    2:4 of a partial bake are computed exactly as in a full bake."""
    import shtools.scene.bake as bake_module

    seen = []
    original = bake_module.bake_clusters

    def spy(prepared, method, t):
        seen.append(t)
        return original(prepared, method, t)

    monkeypatch.setattr(bake_module, "bake_clusters", spy)
    scene = tmp_path / "moving.toml"
    scene.write_text(scene_text(order=3, frames=5, moving_ground=True))
    bake_to_file(load_scene(scene), tmp_path / "part.h5", frames=range(2, 4), workers=1)
    assert seen == [0.0]


def test_batch_fit_cli_one_asset_per_mesh(run_cli, tmp_path):
    import json

    meshes = _two_meshes(tmp_path)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    code, stdout, err = run_cli("spheres", "fit", *meshes, "-n", 5, "--method", "kmeans",
                                "-o", out_dir, "--workers", 2, "--json")
    assert code == 0, err
    summary = json.loads(stdout)
    assert [Path(f["output"]).name for f in summary["fits"]] == ["box.spheres.h5",
                                                                  "capsule.spheres.h5"]
    assert sorted(p.name for p in out_dir.iterdir()) == ["box.spheres.h5",
                                                         "capsule.spheres.h5"]
    # A file as the batch's output folder: one line, nothing written.
    code, _, err = run_cli("spheres", "fit", *meshes, "-n", 5, "-o", meshes[0])
    assert code != 0 and "not a folder" in err
