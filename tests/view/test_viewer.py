"""``shtools view``: what the page is served, the server's lifecycle, and a real browser."""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from shtools.data_formats.bake import write_bake
from shtools.errors import InputError
from shtools.view import BakeView, ViewerServer

REPO = Path(__file__).resolve().parents[2]
ALBEDO = np.array([0.8, 0.5, 0.25])


def _grid(n, x0, y):
    """An n x n vertex grid in the plane y, from x0, triangulated; vertices, normals, faces."""
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    verts = np.column_stack([x0 + u.ravel(), np.full(n * n, y), v.ravel()])
    normals = np.tile([0.0, 1.0, 0.0], (n * n, 1))
    k = np.arange(n * n).reshape(n, n)
    a, b, c, d = k[:-1, :-1].ravel(), k[:-1, 1:].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel()
    return verts, normals, np.concatenate([np.column_stack([a, c, b]),
                                           np.column_stack([b, c, d])])


@pytest.fixture
def bake_path(tmp_path):
    """Two objects, 3 frames: radiance a gradient across the first grid, 1 on the second."""
    v1, n1, f1 = _grid(12, 0.0, 0.0)
    v2, n2, f2 = _grid(6, 1.5, 0.3)
    verts, normals = np.concatenate([v1, v2]), np.concatenate([n1, n2])
    faces = np.concatenate([f1, f2 + len(v1)])
    V, T = len(verts), 3
    radiance = np.ones((T, V, 3))
    radiance[:, :len(v1)] = (0.2 + v1[:, 0])[None, :, None] * (1 + np.arange(T))[:, None, None]
    visibility = np.zeros((T, V, 4))
    visibility[:, :, 0] = math.sqrt(4 * math.pi) * 0.5
    path = tmp_path / "baked.h5"
    write_bake(path, vertices=verts, normals=normals, faces=faces, radiance=radiance,
               sh_order=2, visibility=visibility, albedo=np.tile(ALBEDO, (V, 1)),
               object_offsets=[0, len(v1), V], object_names=["ground", "card"], fps=12.0,
               times=np.arange(T) / 12.0)
    return path


def _aces(x):  # Narkowicz 2015, "ACES Filmic Tone Mapping Curve"
    return np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0, 1)


def _srgb(x):  # IEC 61966-2-1
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def test_colours_are_the_exports_tone_mapping_of_radiance_times_albedo(bake_path):
    view = BakeView(bake_path)
    summary = view.summary()
    assert summary["quantities"] == ["radiance", "irradiance", "visibility"]
    assert [o["name"] for o in summary["objects"]] == ["ground", "card"]
    assert summary["fps"] == 12.0 and summary["frames"] == [0, 1, 2]
    assert sum(o["faces"] for o in summary["objects"]) * 12 == len(view.faces())
    # closed form: auto exposure puts the 97th-percentile luminance of radiance x albedo
    # over all frames at 0.6 (docs/formats.md, export), then ACES and sRGB
    rad = np.asarray(view.bake.radiance, dtype=np.float64) * ALBEDO
    lum = rad.reshape(-1, 3) @ np.array([0.2126, 0.7152, 0.0722])
    scale = 0.6 / np.percentile(lum, 97.0) * 2.0 ** 1.5
    expected = np.round(_srgb(_aces(rad[2] * scale)) * 255)
    got = np.frombuffer(view.colors(2, "radiance", 1.5), np.uint8).reshape(-1, 3)
    # one 8-bit step: the rounding of values that land on a half step
    np.testing.assert_allclose(got, expected, atol=1)
    # visibility: the cosine-weighted unoccluded fraction, 0.5 here (grey, linear)
    vis = np.frombuffer(view.colors(0, "visibility"), np.uint8).reshape(-1, 3)
    np.testing.assert_allclose(vis, np.round(_srgb(np.array(0.5)) * 255), atol=1)
    with pytest.raises(InputError, match=r"outside 0\.\.2"):
        view.colors(3, "radiance")
    with pytest.raises(InputError, match="quantity"):
        view.colors(0, "albedo")


@pytest.fixture
def server(bake_path):
    srv = ViewerServer(BakeView(bake_path), 0)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    yield srv
    srv.shutdown()
    srv.server_close()
    thread.join()


def _get(url):
    # generous: a hang fails the test, a loaded 2-core CI machine must not
    with urllib.request.urlopen(url, timeout=60) as r:
        return r.status, r.headers["Content-Type"], r.read()


def test_server_answers_the_page_and_the_arrays(server, bake_path):
    assert server.server_address[0] == "127.0.0.1"
    status, kind, page = _get(server.url)
    assert status == 200 and kind.startswith("text/html") and b"viewer.js" in page
    _, kind, script = _get(server.url + "viewer.js")
    assert kind.startswith("text/javascript") and b"webgl2" in script
    # nothing the page loads comes from elsewhere: no absolute URL in the page or its script
    assert b"http" not in page and b"http" not in script
    summary = json.loads(_get(server.url + "api/bake.json")[2])
    assert summary["vertices"] == 12 * 12 + 6 * 6 and summary["moving"] is False
    _, _, pos = _get(server.url + "api/positions.bin?frame=1")
    assert len(pos) == summary["vertices"] * 12
    _, _, colours = _get(server.url + "api/colors.bin?frame=1&quantity=irradiance&exposure=-1")
    assert len(colours) == summary["vertices"] * 3
    with pytest.raises(urllib.error.HTTPError) as err:
        _get(server.url + "api/colors.bin?frame=7")
    assert err.value.code == 400
    err.value.close()


def test_port_in_use_is_an_input_error(bake_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(InputError, match=f"--port {port} is in use"):
            ViewerServer(BakeView(bake_path), port)


def _start(*args):
    """``shtools view`` in a child process; returns it and the URL it printed."""
    proc = subprocess.Popen([sys.executable, "-m", "shtools", "view", *map(str, args),
                             "--no-browser"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=REPO, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    line = proc.stdout.readline()
    if "http://127.0.0.1:" not in line:
        proc.kill()
        raise AssertionError(f"no URL: {line!r} {proc.stderr.read()}")
    return proc, line.split()[2]


def _children(pid):
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_command_serves_then_stops_cleanly_on_a_signal(bake_path, sig):
    proc, url = _start(bake_path)
    try:
        assert _get(url)[0] == 200
        assert _children(proc.pid) == []
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "stopped" in out and "Traceback" not in err
    with pytest.raises(OSError):
        urllib.request.urlopen(url, timeout=2)


def test_ctrl_c_while_the_url_is_printed_stops_cleanly(bake_path):
    """A Ctrl-C that lands while ``on_ready`` runs (a client can fetch the page and signal
    before the main thread waits) stops the server as one during the wait does: no
    KeyboardInterrupt escapes, and the socket is closed."""
    from shtools.view import BakeView, serve

    urls = []

    def ready(url):
        urls.append(url)
        assert _get(url)[0] == 200
        raise KeyboardInterrupt

    try:
        serve(BakeView(bake_path), on_ready=ready)
    except KeyboardInterrupt:  # (not raised on: it would stop the whole test session)
        pytest.fail("a Ctrl-C while on_ready ran escaped serve()")
    with pytest.raises(OSError):
        urllib.request.urlopen(urls[0], timeout=2)


def test_command_bad_input_is_one_line(bake_path, tmp_path, run_cli):
    (tmp_path / "not.h5").write_bytes(b"not hdf5")
    code, _, err = run_cli("view", tmp_path / "not.h5", "--no-browser")
    assert code == 1 and err.count("\n") == 1 and "not.h5" in err, err
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        code, _, err = run_cli("view", bake_path, "--no-browser", "--port", s.getsockname()[1])
    assert code == 1 and err.count("\n") == 1 and "in use" in err, err


def chromium() -> str:
    """Debian's headless Chromium; the test skips with the reason when it is absent."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if path := shutil.which(name):
            return path
    pytest.skip("real-browser check: no chromium on PATH (apt-get install chromium; "
                ".ci/run installs it)")


def screenshot(url: str, out: Path, size=(800, 600), budget_ms=8000) -> None:
    """A headless Chromium screenshot of ``url`` (software WebGL: SwiftShader)."""
    subprocess.run([chromium(), "--headless=new", "--no-sandbox", "--disable-gpu-sandbox",
                    "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                    "--no-first-run", "--disable-extensions",
                    f"--user-data-dir={out.parent / 'chromium-profile'}",
                    f"--window-size={size[0]},{size[1]}",
                    f"--virtual-time-budget={budget_ms}", f"--screenshot={out}", url],
                   check=True, capture_output=True, timeout=120)


@pytest.mark.slow  # a browser start with software WebGL: 10-25 s on a busy machine
def test_headless_chromium_shows_the_scene(bake_path, tmp_path):
    chromium()
    from PIL import Image

    proc, url = _start(bake_path)
    try:
        shot = tmp_path / "shot.png"
        screenshot(url + "?ui=0", shot)  # the panel hidden: only the drawn scene counts
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=60)
    img = np.asarray(Image.open(shot).convert("RGB"), dtype=np.float64)
    background = np.array([0x1d, 0x1f, 0x22])
    drawn = np.any(np.abs(img - background) > 12, axis=2)
    # the two grids cover a good part of the view, in more than one colour: the
    # gradient ground and the white card, not one flat colour or an empty canvas
    assert drawn.mean() > 0.05, drawn.mean()
    assert img[drawn].std(axis=0).max() > 20
    assert len(np.unique((img[drawn] // 16).astype(int), axis=0)) > 8


SCENE = """
[settings]
order = 2
frames = 3
fps = 4
[environment]
coeffs = [[3.5, 3.5, 3.5], [0, 0, 0], [1, 1, 1], [0, 0, 0]]
[[objects]]
name = "ground"
primitive = { type = "plane", size = [3, 3], subdivisions = 4 }
role = "receiver"
[[objects]]
name = "ball"
primitive = { type = "sphere", radius = 0.5, subdivisions = 1 }
role = "blocker"
[[objects.keyframes]]
time = 0
translate = [-0.5, 0.7, 0]
[[objects.keyframes]]
time = 0.5
translate = [0.5, 0.9, 0.2]
"""


def test_sphere_overlay_follows_the_scenes_keyframes(tmp_path):
    from shtools.scene.bake import bake_to_file
    from shtools.scene.scene import load_scene
    from shtools.view import scene_spheres

    scene = tmp_path / "scene.toml"
    scene.write_text(SCENE)
    bake_to_file(load_scene(scene), tmp_path / "b.h5", processes=1, workers=1)
    view = BakeView(tmp_path / "b.h5")
    view.spheres = scene_spheres(scene, view.bake)
    # the ball is one exact sphere: at t = 0.25 s (frame 1) halfway between its keys
    spheres = np.frombuffer(view.sphere_bytes(1), "<f4").reshape(-1, 4)
    np.testing.assert_allclose(spheres, [[0.0, 0.8, 0.1, 0.5]], atol=1e-6)
    assert view.summary()["spheres"] is True


def test_missing_modules_are_one_line(bake_path, tmp_path, run_cli, monkeypatch):
    import shtools.view

    # the scene overlay without the geometry extra (its mesh loading)
    def no_trimesh(*args):
        raise ModuleNotFoundError("No module named 'trimesh'", name="trimesh")

    monkeypatch.setattr(shtools.view, "scene_spheres", no_trimesh)
    (tmp_path / "scene.toml").write_text(SCENE)
    code, _, err = run_cli("view", bake_path, "--scene", tmp_path / "scene.toml",
                           "--no-browser")
    assert code == 1 and err.count("\n") == 1 and "'geometry' extra" in err, err
    # the viewer itself missing from the install
    monkeypatch.setitem(sys.modules, "shtools.view", None)
    code, _, err = run_cli("view", bake_path, "--no-browser")
    assert code == 1 and err.count("\n") == 1 and "shtools[view]" in err, err
