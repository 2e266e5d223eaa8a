"""InterHand2.6M's layout, so code written for InterHand2.6M (its `data/InterHand2.6M/dataset.py`, its MANO tools)
reads a darthand dataset of one- and two-hand frames:

    OUT/images/<split>/Capture0/<seq>/cam<n>/image<n>.jpg
    OUT/annotations/<split>/InterHand2.6M_<split>_data.json       COCO-style: images (id, file_name relative to
        images/<split>, width, height, capture, subject, seq_name, camera, frame_idx) and one annotation per image
        (id (frame index + 1: COCOeval takes 0 for no match), image_id, bbox [x, y, w, h] in pixels, area,
        joint_valid (42), hand_type 'right' | 'left' | 'interacting', hand_type_valid 1, category_id 1, iscrowd 0)
    OUT/annotations/<split>/InterHand2.6M_<split>_camera.json     {capture: {campos|camrot|focal|princpt: {cam: ...}}}:
        X_cam = camrot (X - campos), campos in mm; pixel = X_cam[:2] / X_cam[2] * focal + princpt (pixel centres
        at integers: darthand's K with 0.5 subtracted from cx, cy)
    OUT/annotations/<split>/InterHand2.6M_<split>_joint_3d.json   {capture: {frame_idx: {world_coord (42, 3) mm,
        joint_valid (42), hand_type, hand_type_valid, seq}}}
    OUT/annotations/<split>/InterHand2.6M_<split>_MANO_NeuralAnnot.json  {capture: {frame_idx: {right|left: {pose
        (48), shape (10), trans (3)} or None}}}: the world frame, metres, the finger pose with the side's mean hand
        left out (smplx's MANO layer with its default flat_hand_mean false), as InterHand's tool/MANO_render reads it
    OUT/annotations/skeleton.txt  the 42 joints' names and parents (its loader's load_skeleton)
    OUT/README.md

Joints: 42 per frame, the right hand 0-20 then the left 21-41, each in InterHand's order (thumb tip to root, index,
middle, ring, pinky, the wrist last: 'r_thumb4' .. 'r_thumb1', ..., 'r_pinky1', 'r_wrist'); a hand the frame does not
hold has zeros and joint_valid 0. The world frame is darthand's (the right hand's model frame), in mm.

Each darthand frame is its own camera: Capture0, camera id and frame_idx are the frame index; seq_name is the
frame's hand type and interaction type ('interacting_clasped', 'interacting_held', 'right'). A held object (the
held and handover types) has no place in InterHand2.6M's layout: its frames are written with their hands only (the
image shows the object; the object's mesh and pose stay in the native labels).
Followed: facebookresearch/InterHand2.6M's data/InterHand2.6M/dataset.py (file names, the COCO reader, world2cam,
cam2pixel, joint_valid (42), root indices 20 and 41) and tool/MANO_world_to_camera/convert.py (MANO parameters in
the world frame, metres; world coordinates mm).
Its dataset.py reads annotations/<subset>/ ('all', 'human_annot', 'machine_annot'): point its annot_subset at the
split's folder, or link annotations/all to it.

MANO parameters pose the side's model of the dataset (dataset.json 'models'): MANO itself only when the dataset was
rendered from MANO files; the open hand's parameters pose the open hand (README.md says which).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from darthand.dataset.frames import frame_names
from darthand.dataset.freihand import model_kinds, write_jpeg
from darthand.dataset.hands import hand_type, hands_mean, hands_of, interaction_type
from darthand.dataset.run import rendered_dataset
from darthand.errors import InputError
from darthand.fileio import read_json, write_bytes, write_json
from darthand.render.image import read_png

SPLITS = ("train", "val", "test")
SIDES = ("right", "left")
CAPTURE = "0"
FINGERS = ("thumb", "index", "middle", "ring", "pinky")
JOINT_NAMES = [f"{s[0]}_{f}{k}" for s in SIDES for f in FINGERS for k in (4, 3, 2, 1)]
JOINT_NAMES = [*JOINT_NAMES[:20], "r_wrist", *JOINT_NAMES[20:], "l_wrist"]
"""InterHand2.6M's 42 joint names in its order (its skeleton.txt)."""
MM = 1000.0


def skeleton_text() -> str:
    """annotations/skeleton.txt as InterHand's load_skeleton reads it: '<name> <id> <parent id>' per joint (a tip's
    parent the joint below it, a finger's root's the wrist, the wrist's -1)."""
    lines = ["# joint_name joint_id joint_parent_id"]
    for j, name in enumerate(JOINT_NAMES):
        hand, k = divmod(j, 21)
        wrist = 21 * hand + 20
        parent = -1 if k == 20 else (wrist if k % 4 == 3 else j + 1)
        lines.append(f"{name} {j} {parent}")
    return "\n".join(lines) + "\n"


def interhand_order(keypoint_names: list[str]) -> np.ndarray:
    """(21,) indices into a darthand keypoint order (its names: 'wrist', '<finger>1' root .. '<finger>4' tip) giving
    one hand's joints in InterHand's order (thumb4 .. pinky1, wrist last)."""
    names = [n[2:] for n in JOINT_NAMES[:21]]
    try:
        return np.array([keypoint_names.index(n) for n in names])
    except ValueError:
        raise InputError(f"labels' keypoint_names {keypoint_names} lack InterHand's joints {names}") from None


def world_joints(labels: dict) -> tuple[np.ndarray, np.ndarray]:
    """((42, 3) world joints in mm, right then left, InterHand's order; (42,) joint_valid) of a frame's labels."""
    order = interhand_order(labels["keypoint_names"])
    joints, valid = np.zeros((42, 3)), np.zeros(42)
    for hand in hands_of(labels):
        at = 21 * SIDES.index(hand["side"])
        joints[at:at + 21] = np.asarray(hand["keypoints_3d_world"], np.float64)[order] * MM
        valid[at:at + 21] = 1
    return joints, valid


def camera_entry(labels: dict) -> dict:
    """A frame's camera in InterHand's form: campos (mm, the camera centre), camrot (R), focal, princpt (pixel
    centres at integers)."""
    K = np.asarray(labels["K"], np.float64)
    cam = labels["camera"]
    return {"campos": (np.asarray(cam["centre"], np.float64) * MM).tolist(), "camrot": cam["R"],
            "focal": [float(K[0, 0]), float(K[1, 1])], "princpt": [float(K[0, 2] - 0.5), float(K[1, 2] - 0.5)]}


def world_mano(hand: dict, mean: np.ndarray) -> dict:
    """A hand's MANO parameters in the world frame: {pose (48): world root rotation, then the finger pose less the
    model's mean hand `mean` (45,) (flat_hand_mean false); shape (10, or the model's count when more); trans (3) m}.
    The shaped rest root joint J0 follows from the camera-frame parameters (their root joint is J0 + trans), the
    world translation from the world root joint (J0 + trans in the world)."""
    mano = hand["mano"]
    j0 = np.asarray(hand["joints_3d"][0], np.float64) - np.asarray(mano["trans"], np.float64)
    trans = np.asarray(hand["joints_3d_world"][0], np.float64) - j0
    pose = np.asarray(hand["mano_pose"], np.float64).copy()
    pose[3:] -= mean
    betas = np.asarray(mano["betas"], np.float64)
    shape = np.zeros(max(10, len(betas)))             # MANO's 10; a model with more keeps them all
    shape[:len(betas)] = betas
    return {"pose": pose.tolist(), "shape": shape.tolist(), "trans": trans.tolist()}


def keypoint_bbox(labels: dict) -> list[float]:
    """[x, y, w, h] (pixels, centres at integers) of the frame's hands: the labels' bbox, else their keypoints'."""
    box = labels.get("bbox")
    if box is None:
        uv = np.concatenate([np.asarray(h["keypoints_2d"], np.float64) for h in hands_of(labels)])
        box = [*uv.min(0), *uv.max(0)]
    x0, y0, x1, y1 = (float(v) for v in box)
    return [x0 - 0.5, y0 - 0.5, x1 - x0, y1 - y0]


class _Split:
    """The four annotation documents of one split, filled frame by frame."""

    def __init__(self, split: str):
        self.split = split
        self.data: dict = {"images": [], "annotations": [], "categories": [{"id": 1, "name": "hand",
                                                                             "supercategory": "hand"}]}
        self.camera: dict = {CAPTURE: {"campos": {}, "camrot": {}, "focal": {}, "princpt": {}}}
        self.joints: dict = {CAPTURE: {}}
        self.mano: dict = {CAPTURE: {}}

    def add(self, index: int, labels: dict, file_name: str, seq: str, means: dict) -> None:
        frame = str(index)
        width, height = labels["image_size"]
        kind = hand_type(labels)
        self.data["images"].append({"id": index, "file_name": file_name, "width": width, "height": height,
                                    "capture": int(CAPTURE), "subject": 0, "seq_name": seq, "camera": frame,
                                    "frame_idx": index})
        joints, valid = world_joints(labels)
        box = keypoint_bbox(labels)
        self.data["annotations"].append({"id": index + 1, "image_id": index, "bbox": box, "area": box[2] * box[3],
                                         "joint_valid": [[int(v)] for v in valid], "hand_type": kind,
                                         "hand_type_valid": 1, "category_id": 1, "iscrowd": 0})
        for key, value in camera_entry(labels).items():
            self.camera[CAPTURE][key][frame] = value
        self.joints[CAPTURE][frame] = {"world_coord": joints.tolist(), "joint_valid": valid.astype(int).tolist(),
                                       "hand_type": kind, "hand_type_valid": 1, "seq": seq}
        by_side = {h["side"]: h for h in hands_of(labels) if "mano" in h}
        self.mano[CAPTURE][frame] = {side: world_mano(by_side[side], means[side]) if side in by_side else None
                                     for side in SIDES}

    def write(self, out: Path) -> None:
        folder = out / "annotations" / self.split
        for name, doc in (("data", self.data), ("camera", self.camera), ("joint_3d", self.joints),
                          ("MANO_NeuralAnnot", self.mano)):
            write_json(folder / f"InterHand2.6M_{self.split}_{name}.json", doc)


def sequence_name(labels: dict) -> str:
    """A frame's seq_name: its hand type, and its interaction type for a two-hand frame."""
    kind = hand_type(labels)
    return kind if kind != "interacting" else f"{kind}_{interaction_type(labels)}"


def write_interhand(dataset, out=None) -> Path:
    """Write the InterHand2.6M layout of a rendered dataset folder into `out` (default DATASET/interhand); returns
    `out`. Frames outside the train/val/test splits are left out."""
    root = Path(dataset)
    doc, frames = rendered_dataset(root)
    models = doc.get("models") or {}
    out = Path(out) if out is not None else root / "interhand"
    means = {side: hands_mean(models, side) for side in SIDES}
    splits: dict = {}
    counts: dict = {}
    for frame in frames:
        if frame["split"] not in SPLITS:
            continue
        names = frame_names(frame["index"])
        labels = read_json(root / names["labels"], "labels")
        seq = sequence_name(labels)
        file_name = f"Capture{CAPTURE}/{seq}/cam{frame['index']}/image{frame['index']}.jpg"
        split = splits.setdefault(frame["split"], _Split(frame["split"]))
        split.add(frame["index"], labels, file_name, seq, means)
        rgba = read_png(root / names["image"])
        write_jpeg(rgba[..., :3], out / "images" / frame["split"] / file_name)     # over black, as freihand's
        counts[seq] = counts.get(seq, 0) + 1
    for split in splits.values():
        split.write(out)
    write_bytes(out / "annotations" / "skeleton.txt", skeleton_text().encode())
    write_bytes(out / "README.md", _readme(models, counts).encode())
    return out


def _readme(models: dict, counts: dict) -> str:
    kinds = model_kinds(models)
    model = ("MANO files: the MANO parameters pose smplx's MANO layer (flat_hand_mean false) into the written joints "
             "and meshes" if kinds and all(kinds.values()) else
             "not MANO (the open hand): the MANO parameters pose darthand's model of each side "
             "(build/model/<side>.npz, flat_hand_mean false), not smplx's MANO")
    rows = "\n".join(f"- {seq}: {n}" for seq, n in sorted(counts.items()))
    return (f"# InterHand2.6M layout of a darthand dataset\n\nModels: {model}.\n\nFrames per sequence (hand type, "
            f"interaction type):\n{rows}\n\nWorld frame: darthand's (the right hand's model frame), mm; X_cam = "
            f"camrot (X - campos); pixel = X_cam / Z * focal + princpt, pixel centres at integers. Joints: right "
            f"0-20, left 21-41, wrist last per hand. Each darthand frame is its own camera (camera id = frame_idx "
            f"= the frame index). InterHand's dataset.py reads annotations/<subset>/: link annotations/all to a "
            f"split's folder.\n")
