"""Pose correctives fitted to DQS: exact un-skinning, exact recovery, and the candy wrapper on a cylinder."""

from pathlib import Path

import numpy as np
import pytest

from darthand.model.dqs import dqs
from darthand.model.forward import forward
from darthand.model.layout import NUM_JOINTS, NUM_POSE_FEATURES
from darthand.model.npz_io import load_npz
from darthand.template.correctives import (feature_masks, fit_pose_correctives, rest_offsets,
                                          solve_correctives)
from synthetic import CYL_RADIUS as RADIUS, CYL_RINGS as N_RINGS
from synthetic import RING, tube_hand, two_bone_cylinder

OPEN_TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template" / "open_right.npz"
TWIST_LIMIT = np.deg2rad(150)


def twists(model, n, rng):
    """Poses twisting joint 1 about the cylinder axis by up to +-150 deg."""
    p = np.zeros((n, 48))
    p[:, 3] = rng.uniform(-TWIST_LIMIT, TWIST_LIMIT, n)
    return p


def radius_loss(model, poses, correctives):
    """Mean over poses and tube vertices of (1 cm - distance from the axis), metres."""
    side = np.arange(N_RINGS * RING)
    v = forward(model, poses, correctives=correctives).vertices[:, side]
    return float((RADIUS - np.linalg.norm(v[..., 1:], axis=-1)).mean())


def test_rest_offsets_take_lbs_exactly_onto_dqs():
    """LBS of the rest shape plus the offsets, with the same joint transforms, lands on DQS."""
    m = tube_hand(0)
    poses = np.random.default_rng(0).normal(0, 0.4, (3, 48))
    features, offsets = rest_offsets(m, poses)
    posed = forward(m, poses, correctives=False)
    np.testing.assert_allclose(features, (posed.rotations[:, 1:] - np.eye(3)).reshape(3, -1), atol=0)
    # skin v + o directly: sum_j w_j G_j [v + o, 1]
    rest = np.concatenate([m.v_template[None] + offsets, np.ones((3, m.num_vertices, 1))], axis=-1)
    skinned = np.einsum("vj,bjkl,bvl->bvk", m.weights, posed.transforms[:, :, :3, :], rest)
    np.testing.assert_allclose(skinned, dqs(m, poses), atol=1e-12)


def test_solve_recovers_known_correctives_full_and_restricted():
    rng = np.random.default_rng(1)
    m = tube_hand(2)
    V, K = m.num_vertices, NUM_POSE_FEATURES
    masks = feature_masks(m.replace(weights=np.where(m.weights > 0.05, m.weights, 0)), min_weight=0.0)
    truth = rng.normal(0, 1e-3, (V, 3, K)) * masks[:, None, :]
    F = rng.normal(0, 1, (400, K))
    O = np.einsum("vck,sk->svc", truth, F)
    FtF, FtO = F.T @ F, np.einsum("sk,svc->kvc", F, O)
    np.testing.assert_allclose(solve_correctives(FtF, FtO, 0.0), truth, atol=1e-12)
    restricted = solve_correctives(FtF, FtO, 0.0, masks)
    np.testing.assert_allclose(restricted, truth, atol=1e-12)
    assert not restricted[~np.broadcast_to(masks[:, None, :], truth.shape)].any()


def test_feature_masks_follow_the_paths_between_weighted_joints():
    """A vertex's target depends on the local rotations between its weighted joints, up to their common
    ancestor (excluded): e.g. weights on the wrist and thumb MCP need thumb CMC and MCP, not the thumb IP."""
    m = tube_hand(0)
    cases = {(0, 14): {13, 14}, (2, 3): {3}, (1, 4): {1, 4}, (5,): set(), (3, 6): {1, 2, 3, 4, 5, 6},
             (0, 13, 14): {13, 14}, (10, 11, 12): {11, 12}}
    weights = np.zeros((m.num_vertices, NUM_JOINTS))
    weights[:, 0] = 1
    for v, joints in enumerate(cases):
        weights[v] = 0
        weights[v, list(joints)] = 1 / len(joints)
    masks = feature_masks(m.replace(weights=weights))
    for v, expected in enumerate(cases.values()):
        used = {j + 1 for j in range(15) if masks[v, 9 * j:9 * j + 9].all()}
        assert used == expected and masks[v].sum() == 9 * len(expected)
    assert not masks[len(cases):].any()


def test_hard_weights_need_no_correctives():
    """With one joint per vertex DQS is LBS, so the fit must return (nearly) zero correctives."""
    m = tube_hand(3)
    hard = np.zeros_like(m.weights)
    hard[np.arange(m.num_vertices), m.weights.argmax(1)] = 1
    m = m.replace(weights=hard)
    posedirs, report = fit_pose_correctives(m, n_train=60, n_test=20, seed=0, ridge=1e-6, restrict=False)
    assert np.abs(posedirs).max() < 1e-12
    assert report["lbs_max_mm"] < 1e-9 and report["corrected_max_mm"] < 1e-9


def test_fit_undoes_most_of_the_candy_wrapper_on_a_twisted_cylinder():
    m = two_bone_cylinder()
    posedirs, report = fit_pose_correctives(m, n_train=200, n_test=100, seed=0, sampler=twists)
    assert posedirs.shape == (m.num_vertices, 3, NUM_POSE_FEATURES)
    assert report["corrected_mean_mm"] < 0.7 * report["lbs_mean_mm"]
    held_out = twists(m, 100, np.random.default_rng(99))
    fitted = m.replace(posedirs=posedirs)
    lbs_loss, corrected_loss = radius_loss(m, held_out, False), radius_loss(fitted, held_out, True)
    # LBS loses r (1 - |w0 + w1 e^{i theta}|) on the blend rings; DQS keeps the radius (loss 0)
    assert lbs_loss > 1e-4
    assert abs(corrected_loss) < 0.35 * lbs_loss


def test_fit_is_deterministic_per_seed():
    m = two_bone_cylinder()
    a, ra = fit_pose_correctives(m, n_train=50, n_test=10, seed=3, ridge=1e-4, restrict=True, sampler=twists)
    b, rb = fit_pose_correctives(m, n_train=50, n_test=10, seed=3, ridge=1e-4, restrict=True, sampler=twists)
    np.testing.assert_array_equal(a, b)
    assert ra["corrected_mean_mm"] == rb["corrected_mean_mm"]


@pytest.mark.slow
@pytest.mark.skipif(not OPEN_TEMPLATE.is_file(), reason="open hand template not built yet")
def test_open_hand_fit_reduces_held_out_error():
    model = load_npz(OPEN_TEMPLATE)
    _, report = fit_pose_correctives(model, n_train=600, n_test=100, seed=1)
    assert report["corrected_mean_mm"] < 0.6 * report["lbs_mean_mm"]
    assert report["corrected_max_mm"] < report["lbs_max_mm"]
