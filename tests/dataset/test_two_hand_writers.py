"""Two-hand frames (issue 29's labels) in the other layouts: both hands in the WebDataset shards read by the
`webdataset` package, FreiHAND leaving them out with a count, COCO's two annotations read by pycocotools, HaMeR's
two dicts, `darthand eval` of per-hand predictions (MRRPE on a closed-form case), hands_of."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from darthand.cli import main
from darthand.dataset.evaluate import evaluate_files
from darthand.dataset.evaluate_hands import write_hand_predictions
from darthand.dataset.hands import hand_type, hands_of
from darthand.errors import InputError


def _labels(root, index):
    return json.loads((root / "labels" / f"{index:06d}.json").read_text())


def test_hands_of_reads_one_and_two_hand_labels(two_hand_dataset):
    root, made = two_hand_dataset
    two = _labels(root, made[0])
    assert [h["side"] for h in hands_of(two)] == ["right", "left"] and hand_type(two) == "interacting"
    one = next(_labels(root, int(p.stem)) for p in sorted((root / "labels").glob("*.json"))
               if int(p.stem) not in made)
    assert hands_of(one) == [one] and hand_type(one) == one["side"]


def test_webdataset_carries_both_hands(two_hand_dataset, tmp_path):
    import webdataset as wds

    root, made = two_hand_dataset
    assert main(["dataset", "export", str(root), "--format", "webdataset", "--out", str(tmp_path)]) == 0
    urls = sorted(str(p) for p in tmp_path.glob("*.tar"))
    seen = {}
    for sample in wds.WebDataset(urls, shardshuffle=False):
        labels = json.loads(sample["json"])
        verts = np.load(io.BytesIO(sample["verts.npy"]))
        index = int(sample["__key__"])
        seen[index] = "instances.png" in sample
        if index in made:
            assert len(labels["hands"]) == 2 and verts.shape[0] == 2 and verts.ndim == 3
            assert sample["instances.png"] == (root / "instances" / f"{index:06d}.png").read_bytes()
            for b, hand in enumerate(labels["hands"]):
                # the mesh's hand vertices carry the hand's keypoints' scale and place (its camera-frame points)
                assert np.linalg.norm(verts[b].mean(0) - np.mean(hand["keypoints_3d"], 0)) < 0.05
        else:
            assert verts.ndim == 2 and "hands" not in labels
    assert sorted(i for i, has in seen.items() if has) == made and len(seen) == 16


def test_freihand_leaves_two_hand_frames_out_with_a_count(two_hand_dataset, tmp_path):
    root, made = two_hand_dataset
    assert main(["dataset", "export", str(root), "--format", "freihand", "--out", str(tmp_path),
                 "--allow-non-mano"]) == 0
    rows = sum(len(json.loads(p.read_text())) for p in tmp_path.glob("*_frames.json"))
    written = {i for p in tmp_path.glob("*_frames.json") for i in json.loads(p.read_text())}
    assert rows == 16 - len(made) and not written & set(made)
    assert f"{len(made)} two-hand frames left out" in (tmp_path / "README.md").read_text()


def test_coco_has_one_annotation_per_hand(two_hand_dataset, tmp_path):
    coco = pytest.importorskip("pycocotools.coco")
    root, made = two_hand_dataset
    assert main(["dataset", "export", str(root), "--format", "coco", "--out", str(tmp_path)]) == 0
    found = 0
    for path in sorted((tmp_path / "annotations").glob("*.json")):
        db = coco.COCO(str(path))
        for index in set(made) & set(db.imgs):
            anns = db.loadAnns(db.getAnnIds(imgIds=[index]))
            labels = _labels(root, index)
            assert sorted(a["hand_type"] for a in anns) == ["left", "right"]
            for a in anns:
                hand = next(h for h in labels["hands"] if h["side"] == a["hand_type"])
                kp = np.asarray(a["keypoints"]).reshape(21, 3)
                labelled = kp[kp[:, 2] > 0, :2]                  # each one of the hand's own points (any order)
                uv = np.asarray(hand["keypoints_2d"]) - 0.5
                assert len(labelled) and np.linalg.norm(labelled[:, None] - uv[None], axis=-1).min(1).max() < 1e-3
            assert len({a["id"] for a in anns}) == len(anns)
            found += len(anns)
    assert found == 2 * len(made)


def test_hamer_writes_a_dict_per_hand(two_hand_dataset, tmp_path):
    import webdataset as wds

    root, made = two_hand_dataset
    assert main(["dataset", "export", str(root), "--format", "hamer", "--out", str(tmp_path)]) == 0
    urls = sorted(str(p) for p in tmp_path.glob("*/*.tar"))
    for item in wds.WebDataset(urls, shardshuffle=False).decode():
        hands = item["data.pyd"]
        if int(item["__key__"]) in made:
            assert [float(h["right"]) for h in hands] == [1.0, 0.0]
            labels = _labels(root, int(item["__key__"]))
            for h, own in zip(hands, labels["hands"]):
                assert np.allclose(h["keypoints_3d"][:, :3], own["keypoints_3d"], atol=1e-6)
        else:
            assert len(hands) == 1


def _truth(root):
    frames = {}
    for p in sorted((root / "labels").glob("*.json")):
        labels = json.loads(p.read_text())
        frames[int(p.stem)] = [{"side": h["side"], "keypoints_3d": np.asarray(h["keypoints_3d"]),
                                "keypoints_2d": np.asarray(h["keypoints_2d"])} for h in hands_of(labels)]
    return frames


def test_eval_mrrpe_is_the_length_of_a_left_hand_shift(two_hand_dataset, tmp_path):
    """Predictions equal to the truth but every left hand moved by d: MRRPE = |d| over the interacting frames, the
    right hands' errors 0, the left hands' MPJPE |d| and PA-MPJPE 0."""
    root, made = two_hand_dataset
    d = np.array([0.003, -0.004, 0.012])                # |d| = 13 mm
    frames = _truth(root)
    for hands in frames.values():
        for h in hands:
            if h["side"] == "left":
                h["keypoints_3d"] = h["keypoints_3d"] + d
    write_hand_predictions(tmp_path / "pred.json", frames)
    result = evaluate_files(tmp_path / "pred.json", root, out=tmp_path / "eval")
    assert result["mrrpe"]["frames"] == len(made) and result["mrrpe"]["mm"] == pytest.approx(13.0, abs=1e-6)
    assert result["per_side"]["right"]["keypoints"]["mpjpe_mm"] == pytest.approx(0, abs=1e-9)
    assert result["per_side"]["left"]["keypoints"]["mpjpe_mm"] == pytest.approx(13.0, abs=1e-3)
    assert result["per_side"]["left"]["keypoints"]["pa_mpjpe_mm"] == pytest.approx(0, abs=1e-3)
    assert result["samples"] == 16 + len(made) and result["missing_hands"] == 0
    assert result["root_relative_mpjpe_mm"] == {"single": 0.0, "interacting": 0.0}      # a shift moves the root too
    assert "MRRPE" in (tmp_path / "eval" / "eval.md").read_text()


def test_eval_counts_missing_hands_and_refuses_unknown_frames(two_hand_dataset, tmp_path):
    root, made = two_hand_dataset
    frames = _truth(root)
    frames[made[0]] = frames[made[0]][:1]                # the left hand not predicted
    write_hand_predictions(tmp_path / "pred.json", frames)
    result = evaluate_files(tmp_path / "pred.json", root)
    assert result["missing_hands"] == 1 and result["mrrpe"]["frames"] == len(made) - 1
    np.savez(tmp_path / "old.npz", keypoints=np.zeros((16, 21, 3)))
    with pytest.raises(InputError, match="holds two-hand frames"):
        evaluate_files(tmp_path / "old.npz", root)
    frames[999] = frames[made[1]]
    write_hand_predictions(tmp_path / "bad.json", frames)
    with pytest.raises(InputError, match="frame 999"):
        evaluate_files(tmp_path / "bad.json", root)


def test_report_counts_two_hand_frames_per_interaction_type(two_hand_dataset, tmp_path):
    root, made = two_hand_dataset
    types: dict = {}
    for index in made:
        kind = json.loads((root / "labels" / f"{index:06d}.json").read_text())["interaction"]["type"]
        types[kind] = types.get(kind, 0) + 1
    assert main(["dataset", "report", str(root), "--out", str(tmp_path), "--sheet", "8"]) == 0
    figures = json.loads((tmp_path / "report.json").read_text())
    assert figures["two_hands"]["interaction"] == types
    kinds = figures["two_hands"]["hand_type"]
    assert kinds["interacting"] == len(made) and sum(kinds.values()) == 16
    assert figures["pose_coverage"]["embedding"]["dataset_poses"] == 16 + len(made)     # both hands' poses
    assert (tmp_path / "two_hands.png").stat().st_size > 20_000


def test_eval_command_of_a_dataset_against_itself_and_bad_predictions(two_hand_dataset, tmp_path, capsys):
    """The dataset as its own prediction scores zero everywhere; the predictions file follows its schema; a hand
    with a side that does not exist is one line, exit 2."""
    from darthand.schemas import check_schema

    root, made = two_hand_dataset
    assert main(["eval", str(root), str(root), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["mrrpe"] == {"frames": len(made), "mm": 0.0}
    assert all(f["keypoints"]["mpjpe_mm"] == 0 for f in result["per_side"].values())
    assert result["per_side"]["right"]["keypoints"]["mean_2d_px"] == 0
    frames = _truth(root)
    write_hand_predictions(tmp_path / "pred.json", frames)
    check_schema(json.loads((tmp_path / "pred.json").read_text()), "hand_predictions.schema.json", "pred.json")
    doc = json.loads((tmp_path / "pred.json").read_text())
    doc["frames"][0]["hands"][0]["side"] = "up"
    (tmp_path / "bad.json").write_text(json.dumps(doc))
    assert main(["eval", str(tmp_path / "bad.json"), str(root)]) == 2
    err = capsys.readouterr().err.strip()
    assert "bad.json" in err and "side" in err and len(err.splitlines()) == 1


def test_eval_root_relative_error_of_a_moved_fingertip(two_hand_dataset, tmp_path):
    """Every right hand's index tip moved by e: the right hands' root-relative MPJPE is |e| / 21, the left hands'
    0, and MRRPE 0 (the roots did not move)."""
    root, made = two_hand_dataset
    e = np.array([0.0, 0.021, 0.0])
    frames = _truth(root)
    names = _labels(root, made[0])["keypoint_names"]
    tip = names.index("index4")
    for hands in frames.values():
        for h in hands:
            if h["side"] == "right":
                h["keypoints_3d"] = h["keypoints_3d"].copy()
                h["keypoints_3d"][tip] += e
    write_hand_predictions(tmp_path / "pred.json", frames)
    result = evaluate_files(tmp_path / "pred.json", root)
    assert result["per_side"]["right"]["keypoints"]["root_relative_mpjpe_mm"] == pytest.approx(1.0, abs=1e-6)
    assert result["per_side"]["left"]["keypoints"]["root_relative_mpjpe_mm"] == pytest.approx(0.0, abs=1e-9)
    assert result["mrrpe"]["mm"] == pytest.approx(0.0, abs=1e-9)
