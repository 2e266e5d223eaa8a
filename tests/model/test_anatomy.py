"""Anatomical pose space: frames, conversion round trips, flexion sign, limits, mirror symmetry."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from darthand.errors import InputError
from darthand.model import anatomy
from darthand.model.forward import forward
from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS, FINGERS, JOINT_NAMES, NUM_JOINTS
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.model.npz_io import load_npz
from synthetic import tube_hand

OPEN_TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template" / "open_right.npz"
FINGER_CHAIN_JOINTS = [j for f in FINGERS for j in FINGER_JOINTS[f]]
PALM_BEND_JOINTS = [j for j in FINGER_CHAIN_JOINTS if j not in (14, 15)]   # thumb MCP/IP flex toward the pad
TUBE = tube_hand(0)
TUBE_LEFT = mirror_model(TUBE)


def models():
    out = [pytest.param(TUBE, id="tube"), pytest.param(TUBE_LEFT, id="tube-left")]
    if OPEN_TEMPLATE.is_file():
        out.append(pytest.param(load_npz(OPEN_TEMPLATE), id="open"))
    return out


def rot(axis: str, a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


within_limits_fractions = arrays(np.float64, (NUM_JOINTS, 3), elements=st.floats(0, 1))


def angles_from_fractions(u: np.ndarray) -> np.ndarray:
    lim = anatomy.limits_radians()
    return lim[..., 0] + u * (lim[..., 1] - lim[..., 0])


@pytest.mark.parametrize("model", models())
def test_frames_are_orthonormal_and_right_handed(model):
    F = anatomy.joint_frames(model)
    np.testing.assert_allclose(F.transpose(0, 2, 1) @ F, np.broadcast_to(np.eye(3), F.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(F), 1.0, atol=1e-12)


@pytest.mark.parametrize("model", models())
def test_twist_axis_follows_the_bone_and_bend_is_perpendicular_to_the_palm_normal(model):
    F = anatomy.joint_frames(model)
    joints = model.J_regressor @ model.v_template
    n = anatomy.palm_normal(model)
    sign = -1 if model.side == "left" else 1
    for finger, tip in zip(FINGERS, model.tip_ids):
        chain = FINGER_JOINTS[finger]
        ends = list(joints[list(chain[1:])]) + [model.v_template[tip]]
        for j, end in zip(chain, ends):
            bone = (end - joints[j]) / np.linalg.norm(end - joints[j])
            np.testing.assert_allclose(sign * F[j, :, 0], bone, atol=1e-12)
            if j not in (14, 15):
                assert abs(F[j, :, 2] @ n) < 1e-12
    assert n[1] < 0  # the palm faces -Y in MANO's frame, for either hand


def test_angles_to_matrix_is_bend_spread_twist_about_the_frame_axes():
    rng = np.random.default_rng(0)
    for twist, spread, bend in rng.uniform(-1.5, 1.5, (20, 3)):
        expected = rot("z", bend) @ rot("y", spread) @ rot("x", twist)
        np.testing.assert_allclose(anatomy.angles_to_matrix([twist, spread, bend]), expected, atol=1e-14)


@settings(max_examples=60, deadline=None)
@given(within_limits_fractions, st.sampled_from(["right", "left"]))
def test_round_trip_angles_axis_angle_angles(u, side):
    model = TUBE if side == "right" else TUBE_LEFT
    angles = angles_from_fractions(u)
    aa = anatomy.angles_to_axis_angle(model, angles)
    np.testing.assert_allclose(anatomy.axis_angle_to_angles(model, aa), angles, atol=1e-10)
    # and the rotation is F R_local F^T, built here from explicit matrices
    F = anatomy.joint_frames(model)
    j = 2
    t, s, b = angles[j]
    expected = F[j] @ rot("z", b) @ rot("y", s) @ rot("x", t) @ F[j].T
    R = forward(model, aa.reshape(1, 48)).rotations[0, j]
    np.testing.assert_allclose(R, expected, atol=1e-12)


def test_axis_angle_to_angles_accepts_flat_vectors_and_rejects_bad_shapes():
    aa = anatomy.sample_poses(TUBE, 3, np.random.default_rng(1))
    assert anatomy.axis_angle_to_angles(TUBE, aa).shape == (3, 16, 3)
    with pytest.raises(InputError, match="pose"):
        anatomy.axis_angle_to_angles(TUBE, np.zeros((3, 47)))
    with pytest.raises(InputError, match="angles"):
        anatomy.angles_to_axis_angle(TUBE, np.full((16, 3), np.nan))


def bend_displacement(model, joint, degrees=30.0):
    """(3,) displacement of the joint's bone end, carried rigidly by the joint, under a positive bend, and the
    bone length."""
    angles = np.zeros((1, NUM_JOINTS, 3))
    angles[0, joint, 2] = np.deg2rad(degrees)
    aa = anatomy.angles_to_axis_angle(model, angles).reshape(1, 48)
    G = forward(model, aa).transforms[0, joint]
    end = anatomy.bone_ends(model)[joint]
    return G[:3, :3] @ end + G[:3, 3] - end, np.linalg.norm(end - (model.J_regressor @ model.v_template)[joint])


@pytest.mark.parametrize("model", models())
@pytest.mark.parametrize("joint", PALM_BEND_JOINTS, ids=[JOINT_NAMES[j] for j in PALM_BEND_JOINTS])
def test_positive_bend_curls_the_bone_toward_the_palm(model, joint):
    """The bone's end point moves toward the palm (-Y) under a positive bend."""
    moved, length = bend_displacement(model, joint)
    assert moved[1] < -0.4 * length * np.sin(np.deg2rad(30))


@pytest.mark.skipif(not OPEN_TEMPLATE.is_file(), reason="open hand template not built yet")
@pytest.mark.parametrize("joint", [14, 15], ids=["thumb2", "thumb3"])
def test_positive_thumb_bend_curls_toward_the_thumb_pad(joint):
    """Thumb MCP/IP flexion moves the thumb away from its nail (toward its pad), on the open hand, on a copy
    without face labels (which falls back to a fixed roll of the palm normal) and on the left mirror image."""
    model = load_npz(OPEN_TEMPLATE)
    dominant = np.argmax(model.weights[model.faces].sum(1), axis=1)
    nails = (model.face_labels == FACE_LABEL_IDS["nail"]) & np.isin(dominant, FINGER_JOINTS["thumb"])
    v = model.v_template[model.faces[nails]]
    nail_normal = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]).sum(0)
    nail_normal /= np.linalg.norm(nail_normal)
    for m in (model, model.replace(face_labels=None), mirror_model(model)):
        if m.side == "left":
            nail_normal = nail_normal * [-1, 1, 1]  # mirrored once, for the last model
        moved, length = bend_displacement(m, joint)
        assert moved @ nail_normal < -0.8 * length * np.sin(np.deg2rad(30))


@pytest.mark.skipif(not OPEN_TEMPLATE.is_file(), reason="open hand template not built yet")
@pytest.mark.parametrize("joint", [j for j in FINGER_CHAIN_JOINTS if j < 13],
                         ids=[JOINT_NAMES[j] for j in FINGER_CHAIN_JOINTS if j < 13])
def test_mano_flexion_vector_curls_the_open_hand_like_mano(joint):
    """MANO's flexion of a finger joint is a positive rotation about +Z (fingers along -X, palm -Y); the same
    pose vector must curl the open hand's finger toward the palm, and its anatomical bend axis must be close
    to +Z."""
    model = load_npz(OPEN_TEMPLATE)
    pose = np.zeros((1, 16, 3))
    pose[0, joint] = [0, 0, np.deg2rad(40)]
    G = forward(model, pose).transforms[0, joint]
    end = anatomy.bone_ends(model)[joint]
    assert (G[:3, :3] @ end + G[:3, 3] - end)[1] < 0
    assert anatomy.joint_frames(model)[joint, 2, 2] > 0.8


@pytest.mark.parametrize("model", [m for m in models() if m.values[0].side == "right"])
def test_same_angles_give_the_mirror_image_on_the_left_hand(model):
    mirrored = mirror_model(model)
    angles = anatomy.sample_angles(5, np.random.default_rng(2), include_root=True)
    right = anatomy.angles_to_axis_angle(model, angles)
    left = anatomy.angles_to_axis_angle(mirrored, angles)
    np.testing.assert_allclose(left, mirror_pose(right), atol=1e-12)
    v_right = forward(model, right.reshape(5, 48)).vertices
    v_left = forward(mirrored, left.reshape(5, 48)).vertices
    np.testing.assert_allclose(v_left, v_right * [-1, 1, 1], atol=1e-12)


def test_limits_contain_the_rest_pose_and_samples_stay_inside():
    lim = anatomy.limits_radians()
    assert (lim[..., 0] <= 0).all() and (lim[..., 1] >= 0).all() and (lim[..., 0] < lim[..., 1]).all()
    poses = anatomy.sample_poses(TUBE, 200, np.random.default_rng(3))
    angles = anatomy.axis_angle_to_angles(TUBE, poses)
    assert anatomy.within_limits(angles, tol=1e-9).all()
    np.testing.assert_array_equal(poses[:, :3], 0)
    half = anatomy.axis_angle_to_angles(TUBE, anatomy.sample_poses(TUBE, 200, np.random.default_rng(3), scale=0.5))
    assert (np.abs(half) <= 0.5 * np.abs(lim).max(-1) + 1e-9).all()
    with_root = anatomy.sample_angles(50, np.random.default_rng(4), include_root=True)
    assert np.abs(with_root[:, 0]).max() > 0


def test_sampling_is_deterministic_per_generator_seed():
    a = anatomy.sample_poses(TUBE, 4, np.random.default_rng([7, 1]))
    b = anatomy.sample_poses(TUBE, 4, np.random.default_rng([7, 1]))
    np.testing.assert_array_equal(a, b)
