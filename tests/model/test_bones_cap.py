"""Oriented bones (model/bones.py) and the forearm cap (model/cap.py).

Truth: scipy's rotations and a kinematic chain written here the way DCC tools compose bones (world = parent world
x rest offset x local rotation), topology counted by brute force, and `forward` for the posed cap rim.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from synthetic import tube_hand

from darthand.model import bones
from darthand.model.anatomy import bone_ends, palm_normal, rest_joints
from darthand.model.cap import forearm_cap
from darthand.model.forward import forward
from darthand.model.load import TEMPLATE_DIR, load_model
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.model.wrist import add_wrist


@pytest.fixture(scope="module", params=["tube", "open"])
def model(request):
    if request.param == "open":
        if not (TEMPLATE_DIR / "open_right.npz").is_file():
            pytest.skip("assets_src/template/open_right.npz is not in this checkout")
        return add_wrist(load_model("open"))
    return add_wrist(tube_hand(1))


def test_bone_frames_are_rotations_with_y_along_the_bone(model):
    O = bones.bone_frames(model)
    np.testing.assert_allclose(np.swapaxes(O, 1, 2) @ O, np.broadcast_to(np.eye(3), O.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(O), 1.0, atol=1e-12)
    J = rest_joints(model)
    d = bone_ends(model) - J
    np.testing.assert_allclose(O[:, :, 1], d / np.linalg.norm(d, axis=1, keepdims=True), atol=1e-12)
    np.testing.assert_allclose(bones.bone_lengths(model), np.linalg.norm(d, axis=1), atol=1e-15)


def test_positive_x_rotation_curls_fingers_toward_the_palm(model):
    """A finger bone turned by +30 degrees about its own X: its tip moves toward the palm side (-Y, the palm
    normal), on the right hand and on the mirrored left hand."""
    for m in (model, mirror_model(model)):
        O = bones.bone_frames(m)
        n = palm_normal(m)
        for j in (1, 2, 4, 5, 7, 10):
            turned = O[j] @ Rotation.from_rotvec([np.radians(30), 0, 0]).as_matrix() @ np.array([0, 1.0, 0])
            assert (turned - O[j][:, 1]) @ n > 0.1, (m.side, j)


def test_conversion_round_trips_and_matches_a_bone_chain(model):
    """bone_rotations / mano_pose invert each other; composing the bones as Blender does (world_i = world_parent
    (O_parent^T O_i) Q_i, from scipy) gives MANO's accumulated rotation times the rest frame."""
    rng = np.random.default_rng(3)
    pose = rng.normal(0, 0.5, (5, 48))
    O = bones.bone_frames(model)
    Q = bones.bone_rotations(pose, O)
    np.testing.assert_allclose(Rotation.from_matrix(
        bones.mano_rotations(Q, O).reshape(-1, 3, 3)).as_rotvec().reshape(5, 48), pose, atol=1e-9)
    np.testing.assert_allclose(bones.mano_pose(Q, O), pose, atol=1e-9)
    R = Rotation.from_rotvec(pose.reshape(-1, 3)).as_matrix().reshape(5, 16, 3, 3)
    parents = model.parents
    for b in range(5):
        world_bone, world_mano = np.zeros((16, 3, 3)), np.zeros((16, 3, 3))
        for i in range(16):
            p = parents[i]
            if p < 0:
                world_bone[i], world_mano[i] = O[i] @ Q[b, i], R[b, i]
            else:
                world_bone[i] = world_bone[p] @ (O[p].T @ O[i]) @ Q[b, i]
                world_mano[i] = world_mano[p] @ R[b, i]
        np.testing.assert_allclose(world_bone, world_mano @ O, atol=1e-12)
    np.testing.assert_allclose(bones.node_rotations(R, O, parents),
                               bones.rest_node_rotations(O, parents) @ Q, atol=1e-12)


def test_left_hand_bones_are_the_mirror_image(model):
    left = mirror_model(model)
    S = np.diag([-1.0, 1.0, 1.0])
    OR, OL = bones.bone_frames(model), bones.bone_frames(left)
    np.testing.assert_allclose(OL[:, :, 1], (S @ OR)[:, :, 1], atol=1e-12)       # along the mirrored bone
    np.testing.assert_allclose(OL[:, :, 0], -(S @ OR)[:, :, 0], atol=1e-12)      # flexion axis: det(S) S x
    pose = np.random.default_rng(4).normal(0, 0.4, (3, 48))
    # the same bone rotations pose the mirror image (flexion stays flexion)
    np.testing.assert_allclose(bones.bone_rotations(mirror_pose(pose), OL),
                               bones.bone_rotations(pose, OR) * np.array([[1, -1, -1], [-1, 1, 1], [-1, 1, 1]]),
                               atol=1e-12)


# ------------------------------------------------------------------------------------------------ the cap


def test_cap_closes_the_hand_without_renumbering_it(model):
    cap = forearm_cap(model)
    V = model.num_vertices
    # merge each loop copy with the hand vertex it copies: the union is closed, manifold and consistently wound
    merged = np.concatenate([cap.loop, [V]])[cap.faces]
    faces = np.concatenate([model.faces, merged])
    directed = Counter(map(tuple, np.stack([faces, np.roll(faces, -1, 1)], -1).reshape(-1, 2).tolist()))
    assert all(directed[(b, a)] == 1 for (a, b) in directed), "an edge is open or wound twice the same way"
    verts = np.concatenate([model.v_template, cap.vertices[-1:]])
    a, b, c = (verts[faces[:, k]] for k in range(3))
    assert np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6 > 0                 # outward: positive volume
    np.testing.assert_array_equal(cap.vertices[:-1], model.v_template[cap.loop])
    assert cap.weights.shape == (len(cap.loop) + 1, 16) and np.allclose(cap.weights.sum(1), 1)


def test_posed_cap_rim_stays_on_the_hand(model):
    rng = np.random.default_rng(5)
    pose = rng.normal(0, 0.6, (4, 48))
    betas = rng.normal(0, 1, (4, model.num_betas)) if model.num_betas else None
    posed = forward(model, pose, betas)
    rim = forearm_cap(model).pose(posed, betas)
    cap = forearm_cap(model)
    np.testing.assert_allclose(rim[:, :len(cap.loop)], posed.vertices[:, cap.loop], atol=1e-12)
