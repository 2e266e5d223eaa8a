"""FreiHAND's layout, so code written for FreiHAND trains on a darthand dataset unchanged:

    OUT/<set>_K.json       per frame the 3 x 3 intrinsics, OpenCV's pixel convention (pixel centres at integers:
                           darthand's K with 0.5 subtracted from cx, cy)
    OUT/<set>_xyz.json     per frame the 21 keypoints (FreiHAND's order: wrist, then thumb .. pinky, root to tip),
                           camera frame, metres
    OUT/<set>_verts.json   per frame the hand's vertices without DART's wrist rings (MANO's 778 for MANO), metres
    OUT/<set>_mano.json    per frame [[61 numbers]]: 48 pose values (global rotation in the camera frame, then the
                           finger pose with MANO's mean hand left out, flat_hand_mean false), 10 betas, the root
                           keypoint's (index 9, middle-finger MCP) image position (u, v), and scale = focal / root
                           depth, focal the mean of fx and fy: FreiHAND's toolbox recovers the root as
                           [(u, v) - (cx, cy), focal] / scale and poses MANO from it
    OUT/<set>_frames.json  per row, the darthand frame index it came from
    OUT/<set>/rgb/%08d.jpg, OUT/<set>/mask/%08d.jpg   image (over black where the frame has no background), mask

Sets by split: train -> training, val -> validation, test -> evaluation. FreiHAND is right-handed (its MANO is
MANO_RIGHT), so left-hand frames are left out (their number is printed and returned).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.fileio import atomic_path, read_json

SETS = {"train": "training", "val": "validation", "test": "evaluation"}
ROOT = 9
JPEG_QUALITY = 95


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


def freihand_mano_row(labels: dict, hands_mean) -> list[float]:
    """The 61 numbers of FreiHAND's training_mano.json for a frame's labels (module docstring)."""
    mano = labels["mano"]
    pose = np.concatenate([mano["global_orient"], np.asarray(mano["hand_pose"]) - np.asarray(hands_mean)])
    betas = np.zeros(10)
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


def write_freihand(dataset, out=None) -> Path:
    """Write the FreiHAND layout of a rendered dataset folder into `out` (default DATASET/freihand)."""
    from darthand.dataset.run import read_shard_records
    from darthand.dataset.frames import frame_names

    root = Path(dataset)
    doc = read_json(root / "dataset.json", "dataset.json")
    models = doc.get("models") or {}
    out = Path(out) if out is not None else root / "freihand"
    frames = read_shard_records(root)
    if not frames:
        raise InputError(f"{root}: no rendered frames (shards/*.json)")
    writers: dict = {}
    left_out = 0
    try:
        for frame in frames:
            if frame["split"] not in SETS:
                continue
            if frame["side"] != "right":
                left_out += 1
                continue
            names = frame_names(frame["index"])
            labels = read_json(root / names["labels"], "labels")
            if labels.get("keypoint_order") != "openpose" or "mano" not in labels:
                raise InputError(f"{root / names['labels']}: needs openpose keypoints and MANO parameters")
            name = SETS[frame["split"]]
            if name not in writers:
                writers[name] = {kind: _JsonList(out / f"{name}_{kind}.json")
                                 for kind in ("K", "xyz", "verts", "mano", "frames")}
                for sub in ("rgb", "mask"):
                    (out / name / sub).mkdir(parents=True, exist_ok=True)
            w = writers[name]
            row = w["K"].count
            vertices = np.load(root / names["vertices"])[:labels["mesh"]["base_vertices"]]
            w["K"].add(freihand_K(labels["K"]).tolist())
            w["xyz"].add(labels["keypoints_3d"])
            w["verts"].add(np.asarray(vertices, np.float64).tolist())
            w["mano"].add([freihand_mano_row(labels, models.get("right", {}).get("hands_mean", np.zeros(45)))])
            w["frames"].add(frame["index"])
            _write_jpegs(root / names["image"], root / names["mask"], out / name, row)
    finally:
        for w in writers.values():
            for writer in w.values():
                writer.close()
    if left_out:
        print(f"[dataset] freihand: {left_out} left-hand frames left out (FreiHAND is right-handed)")
    return out


def _write_jpegs(image_png: Path, mask_png: Path, folder: Path, row: int) -> None:
    import OpenImageIO as oiio

    from darthand.render.image import read_png

    rgba = read_png(image_png).astype(np.float32) / 255
    rgb = rgba[..., :3] * (rgba[..., 3:4] if rgba.shape[2] == 4 else 1)    # over black (sRGB, like FreiHAND's gs)
    mask = read_png(mask_png)[..., :1]
    for pixels, sub in ((np.rint(rgb * 255).astype(np.uint8), "rgb"), (mask, "mask")):
        buf = oiio.ImageBuf(oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.UINT8))
        buf.set_pixels(oiio.ROI(), np.ascontiguousarray(pixels))
        buf.specmod().attribute("compression", f"jpeg:{JPEG_QUALITY}")
        with atomic_path(folder / sub / f"{row:08d}.jpg") as tmp:
            if not buf.write(str(tmp), fileformat="jpeg"):
                raise OSError(f"{folder / sub}: cannot write JPEG ({buf.geterror()})")
