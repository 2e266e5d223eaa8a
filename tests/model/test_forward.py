"""The forward pass against an independent reference and closed-form cases."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from darthand.errors import InputError
from darthand.model.forward import forward
from darthand.model.layout import KEYPOINT_ORDERS
from synthetic import tube_hand


def reference_lbs(model, pose48, betas=None):
    """MANO's forward pass written plainly, one pose, loops over joints and vertices, scipy rotations.

    An independent implementation of the same equations (no code shared with darthand.model.forward).
    """
    aa = np.asarray(pose48, dtype=np.float64).reshape(16, 3)
    v = model.v_template.copy()
    if betas is not None:
        for s, b in enumerate(betas):
            v = v + b * model.shapedirs[:, :, s]
    J = model.J_regressor.toarray() @ v
    R = Rotation.from_rotvec(aa).as_matrix()
    feat = np.concatenate([(R[i] - np.eye(3)).ravel() for i in range(1, 16)])
    v = v + np.einsum("vck,k->vc", model.posedirs, feat)
    A = [None] * 16
    for i in range(16):
        local = np.eye(4)
        local[:3, :3] = R[i]
        local[:3, 3] = J[i] if i == 0 else J[i] - J[model.parents[i]]
        A[i] = local if i == 0 else A[model.parents[i]] @ local
    G = []
    for i in range(16):
        g = A[i].copy()
        g[:3, 3] -= A[i][:3, :3] @ J[i]
        G.append(g)
    out = np.zeros_like(v)
    for k in range(len(v)):
        T = sum(model.weights[k, i] * G[i] for i in range(16))
        out[k] = T[:3, :3] @ v[k] + T[:3, 3]
    joints = np.array([a[:3, 3] for a in A])
    return out, joints


@pytest.fixture(scope="module")
def model():
    return tube_hand(seed=3, corrective_scale=5e-3)


def test_matches_independent_reference(model):
    rng = np.random.default_rng(0)
    poses = rng.uniform(-np.pi, np.pi, (4, 48))
    betas = rng.standard_normal(4)
    out = forward(model, poses, np.tile(betas, (4, 1)))
    for b in range(4):
        ref_v, ref_j = reference_lbs(model, poses[b], betas)
        np.testing.assert_allclose(out.vertices[b], ref_v, atol=1e-12)
        np.testing.assert_allclose(out.joints[b], ref_j, atol=1e-12)


def test_zero_pose_is_template(model):
    out = forward(model, np.zeros(48))
    np.testing.assert_allclose(out.vertices[0], model.v_template, atol=1e-15)
    np.testing.assert_allclose(out.joints[0], model.J_regressor @ model.v_template, atol=1e-15)


def test_global_rotation_is_rigid_about_the_wrist(model):
    """Rotating only joint 0 rotates every vertex about the wrist joint (weights sum to 1, R_0 not in the feature)."""
    rv = np.array([0.3, -1.2, 2.0])
    pose = np.zeros(48)
    pose[:3] = rv
    out = forward(model, pose).vertices[0]
    j0 = (model.J_regressor @ model.v_template)[0]
    expected = (model.v_template - j0) @ Rotation.from_rotvec(rv).as_matrix().T + j0
    np.testing.assert_allclose(out, expected, atol=1e-14)


@settings(max_examples=25, deadline=None)
@given(arrays(np.float64, (2, 48), elements=st.floats(-3.5, 3.5)), arrays(np.float64, 3, elements=st.floats(-3, 3)))
def test_global_rotation_composes_with_any_pose(pose, rv):
    """forward(R0 * pose) = R0 applied about the wrist to forward(pose) with the same finger pose."""
    m = tube_hand(seed=1)
    base = pose.copy()
    base[:, :3] = 0
    turned = base.copy()
    turned[:, :3] = rv
    j0 = (m.J_regressor @ m.v_template)[0]
    R = Rotation.from_rotvec(rv).as_matrix()
    a = forward(m, base).vertices
    b = forward(m, turned).vertices
    np.testing.assert_allclose(b, (a - j0) @ R.T + j0, atol=1e-12)


def test_a_finger_joint_moves_only_its_subtree(model):
    pose = np.zeros((16, 3))
    pose[2] = [0.0, 0.0, 1.0]  # index2
    out = forward(model, pose[None], correctives=False).vertices[0]
    moved = np.linalg.norm(out - model.v_template, axis=1) > 1e-12
    influenced = model.weights[:, [2, 3]].sum(1) > 0
    assert moved.any()
    assert not (moved & ~influenced).any()


def test_pose_layouts_agree(model):
    rng = np.random.default_rng(1)
    p = rng.normal(size=(3, 48))
    a = forward(model, p).vertices
    np.testing.assert_array_equal(a, forward(model, p.reshape(3, 16, 3)).vertices)
    # BLAS kernels differ by batch size
    np.testing.assert_allclose(a[1:2], forward(model, p[1]).vertices, rtol=0, atol=1e-15)


def test_float32_close_to_float64(model):
    rng = np.random.default_rng(2)
    p = rng.uniform(-np.pi, np.pi, (64, 48))
    a = forward(model, p, dtype=np.float64).vertices
    b = forward(model, p, dtype=np.float32)
    assert b.vertices.dtype == np.float32 and b.transforms.dtype == np.float32
    assert np.abs(a - b.vertices).max() < 1e-6


def test_flat_hand_mean_adds_hands_mean(model):
    p = np.random.default_rng(3).normal(size=48)
    with_mean = p.copy()
    with_mean[3:] += model.hands_mean
    np.testing.assert_allclose(forward(model, p, flat_hand_mean=False).vertices,
                               forward(model, with_mean).vertices, atol=1e-14)


def test_pca_pose_with_all_components_equals_axis_angle(model):
    rng = np.random.default_rng(4)
    coeffs = rng.normal(size=(2, 45))
    fingers = coeffs @ model.hands_components
    root = rng.normal(size=(2, 3))
    a = forward(model, np.concatenate([root, coeffs], 1), ncomps=45).vertices
    b = forward(model, np.concatenate([root, fingers], 1)).vertices
    np.testing.assert_allclose(a, b, atol=1e-13)
    few = forward(model, np.concatenate([root, coeffs[:, :6]], 1), ncomps=6).vertices
    np.testing.assert_allclose(few, forward(model, np.concatenate([root, coeffs[:, :6] @ model.hands_components[:6]],
                                                                  1)).vertices, atol=1e-13)


def test_betas_shape_joints_from_the_shaped_template(model):
    betas = np.array([[1.0, -2.0, 0.5, 0.0]])
    out = forward(model, np.zeros((1, 48)), betas)
    shaped = model.v_template + model.shapedirs @ betas[0]
    np.testing.assert_allclose(out.vertices[0], shaped, atol=1e-15)
    np.testing.assert_allclose(out.joints[0], model.J_regressor @ shaped, atol=1e-15)


def test_translation_and_keypoint_orders(model):
    p = np.random.default_rng(5).normal(size=(2, 48))
    t = np.array([0.1, -0.2, 0.3])
    a = forward(model, p)
    b = forward(model, p, trans=t, keypoint_order="openpose")
    np.testing.assert_allclose(b.vertices, a.vertices + t, atol=1e-15)
    mano = np.concatenate([a.joints, a.vertices[:, model.tip_ids]], 1)
    np.testing.assert_array_equal(a.keypoints, mano)
    np.testing.assert_allclose(b.keypoints, mano[:, KEYPOINT_ORDERS["openpose"]] + t, atol=1e-15)
    # FreiHAND order: wrist, thumb root..tip, index root..tip, ...
    assert KEYPOINT_ORDERS["openpose"][:5].tolist() == [0, 13, 14, 15, 16]
    assert KEYPOINT_ORDERS["openpose"][-4:].tolist() == [7, 8, 9, 20]


def test_transforms_move_bound_points_rigidly(model):
    """G_i maps a rest point bound to joint i to its posed position: here the posed joint centres themselves."""
    p = np.random.default_rng(6).normal(size=(3, 48))
    out = forward(model, p)
    J = model.J_regressor @ model.v_template
    moved = np.einsum("bjik,jk->bji", out.transforms[:, :, :3, :3], J) + out.transforms[:, :, :3, 3]
    np.testing.assert_allclose(moved, out.joints, atol=1e-14)
    np.testing.assert_allclose(out.world_rotations @ out.world_rotations.transpose(0, 1, 3, 2),
                               np.broadcast_to(np.eye(3), (3, 16, 3, 3)), atol=1e-13)


@pytest.mark.parametrize("bad, where", [(np.nan, "[0, 17]"), (np.inf, "[0, 17]"), (-np.inf, "[0, 17]")])
def test_non_finite_pose_rejected_with_index(model, bad, where):
    p = np.zeros((2, 48))
    p[0, 17] = bad
    with pytest.raises(InputError, match=r"pose.*" + where.replace("[", r"\[").replace("]", r"\]")):
        forward(model, p)


@pytest.mark.parametrize("pose, kw", [
    (np.zeros((2, 47)), {}), (np.zeros((2, 16, 2)), {}), (np.zeros((2, 10)), {"ncomps": 6}),
    (np.zeros((2, 9)), {"ncomps": 46}), (np.array(["a"] * 48), {}),
])
def test_bad_pose_shapes_rejected(model, pose, kw):
    with pytest.raises(InputError):
        forward(model, pose, **kw)


def test_bad_betas_and_dtype_rejected(model):
    with pytest.raises(InputError, match="betas"):
        forward(model, np.zeros(48), np.zeros(9))
    with pytest.raises(InputError, match="betas"):
        forward(model, np.zeros(48), [np.nan])
    with pytest.raises(InputError, match="dtype"):
        forward(model, np.zeros(48), dtype=np.float16)


def test_empty_batch(model):
    out = forward(model, np.zeros((0, 48)))
    assert out.vertices.shape == (0, model.num_vertices, 3) and out.keypoints.shape == (0, 21, 3)
