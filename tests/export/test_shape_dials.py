"""Packages built for a shape, with the shape directions as dials: OpenUSD's UsdSkel maths and an independent glTF
reader pose them as darthand does.

Truth: `forward(model, pose, betas)` (joints follow the shape) and, for a dialled shape (blend shapes at non-zero
weight, joints fixed), the same skinning with the built shape's joints written out here from the rig's transforms.
The dial error (joints not following) is measured, compared with what the package reports, and must be real
(> 0) for a posed hand and nil at rest.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, Vt

sys.path.insert(0, str(Path(__file__).resolve().parent))
from synthetic import tube_hand  # noqa: E402
from test_gltf_reference import GltfFile, global_matrices, sample_animation, skinned_positions  # noqa: E402

from darthand.export.blendshapes import encode_channels  # noqa: E402
from darthand.export.gltf_export import GltfOptions, export_gltf  # noqa: E402
from darthand.export.shape_dials import dialled_vertices  # noqa: E402
from darthand.export.usd_asset import export_usd  # noqa: E402
from darthand.export.usd_evaluate import skinned_points  # noqa: E402
from darthand.model.forward import forward  # noqa: E402
from darthand.model.wrist import add_wrist  # noqa: E402

BUILT = np.array([0.8, -1.5, 0.0, 2.0])


@pytest.fixture(scope="module")
def base():
    return add_wrist(tube_hand(0))


@pytest.fixture(scope="module")
def built(base):
    return base.shaped(BUILT)


@pytest.fixture(scope="module")
def gestures():
    p = np.random.default_rng(5).normal(0, 0.5, (4, 48))
    p[0] = 0
    return [f"g{i}" for i in range(len(p))], p


def dial_weights(delta: np.ndarray) -> np.ndarray:
    """The encoded dial weights of delta beta (S,), in the package's order (pos, neg per direction)."""
    names = [f"shape_beta{n:02d}" for n in range(len(delta))]
    return encode_channels(names, [-3.0] * len(delta), [3.0] * len(delta)).weights(delta[None])[0]


def test_built_shape_is_the_template_and_the_baked_betas(base, built):
    rest = forward(built, np.zeros(48)).vertices[0]
    assert np.abs(rest - forward(base, np.zeros(48), BUILT).vertices[0]).max() < 1e-12
    assert built.meta["betas"] == pytest.approx(BUILT)


def test_usd_dials_match_usdskel_and_report_their_error(base, built, gestures, tmp_path):
    info = export_usd(built, tmp_path / "right", gestures=gestures)
    dials = info["shape_dials"]
    assert dials["baked_betas"] == pytest.approx(BUILT)
    assert [s["name"] for s in dials["blend_shapes"]["shapes"]][:2] == ["shape_beta00_pos", "shape_beta00_neg"]
    stage = Usd.Stage.Open(str(tmp_path / "right" / info["interface"]), Usd.Stage.LoadAll)
    hand = "/RightHand/RightHandMesh"
    # weights 0: the built shape, exactly (joints follow the shape because they were written for it)
    at_zero = skinned_points(stage)[hand]
    assert np.abs(at_zero - forward(base, gestures[1], np.tile(BUILT, (4, 1))).vertices).max() < 1e-6

    # a user dials beta 1 to +2.4 and beta 3 to -1.2: add the dials to the timeline's animation in the session layer
    delta = np.array([0.0, 2.4, 0.0, -1.2])
    anim = stage.GetPrimAtPath(info["prims"]["animations"]["all"])
    names = list(anim.GetAttribute("blendShapes").Get())
    dial_names = [s["name"] for s in dials["blend_shapes"]["shapes"]]
    # the session layer's time codes must be the stage's (one per second), or its samples land at other times
    stage.GetSessionLayer().timeCodesPerSecond = stage.GetTimeCodesPerSecond()
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        anim.GetAttribute("blendShapes").Set(Vt.TokenArray(names + dial_names))
        attr = anim.GetAttribute("blendShapeWeights")
        # read every sample before writing any: the session layer's samples override all of the payload's
        weights = [list(attr.Get(t)) for t in range(len(gestures[1]))]
        for t, w in enumerate(weights):
            attr.Set(Vt.FloatArray(w + list(dial_weights(delta))), t)
    dialled = skinned_points(stage)[hand]
    # UsdSkel moves the surface, not the joints: what dialled_vertices computes
    assert np.abs(dialled - dialled_vertices(built, gestures[1], delta)).max() < 1e-6
    truth = forward(base, gestures[1], np.tile(BUILT + delta, (4, 1))).vertices
    err = np.linalg.norm(dialled - truth, axis=-1)
    assert err[0].max() < 1e-6                      # the rest pose: exact
    assert err[1:].max() > 1e-5                     # posed: the joints stay behind, a real error
    # the package's own report bounds one direction at the full range; two directions at smaller values stay below
    # the sum of the per-direction figures
    per_dir = np.array(dials["dial_error"]["per_direction_m"])
    assert err.max() <= per_dir.sum() + 1e-6


def test_gltf_dials_match_the_reader(base, built, gestures, tmp_path):
    out = tmp_path / "right.glb"
    result = export_gltf(built, out, gestures=gestures, options=GltfOptions(influences=None))
    assert result.shape_dials["baked_betas"] == pytest.approx(BUILT)
    f = GltfFile(out)
    mesh = f.doc.meshes[0]
    dial_names = [n for n in mesh.extras["targetNames"] if n.startswith("shape_beta")]
    assert len(dial_names) == 2 * len(BUILT)
    assert result.morph_targets + result.shape_targets == len(mesh.extras["targetNames"])
    node = f.node_index("RightHand")
    delta = np.array([-2.0, 0.0, 1.5, 0.0])
    for i, name in enumerate(gestures[0]):
        trs, weights = sample_animation(f, name, 0.5)
        w = weights[node]
        dials_w = w[-len(dial_names):]
        assert np.all(dials_w == 0)                 # the clips hold the built shape
        built_pose = skinned_positions(f, node, global_matrices(f, trs), w)
        src = f.accessor(f.doc.meshes[0].primitives[0].attributes._VERTEX_ID)[:, 0].astype(int)
        truth = forward(base, gestures[1][i], BUILT).vertices[0][src]
        assert np.abs(built_pose - truth).max() < 1e-5
        w = w.copy()
        w[-len(dial_names):] = dial_weights(delta)
        dialled = skinned_positions(f, node, global_matrices(f, trs), w)
        assert np.abs(dialled - dialled_vertices(built, gestures[1][i:i + 1], delta)[0][src]).max() < 1e-5


def test_no_dials_when_asked(built, gestures, tmp_path):
    result = export_gltf(built, tmp_path / "r.glb", gestures=gestures, options=GltfOptions(shape_dials=0))
    assert not any(n.startswith("shape_beta") for n in GltfFile(tmp_path / "r.glb").doc.meshes[0].extras["targetNames"])
    assert result.shape_dials["channels"] == []
