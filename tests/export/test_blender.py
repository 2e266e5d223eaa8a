"""Blender, the first DCC tool most people open the packages in, as the independent truth: bpy (Blender 5.0 as a
Python module, in .venv-blender) imports the USD and the glTF with its importers' default options, or opens the
native .blend, and the vertices it evaluates (metres, after undoing its Y-up -> Z-up rotation) are compared with
`forward` (float64):

    USD, every gesture (the default `gesture` variant: one gesture per frame)   <= 0.01 mm
    glTF, every clip                                 <= the 4-influence pruning error + 0.01 mm
    the .blend, random poses set on its bones (drivers compute the correctives)   <= 0.01 mm
    an accessory variant: a ring bound to its finger bone moves with it (USD variant, glTF joint child)

One Blender process per package (each test below); they run on the open CC0 hand with its real gestures.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from darthand.export.blender_engine import BlenderUnavailable, blender_python
from darthand.export.gestures import gesture_poses
from darthand.export.influences import pruned_model
from darthand.model.forward import forward
from darthand.model.load import TEMPLATE_DIR, load_model
from darthand.model.wrist import add_wrist

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "render"))

from render_scenes import ring_around  # noqa: E402

TOL = 1e-5   # metres: 0.01 mm

try:
    blender_python()
except BlenderUnavailable as e:
    pytest.skip(f"{e}", allow_module_level=True)
if not (TEMPLATE_DIR / "open_right.npz").is_file():
    pytest.skip("assets_src/template/open_right.npz is not in this checkout", allow_module_level=True)


@pytest.fixture(scope="module")
def hand():
    model = add_wrist(load_model("open"))
    names, poses = gesture_poses(model)
    return model, names, poses, forward(model, poses).vertices


def max_mm(a, b) -> float:
    return 1000 * float(np.linalg.norm(np.asarray(a) - np.asarray(b), axis=-1).max())


def test_blender_imports_the_usd_and_poses_every_gesture_exactly(hand, tmp_path):
    from darthand.export.blender_engine import blender_evaluate
    from darthand.export.usd_asset import export_usd
    from darthand.model.cap import forearm_cap

    model, names, poses, truth = hand
    info = export_usd(model, tmp_path / "right", gestures=(names, poses))
    result = blender_evaluate(tmp_path / "right" / info["interface"], frames=range(len(names)))
    objects = {o["name"]: o for o in result.info["objects"]}
    # names explain themselves and do not collide: no 'Hand.001', no 'Looks' empty, no generic 'Material'
    assert set(objects) == {"RightHand", "RightHandSkeleton", "RightHandMesh", "RightForearmCap"}
    assert result.info["materials"] == ["RightHandSkin"]
    # the shape keys stay within Blender's default [0, 1] and no importer fix-up was needed
    ranges = {tuple(k[1:]) for k in result.info["shape_keys"]["RightHandMesh"]}
    assert ranges == {(0.0, 1.0)}
    caps = forearm_cap(model).pose(forward(model, poses))
    errors = [max_mm(result.vertices[f"frame_{i}"]["RightHandMesh"], truth[i]) for i in range(len(names))]
    assert max(errors) <= 1000 * TOL, dict(zip(names, errors))
    cap_errors = [max_mm(result.vertices[f"frame_{i}"]["RightForearmCap"], caps[i]) for i in range(len(names))]
    assert max(cap_errors) <= 1000 * TOL
    # the comparison has teeth: without correctives the fist is millimetres off
    fist = names.index("fist")
    assert max_mm(result.vertices[f"frame_{fist}"]["RightHandMesh"],
                  forward(model, poses[fist], correctives=False).vertices[0]) > 1.0
    # bones lie along the fingers: index1's bone points at index2 (Blender's armature space -> model frame)
    from darthand.export.blender_engine import from_blender

    bones = result.info["bones"]
    arma = np.array(result.info["armature_matrix"])
    head, tail = (from_blender(arma[:3, :3] @ bones["index1"][k] + arma[:3, 3]) for k in ("head", "tail"))
    J = model.J_regressor @ model.v_template
    direction = (tail - head) / np.linalg.norm(tail - head)
    np.testing.assert_allclose(direction, (J[2] - J[1]) / np.linalg.norm(J[2] - J[1]), atol=1e-5)


def test_blender_imports_the_gltf_and_plays_every_clip_exactly(hand, tmp_path):
    from darthand.export.blender_engine import blender_evaluate
    from darthand.export.gltf_export import export_gltf

    model, names, poses, truth = hand
    out = tmp_path / "right.glb"
    export_gltf(model, out, gestures=(names, poses))
    pruned = forward(pruned_model(model, 4), poses).vertices
    prune_mm = [max_mm(pruned[i], truth[i]) for i in range(len(names))]
    result = blender_evaluate(out, actions=True)
    objects = {o["name"]: o for o in result.info["objects"]}
    # the root node is the armature, the mesh sits under it: no extra empty (the importer adds its own
    # 'Icosphere' bone shape, which no file setting avoids)
    assert {"RightHand", "RightHandMesh"} <= set(objects) and objects["RightHand"]["type"] == "ARMATURE"
    assert not [o for o in objects.values() if o["type"] == "EMPTY"]
    assert objects["RightHandMesh"]["parent"] == "RightHand" and result.info["materials"] == ["RightHandSkin"]
    ids = np.asarray(result.info["vertex_ids"]["RightHandMesh"]).astype(int)
    hand_rows = ids < model.num_vertices
    for i, name in enumerate(names):
        got = result.vertices[f"action_{name}"]["RightHandMesh"]
        err = max_mm(got[hand_rows], truth[i][ids[hand_rows]])
        assert err <= prune_mm[i] + 1000 * TOL, (name, err, prune_mm[i])
    assert max(prune_mm) > 0.1          # the 4-influence allowance is real, and the rest is exact


def test_blender_native_rig_follows_random_bone_poses(hand, tmp_path):
    from darthand.export.blender_engine import blender_evaluate
    from darthand.export.blender_rig import export_blend
    from darthand.model import bones
    from darthand.model.anatomy import sample_poses
    from darthand.model.cap import forearm_cap
    from darthand.model.layout import JOINT_NAMES
    from darthand.model.rotations import matrix_to_quaternion

    model, names, poses, _ = hand
    out = tmp_path / "right.blend"
    export_blend(model, out, gestures=(names, poses))
    rng = np.random.default_rng(12)
    random = sample_poses(model, 4, rng)
    random[:, :3] = rng.normal(0, 0.6, (4, 3))                   # the wrist too
    random[3, 3:] = rng.normal(0, 0.5, 45)                       # and one far outside the joint limits
    q = matrix_to_quaternion(bones.bone_rotations(random, bones.bone_frames(model)))
    bone_poses = {f"pose_{i}": {name: q[i, j].tolist() for j, name in enumerate(JOINT_NAMES)}
                  for i in range(len(random))}
    result = blender_evaluate(out, bone_poses=bone_poses)
    posed = forward(model, random)
    caps = forearm_cap(model).pose(posed)
    for i in range(len(random)):
        assert max_mm(result.vertices[f"pose_{i}"]["RightHandMesh"], posed.vertices[i]) <= 1000 * TOL
        assert max_mm(result.vertices[f"pose_{i}"]["RightForearmCap"], caps[i]) <= 1000 * TOL
    # without the drivers' correctives the same poses are far off (the check has teeth)
    plain = forward(model, random, correctives=False).vertices
    assert max(max_mm(result.vertices[f"pose_{i}"]["RightHandMesh"], plain[i]) for i in range(4)) > 1.0
    assert {f"RightHand_{n}" for n in names} <= set(result.info["actions"])


def test_blender_moves_a_ring_with_its_finger_bone(hand, tmp_path):
    """USD: the `accessory` variant selected in a layer that references the package; glTF: the ring node under its
    joint. Truth: the ring's rest vertices moved by the joint's skinning transform G_j."""
    from darthand.export.blender_engine import blender_evaluate
    from darthand.export.gltf_export import export_gltf
    from darthand.export.usd_asset import export_usd

    model, names, poses, _ = hand
    ring = ring_around(model, 5, 6)                               # middle2 -> middle3
    fist = names.index("fist")
    G = forward(model, poses).transforms[:, 5]
    expected = np.einsum("bij,nj->bni", G[:, :3, :3], ring.vertices) + G[:, None, :3, 3]
    info = export_usd(model, tmp_path / "right", accessories=[ring], gestures=(names, poses))
    wrapper = tmp_path / "shot.usda"
    wrapper.write_text(f'#usda 1.0\n(\n    defaultPrim = "RightHand"\n    metersPerUnit = 1\n    upAxis = "Y"\n'
                       f'    startTimeCode = 0\n    endTimeCode = {len(names) - 1}\n    timeCodesPerSecond = 1\n'
                       f'    framesPerSecond = 1\n)\n\n'
                       f'def "RightHand" (\n    prepend references = @./right/{info["interface"]}@\n'
                       f'    variants = {{\n        string accessory = "{ring.id}"\n    }}\n)\n{{\n}}\n')
    usd = blender_evaluate(wrapper, frames=[0, fist])
    key = next(n for n in usd.vertices["frame_0"] if n.endswith(ring.id))
    for frame, i in ((0, 0), (fist, fist)):
        got = usd.vertices[f"frame_{frame}"][key]
        assert max_mm(np.sort(got, axis=0), np.sort(expected[i], axis=0)) <= 1000 * TOL
    assert max_mm(expected[fist], expected[0]) > 5.0              # the ring did move with the finger

    export_gltf(model, tmp_path / "ring.glb", accessories=[ring], gestures=(names, poses))
    gltf = blender_evaluate(tmp_path / "ring.glb", actions=True)
    objects = {o["name"]: o for o in gltf.info["objects"]}
    assert objects[f"Right_{ring.id}"]["parent"] == "RightHand"     # parented to the armature's bone
    for i in (0, fist):
        got = gltf.vertices[f"action_{names[i]}"][f"Right_{ring.id}"]
        assert max_mm(np.sort(got, axis=0), np.sort(expected[i], axis=0)) <= 1000 * TOL
