"""What an engine computes from the exported glTF equals what the rig computes.

Every file is written by `export_gltf`, read back from disk and evaluated with the independent evaluator of
test_gltf_reference (spec formulas, scipy rotations); the truth is `forward(model, pose)`. Pruned influences and
compressed correctives are checked against forward passes of models the tests prune / compress themselves.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from synthetic import tube_hand  # noqa: E402
from test_gltf_reference import GltfFile, global_matrices, posed_mesh, skinned_positions  # noqa: E402

from darthand.export.gltf_export import GltfOptions, export_gltf  # noqa: E402
from darthand.model.anatomy import sample_poses  # noqa: E402
from darthand.model.forward import forward  # noqa: E402
from darthand.model.wrist import add_wrist  # noqa: E402

TOL = 1e-5  # metres
MESH = "RightHand"


@pytest.fixture(scope="module")
def model():
    return add_wrist(tube_hand(3))


def gestures(model, n: int = 4, seed: int = 7):
    """Named test poses: random anatomical poses (with a wrist rotation) and one large hand-written pose."""
    rng = np.random.default_rng(seed)
    poses = sample_poses(model, n, rng, include_root=True)
    big = np.zeros(48)
    big[:3] = [0.4, -1.2, 0.7]
    big[3 * 13:3 * 14] = [0.3, 0.9, -0.5]
    big[3 * 2:3 * 3] = [0.0, 0.0, 1.4]
    return [f"g{i}" for i in range(n + 1)], np.concatenate([poses, big[None]])


def keep_top(weights: np.ndarray, k: int) -> np.ndarray:
    """Test's own pruning: zero all but the k largest weights per row, renormalise."""
    w = weights.copy()
    cut = np.sort(w, axis=1)[:, -k][:, None]
    rank = np.argsort(np.argsort(-w, axis=1, kind="stable"), axis=1)
    w[rank >= k] = 0
    assert (w[rank < k] >= 0).all() and (cut > 0).all()
    return w / w.sum(1, keepdims=True)


def engine_vertices(path, names, t=None):
    """{gesture: (N, 3) engine-evaluated vertices at the end of its clip}, and the file's vertex ids."""
    f = GltfFile(path)
    prim = f.doc.meshes[f.doc.nodes[f.node_index(MESH)].mesh].primitives[0]
    ids = f.attr(prim, "_VERTEX_ID")[:, 0].astype(int)
    end = f.accessor(f.doc.animations[0].samplers[0].input)[-1, 0] if t is None else t
    return {n: posed_mesh(f, MESH, n, end) for n in names}, ids, f


def max_error(engine: dict, ids, truth: np.ndarray, names) -> float:
    return max(float(np.linalg.norm(engine[n] - truth[i][ids], axis=1).max()) for i, n in enumerate(names))


def test_all_influences_and_full_correctives_match_the_rig(model, tmp_path):
    names, poses = gestures(model)
    assert ((model.weights > 0).sum(1) > 8).any(), "fixture must need more than 8 influences (JOINTS_2...)"
    out = tmp_path / "all.glb"
    report = export_gltf(model, out, options=GltfOptions(influences=None), gestures=(names, poses))
    engine, ids, f = engine_vertices(out, names)
    prim = f.doc.meshes[0].primitives[0]
    assert f.attr(prim, "JOINTS_3") is not None and f.attr(prim, "JOINTS_4") is None
    truth = forward(model, poses).vertices
    assert max_error(engine, ids, truth, names) <= TOL
    assert report.morph_targets == 225 and report.influence_slots == 16


def test_clips_hold_their_gesture_at_every_time(model, tmp_path):
    """Looping playback shows the gesture: the start, the middle and the end of each clip are the gesture."""
    names, poses = gestures(model, n=2)
    out = tmp_path / "clip.glb"
    export_gltf(model, out, options=GltfOptions(influences=None, clip_seconds=2.0), gestures=(names, poses))
    for t in (0.0, 0.7, 2.0):
        engine, ids, _ = engine_vertices(out, names, t=t)
        assert max_error(engine, ids, forward(model, poses).vertices, names) <= TOL


def test_eight_influences_are_exact_when_the_hand_needs_at_most_eight(model, tmp_path):
    sparse = model.replace(weights=keep_top(model.weights, 6))
    names, poses = gestures(sparse)
    out = tmp_path / "eight.glb"
    export_gltf(sparse, out, options=GltfOptions(influences=8), gestures=(names, poses))
    engine, ids, f = engine_vertices(out, names)
    assert f.attr(f.doc.meshes[0].primitives[0], "JOINTS_1") is not None
    assert max_error(engine, ids, forward(sparse, poses).vertices, names) <= TOL


def test_four_influences_skin_with_the_four_strongest_renormalised(model, tmp_path):
    names, poses = gestures(model)
    out = tmp_path / "four.glb"
    export_gltf(model, out, options=GltfOptions(influences=4), gestures=(names, poses))
    engine, ids, _ = engine_vertices(out, names)
    pruned = model.replace(weights=keep_top(model.weights, 4))
    assert max_error(engine, ids, forward(pruned, poses).vertices, names) <= TOL
    # and pruning is a real approximation on this fixture (its weights are dense)
    assert max_error(engine, ids, forward(model, poses).vertices, names) > 10 * TOL


@pytest.mark.parametrize("k", [8, 32])
def test_pca_correctives_are_the_rank_k_projection(model, tmp_path, k):
    names, poses = gestures(model)
    out = tmp_path / f"pca{k}.glb"
    report = export_gltf(model, out, options=GltfOptions(influences=None, correctives=f"pca:{k}", shape_dials=0),
                         gestures=(names, poses))
    assert report.morph_targets == 2 * k                 # a positive and a negative shape per direction
    V = model.num_vertices
    A = model.posedirs.reshape(3 * V, 135)
    U = np.linalg.svd(A, full_matrices=False)[0][:, :k]
    compressed = model.replace(posedirs=(U @ (U.T @ A)).reshape(V, 3, 135))
    engine, ids, f = engine_vertices(out, names)
    assert max_error(engine, ids, forward(compressed, poses).vertices, names) <= TOL
    assert len(f.doc.meshes[0].extras["targetNames"]) == 2 * k


def test_pose_pca_correctives_are_the_pose_weighted_rank_k_projection(model, tmp_path):
    """pose-pca:K, the USD export's Correctives: the rank-K subspace that minimises the mean squared corrective
    offset over the seeded anatomical pose sample, i.e. the top K eigenvectors of A F^T F A^T (F: the sample's pose
    features, from scipy's rotations here), found as the left singular vectors of A Q diag(sqrt(lambda)) with
    F^T F = Q diag(lambda) Q^T. The engine's result is forward with posedirs U U^T A."""
    from scipy.spatial.transform import Rotation

    from darthand.export.correctives import POSE_PCA_SAMPLES, POSE_PCA_SEED

    k = 8
    names, poses = gestures(model)
    out = tmp_path / "pose_pca.glb"
    report = export_gltf(model, out, options=GltfOptions(influences=None, correctives=f"pose-pca:{k}", shape_dials=0),
                         gestures=(names, poses))
    assert report.morph_targets == 2 * k and report.correctives == f"pose-pca:{k}"
    sample = sample_poses(model, POSE_PCA_SAMPLES, np.random.default_rng(POSE_PCA_SEED))
    R = Rotation.from_rotvec(sample.reshape(-1, 3)).as_matrix().reshape(len(sample), 16, 3, 3)
    F = (R[:, 1:] - np.eye(3)).reshape(len(sample), 135)
    V = model.num_vertices
    A = model.posedirs.reshape(3 * V, 135)
    lam, Q = np.linalg.eigh(F.T @ F)
    U = np.linalg.svd(A @ (Q * np.sqrt(np.clip(lam, 0, None))), full_matrices=False)[0][:, :k]
    compressed = model.replace(posedirs=(U @ (U.T @ A)).reshape(V, 3, 135))
    engine, ids, f = engine_vertices(out, names)
    assert max_error(engine, ids, forward(compressed, poses).vertices, names) <= TOL
    assert len(f.doc.meshes[0].extras["targetNames"]) == 2 * k
    # a different subspace from pca:K's, so the comparison above tells them apart
    U_pca = np.linalg.svd(A, full_matrices=False)[0][:, :k]
    pca = model.replace(posedirs=(U_pca @ (U_pca.T @ A)).reshape(V, 3, 135))
    assert max_error(engine, ids, forward(pca, poses).vertices, names) > 10 * TOL


def test_no_correctives_is_plain_skinning(model, tmp_path):
    names, poses = gestures(model)
    out = tmp_path / "none.glb"
    export_gltf(model, out, options=GltfOptions(influences=None, correctives="none", shape_dials=0),
                gestures=(names, poses))
    engine, ids, f = engine_vertices(out, names)
    assert not f.doc.meshes[0].primitives[0].targets
    assert max_error(engine, ids, forward(model, poses, correctives=False).vertices, names) <= TOL


def test_rest_state_and_vertex_map(model, tmp_path):
    out = tmp_path / "rest.glb"
    export_gltf(model, out, gestures=([], np.zeros((0, 48))))
    f = GltfFile(out)
    node = f.node_index(MESH)
    prim = f.doc.meshes[f.doc.nodes[node].mesh].primitives[0]
    ids = f.attr(prim, "_VERTEX_ID")[:, 0].astype(int)
    # the map is right: stored positions are the template's vertices, and every model vertex appears
    np.testing.assert_allclose(f.attr(prim, "POSITION"), model.v_template[ids], atol=1e-7)
    assert set(ids) == set(np.unique(model.faces))
    # default state (mesh weights 0, rest joint nodes) is the rest template
    rest = skinned_positions(f, node, global_matrices(f))
    assert np.linalg.norm(rest - model.v_template[ids], axis=1).max() <= TOL
    # every glTF triangle is a model triangle, same winding, and each corner carries one of the model's UVs
    tri = ids[f.accessor(prim.indices)[:, 0].reshape(-1, 3)]
    rolled = np.array([np.roll(t, -int(np.argmin(t))) for t in tri])
    model_rolled = np.array([np.roll(t, -int(np.argmin(t))) for t in model.faces])
    assert sorted(map(tuple, rolled)) == sorted(map(tuple, model_rolled))
    uv = f.attr(prim, "TEXCOORD_0")
    corner_uv = model.uvs[model.faces_uv.reshape(-1)]
    corner_v = model.faces.reshape(-1)
    for n in range(len(ids)):
        options = corner_uv[corner_v == ids[n]]
        flipped = np.stack([options[:, 0], 1 - options[:, 1]], 1)
        assert np.abs(flipped - uv[n]).max(1).min() < 1e-6


def test_trimesh_reads_the_rest_geometry(model, tmp_path):
    import trimesh

    out = tmp_path / "tm.glb"
    export_gltf(model, out, gestures=([], np.zeros((0, 48))))
    scene = trimesh.load(out, process=False)
    geom = scene.geometry[f"{MESH}Mesh"]
    f = GltfFile(out)
    ids = f.attr(f.doc.meshes[0].primitives[0], "_VERTEX_ID")[:, 0].astype(int)
    np.testing.assert_allclose(geom.vertices, model.v_template[ids], atol=1e-7)
    assert len(geom.faces) == model.num_faces
    assert np.isclose(abs(geom.volume), abs(trimesh.Trimesh(model.v_template, model.faces, process=False).volume),
                      rtol=1e-6)


def test_left_hand_matches_its_rig(model, tmp_path):
    from darthand.model.mirror import mirror_model, mirror_pose

    left = mirror_model(model)
    names, poses = gestures(model, n=2)
    out = tmp_path / "left.glb"
    export_gltf(left, out, options=GltfOptions(influences=None), gestures=(names, mirror_pose(poses)))
    f = GltfFile(out)
    node = "LeftHand"
    ids = f.attr(f.doc.meshes[0].primitives[0], "_VERTEX_ID")[:, 0].astype(int)
    truth = forward(left, mirror_pose(poses)).vertices
    end = f.accessor(f.doc.animations[0].samplers[0].input)[-1, 0]
    for i, n in enumerate(names):
        assert np.linalg.norm(posed_mesh(f, node, n, end) - truth[i][ids], axis=1).max() <= TOL


def test_export_reports_the_error_its_options_cost(model, tmp_path):
    names, poses = gestures(model)
    full = forward(model, poses).vertices
    r = export_gltf(model, tmp_path / "a.glb", options=GltfOptions(influences=4, correctives="none"),
                    gestures=(names, poses))
    pruned = model.replace(weights=keep_top(model.weights, 4))
    expected = np.linalg.norm(forward(pruned, poses).vertices - full, axis=-1).max()
    assert np.isclose(r.influence_error_m, expected, rtol=1e-9)
    expected = np.linalg.norm(forward(model, poses, correctives=False).vertices - full, axis=-1).max()
    assert np.isclose(r.corrective_error_m, expected, rtol=1e-9) and r.corrective_error_m > 0
    r = export_gltf(model, tmp_path / "b.glb", options=GltfOptions(influences=None), gestures=(names, poses))
    assert r.influence_error_m == 0 and r.corrective_error_m < 1e-12


def test_local_correctives_are_stored_sparse_and_stay_exact(model, tmp_path):
    """Correctives that move few vertices (as on a real hand) become sparse accessors; an all-zero one has no data."""
    rng = np.random.default_rng(4)
    mask = rng.random((model.num_vertices, 1, 135)) < 0.2
    posedirs = model.posedirs * mask
    posedirs[:, :, 7] = 0.0
    local = model.replace(posedirs=posedirs)
    names, poses = gestures(local)
    out = tmp_path / "sparse.glb"
    # without the (dense) shape dials: this checks the correctives' storage
    export_gltf(local, out, options=GltfOptions(influences=None, shape_dials=0), gestures=(names, poses))
    engine, ids, f = engine_vertices(out, names)
    targets = f.doc.meshes[0].primitives[0].targets
    accessors = [f.doc.accessors[t["POSITION"] if isinstance(t, dict) else t.POSITION] for t in targets]
    assert all(a.bufferView is None for a in accessors)
    names7 = {"pose_index1_r21_pos", "pose_index1_r21_neg"}                      # channel 7's two shapes
    zero = [i for i, n in enumerate(f.doc.meshes[0].extras["targetNames"]) if n in names7]
    assert len(zero) == 2 and all(accessors[i].sparse is None for i in zero)
    assert all(a.sparse is not None for i, a in enumerate(accessors) if i not in zero)
    assert max_error(engine, ids, forward(local, poses).vertices, names) <= TOL


def test_model_without_uvs_exports_its_used_vertices(tmp_path):
    bare = add_wrist(tube_hand(1, with_uvs=False))
    names, poses = gestures(bare, n=1)
    out = tmp_path / "bare.glb"
    export_gltf(bare, out, options=GltfOptions(influences=None), gestures=(names, poses))
    engine, ids, f = engine_vertices(out, names)
    assert f.attr(f.doc.meshes[0].primitives[0], "TEXCOORD_0") is None
    assert sorted(ids) == sorted(np.unique(bare.faces))
    assert max_error(engine, ids, forward(bare, poses).vertices, names) <= TOL
