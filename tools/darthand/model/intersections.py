"""Self-intersections of a posed hand, split by part: the palm (joint 0) and the five digits.

Self-intersections are MeshLab's (pymeshlab `compute_selection_by_self_intersections_per_face`, which ignores
neighbouring faces). Each face belongs to the part of its dominant joint: the palm (joint 0) or one of the five
digits. A face intersecting a face of another part is found by running the filter on the two parts together and
keeping the faces not already selected within either part alone. (MeshLab can flag exactly coplanar, disjoint
triangles, as on a polygonal cylinder's flat strips; a skinned hand has none.)

This is the measure the gesture check guards with (template/gesture_checks) and the gesture fit verifies against
(model/gesture_fit).
"""

from __future__ import annotations

import itertools

import numpy as np
import pymeshlab

from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS, FINGERS, NUM_JOINTS
from darthand.model.topology import face_joints

PARTS = ("palm",) + FINGERS


def joint_parts() -> np.ndarray:
    """(16,) index into PARTS of each joint: 0 palm (the root), else its digit."""
    part = np.zeros(NUM_JOINTS, dtype=np.int64)
    for k, finger in enumerate(FINGERS):
        part[list(FINGER_JOINTS[finger])] = k + 1
    return part


def face_parts(model: HandModel) -> np.ndarray:
    """(F,) index into PARTS of each face: the part of the joint with the largest summed corner weight."""
    return joint_parts()[face_joints(model.faces, model.weights)]


def self_intersecting(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool faces that intersect another, non-adjacent face (pymeshlab)."""
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=np.asarray(vertices, dtype=np.float64), face_matrix=faces))
    ms.compute_selection_by_self_intersections_per_face()
    return ms.current_mesh().face_selection_array().astype(bool)


def intersections_within_parts(vertices: np.ndarray, faces: np.ndarray,
                               parts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F,) bool faces intersecting anything, and (F,) bool faces intersecting a face of their own part."""
    everywhere = self_intersecting(vertices, faces)
    alone = np.zeros(len(faces), dtype=bool)
    if everywhere.any():
        for p in np.unique(parts):
            alone[parts == p] = self_intersecting(vertices, faces[parts == p])
    return everywhere, alone


def part_intersections(vertices: np.ndarray, faces: np.ndarray, parts: np.ndarray, masks=None) -> dict:
    """Self-intersections of one posed mesh (V, 3), split by part (masks: its `intersections_within_parts`, when
    already computed).

    Returns {"faces": all self-intersecting faces, "within": {part: faces intersecting their own part},
    "between": {"a-b": faces of a or b that intersect the other part}} (counts).
    """
    everywhere, alone = intersections_within_parts(vertices, faces, parts) if masks is None else masks
    out: dict = {"faces": int(everywhere.sum()),
           "within": {PARTS[p]: int(alone[parts == p].sum()) for p in np.unique(parts[alone])},
           "between": {}}
    for p, q in itertools.combinations(np.unique(parts[everywhere & ~alone]), 2):
        pair = (parts == p) | (parts == q)
        hit = self_intersecting(vertices, faces[pair]) & ~alone[pair]
        if hit.any():
            out["between"][f"{PARTS[p]}-{PARTS[q]}"] = int(hit.sum())
    return out


def between_digits(between: dict) -> int:
    """Faces where two digits intersect, from a `part_intersections` "between" dict (palm pairs left out)."""
    return sum(n for k, n in between.items() if "palm" not in k)
