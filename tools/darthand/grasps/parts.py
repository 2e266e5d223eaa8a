"""The hand's contact parts a grasp type names: each a patch of rest-mesh vertices (ids stay valid in any pose and
on any shape of the same model).

    <finger>_tip   the fingertip's end: vertices of the distal segment within TIP_RADIUS of the tip vertex
    <finger>_pad   the palmar side of the distal segment (the thumb's: its pad, facing the fingers)
    <finger>_<phalanx>_<side>
                   a side of a phalanx (proximal, middle, distal; radial: toward the thumb, ulnar: away, palmar):
                   vertices of that segment whose normal is within 60 deg of the side's direction (the lateral
                   pinch's thumb on the index's middle phalanx, the pen on the middle finger's distal side, a
                   mug's handle in the curled fingers)
    palm           the palm's middle: wrist-bound vertices facing the palm normal, within PALM_RADIUS of its
                   centre (measured in the palm's plane)
"""

from __future__ import annotations

import numpy as np

from darthand.errors import InputError
from darthand.model.anatomy import PALM_JOINTS, joint_frames, palm_normal, rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS, FINGERS
from darthand.model.topology import vertex_normals

TIP_RADIUS = 0.007      # m
PALM_RADIUS = 0.025     # m
FACING = 0.5            # cosine: a pad or side vertex's normal within 60 deg of its direction
PHALANGES = ("proximal", "middle", "distal")    # a finger's three joints in FINGER_JOINTS order (the thumb's too)


def contact_patches(model: HandModel, names) -> dict[str, np.ndarray]:
    """{part name: vertex ids (n,)} for the named parts on `model`'s rest mesh."""
    return {name: part_vertices(model, name) for name in names}


def part_vertices(model: HandModel, name: str) -> np.ndarray:
    """Vertex ids (n,) of one contact part ('index_tip', 'thumb_pad', 'palm', ...)."""
    v, normals = model.v_template, vertex_normals(model.v_template, model.faces)
    owner = np.argmax(model.weights, axis=1)
    if name == "palm":
        joints = rest_joints(model)
        centre = joints[list(PALM_JOINTS)].mean(0)
        n = palm_normal(model, joints)
        off = v - centre
        across = np.linalg.norm(off - np.outer(off @ n, n), axis=1)     # distance from the centre in the plane
        ids = (owner == 0) & (off @ n > 0) & (normals @ n > 0.7) & (across < PALM_RADIUS)
        return _nonempty(np.flatnonzero(ids), name)
    finger, _, kind = name.partition("_")
    if finger in FINGERS and kind.count("_") == 1:
        phalanx, _, side = kind.partition("_")
        return _nonempty(side_vertices(model, finger, phalanx, side, normals, owner), name)
    if finger not in FINGERS or kind not in ("tip", "pad"):
        raise InputError(f"contact part {name!r}: expected palm, <finger>_tip, <finger>_pad or "
                         "<finger>_<proximal|middle|distal>_<radial|ulnar|palmar>")
    distal = FINGER_JOINTS[finger][2]
    tip = v[model.tip_ids[FINGERS.index(finger)]]
    if kind == "tip":
        ids = (owner == distal) & (np.linalg.norm(v - tip, axis=1) < TIP_RADIUS)
    else:
        sign = 1.0 if model.side == "right" else -1.0
        palmar = sign * joint_frames(model)[distal][:, 1]      # the spread axis is the palmar direction
        ids = (owner == distal) & (normals @ palmar > FACING)
    return _nonempty(np.flatnonzero(ids), name)


def side_vertices(model: HandModel, finger: str, phalanx: str, side: str, normals: np.ndarray,
                  owner: np.ndarray) -> np.ndarray:
    """Vertex ids (n,) of one side of one phalanx: owned by its joint (PHALANGES), normal within 60 deg of the
    side's direction (the joint frame's bend axis, signed toward the index's knuckle from the pinky's for radial;
    its spread axis for palmar, as the pads')."""
    if phalanx not in PHALANGES or side not in ("radial", "ulnar", "palmar"):
        return np.zeros(0, np.int64)
    joint = FINGER_JOINTS[finger][PHALANGES.index(phalanx)]
    frame = joint_frames(model)[joint]
    if side == "palmar":
        toward = frame[:, 1] * (1.0 if model.side == "right" else -1.0)
    else:
        joints = rest_joints(model)
        radial = joints[FINGER_JOINTS["index"][0]] - joints[FINGER_JOINTS["pinky"][0]]
        toward = frame[:, 2] * np.sign(frame[:, 2] @ radial) * (1.0 if side == "radial" else -1.0)
    return np.flatnonzero((owner == joint) & (normals @ toward > FACING))


def _nonempty(ids: np.ndarray, name: str) -> np.ndarray:
    if len(ids) == 0:
        raise InputError(f"contact part {name!r}: no vertex of the model matches it")
    return ids
