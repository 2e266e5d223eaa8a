"""DART wrist alignment invariants and right/left mirroring."""

import numpy as np
import pytest
import scipy.sparse as sp

from darthand.errors import InputError
from darthand.model.forward import forward
from darthand.model.layout import FACE_LABEL_IDS
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.model.topology import (boundary_loops, close_loops, inconsistent_edges, non_manifold_edges,
                                     signed_volume)
from darthand.model.wrist import add_wrist, default_anchor, wrist_loop
from synthetic import tube_hand


@pytest.fixture(scope="module")
def base():
    return tube_hand(seed=7, corrective_scale=5e-3)


@pytest.fixture(scope="module")
def enhanced(base):
    return add_wrist(base)


def test_counts_match_dart(base, enhanced):
    # A 16-vertex opening gains 4 rings of 16 and 128 faces, as MANO's 778/1538 -> 842/1666.
    assert enhanced.num_vertices == base.num_vertices + 64
    assert enhanced.num_faces == base.num_faces + 128
    np.testing.assert_array_equal(enhanced.faces[:base.num_faces], base.faces)
    np.testing.assert_array_equal(enhanced.v_template[:base.num_vertices], base.v_template)


def test_first_vertices_pose_exactly_as_before(base, enhanced):
    rng = np.random.default_rng(0)
    poses = rng.uniform(-np.pi, np.pi, (32, 48))
    betas = rng.standard_normal((32, 4))
    a = forward(base, poses, betas)
    b = forward(enhanced, poses, betas)
    np.testing.assert_allclose(b.vertices[:, :base.num_vertices], a.vertices, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.joints, a.joints, rtol=0, atol=1e-12)


def test_alignment_of_weights_correctives_regressor(base, enhanced):
    V = base.num_vertices
    anchor = enhanced.meta["wrist"]["anchor"]
    np.testing.assert_array_equal(enhanced.weights[V:], np.tile(base.weights[anchor], (64, 1)))
    assert not enhanced.posedirs[V:].any()
    assert sp.csr_matrix(enhanced.J_regressor)[:, V:].nnz == 0


def test_topology_one_forearm_loop_manifold_consistent(base, enhanced):
    loops = boundary_loops(enhanced.faces)
    assert [len(lp) for lp in loops] == [16]
    assert set(loops[0].tolist()) <= set(range(base.num_vertices, enhanced.num_vertices))
    assert len(non_manifold_edges(enhanced.faces)) == 0
    assert len(inconsistent_edges(enhanced.faces)) == 0
    assert signed_volume(*close_loops(enhanced.v_template, enhanced.faces)) > signed_volume(
        *close_loops(base.v_template, base.faces)) > 0


def test_rings_extend_along_the_forearm(base, enhanced):
    """The tube's opening faces +X, so the rings go +X, one length step per ring, the last one planar."""
    V = base.num_vertices
    rings = enhanced.v_template[V:].reshape(4, 16, 3)
    x = rings[:, :, 0].mean(1)
    assert np.all(np.diff(np.concatenate([[base.v_template[wrist_loop(base), 0].mean()], x])) > 0)
    assert np.ptp(rings[-1, :, 0]) < 1e-12


def test_uvs_labels_for_new_faces(base, enhanced):
    F = base.num_faces
    assert enhanced.faces_uv.shape == enhanced.faces.shape
    new_uv = enhanced.uvs[enhanced.faces_uv[F:]]
    assert np.all((new_uv >= 0) & (new_uv <= 1))
    assert np.all(enhanced.face_labels[F:] == FACE_LABEL_IDS["wrist"])
    # The new UV rectangle does not overlap the (rescaled) hand UVs.
    hand_uv = enhanced.uvs[np.unique(enhanced.faces_uv[:F])]
    assert new_uv[..., 1].min() >= hand_uv[:, 1].max() - 1e-12


def test_smooth_mode_blends_to_the_root(base):
    m = add_wrist(base, smooth=True)
    V = base.num_vertices
    w = m.weights[V:].reshape(4, 16, 16)
    np.testing.assert_allclose(w.sum(-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(w[-1], np.eye(16)[[0] * 16], atol=1e-15)
    assert np.all(np.diff(w[:, :, 0].mean(1)) >= 0)


def test_parameters(base):
    m = add_wrist(base, rings=2, length=0.05, taper=0.8)
    V = base.num_vertices
    assert m.num_vertices == V + 32
    end = m.v_template[V + 16:]
    loop_pts = base.v_template[wrist_loop(base)]
    assert end[:, 0].mean() - loop_pts[:, 0].mean() == pytest.approx(0.05, abs=1e-3)
    r_end = np.linalg.norm(end[:, 1:] - end[:, 1:].mean(0), axis=1).mean()
    r_loop = np.linalg.norm(loop_pts[:, 1:] - loop_pts[:, 1:].mean(0), axis=1).mean()
    assert r_end / r_loop == pytest.approx(0.8, rel=1e-6)
    with pytest.raises(InputError, match="anchor"):
        add_wrist(base, anchor=10 ** 6)
    with pytest.raises(InputError, match="rings"):
        add_wrist(base, rings=0)


def test_mano_anchor_default():
    class Fake:
        num_vertices = 778
    assert default_anchor(Fake(), np.arange(16)) == 777


def test_closed_mesh_has_no_wrist(enhanced):
    closed_v, closed_f = close_loops(enhanced.v_template, enhanced.faces)
    closed = enhanced.replace(v_template=closed_v, faces=closed_f,
                              weights=np.vstack([enhanced.weights, enhanced.weights[:1]]),
                              posedirs=np.vstack([enhanced.posedirs, enhanced.posedirs[:1]]),
                              shapedirs=np.vstack([enhanced.shapedirs, enhanced.shapedirs[:1]]),
                              J_regressor=sp.hstack([enhanced.J_regressor, sp.csr_matrix((16, 1))]),
                              uvs=None, faces_uv=None, face_labels=None)
    with pytest.raises(InputError, match="no boundary loop"):
        add_wrist(closed)


def test_mirrored_pose_on_mirrored_model_gives_mirrored_vertices(enhanced):
    left = mirror_model(enhanced)
    assert left.side == "left"
    rng = np.random.default_rng(1)
    poses = rng.uniform(-np.pi, np.pi, (16, 48))
    betas = rng.standard_normal((16, 4))
    r = forward(enhanced, poses, betas, flat_hand_mean=False)
    l = forward(left, mirror_pose(poses), betas, flat_hand_mean=False)
    M = np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(l.vertices, r.vertices * M, atol=1e-12)
    np.testing.assert_allclose(l.keypoints, r.keypoints * M, atol=1e-12)
    # Outward winding survives the reflection.
    assert signed_volume(*close_loops(left.v_template, left.faces)) > 0


def test_mirror_twice_is_identity(enhanced):
    back = mirror_model(mirror_model(enhanced))
    for name in ("v_template", "faces", "weights", "posedirs", "shapedirs", "hands_mean", "hands_components",
                 "uvs", "faces_uv"):
        np.testing.assert_array_equal(getattr(back, name), getattr(enhanced, name), err_msg=name)
    assert back.side == enhanced.side
    p = np.random.default_rng(2).normal(size=(3, 48))
    np.testing.assert_array_equal(mirror_pose(mirror_pose(p)), p)
    np.testing.assert_array_equal(mirror_pose(p.reshape(3, 16, 3)), mirror_pose(p).reshape(3, 16, 3))


def test_wrist_of_a_left_hand_is_the_mirror_of_the_right_hands(base):
    """A left source (MANO_LEFT.pkl) gets the wrist its right image would: the new vertices in the same order,
    faces and UV faces wound as the mirror winds them."""
    left = add_wrist(mirror_model(base))
    right = mirror_model(add_wrist(base))
    for name in ("v_template", "faces", "weights", "uvs", "faces_uv", "face_labels"):
        a, b = getattr(left, name), getattr(right, name)
        assert (a is None) == (b is None), name
        if a is not None:
            np.testing.assert_array_equal(a, b, err_msg=name)
    assert len(inconsistent_edges(left.faces)) == 0
