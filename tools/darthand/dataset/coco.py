"""mmpose's COCO-style hand layout, so mmpose's hand configs (FreiHAND's, OneHand10K's, COCO-WholeBody-Hand's) train
on a darthand dataset with data_root and ann_file changed:

    OUT/annotations/darthand_<split>.json   one COCO keypoint file per split (train, val, test: the frames' splits)
    OUT/images/<n>.png                      the frames' images (hard links to the dataset's, or copies; a frame
                                            rendered without a background composited over black, as mmpose reads
                                            3 channels and drops alpha)
    OUT/README.md                           what each field holds, and where it departs from the originals

Per split file: `images` (id = frame index, file_name relative to OUT, width, height), `categories` (one: id 1,
'hand', the 21 keypoint names and the 20 skeleton links of mmpose's freihand2d in its order, 1-based as COCO's
skeleton is) and per frame one `annotations` entry:

    id                 frame index + 1 (COCOeval takes id 0 for "no match")
    image_id           frame index
    category_id        1
    keypoints          21 x (x, y, v) in freihand2d's order (wrist, thumb1..4, forefinger1..4, middle_finger1..4,
                       ring_finger1..4, pinky_finger1..4: darthand's 'openpose' order; 'mano'-ordered labels are
                       reordered by name). x, y in pixels with pixel centres at integers (COCO's keypoints and
                       mmpose's flip, x -> w - 1 - x): the labels' keypoints_2d - 0.5, to 1e-4 pixel. v: 2
                       visible (in the image and labels.visibility true), 1 labelled but occluded (in the image,
                       visibility false), 0 not labelled (outside the image: x = y = 0, as COCO writes it)
    num_keypoints      keypoints with v > 0
    segmentation       COCO RLE ({size: [h, w], counts}, pycocotools.mask.encode) of the mask's pixels covered at
                       least half (8-bit coverage >= MASK_THRESHOLD): hand and accessory
    area               that mask's pixel count
    bbox               [x, y, w, h], pixel corners (COCO's box convention): the pixels the mask covers at all
                       (coverage > 0, labels.bbox) and those holding a labelled keypoint
    iscrowd            0
    hand_type          'right' or 'left' (InterHand2.6M's field), hand_type_valid 1. Left hands stay left: mmpose
                       flips at augmentation (hand keypoints have no flip pairs)
    lefthand_kpts, righthand_kpts, lefthand_box, righthand_box, lefthand_valid, righthand_valid
                       COCO-WholeBody's hand fields (CocoWholeBodyHandDataset reads only these): the frame's hand
                       under its side, the other side zeros and valid false

A two-hand frame (issue 29) has one annotation per hand, each with its side as hand_type, its segmentation the
hand's pixels in instances/<n>.png (and its accessory's), the second hand's id TWO_HAND_IDS + frame index + 1.
A frame with neither a mask pixel nor a labelled keypoint lists its image without an annotation. The layout is built
in a staging folder and moved into place whole: an existing OUT that is this layout is replaced, anything else is
refused.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from darthand.dataset.frames import frame_names
from darthand.dataset.hands import hands_of
from darthand.dataset.run import rendered_dataset
from darthand.errors import InputError
from darthand.fileio import read_json, replace_folder, staging_folder
from darthand.render.image import over_black, read_png, read_straight_png, write_png
from darthand.render.png import open_png8

SPLITS = ("train", "val", "test")
MASK_THRESHOLD = 128
KEYPOINT_DECIMALS = 4            # 1e-4 pixel
RLE_GROUPS = 13                  # 5-bit groups of a 64-bit run length or difference
ANNOTATIONS = "annotations/darthand_{split}.json"
TWO_HAND_IDS = 1_000_000_000          # a two-hand frame's second hand's annotation id: this + frame index + 1
README_TITLE = "# mmpose COCO-style hand layout of a darthand dataset"
FINGERS = {"thumb": "thumb", "index": "forefinger", "middle": "middle_finger", "ring": "ring_finger",
           "pinky": "pinky_finger"}
KEYPOINT_NAMES = ("wrist",) + tuple(f"{name}{k}" for name in FINGERS.values() for k in range(1, 5))
SKELETON = tuple((0 if k == 1 else 4 * f + k - 1, 4 * f + k) for f in range(5) for k in range(1, 5))
"""freihand2d's 20 links (0-based keypoint indices), in its order: per finger wrist -> 1, 1 -> 2, 2 -> 3, 3 -> 4."""


def category() -> dict:
    """The one COCO category: 'hand' with freihand2d's keypoint names and skeleton (1-based, as COCO's)."""
    return {"id": 1, "name": "hand", "supercategory": "hand", "keypoints": list(KEYPOINT_NAMES),
            "skeleton": [[a + 1, b + 1] for a, b in SKELETON]}


def keypoint_permutation(names, where: str = "labels") -> np.ndarray:
    """(21,) int: for each of KEYPOINT_NAMES, its position in darthand's `names` (labels.keypoint_names of the
    labels file `where`)."""
    ours = {FINGERS.get(n[:-1], n[:-1]) + n[-1] if n[-1:].isdigit() else n: i for i, n in enumerate(names)}
    missing = [n for n in KEYPOINT_NAMES if n not in ours]
    if missing:
        raise InputError(f"{where}: keypoint_names lack {len(missing)} of freihand2d's keypoints ({missing[0]}, ...)")
    return np.array([ours[n] for n in KEYPOINT_NAMES])


def coco_keypoints(labels: dict, where: str = "labels") -> np.ndarray:
    """(21, 3) float64 COCO keypoints of a frame's labels (the file `where`): x, y (pixel centres at integers), v
    in {0, 1, 2}."""
    order = keypoint_permutation(labels["keypoint_names"], where)
    uv = np.asarray(labels["keypoints_2d"], np.float64)[order] - 0.5
    inside = np.asarray(labels["in_image"], bool)[order]
    seen = np.asarray(labels["visibility"], bool)[order]
    v = np.where(inside, np.where(seen, 2, 1), 0)
    return np.column_stack([np.where(inside[:, None], uv, 0.0), v])


def coco_box(coverage: np.ndarray, keypoints: np.ndarray) -> list[float] | None:
    """[x, y, w, h] pixels (corners) of the pixels with coverage (H, W) > 0 and those holding a labelled keypoint
    of keypoints (21, 3) (COCO x, y, v); None when there are neither."""
    rows, cols = np.flatnonzero(coverage.max(axis=1) > 0), np.flatnonzero(coverage.max(axis=0) > 0)
    labelled = keypoints[keypoints[:, 2] > 0, :2]
    pixels = np.floor(labelled + 0.5)                   # the pixel (column, row) a keypoint lies in
    xs = np.concatenate([cols[:1], cols[-1:], pixels[:, 0]])
    ys = np.concatenate([rows[:1], rows[-1:], pixels[:, 1]])
    if not len(xs):
        return None
    x0, y0 = float(xs.min()), float(ys.min())
    return [x0, y0, float(xs.max()) + 1 - x0, float(ys.max()) + 1 - y0]


def encode_mask(coverage: np.ndarray) -> tuple[dict, int]:
    """(COCO RLE {size: [h, w], counts: text}, pixel count) of the binary mask coverage (H, W) uint8 >=
    MASK_THRESHOLD: what pycocotools.mask.encode writes, without depending on it at run time."""
    binary = coverage >= MASK_THRESHOLD
    return {"size": [int(binary.shape[0]), int(binary.shape[1])], "counts": rle_text(run_lengths(binary))}, \
        int(binary.sum())


def run_lengths(binary: np.ndarray) -> np.ndarray:
    """(R,) int64 lengths of alternating runs of 0 and 1 over binary (H, W) in column-major order (COCO's RLE),
    starting with a run of 0s (of length 0 when the first pixel is set)."""
    flat = binary.ravel(order="F").astype(np.int8)
    bounds = np.concatenate([[0], np.flatnonzero(np.diff(flat)) + 1, [flat.size]])
    runs = np.diff(bounds)
    return np.concatenate([[0], runs]) if flat.size and flat[0] else runs


def rle_text(counts) -> str:
    """COCO's compressed RLE string of run lengths (maskApi.c rleToString: from the third run on, the difference to
    the run two before; each value in 5-bit groups, low first, 0x20 marking more, offset by 48), vectorised."""
    x = np.asarray(counts, np.int64).copy()
    x[3:] -= np.asarray(counts, np.int64)[1:-2]
    shifts = 5 * np.arange(RLE_GROUPS)
    groups = (x[:, None] >> shifts) & 0x1F                           # (R, G) 5-bit groups, low first
    rest = x[:, None] >> (shifts + 5)                                # arithmetic: a negative value ends at -1
    more = np.where(groups & 0x10, rest != -1, rest != 0)
    emitted = np.concatenate([np.ones((len(x), 1), bool), np.cumprod(more, axis=1)[:, :-1].astype(bool)], axis=1)
    chars = (groups | np.where(more, 0x20, 0)) + 48
    return chars[emitted].astype(np.uint8).tobytes().decode("ascii")


def annotation(index: int, labels: dict, coverage: np.ndarray, where: str = "labels") -> dict | None:
    """The COCO annotation of frame `index` (module docstring) from its labels (the file `where`) and mask coverage
    (H, W) uint8; None when it has neither a mask pixel nor a labelled keypoint."""
    kp = coco_keypoints(labels, where)
    box = coco_box(coverage, kp)
    if box is None:
        return None
    segmentation, area = encode_mask(coverage)
    flat = [round(float(x), KEYPOINT_DECIMALS) if i % 3 < 2 else int(x) for i, x in enumerate(kp.ravel())]
    side = labels["side"]
    ann = {"id": index + 1, "image_id": index, "category_id": 1, "keypoints": flat,
           "num_keypoints": int((kp[:, 2] > 0).sum()), "segmentation": segmentation, "area": area, "bbox": box,
           "iscrowd": 0, "hand_type": side, "hand_type_valid": 1}
    for other in ("left", "right"):
        mine = other == side
        ann[f"{other}hand_kpts"] = flat if mine else [0] * len(flat)
        ann[f"{other}hand_box"] = box if mine else [0.0] * 4
        ann[f"{other}hand_valid"] = mine
    return ann


def write_coco(dataset, out=None) -> Path:
    """Write the COCO-style layout of a rendered dataset folder into `out` (default DATASET/coco); returns `out`.
    An existing `out` is replaced when it is this layout, else refused (InputError)."""
    root = Path(dataset)
    _, frames = rendered_dataset(root, SPLITS)
    out = Path(out) if out is not None else root / "coco"
    _check_replaceable(out)
    tmp = staging_folder(out)
    try:
        counts = _write_splits(root, frames, tmp)
        (tmp / "README.md").write_text(_readme(counts))
        replace_folder(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def _write_splits(root: Path, frames: list[dict], tmp: Path) -> dict:
    """Write images and per-split annotation files of `frames` (shard records) into `tmp`; {split: [images,
    annotations, left hands]}."""
    (tmp / "images").mkdir()
    (tmp / "annotations").mkdir()
    counts = {}
    for split in SPLITS:
        chosen = [f for f in frames if f["split"] == split]
        if chosen:
            counts[split] = _write_split(root, chosen, tmp, split)
    return counts


def _write_split(root: Path, frames: list[dict], tmp: Path, split: str) -> list[int]:
    """One split's annotation file (annotations streamed to a part file, then joined); [images, annotations,
    left hands]."""
    images, part, n_ann, n_left = [], tmp / f".{split}.part", 0, 0
    with open(part, "w") as f:
        for frame in frames:
            index, names = int(frame["index"]), frame_names(frame["index"])
            labels = read_json(root / names["labels"], "labels")
            width, height = labels["image_size"]
            images.append({"id": index, "file_name": names["image"], "width": width, "height": height})
            opaque = bool(labels.get("render", {}).get("background"))
            _place_image(root / names["image"], tmp / names["image"], opaque)
            for ann in frame_annotations(root, names, index, labels):
                f.write(json.dumps(ann) + "\n")
                n_ann, n_left = n_ann + 1, n_left + (ann["hand_type"] == "left")
    head = {"info": {"description": f"darthand dataset {root.name}, split {split}"}, "licenses": [],
            "categories": [category()], "images": images}
    with open(tmp / ANNOTATIONS.format(split=split), "w") as f, open(part) as lines:
        f.write(json.dumps(head)[:-1] + ', "annotations": [')
        for k, line in enumerate(lines):
            f.write((", " if k else "") + line.rstrip("\n"))
        f.write("]}\n")
    part.unlink()
    return [len(images), n_ann, n_left]


def frame_annotations(root: Path, names: dict, index: int, labels: dict) -> list[dict]:
    """A frame's annotations: one for a one-hand frame (or none, annotation()); one per hand of a two-hand frame,
    hand b's coverage its instances' pixels (1 + 2b its hand, 2 + 2b its accessory) and its id b * TWO_HAND_IDS +
    index + 1."""
    where = str(root / names["labels"])
    mask = _read_mask(root / names["mask"])
    hands = hands_of(labels)
    if len(hands) == 1:
        ann = annotation(index, {**labels, **hands[0]}, mask, where)
        return [] if ann is None else [ann]
    instances = _read_mask(root / "instances" / Path(names["image"]).name)
    anns = []
    for b, hand in enumerate(hands):
        own = np.where((instances == 1 + 2 * b) | (instances == 2 + 2 * b), mask, 0).astype(np.uint8)
        ann = annotation(index, {**labels, **hand}, own, where)
        if ann is not None:
            anns.append({**ann, "id": b * TWO_HAND_IDS + index + 1})
    return anns


def _place_image(src: Path, dst: Path, opaque: bool) -> None:
    """The frame's image at dst: a hard link (a copy where the file system has none) when opaque, else its straight
    colour composited over black in linear light and written as RGB."""
    if not opaque:
        rgba = read_straight_png(src)
        if rgba.shape[2] == 4:
            write_png(dst, over_black(rgba))
            return
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def _read_mask(path: Path) -> np.ndarray:
    """(H, W) uint8 coverage of a frame's mask PNG (render/png.py's decoder, else OpenImageIO)."""
    png = open_png8(path)
    if png is not None and png.channels == 1:
        out = np.empty((png.height, png.width, 1), np.uint8)
        if png.decode_into(out, 0, [0]):
            return out[..., 0]
    return read_png(path)[..., 0]


def _check_replaceable(out: Path) -> None:
    """Refuse an existing `out` that is not an earlier export of this layout (an empty folder is fine)."""
    if not out.exists():
        return
    if not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder; remove it or export elsewhere (--out)")
    readme = out / "README.md"
    ours = readme.is_file() and readme.read_text(errors="replace").startswith(README_TITLE)
    if not ours and any(out.iterdir()):
        raise InputError(f"{out}: exists and is not a COCO export (README.md says so); remove it or export "
                         f"elsewhere (--out)")


def _readme(counts: dict) -> str:
    """README.md of the layout: files, fields, departures from the originals, how mmpose reads it."""
    rows = "\n".join(f"- {split}: `{ANNOTATIONS.format(split=split)}`, {n[0]} images, {n[1]} annotations "
                     f"({n[2]} left hands)" for split, n in counts.items())
    return f"""{README_TITLE}

{rows}

Images are `images/<frame>.png` (file_name relative to this folder: mmpose's `data_root` is this folder and
`data_prefix=dict(img='')`). Frames rendered over a background are the dataset's own PNGs (hard links, or copies
where the file system has none; RGBA with alpha 255); frames without one are composited over black (RGB).

Fields of `annotations` (one per frame; a frame with no mask pixel and no keypoint in the image has none):

- `keypoints`: 21 x (x, y, v) in mmpose's freihand2d order (`categories[0].keypoints`; OneHand10K's and
  COCO-WholeBody-Hand's are the same). x, y: pixels, pixel centres at integers (darthand's labels' keypoints_2d,
  whose pixel centres are at +0.5, minus 0.5). v: 2 in the image and visible, 1 in the image but occluded (by
  another finger, the palm or an accessory; darthand's labels.visibility), 0 outside the image (x = y = 0).
  mmpose reads v > 0 as visible (keypoints_visible = min(1, v)), so occluded keypoints are trained on.
- `num_keypoints`: keypoints with v > 0. `iscrowd`: 0. `category_id`: 1.
- `segmentation`: COCO RLE (compressed counts, as pycocotools.mask.encode writes them) of the pixels whose 8-bit
  coverage is >= {MASK_THRESHOLD} (covered at least half); the mask holds the hand and any accessory it wears.
  `area`: that mask's pixel count.
- `bbox`: [x, y, w, h], pixel corners: every pixel the hand or accessory covers at all (coverage > 0) and every
  pixel holding a labelled keypoint. It can be a pixel wider than the RLE mask's box (edge pixels covered less
  than half).
- `hand_type`: 'right' or 'left', `hand_type_valid`: 1 (InterHand2.6M's fields). Left hands are kept as rendered;
  mmpose's RandomFlip mirrors at training time.
- `lefthand_kpts`, `righthand_kpts`, `lefthand_box`, `righthand_box`, `lefthand_valid`, `righthand_valid`:
  COCO-WholeBody's hand fields for the one hand of the frame; the other side's are zeros with valid false.

Departures from the originals: ids are darthand's (image id = frame index, annotation id = frame index + 1); there
is one hand per image and no person (COCO-WholeBody's body, face and foot fields are absent); `bbox` is the hand's
exact extent, not an annotator's box; images are the dataset's size, not FreiHAND's 224 x 224.

Reading it in mmpose: `OneHand10KDataset` (or `BaseCocoStyleDataset` with
`metainfo=dict(from_file='configs/_base_/datasets/freihand2d.py')`) reads `bbox` and `keypoints`;
`FreiHandDataset` ignores `bbox` and takes the whole image as 224 x 224, so use it only for a dataset rendered at
`--size 224`; `CocoWholeBodyHandDataset` reads the `*hand_*` fields. For example:

    dataset=dict(type='OneHand10KDataset', data_root='<this folder>/', data_mode='topdown',
                 ann_file='annotations/darthand_train.json', data_prefix=dict(img=''), pipeline=train_pipeline)
"""
