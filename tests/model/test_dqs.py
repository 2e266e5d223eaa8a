"""Dual-quaternion skinning against closed-form cases: hard weights, rigid motions, a twisted two-bone cylinder."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from darthand.model.dqs import dqs
from darthand.model.forward import forward
from synthetic import CYL_LENGTH as LENGTH, CYL_RADIUS as RADIUS, CYL_RINGS as N_RINGS
from synthetic import RING, tube_hand, two_bone_cylinder



def twist(angle: float) -> np.ndarray:
    """(1, 48) pose twisting joint 1 by `angle` radians about the cylinder's axis (X)."""
    p = np.zeros((1, 48))
    p[0, 3] = angle
    return p


def single_influence(m):
    """The model with each vertex bound to its heaviest joint alone (DQS and LBS then agree exactly)."""
    hard = np.zeros_like(m.weights)
    hard[np.arange(m.num_vertices), m.weights.argmax(1)] = 1
    return m.replace(weights=hard)


def random_poses(rng, n, max_angle=np.pi):
    axes = rng.standard_normal((n, 16, 3))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    return (axes * rng.uniform(0, max_angle, (n, 16, 1))).reshape(n, 48)


def test_cylinder_fixture_is_what_the_closed_forms_assume():
    m = two_bone_cylinder()
    joints = m.J_regressor @ m.v_template
    np.testing.assert_allclose(joints[0], [0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(joints[1], [-LENGTH / 2, 0, 0], atol=1e-15)


def test_single_influence_equals_lbs():
    m = single_influence(tube_hand(3))
    poses = random_poses(np.random.default_rng(0), 8)
    for corr in (False, True):
        np.testing.assert_allclose(dqs(m, poses, correctives=corr),
                                   forward(m, poses, correctives=corr).vertices, atol=1e-12)


def test_rigid_motion_is_exact_with_blended_weights():
    m = tube_hand(1)                       # every vertex blends all 16 joints
    rng = np.random.default_rng(1)
    root = Rotation.random(4, random_state=2)
    poses = np.zeros((4, 48))
    poses[:, :3] = root.as_rotvec()
    trans = rng.normal(0, 0.1, (4, 3))
    j0 = (m.J_regressor @ m.v_template)[0]
    expected = np.einsum("bij,vj->bvi", root.as_matrix(), m.v_template - j0) + j0 + trans[:, None]
    np.testing.assert_allclose(dqs(m, poses, trans=trans), expected, atol=1e-12)


@pytest.mark.parametrize("angle_deg", [30, 90, 150, 180])
def test_twisted_cylinder_keeps_its_radius_where_lbs_collapses(angle_deg):
    m = two_bone_cylinder()
    theta = np.deg2rad(angle_deg)
    side = np.arange(N_RINGS * RING)       # tube vertices (the apex sits on the axis)
    w0, w1 = m.weights[side, 0], m.weights[side, 1]
    rest = m.v_template[side]

    v = dqs(m, twist(theta))[0, side]
    np.testing.assert_allclose(np.linalg.norm(v[:, 1:], axis=1), RADIUS, rtol=1e-12)
    np.testing.assert_allclose(v[:, 0], rest[:, 0], atol=1e-15)
    # Blending the unit quaternions of 0 and theta about X gives a rotation by phi about X.
    phi = 2 * np.arctan2(w1 * np.sin(theta / 2), w0 + w1 * np.cos(theta / 2))
    turned = np.angle((v[:, 1] + 1j * v[:, 2]) / (rest[:, 1] + 1j * rest[:, 2]))
    np.testing.assert_allclose(np.exp(1j * turned), np.exp(1j * phi), atol=1e-12)

    lbs = forward(m, twist(theta), correctives=False).vertices[0, side]
    lbs_radius = RADIUS * np.sqrt(w0 ** 2 + w1 ** 2 + 2 * w0 * w1 * np.cos(theta))
    np.testing.assert_allclose(np.linalg.norm(lbs[:, 1:], axis=1), lbs_radius, atol=1e-15)
    if angle_deg == 180:  # the candy wrapper: the half-and-half ring collapses onto the axis under LBS
        half = np.isclose(w1, 0.5)
        assert half.any() and np.linalg.norm(lbs[half, 1:], axis=1).max() < 1e-15


def test_antipodal_quaternions_are_aligned():
    """DQS commutes with a global rotation even when composing it flips some joints' quaternions (w >= 0
    canonical form), which only holds if each vertex blends the quaternions in one hemisphere."""
    m = tube_hand(2)
    rng = np.random.default_rng(5)
    poses = random_poses(rng, 6, max_angle=1.2)
    poses[:, :3] = 0
    root = Rotation.from_rotvec([0, 0, np.deg2rad(175)])
    turned = poses.copy()
    turned[:, :3] = root.as_rotvec()
    j0 = (m.J_regressor @ m.v_template)[0]
    expected = (dqs(m, poses) - j0) @ root.as_matrix().T + j0
    np.testing.assert_allclose(dqs(m, turned), expected, atol=1e-12)


def test_betas_move_the_rest_shape_like_forward():
    m = single_influence(tube_hand(4))
    poses = random_poses(np.random.default_rng(7), 3)
    betas = np.random.default_rng(8).normal(0, 1, (3, m.num_betas))
    np.testing.assert_allclose(dqs(m, poses, betas), forward(m, poses, betas, correctives=False).vertices,
                               atol=1e-12)
