"""Two-hand frames following issue 29's contract, built from a rendered one-hand dataset (until the renderer draws
them): a right frame's hand and a left frame's hand, the left one moved by a rigid placement into the right one's
world, under the right frame's camera. Keypoints, joints, MANO parameters and the mesh of the moved hand are
transformed exactly, so projections and the model's forward pass stay consistent; the image is the right frame's
(the left hand is not drawn), the instances PNG marks the right hand's mask and the left hand's keypoint box."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from darthand.render.image import read_png

PER_HAND = ("side", "keypoints_3d", "keypoints_3d_world", "keypoints_2d", "visibility", "in_image", "joints_3d",
            "joints_3d_world", "mano_pose", "mano", "gesture", "texture", "accessory", "bbox", "bbox_keypoints",
            "coverage", "mesh")
PLACEMENT = np.eye(4)
PLACEMENT[:3, :3] = Rotation.from_rotvec([0.1, 0.3, -0.2]).as_matrix()
PLACEMENT[:3, 3] = [0.0, 0.02, 0.06]
INTERACTIONS = ("touching", "clasped", "overlapping")


def _labels(root: Path, index: int) -> dict:
    return json.loads((root / "labels" / f"{index:06d}.json").read_text())


def _rigid(points, R, t) -> np.ndarray:
    return np.asarray(points, np.float64) @ np.asarray(R).T + np.asarray(t)


def moved_hand(left: dict, left_vertices: np.ndarray, right: dict) -> tuple[dict, np.ndarray]:
    """(the per-hand entry, its (V, 3) camera-frame vertices) of the `left` frame's hand placed by PLACEMENT into
    the `right` frame's world and seen by its camera."""
    Rp, tp = PLACEMENT[:3, :3], PLACEMENT[:3, 3]
    R, t = np.asarray(right["camera"]["R"]), np.asarray(right["camera"]["t"])
    RL, tL = np.asarray(left["camera"]["R"]), np.asarray(left["camera"]["t"])
    K = np.asarray(right["K"])
    hand = {k: left[k] for k in PER_HAND}
    kp_w = _rigid(left["keypoints_3d_world"], Rp, tp)
    kp_c = _rigid(kp_w, R, t)
    uv = kp_c @ K.T
    uv = uv[:, :2] / uv[:, 2:]
    j_w = _rigid(left["joints_3d_world"], Rp, tp)
    j_c = _rigid(j_w, R, t)
    pose = np.asarray(left["mano_pose"], np.float64).copy()
    root = Rotation.from_rotvec(pose[:3]).as_matrix()
    pose[:3] = Rotation.from_matrix(Rp @ root).as_rotvec()
    j0 = np.asarray(left["joints_3d"][0]) - np.asarray(left["mano"]["trans"])     # the shaped rest root joint
    mano = dict(left["mano"], global_orient=Rotation.from_matrix(R @ Rp @ root).as_rotvec().tolist(),
                trans=(j_c[0] - j0).tolist())
    W, H = right["image_size"]
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & (uv[:, 1] < H)
    box = [float(uv[:, 0].min()), float(uv[:, 1].min()), float(uv[:, 0].max()), float(uv[:, 1].max())]
    hand.update(keypoints_3d=kp_c.tolist(), keypoints_3d_world=kp_w.tolist(), keypoints_2d=uv.tolist(),
                in_image=inside.tolist(), joints_3d=j_c.tolist(), joints_3d_world=j_w.tolist(),
                mano_pose=pose.tolist(), mano=mano, bbox=box, bbox_keypoints=box)
    world = _rigid(_rigid(np.asarray(left_vertices, np.float64) - tL, RL.T, 0), Rp, tp)      # R^T (v - t)
    return hand, _rigid(world, R, t)


def two_hand_labels(right: dict, left_hand: dict, interaction: str) -> dict:
    """The labels of a two-hand frame: the right frame's scene-level fields, both hands in `hands`."""
    labels = {k: v for k, v in right.items() if k not in PER_HAND and k not in ("flat_hand_mean",)}
    right_hand = {k: right[k] for k in PER_HAND}
    hands = [right_hand, left_hand]
    for b, hand in enumerate(hands):
        hand["instance"] = {"hand": 1 + 2 * b, "accessory": 2 + 2 * b}
        hand["contacts"] = []
    boxes = np.array([h["bbox"] for h in hands if h["bbox"] is not None])
    labels.update(hand_type="interacting", interaction={"type": interaction, "contact_parts": []}, hands=hands,
                  bbox=[*boxes[:, :2].min(0).tolist(), *boxes[:, 2:].max(0).tolist()])
    labels["files"] = dict(labels["files"], instances=f"../instances/{right['render']['dataset']['frame']:06d}.png")
    return labels


def make_two_hand_dataset(src, out, pairs: int = 3) -> list[int]:
    """Copy the dataset `src` to `out` and turn its first `pairs` right frames into two-hand frames (each with the
    next unused left frame's hand); returns their indices."""
    from render_scenes import write_image

    src, out = Path(src), Path(out)
    shutil.copytree(src, out)
    indices = sorted(int(p.stem) for p in (src / "labels").glob("*.json"))
    docs = {i: _labels(src, i) for i in indices}
    rights = [i for i in indices if docs[i]["side"] == "right"]
    lefts = [i for i in indices if docs[i]["side"] == "left"]
    made = []
    for k, (r, lft) in enumerate(zip(rights[:pairs], lefts)):
        right, left = docs[r], docs[lft]
        left_vertices = np.load(src / "meshes" / f"{lft:06d}.npy")
        hand, vertices = moved_hand(left, left_vertices, right)
        labels = two_hand_labels(right, hand, INTERACTIONS[k % len(INTERACTIONS)])
        meshes = np.stack([np.load(src / "meshes" / f"{r:06d}.npy"), vertices.astype(np.float32)])
        np.save(out / "meshes" / f"{r:06d}.npy", meshes.astype(np.float32))
        mask = read_png(src / "masks" / f"{r:06d}.png")[..., 0]
        instances = np.where(mask >= 128, 1, 0).astype(np.uint8)
        x0, y0, x1, y1 = (int(np.clip(v, 0, s - 1)) for v, s in zip(hand["bbox"], right["image_size"] * 2))
        block = instances[y0:y1 + 1, x0:x1 + 1]
        block[block == 0] = 3
        write_image(out / "instances" / f"{r:06d}.png", instances)
        (out / "labels" / f"{r:06d}.json").write_text(json.dumps(labels))
        made.append(r)
    return made
