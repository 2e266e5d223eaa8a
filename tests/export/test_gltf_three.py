"""A real engine agrees with the rig: three.js (GLTFLoader, AnimationMixer, SkinnedMesh.getVertexPosition) poses
the exported hand at the end of every gesture clip, and its vertices equal forward(model, pose) skinned with the
4 strongest influences (three.js reads JOINTS_0/WEIGHTS_0 only) -- the default export.

Skipped when `node` is absent; fails when node is there but `npm ci` has not installed three.
"""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from synthetic import tube_hand

from darthand.export.gltf_engines import three_poses
from darthand.export.gltf_export import GltfOptions, export_gltf
from darthand.model.anatomy import sample_poses
from darthand.model.forward import forward
from darthand.model.wrist import add_wrist

pytestmark = pytest.mark.skipif(shutil.which("node") is None, reason="node is not installed on this machine")


def top4(weights):
    """The test's own pruning: 4 largest weights per vertex, renormalised."""
    w = weights.copy()
    rank = np.argsort(np.argsort(-w, axis=1, kind="stable"), axis=1)
    w[rank >= 4] = 0
    return w / w.sum(1, keepdims=True)


@pytest.mark.parametrize("correctives", ["full", "pca:16"])
def test_three_js_poses_the_default_asset_like_the_rig(tmp_path, correctives):
    model = add_wrist(tube_hand(9))
    names = ["a", "b", "c"]
    poses = sample_poses(model, 3, np.random.default_rng(2), include_root=True)
    out = tmp_path / "hand.glb"
    export_gltf(model, out, gestures=(names, poses), options=GltfOptions(correctives=correctives))
    engine = three_poses(out, "RightHand")
    ids = engine.vertex_ids
    assert ids is not None and set(ids) == set(np.unique(model.faces))
    np.testing.assert_allclose(engine.rest, model.v_template[ids], atol=1e-7)
    reference = model.replace(weights=top4(model.weights))
    if correctives != "full":   # the test's own rank-16 projection of the correctives
        V = model.num_vertices
        A = model.posedirs.reshape(3 * V, 135)
        U = np.linalg.svd(A, full_matrices=False)[0][:, :16]
        reference = reference.replace(posedirs=(U @ (U.T @ A)).reshape(V, 3, 135))
    truth = forward(reference, poses).vertices
    errors = {n: float(np.linalg.norm(engine.poses[n] - truth[i][ids], axis=1).max()) for i, n in enumerate(names)}
    print(f"three.js r{engine.revision}: max vertex error {max(errors.values()):.3g} m")
    assert max(errors.values()) <= 1e-5
