"""Whether a posed hand passes through itself: two digits inside each other.

Poses sampled uniformly within the joint limits often are not hands at all: a thumb through the index finger, the
ring finger through the pinky. Whatever is measured on such a pose (an accessory's contact with the hand, a
rendered label) measures the impossible pose. The test is the gesture fit's own pair (model/gesture_fit): the signed
distances between parts it solves against (model/proximity), and MeshLab's face intersection test that guards it
(model/intersections). Either finding two digits inside each other is enough: the distances miss crossings near
the webs, where they compare nothing (parts within `proximity.EXCLUDE` of each other along the skin), and MeshLab
names a crossing of a digit's base by the part its faces are labelled with, the palm. Contact with the palm is left
out, as in the gesture checks: a bent finger folds its skin into the palm's.

The distances are measured only between digit pairs whose posed sample regions overlap (bounding boxes), and the
first crossing found ends the test: most poses cost a few pairs (about 20 ms of CPU a pose, MeshLab's test included).
"""

from __future__ import annotations

import itertools

import numpy as np

from darthand.model.forward import forward
from darthand.model.hand_model import HandModel
from darthand.model.intersections import PARTS, between_digits, face_parts, part_intersections
from darthand.model.proximity import PartSurfaces
from darthand.model.topology import vertex_normals

DIGIT_PAIRS = tuple(itertools.combinations(range(1, len(PARTS)), 2))    # index into PARTS; 0 (the palm) left out


class SelfCrossing:
    """The self-crossing test of one model, set up once for any number of poses."""

    def __init__(self, model: HandModel):
        self.model = model
        self.surfaces = PartSurfaces(model)
        self.face_part = face_parts(model)
        # Per digit pair, both ways: the samples of one compared with the faces of the other (their corners).
        self.regions = {}
        for p, q in DIGIT_PAIRS:
            sp, fq = self.surfaces.comparable(p, q)
            sq, fp = self.surfaces.comparable(q, p)
            self.regions[(p, q)] = (sp, np.unique(model.faces[fq]), sq, np.unique(model.faces[fp]))

    def crossing(self, vertices: np.ndarray) -> str | None:
        """The first digit pair ('thumb-index') found inside each other in the posed vertices (V, 3), or None."""
        samples = self.surfaces.samples(vertices)
        normals = None
        for (p, q), (sp, cq, sq, cp) in self.regions.items():
            if not (_overlap(samples[sp], vertices[cq]) or _overlap(samples[sq], vertices[cp])):
                continue
            if normals is None:
                normals = vertex_normals(vertices, self.model.faces)
            if self.surfaces.distance(vertices, normals, p, q) < 0:
                return f"{PARTS[p]}-{PARTS[q]}"
        between = part_intersections(vertices, self.model.faces, self.face_part)["between"]
        if between_digits(between):
            return next(k for k in between if "palm" not in k)
        return None

    def crossing_poses(self, poses: np.ndarray, batch: int = 32) -> list[str | None]:
        """`crossing` of each of the (P, 48) axis-angle poses."""
        out = []
        for s in range(0, len(poses), batch):
            out += [self.crossing(v) for v in forward(self.model, poses[s:s + batch]).vertices]
        return out


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether the bounding boxes of two point sets (N, 3), (M, 3) overlap (False if either is empty)."""
    if len(a) == 0 or len(b) == 0:
        return False
    return bool((np.maximum(a.min(0), b.min(0)) <= np.minimum(a.max(0), b.max(0))).all())
