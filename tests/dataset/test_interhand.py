"""InterHand2.6M's layout of a dataset with one- and two-hand frames: read back through pycocotools, its camera
convention (X_cam = R (X - campos), then focal and princpt) carrying the written world joints onto the labels' 2-D
keypoints, the wrist-last order against named keypoints, the MANO parameters posing the side's model into the
written joints."""

from __future__ import annotations

import json

import numpy as np
import pytest

from darthand.cli import main
from darthand.model.forward import forward
from darthand.render.labels import keypoint_names

pycocotools = pytest.importorskip("pycocotools.coco")

FINGERS = ("thumb", "index", "middle", "ring", "pinky")
NAMES = [f"{f}{k}" for f in FINGERS for k in (4, 3, 2, 1)] + ["wrist"]     # InterHand's skeleton.txt, one hand


@pytest.fixture(scope="module")
def interhand(two_hand_dataset, tmp_path_factory):
    root, made = two_hand_dataset
    out = tmp_path_factory.mktemp("interhand")
    assert main(["dataset", "export", str(root), "--format", "interhand", "--out", str(out)]) == 0
    return root, made, out


def _annotations(out, split):
    folder = out / "annotations" / split
    return {kind: json.loads((folder / f"InterHand2.6M_{split}_{kind}.json").read_text())
            for kind in ("camera", "joint_3d", "MANO_NeuralAnnot")}


def _splits(out):
    return sorted(p.name for p in (out / "annotations").iterdir() if p.is_dir())


def _labels(root, index):
    return json.loads((root / "labels" / f"{index:06d}.json").read_text())


def _hands(labels):
    return labels.get("hands") or [labels]


def test_pycocotools_reads_every_frame_with_its_hand_type(interhand):
    root, made, out = interhand
    seen = {}
    for split in _splits(out):
        db = pycocotools.COCO(str(out / "annotations" / split / f"InterHand2.6M_{split}_data.json"))
        for image_id, img in db.imgs.items():
            anns = db.loadAnns(db.getAnnIds(imgIds=[image_id]))
            assert len(anns) == 1
            labels = _labels(root, img["frame_idx"])
            expected = "interacting" if "hands" in labels else labels["side"]
            assert anns[0]["hand_type"] == expected and anns[0]["hand_type_valid"] == 1
            valid = np.asarray(anns[0]["joint_valid"]).reshape(42)
            assert valid[:21].all() == any(h["side"] == "right" for h in _hands(labels))
            assert valid[21:].all() == any(h["side"] == "left" for h in _hands(labels))
            assert (out / "images" / split / img["file_name"]).is_file()
            seen[img["frame_idx"]] = expected
    assert sorted(i for i, t in seen.items() if t == "interacting") == made
    assert {"right", "left"} <= set(seen.values())


def test_world_joints_project_onto_the_labels_2d_keypoints(interhand):
    """X_cam = camrot (X - campos) (mm), pixel = X_cam / Z * focal + princpt lands on the labels' keypoints_2d
    (pixel-corner origin, so 0.5 less), hand by hand in InterHand's order."""
    root, _, out = interhand
    checked = 0
    for split in _splits(out):
        ann = _annotations(out, split)
        for frame, entry in ann["joint_3d"]["0"].items():
            cam = {k: np.asarray(v[frame], float) for k, v in ann["camera"]["0"].items()}
            X = np.asarray(entry["world_coord"], float)
            Xc = (X - cam["campos"]) @ cam["camrot"].T
            uv = Xc[:, :2] / Xc[:, 2:] * cam["focal"] + cam["princpt"]
            labels = _labels(root, int(frame))
            for hand in _hands(labels):
                at = 0 if hand["side"] == "right" else 21
                order = [labels["keypoint_names"].index(n) for n in NAMES]
                want = np.asarray(hand["keypoints_2d"])[order] - 0.5
                assert np.abs(uv[at:at + 21] - want).max() < 1e-6
                assert np.abs(Xc[at:at + 21] / 1000 - np.asarray(hand["keypoints_3d"])[order]).max() < 1e-9
                checked += 1
    assert checked >= 19


def test_joint_order_is_interhands_with_the_wrist_last(interhand):
    root, made, out = interhand
    split = _labels(root, made[0])["split"]
    entry = _annotations(out, split)["joint_3d"]["0"][str(made[0])]
    labels = _labels(root, made[0])
    X = np.asarray(entry["world_coord"])
    for hand in labels["hands"]:
        at = 0 if hand["side"] == "right" else 21
        named = dict(zip(labels["keypoint_names"], np.asarray(hand["keypoints_3d_world"]) * 1000))
        assert np.allclose(X[at + 20], named["wrist"]) and np.allclose(X[at + 0], named["thumb4"])
        assert np.allclose(X[at + 3], named["thumb1"]) and np.allclose(X[at + 19], named["pinky1"])
        assert np.allclose(X[at + 8], named["middle4"])


def _mano_file_errors(out, models) -> list[tuple[str, float]]:
    """[(side, max |keypoints - written joints| in mm)] of every hand in the layout's MANO files, posed by MANO's
    recipe as InterHand's tools use it (flat_hand_mean false, trans added, metres -> mm) on models[side]."""
    order = [keypoint_names("openpose").index(n) for n in NAMES]
    found = []
    for split in _splits(out):
        ann = _annotations(out, split)
        for frame, by_side in ann["MANO_NeuralAnnot"]["0"].items():
            X = np.asarray(ann["joint_3d"]["0"][frame]["world_coord"])
            for side, params in by_side.items():
                if params is None:
                    continue
                posed = forward(models[side], np.asarray(params["pose"])[None], np.asarray(params["shape"])[None],
                                flat_hand_mean=False, trans=np.asarray(params["trans"])[None],
                                keypoint_order="openpose")
                at = 0 if side == "right" else 21
                found.append((side, float(np.abs(posed.keypoints[0][order] * 1000 - X[at:at + 21]).max())))
    return found


def test_mano_parameters_pose_the_sides_model_into_the_written_joints(interhand, sources):
    """Each hand's parameters pose its side's model into the written world joints."""
    _, _, out = interhand
    errors = _mano_file_errors(out, {side: src.pose_model() for side, src in sources[0].items()})
    assert len(errors) >= 19 and max(e for _, e in errors) < 1e-4


def test_skeleton_file_names_the_joints_and_their_bones(interhand):
    """annotations/skeleton.txt parsed as InterHand's load_skeleton does: each joint's parent is the next joint
    toward the wrist of its own hand, so each bone joins two of the hand's keypoints one finger segment apart."""
    root, made, out = interhand
    rows = [line.split(" ") for line in (out / "annotations" / "skeleton.txt").read_text().splitlines()
            if line[0] != "#"]
    names = {int(i): n for n, i, _ in rows}
    parents = {int(i): int(p) for _, i, p in rows}
    assert [names[i] for i in range(42)] == [f"r_{n}" for n in NAMES] + [f"l_{n}" for n in NAMES]
    labels = _labels(root, made[0])
    finger_order = ["wrist"] + [f"{f}{k}" for f in FINGERS for k in (1, 2, 3, 4)]
    for j, p in parents.items():
        if p < 0:
            assert names[j].endswith("wrist")
            continue
        a, b = names[j][2:], names[p][2:]
        assert names[j][0] == names[p][0]
        assert b == "wrist" and a.endswith("1") or (a[:-1] == b[:-1] and int(a[-1]) == int(b[-1]) + 1)
        assert a in finger_order and b in labels["keypoint_names"]


def test_mano_files_pose_manos_own_models_into_the_written_joints(mano_dataset, tmp_path):
    """A dataset rendered from MANO-format pickles: each hand's parameters pose MANO_RIGHT / MANO_LEFT read from
    the pickles (778 vertices, no wrist, their own mean hands: flat_hand_mean false) into the written world joints,
    and the README says the parameters are MANO's."""
    from darthand.model.load import load_model

    root, right_pkl, left_pkl = mano_dataset
    assert main(["dataset", "export", str(root), "--format", "interhand", "--out", str(tmp_path)]) == 0
    models = {"right": load_model(str(right_pkl)), "left": load_model(str(left_pkl))}
    assert all(np.abs(m.hands_mean).max() > 0.01 for m in models.values())      # the mean hand is not zero
    errors = _mano_file_errors(tmp_path, models)
    sides = [side for side, _ in errors]
    assert max(e for _, e in errors) < 1e-3
    assert len(sides) == 12 and set(sides) == {"right", "left"}
    assert "Models: MANO files" in (tmp_path / "README.md").read_text()
