"""MANO's layout: joint order, parents, keypoint orders and semantic face labels.

Joint order (MANO): 0 wrist; 1-3 index; 4-6 middle; 7-9 pinky; 10-12 ring; 13-15 thumb.
"""

from __future__ import annotations

import numpy as np

NUM_JOINTS = 16
NUM_POSE_FEATURES = 9 * (NUM_JOINTS - 1)  # flatten(R_i - I), i = 1..15 -> 135
MANO_PARENTS = np.array([-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14], dtype=np.int64)
JOINT_NAMES = (
    "wrist",
    "index1", "index2", "index3",
    "middle1", "middle2", "middle3",
    "pinky1", "pinky2", "pinky3",
    "ring1", "ring2", "ring3",
    "thumb1", "thumb2", "thumb3",
)
FINGERS = ("thumb", "index", "middle", "ring", "pinky")
# Fingertip vertex ids of MANO's 778-vertex mesh, in FINGERS order (thumb, index, middle, ring, pinky).
MANO_TIP_IDS = np.array([745, 317, 444, 556, 673], dtype=np.int64)
# Joint chain (root -> distal) of each finger, in FINGERS order.
FINGER_JOINTS = {"thumb": (13, 14, 15), "index": (1, 2, 3), "middle": (4, 5, 6), "ring": (10, 11, 12),
                 "pinky": (7, 8, 9)}

# 21 keypoints are the 16 joints followed by the 5 tips (thumb, index, middle, ring, pinky): indices 16..20.
KEYPOINT_ORDERS = {
    "mano": np.arange(21, dtype=np.int64),
    # FreiHAND / OpenPose: wrist, then thumb, index, middle, ring, pinky, each root -> tip.
    "openpose": np.array([0, 13, 14, 15, 16, 1, 2, 3, 17, 4, 5, 6, 18, 10, 11, 12, 19, 7, 8, 9, 20],
                         dtype=np.int64),
}

# Per-face semantic labels (drive texture overlays). -1 means unlabelled.
FACE_LABELS = ("nail", "palm", "dorsum", "finger_palmar", "finger_dorsal", "wrist")
FACE_LABEL_IDS = {name: i for i, name in enumerate(FACE_LABELS)}
