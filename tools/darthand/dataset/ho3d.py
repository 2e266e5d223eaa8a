"""HO-3D's layout (Hampali et al., CVPR 2020; github.com/shreyashampali/ho3d) of a rendered dataset's object frames:
what hand-object training code (HO-3D v2's readers, and the many that follow its meta files) loads.

    OUT/train/<SEQ>/rgb/<id>.png      8-bit RGB (a frame without a background: composited over black)
    OUT/train/<SEQ>/seg/<id>.png      8-bit RGB: blue 255 on the hand, green 255 on the object (HO-3D's readers take
                                      the hand as the blue channel)
    OUT/train/<SEQ>/depth/<id>.png    when the dataset has depth maps: HO-3D's encoding, metres = (R + 256 G) *
                                      DEPTH_SCALE (blue 0)
    OUT/train/<SEQ>/meta/<id>.pkl     a pickled dict of float32 arrays (below)
    OUT/evaluation/<SEQ>/...          the test split, with the same (full) annotations
    OUT/train.txt, OUT/evaluation.txt one '<SEQ>/<id>' a line

SEQ is SEQUENCE; id is the frame's zero-padded index. Frames are darthand's train and val splits in train/, its test
split in evaluation/; frames without an object and two-hand frames are left out and counted.

HO-3D is right-handed (its MANO is MANO_RIGHT). A left-hand frame is written mirrored (`left="mirror"`, the
default; `"skip"` leaves it out and counts it), as left-hand data is commonly given to right-handed code: rgb, seg
and depth flipped left-right, camMat's principal point mirrored (cx -> W - 1 - cx, pixel centres at integers), every
3-D point x -> -x in the camera frame, so the hand is the right hand that is the left one's mirror image (MANO_RIGHT
posed from the written parameters: each joint's axis-angle (x, y, z) -> (x, -y, -z), the global rotation too,
translation mirrored, betas kept; darthand's left model is its right one mirrored) and the object is its mirror
image: objRot, objTrans pose the object's rest frame mirrored (objCorners3DRest and objVertices3D are the mirrored
ones; a catalogue mesh is mirrored, x -> -x in its own frame, before objRot, objTrans place it). Such a frame's meta
has `flipped` True; an unmirrored frame's has no `flipped` key.

meta/<id>.pkl, HO-3D's conventions: every 3-D quantity in the OpenGL camera frame (x right, y up, z toward the viewer:
X_gl = COORD_CHANGE @ X_opencv, COORD_CHANGE = diag(1, -1, -1)), metres:
    handPose (48,)       MANO axis-angle, global rotation first, relative to the flat hand (flat_hand_mean true)
    handTrans (3,), handBeta (10,)   MANO's translation and shape: MANO posed with them gives handJoints3D
    handJoints3D (21, 3) MANO's 16 joints then the tips thumb, index, middle, ring, pinky (HO-3D's order)
    handVertContact (778,)  1 on the hand vertices touching the object (darthand's 3 mm contacts), else 0
    objRot (3, 1) axis-angle, objTrans (3,): X_gl = R(objRot) X_obj + objTrans for the object's points X_obj
    objName, objLabel: the catalogue's object id and category; objCorners3DRest (8, 3) the object's bounding box in
    its frame, objCorners3D (8, 3) the same posed
    camMat (3, 3)        intrinsics with OpenCV's pixel centres at integers: uv ~ camMat @ (COORD_CHANGE @ X_gl)
Why HO-3D and not DexYCB: HO-3D's per-frame meta files carry exactly what a frame here has (one right hand's MANO
parameters and joints, one object's pose, mesh name and corners, masks, depth) without DexYCB's multi-camera
calibration and YCB-specific object ids and pose files, and most hand-object code (HFL-Net, HandOccNet, ArtiBoost,
...) reads it.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.dataset.frames import OBJECT_MESHES, frame_names
from darthand.dataset.freihand import mirror_hand, mirrored_K
from darthand.dataset.hands import hands_of
from darthand.dataset.run import rendered_dataset
from darthand.errors import InputError
from darthand.fileio import make_folder, read_json, write_bytes
from darthand.model.layout import KEYPOINT_ORDERS
from darthand.model.mirror import mirror_points
from darthand.model.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from darthand.render.image import read_png, write_png

SEQUENCE = "DH"
FOLDERS = {"train": "train", "val": "train", "test": "evaluation"}
COORD_CHANGE = np.diag([1.0, -1.0, -1.0])
DEPTH_SCALE = 0.00012498664727900177          # HO-3D's metres per depth code
MANO_VERTICES = 778
BETAS = 10
LEFT_MODES = ("mirror", "skip")
MIRROR = np.diag([-1.0, 1.0, 1.0])             # the camera frame's left-right mirror (either frame: commutes with C)
HAND_POINTS = ("joints_3d", "keypoints_3d")     # the 3-D fields of a hand that ho3d_meta reads (mirrored with it)


def write_ho3d(dataset, out=None, *, left: str = "mirror") -> Path:
    """Write HO-3D's layout of a rendered dataset folder's object frames into `out` (default DATASET/ho3d); left:
    "mirror" writes a left hand's frame mirrored into a right hand's, "skip" leaves it out (module docstring)."""
    if left not in LEFT_MODES:
        raise InputError(f"--left: {left!r} is not one of {', '.join(LEFT_MODES)}")
    root = Path(dataset)
    doc, frames = rendered_dataset(root)
    has_depth = "depth" in (doc.get("maps") or ())
    out = Path(out) if out is not None else root / "ho3d"
    lists: dict = {name: [] for name in set(FOLDERS.values())}
    counts = {"written": 0, "mirrored": 0, "no_object": 0, "two_hands": 0, "left": 0, "no_split": 0}
    for frame in frames:
        names = frame_names(frame["index"], tuple(doc.get("maps") or ()), instances=True, objects=True)
        folder = FOLDERS.get(frame["split"])
        labels = read_json(root / names["labels"], "labels") if folder else None
        why = _left_out(labels)
        flip = why == "left" and left == "mirror"
        if why and not flip:
            counts[why] += 1
            continue
        assert labels is not None and folder is not None
        frame_id = f"{frame['index']:06d}"
        base = out / folder / SEQUENCE
        write_frame_files(root, names, labels, base, frame_id, has_depth, flip)
        counts["mirrored"] += flip
        lists[folder].append(f"{SEQUENCE}/{frame_id}")
        counts["written"] += 1
    if not counts["written"]:
        raise InputError(f"{root}: no frame of a {'right ' if left == 'skip' else ''}hand holding an object to "
                         "write in HO-3D's layout")
    make_folder(out)
    for folder, rows in lists.items():
        write_bytes(out / f"{folder}.txt", "".join(f"{row}\n" for row in rows).encode())
    mirrored = f" ({counts['mirrored']} left hands mirrored)" if counts["mirrored"] else ""
    print(f"[dataset] ho3d: {counts['written']} object frames written{mirrored}; left out: " + ", ".join(
        f"{n} {k.replace('_', ' ')}" for k, n in counts.items() if k not in ("written", "mirrored") and n))
    return out


def _left_out(labels: dict | None) -> str | None:
    """Why a frame's labels (None: a frame outside the splits) are not written, or None."""
    if labels is None:
        return "no_split"
    if not labels.get("objects"):
        return "no_object"
    hands = hands_of(labels)
    if len(hands) != 1:
        return "two_hands"
    return None if hands[0]["side"] == "right" else "left"


def write_frame_files(root: Path, names: dict, labels: dict, base: Path, frame_id: str, has_depth: bool,
                      flip: bool = False) -> None:
    """One frame's rgb, seg, depth (when there is one) and meta files under `base` (OUT/<folder>/<SEQ>); flip: the
    frame mirrored left-right (a left hand written as a right one, module docstring)."""
    if flip:
        labels = mirrored_labels(labels)
    rgba = read_png(root / names["image"])
    alpha = rgba[..., 3:4].astype(np.float64) / 255
    rgb = np.round(rgba[..., :3] * alpha).astype(np.uint8)
    _write(base / "rgb" / f"{frame_id}.png", rgb[:, ::-1] if flip else rgb)
    instances = read_png(root / names["instances"])[..., 0]
    instances = instances[:, ::-1] if flip else instances
    seg = np.zeros(instances.shape + (3,), np.uint8)
    seg[..., 2] = np.where(instances == 1, 255, 0)
    seg[..., 1] = np.where(instances == labels["objects"][0]["instance"], 255, 0)
    _write(base / "seg" / f"{frame_id}.png", seg)
    if has_depth:
        code = depth_code(_depth_metres(root / names["depth"]))
        _write(base / "depth" / f"{frame_id}.png", code[:, ::-1] if flip else code)
    object_mesh = root / names[OBJECT_MESHES]
    mesh = np.load(object_mesh) if object_mesh.is_file() else None
    meta = ho3d_meta(labels, mirror_points(mesh) if flip and mesh is not None else mesh)
    if flip:
        meta["flipped"] = True
    path = base / "meta" / f"{frame_id}.pkl"
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes(path, pickle.dumps(meta, protocol=2))


def mirrored_labels(labels: dict) -> dict:
    """The labels ho3d_meta reads of a frame mirrored left-right (x -> -x in the camera frame; pixel column
    u -> W - u, darthand's pixel-corner origin): its hand the right hand that is the left one's mirror image
    (freihand.mirror_hand, with its joints), its object the object's mirror image (rotation conjugated by the
    mirror, its rest frame mirrored)."""
    out = {**labels, "K": mirrored_K(labels), "objects": [_mirror_object(o) for o in labels["objects"]]}
    if "hands" in labels:
        out["hands"] = [mirror_hand(h, HAND_POINTS) for h in labels["hands"]]
        return out
    return out | mirror_hand(labels, HAND_POINTS)


def _mirror_object(held: dict) -> dict:
    """A held object's pose and 3-D corners mirrored left-right: R -> M R M, t -> M t (M = MIRROR)."""
    R, t = np.asarray(held["pose"]["R"], np.float64), np.asarray(held["pose"]["t"], np.float64)
    return {**held, "pose": {**held["pose"], "R": (MIRROR @ R @ MIRROR).tolist(), "t": (MIRROR @ t).tolist()},
            "corners_3d": mirror_points(np.asarray(held["corners_3d"], np.float64)).tolist()}


def _write(path: Path, pixels: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png(path, pixels, srgb=False)


def _depth_metres(path: Path) -> np.ndarray:
    """(H, W) metres of a darthand depth map (16-bit millimetres, render/truth.py)."""
    pixels = np.asarray(oiio.ImageBuf(str(path)).get_pixels(oiio.UINT16))
    return pixels[..., 0].astype(np.float64) / 1000


def depth_code(metres: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 HO-3D's depth image of depths (H, W) in metres: code = metres / DEPTH_SCALE, red its low
    byte, green its high byte."""
    code = np.clip(np.round(np.asarray(metres) / DEPTH_SCALE), 0, 65535).astype(np.uint16)
    out = np.zeros(code.shape + (3,), np.uint8)
    out[..., 0], out[..., 1] = code & 255, code >> 8
    return out


def ho3d_meta(labels: dict, object_mesh: np.ndarray | None = None) -> dict:
    """HO-3D's meta dict of a frame's labels (one right hand holding an object; module docstring)."""
    hand = hands_of(labels)[0]
    held = labels["objects"][0]
    if "mano" not in hand:
        raise InputError("ho3d: a frame's hand has no MANO parameters (a USD package's frames cannot be written)")
    mano = hand["mano"]
    C = COORD_CHANGE
    orient = np.asarray(mano["global_orient"], np.float64)
    trans = np.asarray(mano["trans"], np.float64)
    root_joint = np.asarray(hand["joints_3d"][0], np.float64) - trans        # MANO's rest root joint J0
    R_orient = np.asarray(axis_angle_to_matrix(orient), np.float64).reshape(3, 3)
    keypoints = np.asarray(hand["keypoints_3d"], np.float64)
    mano_order = np.empty_like(keypoints)
    mano_order[np.asarray(KEYPOINT_ORDERS[labels["keypoint_order"]])] = keypoints
    R_obj, t_obj = np.asarray(held["pose"]["R"], np.float64), np.asarray(held["pose"]["t"], np.float64)
    corners = np.asarray(held["corners_3d"], np.float64)
    contact = np.zeros(MANO_VERTICES, np.float32)
    ids = np.asarray(held["contacts"]["hand_vertices"], np.int64)
    contact[ids[ids < MANO_VERTICES]] = 1
    betas = np.zeros(BETAS)
    given = np.asarray(mano["betas"], np.float64)[:BETAS]
    betas[:len(given)] = given
    f32 = lambda a: np.asarray(a, np.float32)
    meta = {"handPose": f32(np.concatenate([matrix_to_axis_angle(C @ R_orient), mano["hand_pose"]])),
            "handTrans": f32(C @ (root_joint + trans) - root_joint), "handBeta": f32(betas),
            "handJoints3D": f32(mano_order @ C.T), "handVertContact": contact,
            "objRot": f32(matrix_to_axis_angle(C @ R_obj).reshape(3, 1)), "objTrans": f32(C @ t_obj),
            "objName": held["id"], "objLabel": held["category"],
            "objCorners3DRest": f32((corners - t_obj) @ R_obj), "objCorners3D": f32(corners @ C.T),
            "camMat": f32(np.asarray(labels["K"], np.float64) - [[0, 0, 0.5], [0, 0, 0.5], [0, 0, 0]])}
    if object_mesh is not None:
        meta["objVertices3D"] = f32(np.asarray(object_mesh, np.float64) @ C.T)
    return meta
