"""The realistic MANO-format fixture (the open hand remeshed to MANO's budget and re-rigged), checked against MANO's
published layout and against the hand it was made from; and what the model step makes of it on either side."""

from __future__ import annotations

import pickletools

import numpy as np
import pytest

from darthand.model.layout import MANO_PARENTS, MANO_TIP_IDS
from darthand.model.load import open_hand
from darthand.model.mano_pkl import LEFT_SHAPEDIRS_FIX, load_mano_pkl
from darthand.model.mirror import mirror_model
from darthand.model.regions import ensure_face_labels
from darthand.model.topology import boundary_loops, inconsistent_edges, non_manifold_edges
from darthand.model.wrist import add_wrist
from model.mano_fixture import mano_like_model, write_mano_like


@pytest.fixture(scope="module")
def pickles(tmp_path_factory):
    return write_mano_like(tmp_path_factory.mktemp("mano_like"))


def test_mesh_has_manos_counts_and_a_16_vertex_wrist_loop():
    m = mano_like_model()
    assert (m.num_vertices, m.num_faces) == (778, 1538)
    loops = boundary_loops(m.faces)
    assert [len(loop) for loop in loops] == [16]
    assert len(non_manifold_edges(m.faces)) == 0 and len(inconsistent_edges(m.faces)) == 0
    assert 777 in loops[0] and m.weights[777, 0] == m.weights[loops[0], 0].max()   # DART's anchor on the loop
    assert np.array_equal(m.tip_ids, MANO_TIP_IDS) and np.array_equal(m.parents, MANO_PARENTS)
    assert m.shapedirs.shape == (778, 3, 10) and m.hands_components.shape == (45, 45)
    np.testing.assert_allclose(m.hands_components @ m.hands_components.T, np.eye(45), atol=1e-10)


def test_rig_is_the_source_hands_rig():
    """Every vertex is a vertex of the open hand, with its weights and correctives; the regressed joints are the
    open hand's joints; the tips are where the open hand's are (within the remesh's spacing)."""
    m, src = mano_like_model(), open_hand("right")
    dist = np.linalg.norm(m.v_template[:, None] - src.v_template[None], axis=2)
    match = dist.argmin(1)
    assert dist.min(1).max() == 0.0
    np.testing.assert_array_equal(m.weights, src.weights[match])
    np.testing.assert_array_equal(m.posedirs, src.posedirs[match])
    np.testing.assert_array_equal(m.shapedirs, src.shapedirs[match])
    joints = np.asarray(m.J_regressor @ m.v_template)
    np.testing.assert_allclose(joints, src.J_regressor @ src.v_template, atol=0.1e-3)
    assert (m.J_regressor.data > 0).all()
    assert np.linalg.norm(m.v_template[m.tip_ids] - src.v_template[src.tip_ids], axis=1).max() < 3e-3


def test_pickles_are_laid_out_like_manos(pickles):
    right, left = pickles
    ops = {op.name for op, _, _ in pickletools.genops(right.read_bytes())}
    assert "PROTO" in ops and b"chumpy.ch\nCh" in right.read_bytes() and b"scipy.sparse.csc" in right.read_bytes()
    r, lf = load_mano_pkl(right), load_mano_pkl(left)
    assert (r.side, lf.side) == ("right", "left")
    assert not r.has_uvs and r.face_labels is None
    assert r.meta["fixes"] == [] and lf.meta["fixes"] == [LEFT_SHAPEDIRS_FIX]
    assert lf.meta["shapedirs_check"].startswith("x sign disagreed")       # found by the size test, not assumed
    np.testing.assert_array_equal(r.v_template, mano_like_model().v_template)
    back = mirror_model(lf)
    for name in ("v_template", "weights", "posedirs", "shapedirs", "hands_mean", "hands_components", "tip_ids"):
        np.testing.assert_allclose(getattr(back, name), getattr(r, name), rtol=0, atol=1e-15, err_msg=name)
    assert abs(back.J_regressor - r.J_regressor).max() == 0


def test_model_step_labels_both_sides_alike(pickles):
    """The wrist (842 / 1666, DART's counts) and the face labels derived from geometry, from either pickle: a left
    source is labelled through its mirror image, so both get the same labels."""
    right, left = (add_wrist(load_mano_pkl(p)) for p in pickles)
    assert (right.num_vertices, right.num_faces) == (842, 1666)
    np.testing.assert_array_equal(right.weights[778:], np.tile(right.weights[777], (64, 1)))
    r, lf = ensure_face_labels(right).face_labels, ensure_face_labels(left).face_labels
    # (The mirror lists each face's corners in another order; a face whose centroid is equally near two bones
    # can round either way.)
    assert (r != lf).sum() <= 2
    counts = np.bincount(r, minlength=6)
    assert (counts > 0).all() and (r >= 0).all()       # nail, palm, dorsum, finger sides, wrist all present
    assert (r[1538:] == 5).all()                       # the wrist rings are wrist


def test_model_step_builds_the_same_hand_from_either_file(pickles, tmp_path):
    """`darthand model build` from MANO_LEFT.pkl (x-mirrored, shapedirs bug included) writes the same right and left
    models as from MANO_RIGHT.pkl: geometry, rig, shape space, labels and fitted gestures."""
    from darthand.cli import main
    from darthand.model.gestures import model_gestures
    from darthand.model.npz_io import load_npz

    built = {}
    for pkl in pickles:
        out = tmp_path / pkl.stem
        assert main(["model", "build", str(pkl), "--out-dir", str(out), "--atlas-res", "256"]) == 0
        built[pkl.stem] = {side: load_npz(out / f"{side}.npz") for side in ("right", "left")}
    for side in ("right", "left"):
        a, b = built["MANO_RIGHT"][side], built["MANO_LEFT"][side]
        assert a.side == b.side == side and (a.num_vertices, a.num_faces) == (842, 1666)
        for name in ("v_template", "weights", "posedirs", "shapedirs"):
            np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-15, err_msg=name)
        assert (a.face_labels != b.face_labels).sum() <= 2 and a.has_uvs and b.has_uvs
        ga, gb = model_gestures(a), model_gestures(b)
        assert ga.fitted and ga.names == gb.names
        np.testing.assert_allclose(ga.angles, gb.angles, atol=np.deg2rad(0.05))
