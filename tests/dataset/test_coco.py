"""mmpose's COCO-style hand layout read by its consumers' own library: pycocotools' COCO index, annToMask, toBbox
against the dataset's masks and labels; freihand2d's keypoint names and skeleton written out here from mmpose's
configs/_base_/datasets/freihand2d.py."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from pycocotools import mask as mask_utils
from pycocotools.coco import COCO

from darthand.cli import main
from darthand.dataset.coco import MASK_THRESHOLD, _place_image, coco_keypoints, encode_mask
from darthand.dataset.run import read_shard_records
from darthand.errors import InputError
from darthand.render.image import read_png, write_png
from darthand.render.labels import keypoint_names

pytestmark = pytest.mark.filterwarnings("ignore:__array__ implementation:DeprecationWarning")   # pycocotools, numpy 2

FREIHAND2D_NAMES = [
    "wrist", "thumb1", "thumb2", "thumb3", "thumb4", "forefinger1", "forefinger2", "forefinger3", "forefinger4",
    "middle_finger1", "middle_finger2", "middle_finger3", "middle_finger4", "ring_finger1", "ring_finger2",
    "ring_finger3", "ring_finger4", "pinky_finger1", "pinky_finger2", "pinky_finger3", "pinky_finger4"]
FREIHAND2D_LINKS = [                     # skeleton_info 0 .. 19, by name
    ("wrist", "thumb1"), ("thumb1", "thumb2"), ("thumb2", "thumb3"), ("thumb3", "thumb4"),
    ("wrist", "forefinger1"), ("forefinger1", "forefinger2"), ("forefinger2", "forefinger3"),
    ("forefinger3", "forefinger4"), ("wrist", "middle_finger1"), ("middle_finger1", "middle_finger2"),
    ("middle_finger2", "middle_finger3"), ("middle_finger3", "middle_finger4"), ("wrist", "ring_finger1"),
    ("ring_finger1", "ring_finger2"), ("ring_finger2", "ring_finger3"), ("ring_finger3", "ring_finger4"),
    ("wrist", "pinky_finger1"), ("pinky_finger1", "pinky_finger2"), ("pinky_finger2", "pinky_finger3"),
    ("pinky_finger3", "pinky_finger4")]


@pytest.fixture(scope="module")
def coco_export(small_dataset, tmp_path_factory):
    """(dataset folder, export folder) of `darthand dataset export DIR --format coco`."""
    out, _ = small_dataset
    where = tmp_path_factory.mktemp("coco") / "layout"
    assert main(["dataset", "export", str(out), "--format", "coco", "--out", str(where)]) == 0
    return out, where


def _load(where, split) -> COCO:
    return COCO(str(where / "annotations" / f"darthand_{split}.json"))


def _labels(dataset, index) -> dict:
    return json.loads((dataset / "labels" / f"{index:06d}.json").read_text())


def test_splits_hold_the_frames_of_their_split(coco_export):
    dataset, where = coco_export
    frames = read_shard_records(dataset)
    seen = 0
    for split in ("train", "val", "test"):
        path = where / "annotations" / f"darthand_{split}.json"
        expected = sorted(f["index"] for f in frames if f["split"] == split)
        if not expected:
            assert not path.exists()
            continue
        coco = _load(where, split)
        assert sorted(coco.getImgIds()) == expected
        for img in coco.loadImgs(coco.getImgIds()):
            labels = _labels(dataset, img["id"])
            assert [img["width"], img["height"]] == labels["image_size"]
            assert read_png(where / img["file_name"]).shape[:2] == (img["height"], img["width"])
        seen += len(expected)
    assert seen == 16


def test_categories_are_freihand2d(coco_export):
    _, where = coco_export
    split = next(p.name for p in (where / "annotations").iterdir()).split("_")[1].split(".")[0]
    cats = _load(where, split).loadCats([1])
    assert len(cats) == 1 and cats[0]["name"] == "hand"
    names = cats[0]["keypoints"]
    assert names == FREIHAND2D_NAMES
    assert [(names[a - 1], names[b - 1]) for a, b in cats[0]["skeleton"]] == FREIHAND2D_LINKS


def test_annotations_match_the_masks_and_labels(coco_export):
    """Per frame: annToMask is the thresholded mask, area its count, bbox holds the mask's pixels and the labelled
    keypoints, keypoints are the labels' 2D points (pixel centres at integers), v from in_image and visibility."""
    dataset, where = coco_export
    sides, states = set(), set()
    for split in ("train", "val", "test"):
        if not (where / "annotations" / f"darthand_{split}.json").exists():
            continue
        coco = _load(where, split)
        for img_id in coco.getImgIds():
            anns = coco.loadAnns(coco.getAnnIds(imgIds=img_id))
            assert len(anns) == 1
            ann, labels = anns[0], _labels(dataset, img_id)
            coverage = read_png(dataset / "masks" / f"{img_id:06d}.png")[..., 0]
            _check_mask(coco, ann, coverage)
            kp = np.array(ann["keypoints"], float).reshape(21, 3)
            _check_keypoints(kp, labels, ann)
            _check_box(ann["bbox"], coverage, kp)
            _check_side(ann, labels)
            sides.add(labels["side"])
            states |= set(kp[:, 2].astype(int).tolist())
    assert sides == {"left", "right"}                    # a left hand's annotation was checked, kept as rendered
    assert {1, 2} <= states                              # occluded and visible keypoints both occur


def _check_mask(coco, ann, coverage) -> None:
    binary = coverage >= 128
    assert np.array_equal(coco.annToMask(ann), binary.astype(np.uint8))
    assert ann["area"] == int(binary.sum()) == int(mask_utils.area(ann["segmentation"]))
    assert ann["iscrowd"] == 0 and ann["category_id"] == 1


def _check_keypoints(kp, labels, ann) -> None:
    names = keypoint_names(labels["keypoint_order"])
    ours = [n.replace("index", "forefinger").replace("middle", "middle_finger").replace("ring", "ring_finger")
            .replace("pinky", "pinky_finger") for n in names]
    order = [ours.index(n) for n in FREIHAND2D_NAMES]
    uv = np.array(labels["keypoints_2d"])[order]
    inside, seen = np.array(labels["in_image"])[order], np.array(labels["visibility"])[order]
    assert np.array_equal(kp[:, 2], np.where(inside, np.where(seen, 2, 1), 0))
    np.testing.assert_allclose(kp[inside, :2], uv[inside] - 0.5, rtol=0, atol=0.5e-4)
    assert np.all(kp[~inside, :2] == 0)
    assert ann["num_keypoints"] == int((kp[:, 2] > 0).sum())


def _check_box(bbox, coverage, kp) -> None:
    x, y, w, h = bbox
    rows, cols = np.nonzero(coverage)
    assert x <= cols.min() and cols.max() + 1 <= x + w and y <= rows.min() and rows.max() + 1 <= y + h
    labelled = kp[kp[:, 2] > 0, :2] + 0.5                # continuous pixel coordinates
    assert np.all((labelled >= [x, y]) & (labelled <= [x + w, y + h]))
    visible = kp[kp[:, 2] == 2, :2] + 0.5
    assert np.all((visible >= [x, y]) & (visible <= [x + w, y + h]))


def _check_side(ann, labels) -> None:
    side, other = labels["side"], {"left": "right", "right": "left"}[labels["side"]]
    assert ann["hand_type"] == side
    assert ann[f"{side}hand_valid"] is True and ann[f"{other}hand_valid"] is False
    assert ann[f"{side}hand_kpts"] == ann["keypoints"] and ann[f"{side}hand_box"] == ann["bbox"]
    assert max(ann[f"{other}hand_kpts"]) == 0 and len(ann[f"{other}hand_kpts"]) == 63


def test_images_are_the_frames(coco_export):
    """Opaque frames (over a background) are the dataset's PNGs byte for byte."""
    dataset, where = coco_export
    for path in sorted((where / "images").iterdir()):
        labels = _labels(dataset, int(path.stem))
        if labels["render"].get("background"):
            assert path.read_bytes() == (dataset / "images" / path.name).read_bytes()
        else:
            assert read_png(path).shape[2] == 3


def test_rle_is_pycocotools_encoding():
    """encode_mask (no pycocotools at run time) writes what pycocotools.mask.encode writes, decoded back exactly."""
    rng = np.random.default_rng(7)
    for case in range(200):
        h, w = (int(n) for n in rng.integers(1, 40, 2))
        coverage = (rng.random((h, w)) * 256 * (case % 4 + 1) / 4).astype(np.uint8)
        if case % 17 == 0:
            coverage[:] = 255 * (case % 2)
        rle, area = encode_mask(coverage)
        ref = mask_utils.encode(np.asfortranarray(coverage >= MASK_THRESHOLD, dtype=np.uint8))
        assert rle["counts"] == ref["counts"].decode() and rle["size"] == [h, w]
        assert area == int(mask_utils.area(ref))
        assert np.array_equal(mask_utils.decode({**rle, "counts": rle["counts"].encode()}), coverage >= 128)


def test_a_frame_without_background_is_composited_over_black(tmp_path):
    """mmpose reads 3 channels and drops alpha: straight colour is composited over black in linear light."""
    rgba = np.zeros((2, 3, 4), np.uint8)
    rgba[..., :3] = [[200, 100, 50]]
    rgba[..., 3] = [[0, 128, 255], [64, 192, 255]]
    write_png(tmp_path / "in.png", rgba)
    _place_image(tmp_path / "in.png", tmp_path / "out.png", opaque=False)
    out = read_png(tmp_path / "out.png")
    assert out.shape == (2, 3, 3)
    lin = np.where(rgba[..., :3] / 255 <= 0.04045, rgba[..., :3] / 255 / 12.92,
                   ((rgba[..., :3] / 255 + 0.055) / 1.055) ** 2.4) * rgba[..., 3:] / 255
    srgb = np.where(lin <= 0.0031308, lin * 12.92, 1.055 * lin ** (1 / 2.4) - 0.055)
    assert np.abs(out.astype(int) - np.rint(srgb * 255)).max() <= 1
    assert np.all(out[0, 0] == 0) and np.array_equal(out[:, 2], rgba[:, 2, :3])


def test_mano_ordered_labels_are_reordered_by_name(small_dataset):
    dataset, _ = small_dataset
    labels = _labels(dataset, 0)
    perm = [keypoint_names("openpose").index(n) for n in keypoint_names("mano")]
    mano = {**labels, "keypoint_order": "mano", "keypoint_names": keypoint_names("mano")}
    for key in ("keypoints_2d", "in_image", "visibility"):
        mano[key] = [labels[key][i] for i in perm]
    np.testing.assert_array_equal(coco_keypoints(mano), coco_keypoints(labels))
    with pytest.raises(InputError, match="x.json: keypoint_names lack 20 of freihand2d's keypoints"):
        coco_keypoints({**labels, "keypoint_names": ["wrist"] + ["palm1"] * 20}, "x.json")


def test_export_replaces_its_own_layout_and_refuses_other_folders(coco_export, tmp_path, capsys):
    dataset, where = coco_export
    again = tmp_path / "again"
    shutil.copytree(where, again)
    (again / "stale.txt").write_text("from before")
    assert main(["dataset", "export", str(dataset), "--format", "coco", "--out", str(again)]) == 0
    assert not (again / "stale.txt").exists()
    files = sorted(p.relative_to(where) for p in where.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    assert all((where / f).read_bytes() == (again / f).read_bytes() for f in files)     # the same bytes again
    assert [p.name for p in tmp_path.iterdir()] == ["again"]           # no staging folder left
    other = tmp_path / "other"
    other.mkdir()
    (other / "keep.txt").write_text("mine")
    capsys.readouterr()
    assert main(["dataset", "export", str(dataset), "--format", "coco", "--out", str(other)]) == 2
    assert "not a COCO export" in capsys.readouterr().err
    assert [p.name for p in other.iterdir()] == ["keep.txt"]


def test_a_dataset_without_frames_is_refused(tmp_path):
    from darthand.dataset.coco import write_coco

    (tmp_path / "dataset.json").write_text("{}")
    with pytest.raises(InputError, match="no rendered frames"):
        write_coco(tmp_path)


def test_render_dataset_formats_coco_without_background(package, tmp_path):
    """`render-dataset --formats coco` writes the layout after rendering; frames without a background are RGB
    composites, and their annotations hold as the exported dataset's do."""
    model, tex, acc = package
    out = tmp_path / "ds"
    assert main(["render-dataset", model, "--textures", tex, "--accessories", acc, "--count", "4", "--seed", "2",
                 "--size", "48", "--processes", "1", "--backgrounds", "none", "--split", "1,0,0", "--out", str(out),
                 "--formats", "coco"]) == 0
    coco = _load(out / "coco", "train")
    assert sorted(coco.getImgIds()) == [0, 1, 2, 3]
    for ann in coco.loadAnns(coco.getAnnIds()):
        labels = _labels(out, ann["image_id"])
        assert not labels["render"].get("background")
        assert read_png(out / "coco" / "images" / f"{ann['image_id']:06d}.png").shape == (48, 48, 3)
        coverage = read_png(out / "masks" / f"{ann['image_id']:06d}.png")[..., 0]
        _check_mask(coco, ann, coverage)
        kp = np.array(ann["keypoints"], float).reshape(21, 3)
        _check_keypoints(kp, labels, ann)
        _check_box(ann["bbox"], coverage, kp)
