"""Where things are on a MANO-layout hand: its skeleton of bones, and semantic face labels derived from geometry
for models that come without them (MANO). The model build labels such a model (so every stage sees the same
labels); the textures stage places its maps with the skeleton.

Frame (MANO canonical, right hand): fingers toward -X, palm facing -Y, thumb toward +Z, wrist near +X.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.model.hand_model import HandModel
from darthand.model.layout import FACE_LABEL_IDS, FINGER_JOINTS, FINGERS
from darthand.model.mirror import mirror_model

PALM_NORMAL = np.array([0.0, -1.0, 0.0])
FOREARM_AXIS = np.array([1.0, 0.0, 0.0])
# The thumb's nail does not face +Y like the other fingers' in the rest pose: it is rolled about the thumb's
# axis toward +Z (away from the palm). Radians; best agreement with the open template's nail labels.
THUMB_NAIL_ROLL = 1.2


@dataclass(frozen=True)
class Skeleton:
    """Bones of a hand as segments (B = 21): per finger (FINGERS order) its three segments root -> tip, then the
    five palm segments wrist -> finger root, then the forearm (wrist -> +X).

    joints  (16, 3) rest joints (J_regressor @ v_template), metres
    tips    (5, 3)  fingertip vertices, FINGERS order
    start, end (B, 3) segment endpoints
    finger  (B,) int64, index into FINGERS for finger and palm segments, -1 for the forearm
    kind    (B,) int64, 0 phalanx (or thumb chain) segment, 1 palm (metacarpal) segment, 2 forearm
    level   (B,) int64, 0..2 along a finger chain (proximal -> distal), -1 otherwise
    dorsal  (B, 3) unit vector perpendicular to the segment pointing to its back (nail side); palm: +Y
    """

    joints: np.ndarray
    tips: np.ndarray
    start: np.ndarray
    end: np.ndarray
    finger: np.ndarray
    kind: np.ndarray
    level: np.ndarray
    dorsal: np.ndarray

    @property
    def num_bones(self) -> int:
        return len(self.start)

    def bone(self, finger: str, level: int) -> int:
        """Index of `finger`'s segment at `level` (0 proximal .. 2 distal)."""
        return FINGERS.index(finger) * 3 + level

    def palm_bone(self, finger: str) -> int:
        return 15 + FINGERS.index(finger)

    @property
    def forearm_bone(self) -> int:
        return 20

    def axis(self, bone: int) -> np.ndarray:
        d = self.end[bone] - self.start[bone]
        return d / np.linalg.norm(d)


def skeleton(model: HandModel, forearm_length: float = 0.12, thumb_nail_roll: float = THUMB_NAIL_ROLL) -> Skeleton:
    """The bone segments of `model` in its rest pose."""
    return skeleton_from_joints(np.asarray(model.J_regressor @ model.v_template), model.v_template[model.tip_ids],
                                forearm_length, thumb_nail_roll)


def skeleton_from_joints(joints: np.ndarray, tips: np.ndarray, forearm_length: float = 0.12,
                         thumb_nail_roll: float = THUMB_NAIL_ROLL) -> Skeleton:
    """The bone segments from rest joints (16, 3) and fingertips (5, 3) (FINGERS order)."""
    joints, tips = np.asarray(joints, float), np.asarray(tips, float)
    start, end, finger, kind, level, dorsal = [], [], [], [], [], []
    for f, name in enumerate(FINGERS):
        chain = [joints[j] for j in FINGER_JOINTS[name]] + [tips[f]]
        up = _dorsal_direction(chain[-1] - chain[0], thumb_nail_roll if name == "thumb" else 0.0)
        for k in range(3):
            start.append(chain[k])
            end.append(chain[k + 1])
            finger.append(f)
            kind.append(0)
            level.append(k)
            dorsal.append(_perpendicular(up, chain[k + 1] - chain[k]))
    for f, name in enumerate(FINGERS):
        root = joints[FINGER_JOINTS[name][0]]
        start.append(joints[0])
        end.append(root)
        finger.append(f)
        kind.append(1)
        level.append(-1)
        dorsal.append(_perpendicular(-PALM_NORMAL, root - joints[0]))
    start.append(joints[0])
    end.append(joints[0] + forearm_length * FOREARM_AXIS)
    finger.append(-1)
    kind.append(2)
    level.append(-1)
    dorsal.append(-PALM_NORMAL)
    return Skeleton(joints=joints, tips=tips, start=np.array(start), end=np.array(end),
                    finger=np.array(finger, np.int64), kind=np.array(kind, np.int64),
                    level=np.array(level, np.int64), dorsal=np.array(dorsal))


def _dorsal_direction(axis: np.ndarray, roll: float) -> np.ndarray:
    """+Y made perpendicular to a finger's axis, rolled by `roll` radians toward +Z (about the axis)."""
    axis = axis / np.linalg.norm(axis)
    up = _perpendicular(-PALM_NORMAL, axis)
    side = np.cross(axis, up)
    side *= np.sign(side[2]) if side[2] != 0 else 1.0  # the +Z side
    return np.cos(roll) * up + np.sin(roll) * side


def _perpendicular(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    p = v - np.dot(v, axis) * axis
    return p / np.linalg.norm(p)


def segment_coordinates(points: np.ndarray, start: np.ndarray, end: np.ndarray):
    """Distance (N, B) from points (N, 3) to segments (B, 3)-(B, 3), and the unclamped parameter t (N, B) of
    each point's projection (0 at start, 1 at end)."""
    d = end - start
    length2 = np.einsum("bi,bi->b", d, d)
    rel = points[:, None, :] - start[None]
    t = np.einsum("nbi,bi->nb", rel, d) / length2
    closest = start[None] + np.clip(t, 0, 1)[..., None] * d[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2), t


def nearest_bones(points: np.ndarray, skel: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """For points (N, 3): index of the nearest bone (N,) and the unclamped parameter t along it (N,)."""
    out_b = np.empty(len(points), np.int64)
    out_t = np.empty(len(points))
    for s in range(0, len(points), 1 << 16):
        dist, t = segment_coordinates(points[s:s + (1 << 16)], skel.start, skel.end)
        b = dist.argmin(1)
        out_b[s:s + len(b)], out_t[s:s + len(b)] = b, t[np.arange(len(b)), b]
    return out_b, out_t


def face_geometry(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face centroids (F, 3), unit normals (F, 3) and areas (F,)."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    return tri.mean(1), cross / np.maximum(area2, 1e-300)[:, None], 0.5 * area2


def derive_face_labels(model: HandModel, *, nail_start: float = 0.55, nail_end: float = 0.97,
                       nail_cos: float = 0.75, wrist_margin: float = 0.0,
                       skel: Skeleton | None = None) -> np.ndarray:
    """Semantic label per face (F,) int8 (layout.FACE_LABELS) from geometry alone; works on MANO's mesh.

    - wrist: centroid beyond the wrist joint along +X (by `wrist_margin` metres);
    - nail: the dorsal cap of a fingertip segment: nearest bone is a distal segment, the centroid projects
      between `nail_start` and `nail_end` of it, and the normal is within acos(`nail_cos`) of the finger's
      dorsal direction (defaults: the best face IoU, ~0.5, against the open template's painted nails);
    - palm / dorsum: faces of the palm segments facing the palm normal (-Y) or away from it;
    - finger_palmar / finger_dorsal: the same split for the finger segments, against each finger's dorsal axis.
    """
    skel = skel or skeleton(model)
    centroid, normal, _ = face_geometry(model.v_template, model.faces)
    bone, t = nearest_bones(centroid, skel)
    facing = np.einsum("fi,fi->f", normal, skel.dorsal[bone])
    labels = np.full(len(centroid), -1, np.int8)
    on_finger = skel.kind[bone] == 0
    labels[on_finger] = np.where(facing[on_finger] >= 0, FACE_LABEL_IDS["finger_dorsal"],
                                 FACE_LABEL_IDS["finger_palmar"])
    on_palm = ~on_finger
    labels[on_palm] = np.where(facing[on_palm] >= 0, FACE_LABEL_IDS["dorsum"], FACE_LABEL_IDS["palm"])
    nail = on_finger & (skel.level[bone] == 2) & (t >= nail_start) & (t <= nail_end) & (facing >= nail_cos)
    labels[nail] = FACE_LABEL_IDS["nail"]
    wrist = centroid[:, 0] > skel.joints[0, 0] + wrist_margin
    labels[wrist & ~nail] = FACE_LABEL_IDS["wrist"]
    return labels


def ensure_face_labels(model: HandModel) -> HandModel:
    """`model` unchanged if every face has a label, else a copy whose unlabelled faces take derived labels (a
    left hand's from its right mirror image: the derivation reads the right hand's frame; faces keep their order)."""
    if model.face_labels is not None and (model.face_labels >= 0).all():
        return model
    if model.side == "left":
        derived = derive_face_labels(mirror_model(model))
    else:
        derived = derive_face_labels(model)
    labels = derived if model.face_labels is None else np.where(model.face_labels >= 0, model.face_labels, derived)
    return model.replace(face_labels=labels)


def hand_frame(skel: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coordinates of the hand in the XZ plane (the palm's plane, seen along the palm normal): returns the
    origin (2,) at the wrist joint and the vectors f (2,) to the midpoint of the index and little-finger roots
    and s (2,) from the middle toward the index root, so that a point is origin + f_coord * f + s_coord * s with
    f_coord 0 at the wrist .. 1 at the knuckle line and s_coord -1 little-finger edge .. 1 index edge."""
    w = skel.joints[0][[0, 2]]
    near = skel.joints[FINGER_JOINTS["index"][0]][[0, 2]]
    far = skel.joints[FINGER_JOINTS["pinky"][0]][[0, 2]]
    f_vec = 0.5 * (near + far) - w
    unit = f_vec / np.linalg.norm(f_vec)
    s_dir = np.array([-unit[1], unit[0]])
    if np.dot(near - far, s_dir) < 0:
        s_dir = -s_dir
    return w, f_vec, s_dir * 0.5 * abs(np.dot(near - far, s_dir))


def to_hand_frame(xz: np.ndarray, frame) -> np.ndarray:
    """(N, 2) hand-frame coordinates (f, s) of XZ points (N, 2)."""
    origin, f_vec, s_vec = frame
    m = np.stack([f_vec, s_vec], 1)
    return np.linalg.solve(m, (np.asarray(xz) - origin).T).T
