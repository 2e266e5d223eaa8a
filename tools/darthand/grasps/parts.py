"""The hand's contact parts a grasp type names: each a patch of rest-mesh vertices (ids stay valid in any pose and
on any shape of the same model).

    <finger>_tip   the fingertip's end: vertices of the distal segment within TIP_RADIUS of the tip vertex
    <finger>_pad   the palmar side of the distal segment (the thumb's: its pad, facing the fingers)
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
FACING = 0.5            # cosine: a pad vertex's normal within 60 deg of the palmar direction


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
    if finger not in FINGERS or kind not in ("tip", "pad"):
        raise InputError(f"contact part {name!r}: expected palm, <finger>_tip or <finger>_pad")
    distal = FINGER_JOINTS[finger][2]
    tip = v[model.tip_ids[FINGERS.index(finger)]]
    if kind == "tip":
        ids = (owner == distal) & (np.linalg.norm(v - tip, axis=1) < TIP_RADIUS)
    else:
        sign = 1.0 if model.side == "right" else -1.0
        palmar = sign * joint_frames(model)[distal][:, 1]      # the spread axis is the palmar direction
        ids = (owner == distal) & (normals @ palmar > FACING)
    return _nonempty(np.flatnonzero(ids), name)


def _nonempty(ids: np.ndarray, name: str) -> np.ndarray:
    if len(ids) == 0:
        raise InputError(f"contact part {name!r}: no vertex of the model matches it")
    return ids
