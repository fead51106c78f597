"""glTF skins and animations: joint matrices vs hand-computed transforms, LBS, bad rigs.

The rig is built here with pygltflib: a bar along +x (a closed box mesh),
three joints in a chain at x = 0, 1, 2, inverse bind matrices = inverse rest
transforms, and one animation with LINEAR (rotation, scale), STEP
(translation) and CUBICSPLINE (translation) channels.  Expected matrices are
composed by hand from elementary rotations/translations, not by the module.
"""

from __future__ import annotations

import numpy as np
import pygltflib
import pytest

from shtools.errors import InputError
from shtools.geometry.skin import load_skinned_gltf

#: float32 storage of positions and keys in the glTF (~6e-8 relative) sets the
#: comparison tolerance
F32_TOL = 1e-6


def _rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def _translate(t):
    m = np.eye(4)
    m[:3, 3] = t
    return m


def _scale(s):
    return np.diag([*s, 1.0])


def _bar_mesh():
    """Closed box [0,2]x[-.2,.2]x[-.2,.2] split at x = 0, 0.5, ..., 2, and weights."""
    xs = np.linspace(0.0, 2.0, 5)
    ring = np.array([[-0.2, -0.2], [0.2, -0.2], [0.2, 0.2], [-0.2, 0.2]])
    verts = np.array([[x, y, z] for x in xs for y, z in ring])
    faces = []
    for i in range(len(xs) - 1):
        for k in range(4):
            a, b = 4 * i + k, 4 * i + (k + 1) % 4
            c, d = a + 4, b + 4
            faces += [[a, b, d], [a, d, c]]
    last = 4 * (len(xs) - 1)
    faces += [[0, 2, 1], [0, 3, 2], [last, last + 1, last + 2], [last, last + 2, last + 3]]
    # joint 0 at x=0, joint 1 at x=1, joint 2 at x=2: hat weights
    x = verts[:, 0]
    w = np.stack([np.clip(1 - x, 0, 1), 1 - np.abs(x - 1), np.clip(x - 1, 0, 1)], 1)
    w = np.clip(w, 0, 1)
    return verts, np.asarray(faces), w / w.sum(1, keepdims=True)


def build_rig(path, *, animated=True, skinned=True, identity_keys=False):
    """Write the test rig as .glb; returns rest-pose data for the checks."""
    verts, faces, weights = _bar_mesh()
    joints = np.tile(np.array([0, 1, 2, 0], dtype=np.uint16), (len(verts), 1))
    w4 = np.concatenate([weights, np.zeros((len(verts), 1))], 1).astype(np.float32)
    rest_globals = [_translate([0, 0, 0]), _translate([1, 0, 0]), _translate([2, 0, 0])]
    ibm = np.stack([np.linalg.inv(g) for g in rest_globals]).astype(np.float32)
    # keyframes
    times = np.array([0.0, 1.0], dtype=np.float32)
    step_times = np.array([0.0, 0.5, 1.0], dtype=np.float32)
    if identity_keys:
        rot = np.array([[0, 0, 0, 1], [0, 0, 0, 1]], dtype=np.float32)
        step_tr = np.zeros((3, 3), dtype=np.float32)
        scl = np.ones((2, 3), dtype=np.float32)
        cubic = np.zeros((6, 3), dtype=np.float32)
        cubic[[1, 4], 0] = 1.0  # joint 2's rest translation (1, 0, 0) relative to joint 1
    else:
        h = np.sin(np.pi / 4)
        rot = np.array([[0, 0, 0, 1], [0, 0, h, h]], dtype=np.float32)  # 0 -> 90 deg about z
        step_tr = np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0]], dtype=np.float32)
        scl = np.array([[1, 1, 1], [3, 1, 1]], dtype=np.float32)
        # cubic spline translation of joint 2: (in, value, out) per key, zero tangents
        cubic = np.zeros((6, 3), dtype=np.float32)
        cubic[1] = [1, 0, 0]
        cubic[4] = [1, 2, 0]
    blobs = [
        verts.astype(np.float32), faces.astype(np.uint32).reshape(-1), joints, w4,
        ibm.transpose(0, 2, 1).reshape(-1, 16),  # column-major
        times, rot, step_times, step_tr, scl, cubic,
    ]
    types = ["VEC3", "SCALAR", "VEC4", "VEC4", "MAT4", "SCALAR", "VEC4", "SCALAR", "VEC3",
             "VEC3", "VEC3"]
    comp = {np.dtype(np.float32): 5126, np.dtype(np.uint32): 5125, np.dtype(np.uint16): 5123}
    data = b""
    views, accessors = [], []
    for arr, typ in zip(blobs, types, strict=True):
        raw = np.ascontiguousarray(arr).tobytes()
        views.append(pygltflib.BufferView(buffer=0, byteOffset=len(data), byteLength=len(raw)))
        count = arr.shape[0] if typ != "SCALAR" else arr.size
        accessors.append(pygltflib.Accessor(bufferView=len(views) - 1,
                                            componentType=comp[arr.dtype],
                                            count=int(count), type=typ))
        data += raw + b"\0" * (-len(raw) % 4)
    attrs = pygltflib.Attributes(POSITION=0)
    if skinned:
        attrs.JOINTS_0, attrs.WEIGHTS_0 = 2, 3
    nodes = [
        pygltflib.Node(name="j0", children=[1]),
        pygltflib.Node(name="j1", translation=[1, 0, 0], children=[2]),
        pygltflib.Node(name="j2", translation=[1, 0, 0]),
        pygltflib.Node(name="bar", mesh=0, skin=0 if skinned else None,
                       translation=[5, 5, 5]),  # ignored by skinning (glTF spec)
    ]
    gltf = pygltflib.GLTF2(
        scene=0,
        scenes=[pygltflib.Scene(nodes=[0, 3])],
        nodes=nodes,
        meshes=[pygltflib.Mesh(primitives=[pygltflib.Primitive(attributes=attrs, indices=1)])],
        skins=[pygltflib.Skin(joints=[0, 1, 2], inverseBindMatrices=4)] if skinned else [],
        accessors=accessors,
        bufferViews=views,
        buffers=[pygltflib.Buffer(byteLength=len(data))],
    )
    if animated:
        gltf.animations = [pygltflib.Animation(
            name="wave",
            samplers=[
                pygltflib.AnimationSampler(input=5, output=6, interpolation="LINEAR"),
                pygltflib.AnimationSampler(input=7, output=8, interpolation="STEP"),
                pygltflib.AnimationSampler(input=5, output=9, interpolation="LINEAR"),
                pygltflib.AnimationSampler(input=5, output=10, interpolation="CUBICSPLINE"),
            ],
            channels=[
                pygltflib.AnimationChannel(sampler=0, target=pygltflib.AnimationChannelTarget(
                    node=1, path="rotation")),
                pygltflib.AnimationChannel(sampler=1, target=pygltflib.AnimationChannelTarget(
                    node=0, path="translation")),
                pygltflib.AnimationChannel(sampler=2, target=pygltflib.AnimationChannelTarget(
                    node=2, path="scale")),
                pygltflib.AnimationChannel(sampler=3, target=pygltflib.AnimationChannelTarget(
                    node=2, path="translation")),
            ],
        )]
    gltf.set_binary_blob(data)
    gltf.save(str(path))
    return verts, faces, weights, rest_globals


def expected_joint_matrices(t, rest_globals):
    """Hand-composed skinning matrices of the 'wave' animation at time t."""
    angle = np.pi / 2 * t  # slerp between 0 and 90 deg about z is uniform in angle
    lift = 0.0 if t < 0.5 else (1.0 if t < 1.0 else 2.0)  # STEP keys at 0, .5, 1
    sx = 1 + 2 * t
    s = 3 * t * t - 2 * t**3  # Hermite with zero tangents
    g0 = _translate([0, lift, 0])
    g1 = g0 @ _translate([1, 0, 0]) @ _rot_z(angle)
    g2 = g1 @ _translate([1, 2 * s, 0]) @ _scale([sx, 1, 1])
    return np.stack([g @ np.linalg.inv(r) for g, r in zip((g0, g1, g2), rest_globals,
                                                             strict=True)])


@pytest.fixture
def bar_rig(tmp_path):
    path = tmp_path / "rig.glb"
    data = build_rig(path)
    return path, data


def test_loads_mesh_weights_and_bind(bar_rig):
    path, (verts, faces, weights, rest_globals) = bar_rig
    model = load_skinned_gltf(path)
    np.testing.assert_allclose(model.rest_vertices, verts, atol=F32_TOL)
    np.testing.assert_array_equal(model.faces, faces)
    dense = np.zeros((len(verts), 3))
    np.add.at(dense, (np.arange(len(verts))[:, None], model.joints), model.weights)
    np.testing.assert_allclose(dense, weights, atol=F32_TOL)
    np.testing.assert_allclose(model.inverse_bind, [np.linalg.inv(g) for g in rest_globals],
                               atol=F32_TOL)
    assert model.animations == ["wave"]
    assert model.duration() == 1.0
    assert model.joint_names == ["j0", "j1", "j2"]


@pytest.mark.parametrize("t", [0.0, 0.25, 0.5, 0.7, 1.0, 1.5, -1.0])
def test_joint_matrices_match_hand_computed(bar_rig, t):
    path, (_, _, _, rest_globals) = bar_rig
    model = load_skinned_gltf(path)
    want = expected_joint_matrices(min(max(t, 0.0), 1.0), rest_globals)  # clamped time
    np.testing.assert_allclose(model.joint_matrices(t, "wave"), want, atol=F32_TOL)
    np.testing.assert_allclose(model.joint_matrices(t, 0), want, atol=F32_TOL)


def test_linear_blend_skinning(bar_rig):
    path, (verts, _, weights, rest_globals) = bar_rig
    model = load_skinned_gltf(path)
    mats = expected_joint_matrices(0.6, rest_globals)
    hom = np.concatenate([verts, np.ones((len(verts), 1))], 1)
    want = sum(weights[:, [j]] * (hom @ mats[j].T)[:, :3] for j in range(3))
    # glTF stores vertices, weights and keyframes as float32: rounding of unit-sized data
    np.testing.assert_allclose(model.skin(model.joint_matrices(0.6)), want, atol=1e-5)


def test_identity_animation_gives_rest_pose(tmp_path):
    path = tmp_path / "still.glb"
    verts, *_ = build_rig(path, identity_keys=True)
    model = load_skinned_gltf(path)
    for t in (0.0, 0.3, 1.0):
        mats = model.joint_matrices(t)
        np.testing.assert_allclose(mats, np.tile(np.eye(4), (3, 1, 1)), atol=F32_TOL)
        np.testing.assert_allclose(model.skin(mats), verts, atol=F32_TOL)
    np.testing.assert_allclose(model.skin(model.rest_joint_matrices()), verts, atol=F32_TOL)


def test_rig_without_skin_is_refused(tmp_path):
    path = tmp_path / "static.glb"
    build_rig(path, skinned=False)
    with pytest.raises(InputError, match="no skin"):
        load_skinned_gltf(path)


def test_missing_animation_is_refused(tmp_path):
    path = tmp_path / "pose.glb"
    build_rig(path, animated=False)
    model = load_skinned_gltf(path)  # a rest-pose rig still loads (binding needs no clip)
    with pytest.raises(InputError, match="no animation"):
        model.joint_matrices(0.0)
    rigged = load_skinned_gltf(tmp_path / "pose.glb")
    with pytest.raises(InputError):
        rigged.duration("walk")


def test_missing_and_garbage_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_skinned_gltf(tmp_path / "nope.glb")
    bad = tmp_path / "bad.glb"
    bad.write_bytes(b"definitely not a glb")
    with pytest.raises(InputError):
        load_skinned_gltf(bad)


def test_cli_bind_and_bad_rigs(tmp_path, run_cli):
    from shtools.data_formats import write_asset
    from shtools.data_formats.bound import read_bound
    from shtools.runtime.spheres import pose_bound_spheres

    rig_path = tmp_path / "rig.glb"
    build_rig(rig_path)
    centers = np.array([[0.3, 0.0, 0.0], [1.0, 0.05, 0.0], [1.7, 0.0, -0.05]])
    spheres = tmp_path / "s.h5"
    write_asset(spheres, "spheres", {"centers": centers, "radii": np.full(3, 0.4)},
                attrs={"outside_volume_ratio": 0.0})
    out = tmp_path / "bound.h5"
    code, stdout, stderr = run_cli("spheres", "bind", spheres, rig_path, "-o", out, "--json",
                                   "--bones-per-sphere", "2")
    assert code == 0, stderr
    bound = read_bound(out)
    assert bound.bone_index.shape == (3, 2) and bound.joint_count == 3
    assert "rig.glb" in bound.attrs["inputs"]
    # rest pose (identity skinning matrices) reproduces the centres
    posed = pose_bound_spheres(bound.bone_index, bound.bone_vectors, np.tile(np.eye(4), (3, 1, 1)))
    np.testing.assert_allclose(posed, centers, atol=1e-9)
    assert '"mesh_closed": true' in stdout
    assert bound.fit_radii is None

    grown = tmp_path / "grown.h5"
    code, _, stderr = run_cli("spheres", "bind", spheres, rig_path, "-o", grown,
                              "--cover-animations")
    assert code == 0, stderr
    bound = read_bound(grown)
    np.testing.assert_array_equal(bound.fit_radii, np.full(3, 0.4))
    assert np.all(bound.radii >= bound.fit_radii) and np.any(bound.radii > 0.4)

    still = tmp_path / "still.glb"
    build_rig(still, animated=False)
    target = tmp_path / "never.h5"
    code, _, stderr = run_cli("spheres", "bind", spheres, still, "-o", target,
                              "--cover-animations")
    assert code == 1 and "needs an animation" in stderr and not target.exists()

    static = tmp_path / "static.glb"
    build_rig(static, skinned=False)
    for args in ((spheres, static), (spheres, tmp_path / "missing.glb"),
                 (tmp_path / "missing.h5", rig_path)):
        target = tmp_path / "never.h5"
        code, _, stderr = run_cli("spheres", "bind", *args, "-o", target)
        assert code != 0
        assert stderr.startswith("error:") and len(stderr.strip().splitlines()) == 1
        assert not target.exists()


def test_covering_radii_keep_vertices_covered_over_the_animation(bar_rig):
    from shtools.geometry.binding import bind_spheres, covering_radii

    path, (verts, _, _, rest_globals) = bar_rig
    model = load_skinned_gltf(path)
    centers = np.array([[0.25, 0.0, 0.0], [1.0, 0.0, 0.0], [1.75, 0.0, 0.0]])
    radii = np.full(3, 0.45)  # covers the bar at rest (half-width 0.2*sqrt(2), 0.25 along x)
    binding = bind_spheres(centers, model, bones_per_sphere=2)
    grown = covering_radii(binding, radii, model, frames=9)
    assert np.all(grown >= radii) and np.any(grown > radii * 1.01)
    # independent check at the sampled times with hand-composed matrices
    hom = np.concatenate([verts, np.ones((len(verts), 1))], 1)
    weights = _bar_mesh()[2]
    for t in np.linspace(0.0, 1.0, 9):
        mats = expected_joint_matrices(t, rest_globals)
        skinned = sum(weights[:, [j]] * (hom @ mats[j].T)[:, :3] for j in range(3))
        posed = np.array([sum(mats[j] @ q for j, q in zip(binding.bone_index[n],
                                                        binding.bone_vectors[n], strict=True))[:3]
                          for n in range(3)])
        dist = np.linalg.norm(skinned[:, None] - posed[None], axis=2)
        # every vertex inside some sphere; 1e-5: float32 keys in the file vs float64
        # hand-composed matrices
        assert np.all((dist - grown).min(axis=1) <= 1e-5)
        # with the rest radii the bent, stretched bar is not covered at the end
        if t == 1.0:
            assert np.any((dist - radii).min(axis=1) > 0.05)


def test_spheres_fitted_in_scene_space_are_moved_to_bind_space(bar_rig):
    from shtools.geometry.binding import spheres_to_bind_space

    path, _ = bar_rig
    model = load_skinned_gltf(path)
    # the mesh node is translated by (5, 5, 5): scene = bind + 5 (trimesh.load's view)
    np.testing.assert_allclose(model.mesh_transform[:3, 3], [5, 5, 5])
    centers = np.array([[0.5, 0, 0], [1.5, 0, 0]])
    radii = np.full(2, 0.8)
    c, r, space = spheres_to_bind_space(centers + 5.0, radii, model)
    assert space == "scene"
    np.testing.assert_allclose(c, centers, atol=1e-12)
    np.testing.assert_allclose(r, radii)
    c, r, space = spheres_to_bind_space(centers, radii, model)
    assert space == "bind" and np.array_equal(c, centers)
    with pytest.raises(InputError, match="cover only"):
        spheres_to_bind_space(centers + 50.0, radii, model)
