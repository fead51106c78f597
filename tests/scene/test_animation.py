"""Rigid keyframes, parent chains, lights and skinning: checked against hand-computed poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers.rig import LENGTH, RADIUS, bone_weights, write_bending_tube

from shtools.errors import InputError
from shtools.geometry.transforms import euler_to_quaternion, quaternion_matrix, slerp
from shtools.scene.animation import (
    interpolate_pose,
    light_at,
    transform_spheres,
    vertex_normals,
    world_matrices,
)
from shtools.scene.scene import parse_scene


def rot_z(deg):
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])


def rot_y(deg):
    a = math.radians(deg)
    return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])


def test_euler_and_quaternion_matrix_match_closed_forms():
    # R = Rz Ry Rx; with only one angle non-zero it is the elementary rotation
    np.testing.assert_allclose(quaternion_matrix(euler_to_quaternion([0, 0, 30])), rot_z(30),
                               atol=1e-12)
    np.testing.assert_allclose(quaternion_matrix(euler_to_quaternion([0, 40, 30])),
                               rot_z(30) @ rot_y(40), atol=1e-12)


def test_slerp_is_constant_speed_about_one_axis():
    q0 = euler_to_quaternion([0, 0, 10])
    q1 = euler_to_quaternion([0, 0, 130])
    for u in (0.0, 0.25, 0.5, 1.0):
        np.testing.assert_allclose(quaternion_matrix(slerp(q0, q1, u)), rot_z(10 + 120 * u),
                                   atol=1e-12)
    # q and -q are the same rotation: slerp takes the short way (10 -> -10 through 0)
    np.testing.assert_allclose(
        quaternion_matrix(slerp(q0, -euler_to_quaternion([0, 0, -10]), 0.5)), np.eye(3),
        atol=1e-12)


SCENE = """
[settings]
frames = 5
fps = 2
[environment]
coeffs = [[1, 1, 1], [0, 0, 0], [0, 0, 0], [0, 0, 0],
          [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0],
          [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]
[[lights]]
position = [0, 4, 0]
radius = 1.0
color = [2, 2, 2]
[[lights.keyframes]]
time = 0
[[lights.keyframes]]
time = 2
position = [4, 4, 0]
radius = 0.5

[[objects]]
name = "body"
primitive = "sphere"
role = "both"
scale = 2
[[objects.keyframes]]
time = 0
translate = [0, 0, 0]
rotate = [0, 0, 0]
[[objects.keyframes]]
time = 2
translate = [4, 0, 0]
rotate = [0, 0, 90]

[[objects]]
name = "arm"
primitive = "sphere"
role = "blocker"
parent = "body"
translate = [1, 0, 0]
"""


def test_rigid_keyframes_and_parent_chain(tmp_path):
    scene = parse_scene(SCENE, tmp_path / "s.toml")
    body = scene.object("body")
    pose = interpolate_pose(body.keyframes, 1.0)
    np.testing.assert_allclose(pose.translate, [2, 0, 0])
    np.testing.assert_allclose(quaternion_matrix(pose.quaternion), rot_z(45), atol=1e-12)
    np.testing.assert_allclose(pose.scale, [2, 2, 2])  # inherited from the static transform
    # beyond the last key the pose holds
    np.testing.assert_allclose(interpolate_pose(body.keyframes, 5.0).translate, [4, 0, 0])
    worlds = world_matrices(scene.objects, 1.0)
    # arm = body(t) @ translate(1, 0, 0): its origin is body's origin + R(45) * 2 * (1, 0, 0)
    expected = np.array([2, 0, 0]) + rot_z(45) @ np.array([2.0, 0, 0])
    np.testing.assert_allclose(worlds["arm"][:3, 3], expected, atol=1e-12)
    # spheres move with the transform; radius scales with it
    c, r = transform_spheres(worlds["body"], np.array([[0.5, 0, 0]]), np.array([0.25]))
    np.testing.assert_allclose(c[0], [2, 0, 0] + rot_z(45) @ [1.0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(r, [0.5])
    light = light_at(scene.lights[0], 1.0)
    np.testing.assert_allclose(light.position, [2, 4, 0])
    assert light.radius == pytest.approx(0.75)


def test_looping_keyframes(tmp_path):
    text = SCENE.replace('name = "body"', 'name = "body"\nloop = true')
    body = parse_scene(text, tmp_path / "s.toml").object("body")
    np.testing.assert_allclose(interpolate_pose(body.keyframes, 3.0, loop=True).translate,
                               [2, 0, 0])


def test_vertex_normals_of_a_sphere_point_outward():
    from shtools.scene.primitives import make_primitive

    prim = make_primitive("sphere", {"radius": 2.0, "subdivisions": 3})
    n = vertex_normals(np.asarray(prim.mesh.vertices), np.asarray(prim.mesh.faces))
    radial = prim.mesh.vertices / np.linalg.norm(prim.mesh.vertices, axis=1, keepdims=True)
    # area-weighted face normals of a 642-vertex icosphere are within ~1 degree of radial
    assert np.min(np.sum(n * radial, axis=1)) > math.cos(math.radians(2.0))


def test_skinned_mesh_and_bound_spheres_follow_the_bone(tmp_path):
    """The tip bone bends 90 degrees about z at (0, 1, 0): mesh and spheres move together."""
    from shtools.geometry.binding import bind_spheres
    from shtools.geometry.skin import load_skinned_gltf
    from shtools.runtime.spheres import pose_bound_spheres
    from shtools.scene.animation import SkinnedMotion

    path = tmp_path / "rig.glb"
    write_bending_tube(path, bend_degrees=90.0)
    model = load_skinned_gltf(path)
    motion = SkinnedMotion(model, "bend", speed=1.0, offset=0.0)
    joints = motion.joint_matrices(1.0)
    # independent expectation: rotate about z by 90 degrees around the pivot (0, 1, 0)
    pivot = np.array([0.0, 1.0, 0.0])

    def bent(p):
        return (p - pivot) @ rot_z(90).T + pivot

    rest = model.rest_vertices
    posed = model.skin(joints)
    tip = bone_weights(rest[:, 1]) == 1.0
    base = bone_weights(rest[:, 1]) == 0.0
    np.testing.assert_allclose(posed[tip], bent(rest[tip]), atol=1e-6)  # float32 file data
    np.testing.assert_allclose(posed[base], rest[base], atol=1e-6)

    # spheres along the axis, bound with mean value coordinates + bone weights
    centers = np.array([[0, 0.3, 0], [0, 0.6, 0], [0, 1.5, 0], [0, 1.8, 0]], float)
    binding = bind_spheres(centers, model)
    moved = pose_bound_spheres(binding.bone_index, binding.bone_vectors, joints)
    # Mean value coordinates are global: every tube vertex, including the blended
    # ones around the joint, pulls a centre a little, so a centre in the tip
    # region follows the tip bone to within ~1 % of the tube length (2.3 mm seen).
    MVC_NONLOCAL_TOL = 0.02
    np.testing.assert_allclose(moved[2:], bent(centers[2:]), atol=MVC_NONLOCAL_TOL)
    np.testing.assert_allclose(moved[:2], centers[:2], atol=MVC_NONLOCAL_TOL)
    # a rigid motion of the whole skeleton moves mesh and spheres exactly alike
    rigid = np.eye(4)
    rigid[:3, :3] = rot_y(30) @ rot_z(20)
    rigid[:3, 3] = [0.5, -1.0, 2.0]
    all_bones = rigid @ model.rest_joint_matrices()
    moved_rigid = pose_bound_spheres(binding.bone_index, binding.bone_vectors, all_bones)
    np.testing.assert_allclose(moved_rigid, centers @ rigid[:3, :3].T + rigid[:3, 3], atol=1e-9)
    np.testing.assert_allclose(model.skin(all_bones), rest @ rigid[:3, :3].T + rigid[:3, 3],
                               atol=1e-6)
    # and stay inside the posed tube: every posed vertex of the tip region is within
    # RADIUS of the bent axis that the posed sphere centres lie on
    axis_dir = bent(np.array([0, 2.0, 0])) - bent(np.array([0, 1.2, 0]))
    axis_dir /= np.linalg.norm(axis_dir)
    rel = moved[3] - posed[tip]
    dist_to_axis = np.linalg.norm(rel - (rel @ axis_dir)[:, None] * axis_dir, axis=1)
    assert np.all(dist_to_axis <= RADIUS + MVC_NONLOCAL_TOL)
    # clip time wraps over the 2 s clip: t = 3 is t = 1
    np.testing.assert_allclose(motion.joint_matrices(3.0), joints, atol=1e-12)
    assert LENGTH == 2.0


def test_skinned_object_without_skin_or_animation(tmp_path):
    from shtools.geometry.skin import load_skinned_gltf
    from shtools.scene.animation import SkinnedMotion

    no_skin = tmp_path / "noskin.glb"
    write_bending_tube(no_skin, with_skin=False)
    with pytest.raises(InputError):
        load_skinned_gltf(no_skin)
    no_anim = tmp_path / "noanim.glb"
    write_bending_tube(no_anim, with_animation=False)
    with pytest.raises(InputError, match="animation"):
        SkinnedMotion(load_skinned_gltf(no_anim), 0)
