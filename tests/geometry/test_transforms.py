"""Rigid transforms against scipy.spatial.transform (an independent implementation)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from shtools.geometry.transforms import (
    decompose_trs,
    matrix_quaternion,
    quaternion_matrix,
    slerp,
    trs_matrix,
)

# double-precision round-off of a few products of unit-size numbers
TOL = 1e-12


@pytest.fixture
def quats():
    return Rotation.random(20, random_state=3).as_quat()  # (x, y, z, w), like glTF


def test_quaternion_matrix_matches_scipy(quats):
    np.testing.assert_allclose(quaternion_matrix(quats), Rotation.from_quat(quats).as_matrix(),
                               atol=TOL)
    # not normalised on input: normalised here
    np.testing.assert_allclose(quaternion_matrix(3.0 * quats[0]),
                               Rotation.from_quat(quats[0]).as_matrix(), atol=TOL)


@pytest.mark.parametrize("u", [0.0, 0.3, 0.5, 1.0])
def test_slerp_matches_scipy_on_the_shortest_arc(quats, u):
    # scipy interpolates rotations (whatever the sign of q1): the shortest arc too
    for q0, q1 in itertools.pairwise(quats):
        want = Slerp([0.0, 1.0], Rotation.from_quat([q0, q1]))(u).as_matrix()
        # 1e-9: scipy's rotation-vector route rounds differently from the sin formula
        np.testing.assert_allclose(quaternion_matrix(slerp(q0, q1, u)), want, atol=1e-9)


def test_trs_round_trip(quats):
    rng = np.random.default_rng(0)
    for q in quats:
        t, s = rng.normal(size=3), rng.uniform(0.2, 3.0, size=3)
        m = trs_matrix(t, q, s)
        want = np.eye(4)
        want[:3, :3] = Rotation.from_quat(q).as_matrix() @ np.diag(s)
        want[:3, 3] = t
        np.testing.assert_allclose(m, want, atol=TOL)
        t2, q2, s2 = decompose_trs(m)
        np.testing.assert_allclose(t2, t, atol=TOL)
        np.testing.assert_allclose(s2, s, atol=1e-10)
        # q and -q are the same rotation
        np.testing.assert_allclose(abs(q2 @ q), 1.0, atol=1e-10)
        np.testing.assert_allclose(quaternion_matrix(matrix_quaternion(
            Rotation.from_quat(q).as_matrix())), Rotation.from_quat(q).as_matrix(), atol=1e-10)
