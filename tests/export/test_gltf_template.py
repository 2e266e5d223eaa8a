"""The real open hand (wrist-enhanced) through the glTF exporter: valid, and an engine's result equals the rig's.

Skipped with its reason while the open template (assets_src/template/open_right.npz) is not in the checkout.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from test_gltf_reference import GltfFile, posed_mesh  # noqa: E402

from darthand.export.gestures import gesture_poses  # noqa: E402
from darthand.export.gltf_export import GltfOptions, export_gltf  # noqa: E402
from darthand.model.anatomy import sample_poses  # noqa: E402
from darthand.model.forward import forward  # noqa: E402
from darthand.model.load import TEMPLATE_DIR  # noqa: E402

TEMPLATE = TEMPLATE_DIR / "open_right.npz"
pytestmark = pytest.mark.skipif(not TEMPLATE.is_file(), reason=f"{TEMPLATE} is not in this checkout yet")


@pytest.fixture(scope="module")
def hand():
    from darthand.model.load import load_model
    from darthand.model.wrist import add_wrist

    return add_wrist(load_model("open"))


def test_open_hand_all_influences_match_the_rig_for_every_gesture(hand, tmp_path):
    names, poses = gesture_poses(hand)
    names = list(names) + ["random0", "random1"]
    poses = np.concatenate([poses, sample_poses(hand, 2, np.random.default_rng(1), include_root=True)])
    out = tmp_path / "open.glb"
    export_gltf(hand, out, options=GltfOptions(influences=None), gestures=(names, poses))
    f = GltfFile(out)
    ids = f.attr(f.doc.meshes[0].primitives[0], "_VERTEX_ID")[:, 0].astype(int)
    end = f.accessor(f.doc.animations[0].samplers[0].input)[-1, 0]
    truth = forward(hand, poses).vertices
    errors = [np.linalg.norm(posed_mesh(f, "RightHand", n, end) - truth[i][ids], axis=1).max()
              for i, n in enumerate(names)]
    print(f"open hand, all influences: max engine-vs-rig error {max(errors):.3g} m over {len(names)} poses")
    assert max(errors) <= 1e-5


def test_open_hand_default_asset_validates(hand, tmp_path):
    if shutil.which("node") is None:
        pytest.skip("node is not installed on this machine: the Khronos glTF validator cannot run")
    from darthand.export.gltf_validator import validate

    out = tmp_path / "right.glb"
    export_gltf(hand, out)
    report = validate(out)
    print(report.summary())
    assert report.errors == 0, report.issues("errors")[:5]


def test_open_hand_in_three_js_matches_the_rig_with_four_influences(hand, tmp_path):
    if shutil.which("node") is None:
        pytest.skip("node is not installed on this machine: three.js cannot run")
    from darthand.export.influences import pruned_model
    from darthand.export.gltf_engines import three_poses

    names, poses = gesture_poses(hand)
    out = tmp_path / "right.glb"
    report = export_gltf(hand, out, gestures=(names, poses))
    engine = three_poses(out, "RightHand")
    truth = forward(pruned_model(hand, 4), poses).vertices
    ids = engine.vertex_ids
    error = max(np.linalg.norm(engine.poses[n] - truth[i][ids], axis=1).max() for i, n in enumerate(names))
    print(f"open hand in three.js r{engine.revision}: {error:.3g} m vs the 4-influence rig; pruning costs "
          f"{report.influence_error_m * 1000:.3f} mm against the full weights")
    assert error <= 1e-5
