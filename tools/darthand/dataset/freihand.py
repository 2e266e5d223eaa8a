"""FreiHAND's layout, so code written for FreiHAND trains on a darthand dataset unchanged:

    OUT/<set>_K.json       per frame the 3 x 3 intrinsics, OpenCV's pixel convention (pixel centres at integers:
                           darthand's K with 0.5 subtracted from cx, cy)
    OUT/<set>_xyz.json     per frame the 21 keypoints (FreiHAND's order: wrist, then thumb .. pinky, root to tip),
                           camera frame, metres
    OUT/<set>_verts.json   per frame the hand's vertices without DART's wrist rings (MANO's 778 for MANO), metres
    OUT/<set>_mano.json    per frame [[61 numbers]]: 48 pose values (global rotation in the camera frame, then the
                           finger pose with the model's mean hand left out, flat_hand_mean false), 10 shape values,
                           the root keypoint's (index 9, middle-finger MCP) image position (u, v), and scale = focal /
                           root depth, focal the mean of fx and fy: FreiHAND's toolbox recovers the root as
                           [(u, v) - (cx, cy), focal] / scale and poses MANO from it
    OUT/<set>_frames.json  per row, the darthand frame index it came from (its labels say which side was rendered)
    OUT/<set>/rgb/%08d.jpg, OUT/<set>/mask/%08d.jpg   image (over black where the frame has no background), mask
    OUT/README.md          what the files hold for this dataset: the model, what the 61 values mean, mirrored rows

Sets by split: train -> training, val -> validation, test -> evaluation.

What the 61 values are worth depends on the hand the dataset was rendered with. For a model read from a MANO file
(`make assets MANO=...`) they are MANO's own parameters: MANO_RIGHT posed from them the FreiHAND way reproduces the
written keypoints and vertices. The open CC0 hand is not MANO: its 10 betas live in its own shape space and its
skeleton is not MANO's, so MANO posed from any row is a different hand. Its export is refused unless asked for
(`allow_non_mano`); the shape slots are then written as zeros, and README.md says so.

FreiHAND is right-handed (its MANO is MANO_RIGHT). A left-hand frame is mirrored into a right one (`left="mirror"`,
the default; `"skip"` leaves it out): image and mask flipped left-right, the camera-frame points x -> -x, K's
principal point cx -> W - cx (pixel-corner origin), the MANO rotations conjugated by diag(-1, 1, 1) (axis-angle
(x, y, z) -> (x, -y, -z) per joint, the global rotation too), the betas kept. With a left model that is the right
one mirrored (darthand's mirrored twin; MANO_LEFT is meant to be MANO_RIGHT's mirror image, which the tests check on
the MANO-format fixture only), the right model posed from the mirrored row is the mirrored hand; its translation,
left out of FreiHAND's row, follows from (u, v) and scale.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.dataset.frames import frame_names
from darthand.dataset.hands import hands_mean, hands_of, is_multi_hand
from darthand.dataset.run import rendered_dataset
from darthand.errors import InputError
from darthand.fileio import atomic_path, read_json, write_bytes
from darthand.model.mano_pkl import MANO_FORMAT
from darthand.model.mirror import mirror_points, mirror_pose
from darthand.render.image import read_png

SETS = {"train": "training", "val": "validation", "test": "evaluation"}
ROOT = 9
JPEG_QUALITY = 95
LEFT_MODES = ("mirror", "skip")


class _JsonList:
    """A JSON list written one item at a time into a temporary file, renamed into place by close()."""

    def __init__(self, path: Path):
        self._ctx = atomic_path(path)
        self._tmp = self._ctx.__enter__()
        self._f = open(self._tmp, "w")
        self._f.write("[")
        self.count = 0

    def add(self, item) -> None:
        self._f.write((", " if self.count else "") + json.dumps(item))
        self.count += 1

    def close(self) -> None:
        self._f.write("]\n")
        self._f.close()
        self._ctx.__exit__(None, None, None)


def freihand_mano_row(labels: dict, hands_mean, shape: bool = True) -> list[float]:
    """The 61 numbers of FreiHAND's training_mano.json for a (right-hand) frame's labels (module docstring).
    hands_mean (45,): the model's mean hand, left out of the finger pose; shape False writes the 10 shape slots as
    zeros (a model whose betas mean nothing to MANO)."""
    mano = labels["mano"]
    pose = np.concatenate([mano["global_orient"], np.asarray(mano["hand_pose"]) - np.asarray(hands_mean)])
    betas = np.zeros(10)
    if shape:
        b = np.asarray(mano["betas"], float)[:10]
        betas[:len(b)] = b
    K = freihand_K(labels["K"])
    root = np.asarray(labels["keypoints_3d"][ROOT], float)
    uv = (K @ root)[:2] / root[2]
    focal = 0.5 * (K[0, 0] + K[1, 1])
    return [*pose.tolist(), *betas.tolist(), *uv.tolist(), float(focal / root[2])]


def freihand_K(K) -> np.ndarray:
    """darthand's K (pixel-corner origin) in OpenCV's convention (pixel centres at integers)."""
    K = np.array(K, float)
    K[:2, 2] -= 0.5
    return K


def mirror_labels(labels: dict) -> dict:
    """The labels FreiHAND's writer reads (K, keypoints_3d, mano) of a frame mirrored left-right: the right hand
    that is the mirror image of the frame's left hand, seen in the image flipped left-right."""
    return {**mirror_hand(labels), "K": mirrored_K(labels), "side": "right"}


def mirrored_K(labels: dict) -> list:
    """A frame's K (3, 3) for its image flipped left-right: pixel column u -> W - u (pixel-corner origin), a skew
    (were there one) negated."""
    K = np.array(labels["K"], float)
    K[0, 2] = labels["image_size"][0] - K[0, 2]
    K[0, 1] = -K[0, 1]
    return K.tolist()


def mirror_hand(hand: dict, points: tuple = ("keypoints_3d",)) -> dict:
    """A hand's labels mirrored left-right (x -> -x in the camera frame): the other side, its MANO parameters
    (axis-angles and translation) and its 3-D `points` fields."""
    mano = dict(hand["mano"])
    mano["global_orient"] = mirror_pose(mano["global_orient"]).tolist()
    mano["hand_pose"] = mirror_pose(mano["hand_pose"]).tolist()
    mano["trans"] = mirror_points(mano["trans"]).tolist()
    return {**hand, "mano": mano, "side": "right" if hand.get("side") == "left" else "left",
            **{key: mirror_points(np.asarray(hand[key], float)).tolist() for key in points}}


def model_kinds(models: dict) -> dict:
    """{side: True when the side's model was read from a MANO file} for a dataset.json's `models`."""
    return {side: info.get("format") == MANO_FORMAT for side, info in models.items()}


def check_mano(models: dict, where, allow_non_mano: bool) -> bool:
    """Whether every model of a dataset is MANO (its FreiHAND rows then carry MANO's shape); raises InputError for
    a model that is not, unless allow_non_mano."""
    kinds = model_kinds(models)
    if all(kinds.values()) and kinds:
        return True
    if not allow_non_mano:
        side = next((s for s in sorted(kinds, reverse=True) if not kinds[s]), None)      # right first
        info = models.get(side, {})
        if side is not None and "format" not in info:
            raise InputError(f"{where}: FreiHAND export: models.{side} does not record the model's format (a dataset "
                             f"rendered before darthand recorded it), so whether it is MANO is unknown; render it "
                             f"again, or --allow-non-mano to write it with shape slots 0 (said in README.md)")
        raise InputError(f"{where}: FreiHAND export: the hand ({info.get('source', side or 'unknown')}) is not a MANO "
                         f"model, so training_mano.json's shape and pose values would pose a different hand in MANO; "
                         f"render from MANO (make assets MANO=MANO_RIGHT.pkl), or --allow-non-mano to write them "
                         f"anyway (shape slots 0, said in README.md)")
    return False


def right_hands_mean(models: dict) -> np.ndarray:
    """(45,) the right model's mean hand: its own, else the left model's mirrored (a left-only dataset)."""
    return hands_mean(models, "right")


def write_freihand(dataset, out=None, *, left: str = "mirror", allow_non_mano: bool = False) -> Path:
    """Write the FreiHAND layout of a rendered dataset folder into `out` (default DATASET/freihand); left: "mirror"
    (left-hand frames become right ones) or "skip". Refuses a dataset whose hand is not MANO unless
    allow_non_mano (module docstring)."""
    if left not in LEFT_MODES:
        raise InputError(f"--left: {left!r} is not one of {', '.join(LEFT_MODES)}")
    root = Path(dataset)
    doc, frames = rendered_dataset(root)
    models = doc.get("models") or {}
    is_mano = check_mano(models, root, allow_non_mano)
    hands_mean = right_hands_mean(models)
    out = Path(out) if out is not None else root / "freihand"
    writers: dict = {}
    counts = {"right": 0, "mirrored": 0, "skipped_left": 0}
    try:
        for frame in frames:
            if frame["split"] not in SETS:
                continue
            names = frame_names(frame["index"])
            labels = read_json(root / names["labels"], "labels")
            if is_multi_hand(labels):
                counts["two_hands"] = counts.get("two_hands", 0) + 1       # FreiHAND holds one hand per image
                continue
            labels = {**labels, **hands_of(labels)[0]}            # a one-body 'hands' list: its hand at top level
            flip = labels["side"] != "right"
            if flip and left == "skip":
                counts["skipped_left"] += 1
                continue
            if labels.get("keypoint_order") != "openpose" or "mano" not in labels:
                raise InputError(f"{root / names['labels']}: needs openpose keypoints and MANO parameters")
            vertices = np.load(root / names["vertices"])
            vertices = np.asarray((vertices[0] if vertices.ndim == 3 else vertices)[:labels["mesh"]["base_vertices"]],
                                  np.float64)
            if flip:
                labels, vertices = mirror_labels(labels), mirror_points(vertices)
            name = SETS[frame["split"]]
            if name not in writers:
                writers[name] = {kind: _JsonList(out / f"{name}_{kind}.json")
                                 for kind in ("K", "xyz", "verts", "mano", "frames")}
            w = writers[name]
            row = w["K"].count
            w["K"].add(freihand_K(labels["K"]).tolist())
            w["xyz"].add(labels["keypoints_3d"])
            w["verts"].add(vertices.tolist())
            w["mano"].add([freihand_mano_row(labels, hands_mean, shape=is_mano)])
            w["frames"].add(frame["index"])
            _write_jpegs(root / names["image"], root / names["mask"], out / name, row, flip)
            counts["mirrored" if flip else "right"] += 1
    finally:
        for w in writers.values():
            for writer in w.values():
                writer.close()
    write_bytes(out / "README.md", _readme(models, is_mano, counts, left).encode())
    if counts["mirrored"]:
        print(f"[dataset] freihand: {counts['mirrored']} left-hand frames mirrored into right hands")
    if counts["skipped_left"]:
        print(f"[dataset] freihand: {counts['skipped_left']} left-hand frames left out (--left skip)")
    if counts.get("two_hands"):
        print(f"[dataset] freihand: {counts['two_hands']} two-hand frames left out (FreiHAND holds one hand)")
    return out


def _readme(models: dict, is_mano: bool, counts: dict, left: str) -> str:
    """README.md of a FreiHAND export: where its rows came from and what each of the 61 values holds."""
    sources = "; ".join(f"{side}: {info.get('source', '?')}" for side, info in models.items())
    if is_mano:
        shape = ("values 48-57: MANO's betas. The models are MANO files: MANO_RIGHT posed from a row "
                 "(flat_hand_mean false, root from (u, v) and scale) is the hand in the images.")
    else:
        shape = ("values 48-57: ZERO. The hand is not a MANO model (it has its own shape space and skeleton): the "
                 "betas it was rendered with are in the darthand labels (labels/<frame>.json, mano.betas; rows map "
                 "to frames through <set>_frames.json), and MANO posed from a row is NOT the hand in the images. "
                 "Use the keypoints (<set>_xyz.json) and vertices (<set>_verts.json, this model's own topology), "
                 "which are exact. Values 0-47 are this model's joint rotations in MANO's layout (its mean hand left "
                 "out), values 58-60 the root's image position and scale: both exact for this hand.")
    if left == "mirror":
        sides = (f"{counts['right']} right-hand frames; {counts['mirrored']} left-hand frames mirrored into right "
                 "hands (image and mask flipped left-right, x -> -x in the camera frame, cx -> W - cx, MANO "
                 "rotations (x, y, z) -> (x, -y, -z) per joint).")
    else:
        sides = f"{counts['right']} right-hand frames; {counts['skipped_left']} left-hand frames left out."
    if counts.get("two_hands"):
        sides += f" {counts['two_hands']} two-hand frames left out (FreiHAND holds one hand per image)."
    return (f"# FreiHAND layout of a darthand dataset\n\nModels: {sources}.\n\nRows: {sides}\n\n"
            f"<set>_mano.json, per row [[61 values]]: values 0-2 the global rotation (axis-angle, camera frame), "
            f"3-47 the finger pose with the model's mean hand left out (flat_hand_mean false); {shape} Values "
            f"58-59: the root keypoint's (index 9) pixel position, 60: focal / root depth (FreiHAND's toolbox: root "
            f"= [(u, v) - (cx, cy), focal] / scale, focal the mean of fx and fy).\n\nK is in OpenCV's pixel "
            f"convention (pixel centres at integers); points are in metres.\n")


def _write_jpegs(image_png: Path, mask_png: Path, folder: Path, row: int, flip: bool = False) -> None:
    # read_png associates alpha, as OpenImageIO reads PNGs: the colour is already over black (sRGB, like FreiHAND's)
    rgb = read_png(image_png)[..., :3]
    mask = read_png(mask_png)[..., :1]
    for pixels, sub in ((rgb, "rgb"), (mask, "mask")):
        write_jpeg(pixels[:, ::-1] if flip else pixels, folder / sub / f"{row:08d}.jpg")


def write_jpeg(pixels: np.ndarray, path: Path) -> None:
    """Write (H, W, C) uint8 pixels as a JPEG (quality JPEG_QUALITY), atomically."""
    buf = oiio.ImageBuf(oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.UINT8))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(pixels))
    buf.specmod().attribute("compression", f"jpeg:{JPEG_QUALITY}")
    with atomic_path(path) as tmp:
        if not buf.write(str(tmp), fileformat="jpeg"):
            raise OSError(f"{path.parent}: cannot write JPEG ({buf.geterror()})")
