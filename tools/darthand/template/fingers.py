"""Per-finger geometry read off the mesh: where each nail is, which way each finger's palm side faces, and the
fingertip vertex.

Fingers are in `layout.FINGERS` order (thumb, index, middle, ring, pinky) throughout; `chain` below is a finger's
three MANO joints (root -> distal), and `tips` the ends of the distal bones (hm08's `joint-r-finger-k-4` helpers).
The palm side of a finger is the side away from its nail: that holds for the thumb too, whose palm side does not face
-Y like the others'.
"""

from __future__ import annotations

import numpy as np

from darthand.errors import InputError
from darthand.model.layout import FINGER_JOINTS, FINGERS
from darthand.template.mesh import face_areas

DISTAL = np.array([FINGER_JOINTS[f][2] for f in FINGERS])  # DIP (IP for the thumb) joint of each finger


def nail_fingers(vertices: np.ndarray, faces: np.ndarray, nail: np.ndarray, joints: np.ndarray,
                 tips: np.ndarray) -> np.ndarray:
    """(F,) finger index 0..4 of every nail face (-1 elsewhere): the finger whose distal bone is nearest."""
    out = np.full(len(faces), -1, dtype=np.int64)
    c = vertices[faces[nail]].mean(1)
    d = np.stack([_segment_distance(c, joints[j], tips[k]) for k, j in enumerate(DISTAL)], 1)
    out[nail] = np.argmin(d, axis=1)
    return out


def nail_centres(vertices: np.ndarray, faces: np.ndarray, finger_of_face: np.ndarray) -> np.ndarray:
    """(5, 3) area-weighted centroid of each finger's nail faces; raises if a finger has no nail."""
    areas = face_areas(vertices, faces)
    centres = np.zeros((len(FINGERS), 3))
    for k, name in enumerate(FINGERS):
        m = finger_of_face == k
        if not m.any():
            raise InputError(f"fingernail mask: no nail found on the {name} finger")
        centres[k] = (areas[m, None] * vertices[faces[m]].mean(1)).sum(0) / areas[m].sum()
    return centres


def palmar_directions(joints: np.ndarray, tips: np.ndarray, nails: np.ndarray) -> np.ndarray:
    """(5, 3) unit palm-side direction of each finger, perpendicular to its distal bone, pointing away from the nail.

    Checks the hand's chirality: in MANO's frame a right hand's four fingers have their nails toward +Y.
    """
    out = np.zeros((len(FINGERS), 3))
    for k, j in enumerate(DISTAL):
        bone = _unit(tips[k] - joints[j])
        rel = nails[k] - joints[j]
        out[k] = -_unit(rel - (rel @ bone) * bone)
    if not (out[1:, 1] < 0).all():
        raise InputError("hm08 right hand: the nails are not on the back of the hand (+Y) in the hand frame; "
                         "the '-r-' groups do not describe a right hand as expected")
    return out


def bone_palmar(joints: np.ndarray, tips: np.ndarray, palmar: np.ndarray) -> np.ndarray:
    """(16, 3) palm-side unit direction per joint's bone (its finger's direction made perpendicular to the bone);
    row 0 (wrist, no bone of its own) is -Y, the palm normal of MANO's frame."""
    out = np.zeros((len(joints), 3))
    out[0] = [0.0, -1.0, 0.0]
    for k, name in enumerate(FINGERS):
        chain = FINGER_JOINTS[name]
        ends = [joints[chain[1]], joints[chain[2]], tips[k]]
        for j, end in zip(chain, ends):
            bone = _unit(end - joints[j])
            out[j] = _unit(palmar[k] - (palmar[k] @ bone) * bone)
    return out


def fingertip_vertices(vertices: np.ndarray, weights: np.ndarray, joints: np.ndarray, tips: np.ndarray,
                       palmar: np.ndarray, tilt_deg: float = 20.0) -> np.ndarray:
    """(5,) fingertip vertex of each finger: among the vertices of its distal segment, the one farthest along the
    distal bone tilted `tilt_deg` toward the palm side (the pulp at the very tip, like MANO's tip vertices)."""
    owner = np.argmax(weights, axis=1)
    out = np.zeros(len(FINGERS), dtype=np.int64)
    t = np.radians(tilt_deg)
    for k, j in enumerate(DISTAL):
        bone = _unit(tips[k] - joints[j])
        direction = np.cos(t) * bone + np.sin(t) * _unit(palmar[k] - (palmar[k] @ bone) * bone)
        cand = np.nonzero(owner == j)[0]
        if not len(cand):
            raise InputError(f"skin weights: no vertex belongs to the {FINGERS[k]}'s distal segment")
        out[k] = cand[np.argmax(vertices[cand] @ direction)]
    return out


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)
