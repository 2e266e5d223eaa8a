"""HaMeR's layout (github.com/geopavlakos/hamer), so its training and evaluation code read a darthand dataset
unchanged:

    OUT/<split>/000000.tar, ...  WebDataset shards as HaMeR's training tars (configs/datasets_tar.yaml: URLS
                                 .../{000000..N}.tar, read by ImageDataset.load_tars_as_webdataset): one sample per
                                 frame, up to SAMPLES_PER_SHARD per shard, in frame order; its key is the zero-padded
                                 frame index, its members <key>.jpg (the image) and <key>.data.pyd (a pickled list
                                 with one dict per hand, below: two for a two-hand frame)
    OUT/<split>.npz              val and test: HaMeR's evaluation file (configs/datasets_eval.yaml: DATASET_FILE, read
                                 by ImageDataset.__init__), one row per hand
    OUT/images/<split>/<key>.jpg the images the .npz rows name (imgname, relative to IMG_DIR = OUT/images)
    OUT/README.md                what the fields hold for this dataset, and the config entries that read it

A hand's dict in data.pyd (float32 numpy arrays):

    keypoints_2d  (21, 3)  pixels in OpenCV's convention (pixel centres at integers: HaMeR flips u -> W - 1 - u),
                           then confidence 1 (every keypoint's position is exact, occluded or not)
    keypoints_3d  (21, 4)  camera frame (OpenCV's), metres, then confidence 1; OpenPose order (wrist, then thumb,
                           index, middle, ring, pinky, root -> tip), as HaMeR's MANO wrapper orders its joints
    center, scale (2,)     the box: centre (pixels) and [width, height] / 200, the tight box of keypoints_2d
                           enlarged BOX_RESCALE times about its centre (HaMeR's demo.py boxes a hand so at inference)
    hand_pose     (48,)    axis-angle, global rotation (camera frame) then the 15 finger joints, relative to the
                           flat hand: HaMeR's MANO is smplx's MANOLayer, whose forward adds no mean pose
    betas         (10,)    MANO shape
    right, has_hand_pose, has_betas   0-d: 1.0 / 0.0
    extra_info    {frame, side, visibility (21,) bool}

Left hands are written as they are (the left hand's own keypoints and MANO_LEFT parameters, right = 0): HaMeR's
loader flips them into right ones itself (datasets/utils.get_example). For a MANO model, the five fingertips are
the mesh vertices smplx names (744, 320, 443, 554, 671: what HaMeR's MANO regresses), not darthand's labels' own
tips (745, 317, 444, 556, 673): so MANO posed from the written parameters gives the written keypoints. A hand that
is not MANO's (the open hand) keeps its labels' keypoints, and its MANO values are written as zeros with
has_hand_pose = has_betas = 0, unless allow_non_mano (its pose written, has_hand_pose 1; betas still 0).
"""

from __future__ import annotations

import io
import os
import pickle
import tarfile
import tempfile
from pathlib import Path

import numpy as np

from darthand.dataset.frames import frame_names
from darthand.dataset.freihand import LEFT_MODES, model_kinds
from darthand.dataset.hands import hands_of
from darthand.dataset.run import rendered_dataset
from darthand.dataset.webdataset import add_member
from darthand.errors import InputError
from darthand.fileio import atomic_path, read_json, write_bytes
from darthand.render.image import over_black, read_straight_png

SAMPLES_PER_SHARD = 1000
SPLITS = ("train", "val", "test")
EVAL_SPLITS = ("val", "test")
JPEG_QUALITY = 95
BOX_RESCALE = 2.0                       # demo.py's --rescale_factor default
SCALE_UNIT = 200.0                      # HaMeR's scale = box size / 200
SMPLX_TIP_IDS = np.array([744, 320, 443, 554, 671])     # smplx vertex_ids['mano']: thumb, index, middle, ring, pinky
OPENPOSE_TIPS = np.array([4, 8, 12, 16, 20])            # the tips' places in the OpenPose order
MANO_VERTICES = 778
PICKLE_PROTOCOL = 4


def write_hamer(dataset, out=None, *, left: str = "mirror", allow_non_mano: bool = False) -> Path:
    """Write HaMeR's layout of a rendered dataset folder into `out` (default DATASET/hamer); left: "mirror" (left
    hands written as left hands, right = 0: HaMeR's loader mirrors them) or "skip" (module docstring)."""
    if left not in LEFT_MODES:
        raise InputError(f"--left: {left!r} is not one of {', '.join(LEFT_MODES)}")
    root = Path(dataset)
    doc, frames = rendered_dataset(root, SPLITS)
    kinds = model_kinds(doc.get("models") or {})
    out = Path(out) if out is not None else root / "hamer"
    chosen = {split: [f for f in frames if f["split"] == split and (left != "skip" or f.get("side") != "left")]
              for split in SPLITS}
    for split, some in chosen.items():
        check_no_stale_shards(out / split, -(-len(some) // SAMPLES_PER_SHARD))
    counts: dict = {}
    for split, some in chosen.items():
        rows = _write_split(root, out, split, some, kinds, allow_non_mano, left)
        if rows is not None:
            counts[split] = rows
    write_bytes(out / "README.md", _readme(out, doc.get("models") or {}, counts, left, allow_non_mano).encode())
    return out


def check_no_stale_shards(folder: Path, shards: int) -> None:
    """Refuse (before anything is written) a folder holding shards numbered from `shards` on: an earlier, larger
    export's, which a brace pattern or glob over the folder would read with this one's."""
    stale = sorted(p.name for p in folder.glob("[0-9][0-9][0-9][0-9][0-9][0-9].tar") if int(p.name[:6]) >= shards)
    if stale:
        raise InputError(f"{folder}: holds {len(stale)} shards ({stale[0]} ..) beyond the {shards} this export "
                         f"writes, from an earlier export: remove them or export into another folder")


def _write_split(root: Path, out: Path, split: str, frames: list, kinds: dict, allow_non_mano: bool,
                 left: str = "mirror"):
    """The shards of one split (and its .npz and images for an evaluation split); returns {shards, hands, mano}
    or None when the split has no frames."""
    if not frames:
        return None
    rows: list[dict] = []
    names: list[str] = []
    sides: list[str] = []
    for shard, k in enumerate(range(0, len(frames), SAMPLES_PER_SHARD)):
        with atomic_path(out / split / f"{shard:06d}.tar") as tmp, \
                tarfile.open(tmp, "w", format=tarfile.USTAR_FORMAT) as tar:
            for frame in frames[k:k + SAMPLES_PER_SHARD]:
                key, jpeg, hands = _sample(root, out, frame, kinds, allow_non_mano, left)
                add_member(tar, f"{key}.jpg", jpeg)
                add_member(tar, f"{key}.data.pyd", pickle.dumps(hands, protocol=PICKLE_PROTOCOL))
                sides += [h["extra_info"]["side"] for h in hands]
                if split in EVAL_SPLITS:
                    write_bytes(out / "images" / split / f"{key}.jpg", jpeg)
                    rows += hands
                    names += [f"{split}/{key}.jpg"] * len(hands)
    if split in EVAL_SPLITS:
        _write_npz(out / f"{split}.npz", rows, names)
    shards = -(-len(frames) // SAMPLES_PER_SHARD)
    return {"shards": shards, "hands": len(sides), "mano": sum(bool(kinds.get(side)) for side in sides)}


def _sample(root: Path, out: Path, frame: dict, kinds: dict, allow_non_mano: bool,
            left: str = "mirror") -> tuple[str, bytes, list[dict]]:
    """(key, JPEG bytes, the dicts of its hands) of one frame: one per hand of a two-hand frame (its left one left
    out with left 'skip')."""
    names = frame_names(frame["index"])
    labels = read_json(root / names["labels"], "labels")
    if labels.get("keypoint_order") != "openpose":
        raise InputError(f"{root / names['labels']}: HaMeR export needs openpose keypoints (labels keypoint_order)")
    meshes = None
    hands = []
    for b, own in enumerate(hands_of(labels)):
        if left == "skip" and own["side"] == "left":
            continue
        hand = {**labels, **own}
        mano = bool(kinds.get(hand["side"])) and hand.get("mesh", {}).get("base_vertices") == MANO_VERTICES
        vertices = None
        if mano:
            meshes = np.load(root / names["vertices"]) if meshes is None else meshes
            vertices = meshes[b] if meshes.ndim == 3 else meshes
        hands.append(hand_record(hand, vertices, mano=mano, pose=mano or allow_non_mano, index=int(frame["index"])))
    jpeg = jpeg_bytes(over_black(read_straight_png(root / names["image"])), out)
    return Path(names["labels"]).stem, jpeg, hands


def hand_record(labels: dict, vertices, *, mano: bool, pose: bool, index: int) -> dict:
    """One hand's dict of data.pyd (module docstring) from its labels. vertices (V, 3): the posed mesh, camera
    frame, metres (read for a MANO hand's tips; None otherwise); mano: the hand is MANO's (its betas are written);
    pose: write its MANO pose (has_hand_pose 1)."""
    K = np.asarray(labels["K"], float)
    points = hamer_keypoints(labels, vertices if mano else None)
    uv = project(K, points)
    center, size = keypoint_box(uv)
    params = labels.get("mano")
    hand_pose, betas = np.zeros(48), np.zeros(10)
    has_pose = has_betas = 0.0
    if params is not None and pose:
        hand_pose, has_pose = np.concatenate([params["global_orient"], params["hand_pose"]]), 1.0
    if params is not None and mano:
        b = np.asarray(params["betas"], float)[:10]
        betas[:len(b)], has_betas = b, 1.0
    ones = np.ones((21, 1))
    f32 = np.float32
    return {"keypoints_2d": np.hstack([uv, ones]).astype(f32), "keypoints_3d": np.hstack([points, ones]).astype(f32),
            "center": center.astype(f32), "scale": (BOX_RESCALE * size / SCALE_UNIT).astype(f32),
            "hand_pose": hand_pose.astype(f32), "betas": betas.astype(f32),
            "right": np.array(labels["side"] == "right", f32), "has_hand_pose": np.array(has_pose, f32),
            "has_betas": np.array(has_betas, f32),
            "extra_info": {"frame": index, "side": labels["side"],
                           "visibility": np.asarray(labels["visibility"], bool)}}


def hamer_keypoints(labels: dict, vertices=None) -> np.ndarray:
    """(21, 3) the keypoints HaMeR's MANO gives, camera frame, metres, OpenPose order: the labels' keypoints, with
    the tips the smplx vertices of `vertices` (a MANO mesh, (V >= 778, 3)) when given."""
    points = np.asarray(labels["keypoints_3d"], float).copy()
    if vertices is not None:
        points[OPENPOSE_TIPS] = np.asarray(vertices, float)[SMPLX_TIP_IDS]
    return points


def project(K, points) -> np.ndarray:
    """(N, 2) pixels of camera-frame points (N, 3) through darthand's K (pixel-corner origin), in OpenCV's
    convention (pixel centres at integers), which HaMeR's flip (u -> W - 1 - u) assumes."""
    p = np.asarray(points, float) @ np.asarray(K, float).T
    return p[:, :2] / p[:, 2:3] - 0.5


def keypoint_box(uv) -> tuple[np.ndarray, np.ndarray]:
    """(centre (2,), [width, height] (2,)) pixels of the tight box of 2-D points (N, 2)."""
    lo, hi = np.min(uv, axis=0), np.max(uv, axis=0)
    return (lo + hi) / 2, hi - lo


def jpeg_bytes(rgb: np.ndarray, scratch: Path) -> bytes:
    """JPEG (quality JPEG_QUALITY) of an (H, W, 3) uint8 image, encoded through a temporary file in `scratch`."""
    import OpenImageIO as oiio      # lazy: `darthand --help` imports this module through dataset/writers

    buf = oiio.ImageBuf(oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(rgb))
    buf.specmod().attribute("compression", f"jpeg:{JPEG_QUALITY}")
    scratch.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=".hamer-", suffix=".jpg", dir=scratch)
    os.close(fd)
    try:
        if not buf.write(name, fileformat="jpeg"):
            raise OSError(f"{scratch}: cannot write JPEG ({buf.geterror()})")
        return Path(name).read_bytes()
    finally:
        Path(name).unlink(missing_ok=True)


def _write_npz(path: Path, rows: list[dict], names: list[str]) -> None:
    """HaMeR's evaluation .npz of an evaluation split: one row per hand. scale is the box in PIXELS (N, 2): HaMeR's
    ImageDataset divides it by 200 when it reads it."""
    def stack(key):
        return np.stack([r[key] for r in rows]).astype(np.float32)

    arrays = {"imgname": np.array(names), "center": stack("center"), "scale": stack("scale") * SCALE_UNIT,
              "right": stack("right"), "hand_pose": stack("hand_pose"), "has_hand_pose": stack("has_hand_pose"),
              "betas": stack("betas"), "has_betas": stack("has_betas"), "hand_keypoints_2d": stack("keypoints_2d"),
              "hand_keypoints_3d": stack("keypoints_3d"),
              "frame": np.array([r["extra_info"]["frame"] for r in rows], np.int64)}
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    write_bytes(path, buf.getvalue())


def _readme(out: Path, models: dict, counts: dict, left: str, allow_non_mano: bool) -> str:
    """README.md of a HaMeR export: what the fields hold, where they depart from HaMeR's own data, the configs."""
    sources = "; ".join(f"{side}: {info.get('source', '?')} ({info.get('format', 'format not recorded')})"
                        for side, info in models.items()) or "not recorded"
    lines = [f"# HaMeR layout of a darthand dataset\n\nModels: {sources}.\n\n## Contents\n"]
    for split, c in counts.items():
        lines.append(f"- `{split}/{{000000..{c['shards'] - 1:06d}}}.tar`: {c['hands']} hands "
                     f"({c['mano']} of a MANO model, with MANO parameters)"
                     + (f"; `{split}.npz` and `images/{split}/`" if split in EVAL_SPLITS else ""))
    lines.append("\nLeft hands: " + ("left out (--left skip)." if left == "skip" else
                 "written as left hands (right = 0, their own keypoints and MANO_LEFT parameters); HaMeR's loader "
                 "flips them into right hands (image, u -> W - 1 - u, x -> -x, axis-angle (x, y, z) -> (x, -y, -z))."))
    lines.append(_FIELDS)
    lines.append("Hands not of a MANO model: keypoints exact; hand_pose "
                 + ("written (that model's joint rotations in MANO's layout, has_hand_pose 1)" if allow_non_mano
                    else "zeros with has_hand_pose 0") + "; betas zeros with has_betas 0.\n")
    lines.append(_configs(out, counts))
    return "\n".join(lines)


_FIELDS = """
## data.pyd: a pickled list with one dict per hand (float32 numpy arrays)

- `keypoints_2d` (21, 3): pixels, OpenCV's convention (pixel centres at integers; darthand's labels put them at
  +0.5), then confidence 1.0 for every keypoint (positions are exact even when occluded; per-keypoint visibility is
  in `extra_info.visibility`).
- `keypoints_3d` (21, 4): camera frame (OpenCV's: x right, y down, z forward), metres, then confidence 1.0. OpenPose
  order (wrist, thumb, index, middle, ring, pinky, root to tip). For a MANO model the fingertips are the mesh
  vertices 744, 320, 443, 554, 671 (smplx's, which HaMeR's MANO uses), not darthand's labels' tips.
- `center` (2,), `scale` (2,): the box, centre in pixels and [width, height] / 200: the tight box of keypoints_2d
  enlarged 2.0 times about its centre (HaMeR's demo.py boxes hands at inference so, --rescale_factor 2.0).
  HaMeR's loader squares it to the model's aspect (BBOX_SHAPE) and takes the larger side.
- `hand_pose` (48,): axis-angle, global rotation in the camera frame then the 15 finger joints, relative to the
  flat hand (HaMeR's MANO, smplx's MANOLayer, adds no mean pose). `betas` (10,): MANO shape.
- `right`, `has_hand_pose`, `has_betas`: 0-d, 1.0 or 0.0. `extra_info`: {frame, side, visibility}.

No `detection.npz` member: HaMeR's loader then takes the whole image as the mask.
Images: JPEG quality 95, RGB; frames rendered without a background are composited over black in linear light (the
colour HaMeR's crop pads with).

## <split>.npz (val, test): HaMeR's evaluation file, one row per hand

`imgname` (relative to `images/`), `center` (N, 2), `scale` (N, 2) the same box in PIXELS (HaMeR's ImageDataset
divides it by 200 when reading), `right`, `hand_pose`, `has_hand_pose`, `betas`, `has_betas`,
`hand_keypoints_2d` (N, 21, 3), `hand_keypoints_3d` (N, 21, 4), and `frame` (darthand frame index, not read by
HaMeR). The box is already enlarged: evaluate with rescale_factor -1 (as eval.py does for FREIHAND-VAL), which crops
as training does; eval.py's predictions file ([keypoints, vertices]) is FreiHAND's pred.json, which `darthand eval`
reads.

## Departures from HaMeR's own data

- Synthetic images with exact labels: every keypoint has confidence 1 (HaMeR's data has 0 where unannotated).
- The box comes from the exact keypoints, not from a detector or annotation.
- HaMeR predicts every hand as a right one: its predictions for left rows (right = 0) are of the mirrored hand;
  mirror them (x -> -x) before comparing with the left hand's keypoints_3d.
"""


def _configs(out: Path, counts: dict) -> str:
    """The entries of HaMeR's datasets_tar.yaml and datasets_eval.yaml that read this export."""
    root = out.resolve()
    text = ["## HaMeR configs\n\n```yaml\n# hamer/configs/datasets_tar.yaml"]
    for split, c in counts.items():
        text.append(f"DARTHAND-{split.upper()}:\n    TYPE: ImageDataset\n"
                    f"    URLS: {root}/{split}/{{000000..{c['shards'] - 1:06d}}}.tar\n    epoch_size: {c['hands']}")
    text.append("# hamer/configs/datasets_eval.yaml")
    for split in (s for s in EVAL_SPLITS if s in counts):
        text.append(f"DARTHAND-{split.upper()}-EVAL:\n    TYPE: ImageDataset\n    DATASET_FILE: {root}/{split}.npz\n"
                    f"    IMG_DIR: {root}/images/\n    KEYPOINT_LIST: [0] # Dummy")
    return "\n".join(text) + "\n```\n"
