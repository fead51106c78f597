"""Exports a pipeline consumes: USD, per-object GLB (single and sequences), VAT, quantities.

Every file is read back with an independent reader (``pxr``, pygltflib,
OpenEXR) and compared value for value with the bake asset; the USD stage goes
through USD's own validators and the GLBs through the Khronos glTF validator
(npm package, installed by ``make test``) when it is there.
"""

from __future__ import annotations

import math

import numpy as np
import pygltflib
import pytest
from helpers.exports import export_json

from shtools.data_formats.bake import read_bake, write_bake
from shtools.export.tonemap import aces
from shtools.scene.primitives import make_primitive

FRAMES = [5, 6, 7, 8]  # scene frame numbers held by the bake
FPS = 12.0


@pytest.fixture(scope="module")
def bake_file(tmp_path_factory):
    """Two receivers: a static plane 'ground' and a sphere 'my ball' moving along +x.

    Radiance is a different non-negative ramp per frame; visibility vectors are
    random but fixed (seeded), so every exported value has a known source.
    """
    rng = np.random.default_rng(7)
    plane = make_primitive("plane", {"size": [2.0, 2.0], "subdivisions": 4})
    ball = make_primitive("sphere", {"radius": 0.3, "subdivisions": 1})
    pv, bv = np.asarray(plane.mesh.vertices), np.asarray(ball.mesh.vertices) + np.array([0, 0.5, 0])
    V0, V1 = len(pv), len(bv)
    T = len(FRAMES)
    verts = np.stack([np.concatenate([pv, bv + np.array([0.2 * t, 0, 0])]) for t in range(T)])
    normals = np.broadcast_to(np.concatenate([plane.normals, ball.normals]), verts.shape)
    faces = np.concatenate([plane.mesh.faces, ball.mesh.faces + V0])
    radiance = rng.uniform(0.0, 2.0, (T, V0 + V1, 3))
    vis = rng.normal(0.0, 0.3, (T, V0 + V1, 9))
    vis[..., 0] += math.sqrt(4 * math.pi) * 0.8
    albedo = np.concatenate([np.full((V0, 3), 0.5), np.tile([0.9, 0.2, 0.1], (V1, 1))])
    path = tmp_path_factory.mktemp("bake") / "baked.h5"
    write_bake(path, vertices=verts, normals=np.ascontiguousarray(normals), faces=faces,
               radiance=radiance, visibility=vis, sh_order=3, frame_index=FRAMES,
               times=np.asarray(FRAMES) / FPS, albedo=albedo,
               object_offsets=[0, V0, V0 + V1], object_names=["ground", "my ball"], fps=FPS)
    return path


# ----------------------------------------------------------------------------- USD
@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_usd_reads_back_value_for_value(run_cli, bake_file, tmp_path, suffix):
    from pxr import Usd, UsdGeom

    out = tmp_path / f"baked{suffix}"
    summary = export_json(run_cli, bake_file, out)
    bake = read_bake(bake_file)
    stage = Usd.Stage.Open(str(out))
    assert stage.GetTimeCodesPerSecond() == FPS and stage.GetFramesPerSecond() == FPS
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (FRAMES[0], FRAMES[-1])
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
    assert stage.GetDefaultPrim().GetPath() == "/World"
    # one prim per object under its (valid-identifier) name; the original name kept
    assert summary["prims"] == ["/World/ground", "/World/my_ball"]
    assert stage.GetPrimAtPath("/World/my_ball").GetDisplayName() == "my ball"
    assert summary["animated"] == ["/World/my_ball"]
    for o, path in enumerate(summary["prims"]):
        lo, hi = bake.object_offsets[o], bake.object_offsets[o + 1]
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(path))
        faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        np.testing.assert_array_equal(faces, bake.object_faces(o))
        points, color, raw = (mesh.GetPointsAttr(), mesh.GetDisplayColorPrimvar(),
                              UsdGeom.PrimvarsAPI(mesh).GetPrimvar("radiance"))
        assert color.GetInterpolation() == raw.GetInterpolation() == "vertex"
        # the static plane has no point samples, the ball one per frame
        assert points.GetTimeSamples() == ([] if o == 0 else FRAMES)
        assert raw.GetAttr().GetTimeSamples() == FRAMES
        for t, frame in enumerate(FRAMES):
            np.testing.assert_array_equal(  # float32 written and read verbatim
                np.asarray(points.Get(frame)), bake.vertices[t, lo:hi].astype(np.float32))
            np.testing.assert_array_equal(np.asarray(raw.Get(frame)),
                                          bake.radiance[t, lo:hi].astype(np.float32))
            # display colour: ACES of albedo x radiance (fixed exposure), linear;
            # float32 storage of a [0, 1] value: 1e-6
            expected = aces(bake.radiance[t, lo:hi] * bake.albedo[lo:hi])
            np.testing.assert_allclose(np.asarray(color.Get(frame)), expected, atol=1e-6)


def test_usd_passes_the_usd_validators(run_cli, bake_file, tmp_path):
    """USD's own checks (what ``usdchecker`` runs): no error on the stage."""
    from pxr import Usd, UsdValidation

    out = tmp_path / "baked.usdc"
    export_json(run_cli, bake_file, out, "--frames", "5:9:2")
    registry = UsdValidation.ValidationRegistry()
    validators = registry.GetOrLoadAllValidators()
    assert len(validators) > 10  # the geometry, shading, stage-metadata... suites are loaded
    errors = UsdValidation.ValidationContext(validators).Validate(Usd.Stage.Open(str(out)))
    assert [e.GetMessage() for e in errors] == []
    stage = Usd.Stage.Open(str(out))
    assert stage.GetPrimAtPath("/World/ground").GetAttribute(
        "primvars:radiance").GetTimeSamples() == [5, 7]  # the step


# ----------------------------------------------------------------------------- glTF
def _accessor(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    """Strict accessor read: bounds of the view and buffer checked, no padding guessed."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    blob = gltf.binary_blob()
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[acc.type]
    dtype = {5126: np.float32, 5125: np.uint32}[acc.componentType]
    nbytes = acc.count * width * np.dtype(dtype).itemsize
    assert (acc.byteOffset or 0) + nbytes <= view.byteLength
    assert view.byteOffset + view.byteLength <= len(blob) == gltf.buffers[0].byteLength
    start = view.byteOffset + (acc.byteOffset or 0)
    data = np.frombuffer(blob[start:start + nbytes], dtype=dtype)
    return data.reshape(acc.count, width) if width > 1 else data


def test_glb_sequence_keeps_objects_and_frames(run_cli, bake_file, tmp_path, khronos):
    out = tmp_path / "shot.glb"
    summary = export_json(run_cli, bake_file, out, "--frames", "5:9:2", "--quantity", "irradiance",
                      "--sequence")
    files = [tmp_path / "shot.0005.glb", tmp_path / "shot.0007.glb"]
    assert summary["files"] == [str(f) for f in files] and not out.exists()
    bake = read_bake(bake_file)
    for t, path in zip((0, 2), files, strict=True):
        gltf = pygltflib.GLTF2().load(str(path))
        assert [n.name for n in gltf.nodes] == [m.name for m in gltf.meshes] == [
            "ground", "my ball"]
        assert gltf.scenes[0].nodes == [0, 1]
        for o, mesh in enumerate(gltf.meshes):
            lo, hi = bake.object_offsets[o], bake.object_offsets[o + 1]
            attrs = mesh.primitives[0].attributes
            np.testing.assert_array_equal(_accessor(gltf, attrs.POSITION),
                                          bake.vertices[t, lo:hi].astype(np.float32))
            # the raw attribute is irradiance = pi x radiance, before albedo
            np.testing.assert_allclose(_accessor(gltf, attrs._IRRADIANCE),
                                       math.pi * bake.radiance[t, lo:hi], rtol=1e-6)
            np.testing.assert_array_equal(
                _accessor(gltf, mesh.primitives[0].indices).reshape(-1, 3), bake.object_faces(o))
        issues = khronos(path)
        assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]


# ----------------------------------------------------------------------------- quantities
def test_visibility_quantity_matches_quadrature(bake_file):
    """(1/pi) integral V(w) max(n.w, 0) dw by brute-force quadrature of the SH vector."""
    from shtools.export.quantity import raw_values
    from shtools.sh import basis

    bake = read_bake(bake_file)
    got = raw_values(bake, 1, "visibility")
    # Fibonacci sphere, 200k points: quadrature error of this smooth-times-kink
    # integrand ~1e-5 at these magnitudes; 1e-4 leaves margin
    n = 200_000
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = math.pi * (1 + 5 ** 0.5) * k
    r = np.sqrt(1 - z * z)
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
    y = basis(dirs, 3)
    pick = np.arange(0, bake.n_vertices, 7)
    for v in pick:
        vis = y @ bake.visibility[1, v]
        cos = np.maximum(dirs @ bake.frame_normals(1)[v], 0.0)
        expected = 4 * math.pi / n * np.sum(vis * cos) / math.pi
        assert got[v] == pytest.approx(expected, abs=1e-4)


def test_visibility_needs_stored_vectors(run_cli, tmp_path):
    prim = make_primitive("plane", {"size": [1.0, 1.0], "subdivisions": 1})
    path = tmp_path / "novis.h5"
    write_bake(path, vertices=prim.mesh.vertices, normals=prim.normals, faces=prim.mesh.faces,
               radiance=np.ones((1, len(prim.mesh.vertices), 3)), sh_order=2)
    code, _, stderr = run_cli("export", path, "-o", tmp_path / "x.glb", "--quantity",
                              "visibility")
    assert code == 1 and "--store-visibility" in stderr and stderr.count("\n") == 1
    assert not (tmp_path / "x.glb").exists()


# ----------------------------------------------------------------------------- VAT
def test_vat_texture_and_uvs_index_every_vertex_and_frame(run_cli, bake_file, tmp_path,
                                                         khronos):
    import OpenEXR

    out = tmp_path / "fx.exr"
    summary = export_json(run_cli, bake_file, out, "--frames", "6:9")
    bake = read_bake(bake_file)
    with OpenEXR.File(str(out)) as f:
        tex = np.asarray(f.channels()["RGB"].pixels)
    with OpenEXR.File(str(tmp_path / "fx.pos.exr")) as f:  # the ball moves
        pos = np.asarray(f.channels()["RGB"].pixels)
    W, R, H = summary["width"], summary["rows_per_frame"], summary["height"]
    assert tex.shape == pos.shape == (H, W, 3) and H == 3 * R
    gltf = pygltflib.GLTF2().load(str(tmp_path / "fx.glb"))
    assert gltf.asset.extras["shtools_vat"]["frames"] == [6, 7, 8]
    issues = khronos(tmp_path / "fx.glb")
    assert issues["numErrors"] == 0, issues["messages"]
    for o, mesh in enumerate(gltf.meshes):
        lo, hi = bake.object_offsets[o], bake.object_offsets[o + 1]
        uv = _accessor(gltf, mesh.primitives[0].attributes.TEXCOORD_1)
        for k, t in enumerate((1, 2, 3)):
            # what a shader does at frame k: sample (u, v + k R / H), nearest texel
            col = np.floor(uv[:, 0] * W).astype(int)
            row = np.floor((uv[:, 1] + k * R / H) * H).astype(int)
            np.testing.assert_array_equal(tex[row, col], bake.radiance[t, lo:hi].astype(
                np.float32))
            np.testing.assert_array_equal(pos[row, col], bake.vertices[t, lo:hi].astype(
                np.float32))


# ----------------------------------------------------------------------------- framing
def test_target_frames_the_chosen_object(bake_file):
    from shtools.export.png import View, _camera

    bake = read_bake(bake_file)
    lo, hi = bake.object_offsets[1], bake.object_offsets[2]
    view = View(width=200, height=150, azimuth=20.0, elevation=10.0)

    def extent(camera):
        m = camera.view_matrix()
        cam = bake.vertices[0, lo:hi] @ m[:, :3].T + m[:, 3]
        focal = (150 / 2) / math.tan(camera.fov_y / 2)
        x = 100 + focal * cam[:, 0] / cam[:, 2]
        y = 75 - focal * cam[:, 1] / cam[:, 2]
        return x.min(), x.max(), y.min(), y.max()

    x0, x1, y0, y1 = extent(_camera(bake, [0], view, target="my ball"))
    # inside the image, and spanning most of its height or width (the fit's 4 % margin)
    assert 0 <= x0 and x1 <= 200 and 0 <= y0 and y1 <= 150
    assert max((x1 - x0) / 200, (y1 - y0) / 150) > 0.85
    whole = extent(_camera(bake, [0], view))
    assert (whole[1] - whole[0]) < 0.5 * (x1 - x0)  # framing everything, the ball is small
    # a fixed distance puts the camera that far from the framed centre
    cam = _camera(bake, [0], View(distance=3.0), target="my ball")
    assert np.linalg.norm(cam.eye - cam.target) == pytest.approx(3.0)


def test_export_range_and_target_errors(run_cli, bake_file, tmp_path):
    for args, message in (
        (("--frames", "5:9:0", "-o", tmp_path / "x.png"), "step must be >= 1"),
        (("--frames", "5:9:x", "-o", tmp_path / "x.png"), "is not A:B[:S]"),
        (("--target", "nope", "-o", tmp_path / "x.png"), "no receiver object 'nope'"),
        (("--target", "ground", "-o", tmp_path / "x.usda"), "applies to .png and .gif"),
    ):
        code, _, stderr = run_cli("export", bake_file, *args)
        assert code == 1 and message in stderr and stderr.count("\n") == 1, stderr
    assert list(tmp_path.glob("x*")) == []


def test_usd_writes_uniform_values_once_as_constant_primvars(run_cli, bake_file, tmp_path):
    """An object of one albedo (every scene object) gets one constant element; a value
    that varies over the vertices stays per vertex; an object lit the same at every
    vertex in every frame gets constant colour and radiance too."""
    from pxr import Usd, UsdGeom

    out = tmp_path / "baked.usda"
    export_json(run_cli, bake_file, out)
    stage = Usd.Stage.Open(str(out))
    for path, albedo in (("/World/ground", [0.5] * 3), ("/World/my_ball", [0.9, 0.2, 0.1])):
        primvars = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(path))
        pv = primvars.GetPrimvar("albedo")
        assert pv.GetInterpolation() == "constant"
        np.testing.assert_allclose(np.asarray(pv.Get()), [albedo], rtol=1e-7)  # float32
        # the fixture's random radiance varies per vertex
        assert primvars.GetPrimvar("radiance").GetInterpolation() == "vertex"
        assert primvars.GetPrimvar("displayColor").GetInterpolation() == "vertex"

    # a second bake: 'flat' lit uniformly in every frame with a two-tone albedo, 'dot'
    # uniformly lit and of one albedo
    plane = make_primitive("plane", {"size": [1.0, 1.0], "subdivisions": 2})
    V = len(plane.mesh.vertices)
    verts = np.concatenate([plane.mesh.vertices, plane.mesh.vertices + np.array([0, 1.0, 0])])
    radiance = np.empty((2, 2 * V, 3))
    radiance[0], radiance[1] = [0.2, 0.3, 0.4], [0.5, 0.5, 0.5]
    albedo = np.concatenate([np.where(np.arange(V)[:, None] % 2, 0.2, 0.9) * np.ones(3),
                             np.full((V, 3), 0.7)])
    path = tmp_path / "uniform.h5"
    write_bake(path, vertices=verts, normals=np.tile([0.0, 1.0, 0.0], (2 * V, 1)),
               faces=np.concatenate([plane.mesh.faces, plane.mesh.faces + V]),
               radiance=radiance, sh_order=2, frame_index=[0, 1], times=[0.0, 1.0],
               albedo=albedo, object_offsets=[0, V, 2 * V], object_names=["flat", "dot"],
               fps=1.0)
    out = tmp_path / "uniform.usda"
    export_json(run_cli, path, out)
    stage = Usd.Stage.Open(str(out))
    flat = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/flat"))
    dot = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/dot"))
    assert flat.GetPrimvar("albedo").GetInterpolation() == "vertex"
    assert flat.GetPrimvar("radiance").GetInterpolation() == "constant"
    assert flat.GetPrimvar("displayColor").GetInterpolation() == "vertex"  # x two albedos
    for name in ("albedo", "radiance", "displayColor"):
        assert dot.GetPrimvar(name).GetInterpolation() == "constant", name
    np.testing.assert_array_equal(np.asarray(dot.GetPrimvar("radiance").Get(1)),
                                  np.float32([[0.5, 0.5, 0.5]]))
    # constant colour: ACES of albedo x radiance (fixed exposure), one element per frame
    np.testing.assert_allclose(np.asarray(dot.GetPrimvar("displayColor").Get(0)),
                               aces(np.array([[0.2, 0.3, 0.4]]) * 0.7), atol=1e-6)
