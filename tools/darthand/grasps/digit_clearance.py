"""Digits kept out of each other during a grasp fit: each phalanx a capsule (the thumb's two, each finger's three:
its bone's segment, joint to child joint or to the tip, and a radius from the template's skin around it), and every
pair of capsules on two different digits kept at least their radii apart.

    clearance(a, b) = |p_a - p_b| - need_ab        p_a, p_b the closest points of the two segments (m)
    need_ab         = min(r_a + r_b, REST_SHARE x their distance in the flat rest hand)

so phalanges that sit close at rest (the proximal ones beside a web) are not pushed apart. A radius is RADIUS_SHARE
of the median distance of its bone's vertices to the segment: the skin's soft side may touch the next digit's, the
bones may not come through each other. The fit adds (max(0, -clearance) / SCALE)^2 per pair; MeshLab's test
(model/self_crossing) stays the build's independent guard.

The Jacobian of a distance d = u . (p_a - p_b) (u the unit direction from p_b to p_a) is u . (dp_a - dp_b): both
points are fixed in their bones, so an angle k turning about the posed joint J_k with world angular velocity w_k
moves p by w_k x (p - J_k) when k is the bone or one of its parents (pair_digits.angle_rows with a share of 1); the
hand's rigid placement moves both alike and leaves d unchanged. The closest points' own motion along the segments
is second order (they minimise the distance).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from darthand.model.anatomy import rest_joints
from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS, FINGERS
from darthand.model.pair_digits import angle_rows

RADIUS_SHARE = 1.0     # of a phalanx's median skin distance to its bone segment
REST_SHARE = 0.9       # a pair closer than its radii at rest needs this share of its rest distance
SCALE = 0.2e-3         # m of digit overlap that costs one sigma of pre-shape change


@dataclass
class Capsules:
    """The phalanges of a model as capsules: bone (C,) joint ids, start (C, 3) and child point (C, 3) in the rest
    frame (the bone's joint; the next joint or the tip vertex), pairs (P, 2) capsule ids on different digits,
    need (P,) m, ancestors (C, 16) bool (the joints whose turn moves each bone)."""

    bone: np.ndarray
    start: np.ndarray
    child: np.ndarray
    pairs: np.ndarray
    need: np.ndarray
    ancestors: np.ndarray

    @classmethod
    def of(cls, model: HandModel) -> "Capsules":
        joints = rest_joints(model)
        bone, child, digit = [], [], []
        for d, (finger, tip) in enumerate(zip(FINGERS, model.tip_ids)):
            chain = FINGER_JOINTS[finger]
            for k, j in enumerate(chain):
                if finger == "thumb" and k == 0:
                    continue                     # the thumb's metacarpal is the thenar: palm, not digit
                bone.append(j)
                child.append(joints[chain[k + 1]] if k + 1 < len(chain) else model.v_template[tip])
                digit.append(d)
        bone_a, child_a = np.array(bone), np.array(child, np.float64)
        radius = RADIUS_SHARE * skin_radii(model, bone_a, joints[bone_a], child_a)
        pairs = np.array([(a, b) for a, b in itertools.combinations(range(len(bone)), 2) if digit[a] != digit[b]])
        rest = segment_distances(joints[bone_a][pairs[:, 0]], child_a[pairs[:, 0]],
                                 joints[bone_a][pairs[:, 1]], child_a[pairs[:, 1]])[0]
        need = np.minimum(radius[pairs].sum(1), REST_SHARE * rest)
        return cls(bone_a, joints[bone_a], child_a, pairs, need, ancestor_table(model.parents, bone_a))

    def segments(self, transforms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(start (C, 3), end (C, 3)) of the posed segments, from forward's skinning transforms (16, 4, 4): a bone's
        start is its joint, its end the child point carried by the bone's own transform."""
        G = transforms[self.bone]
        start = G[:, :3, 3] + np.einsum("cij,cj->ci", G[:, :3, :3], self.start)
        end = G[:, :3, 3] + np.einsum("cij,cj->ci", G[:, :3, :3], self.child)
        return start, end

    def clearances(self, transforms: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(clearance (P,) m, unit direction u (P, 3) from the second capsule's closest point to the first's,
        those points (P, 3) each) of every pair, posed by transforms (16, 4, 4)."""
        start, end = self.segments(transforms)
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        d, pa, pb = segment_distances(start[a], end[a], start[b], end[b])
        u = (pa - pb) / np.maximum(d, 1e-12)[:, None]
        return d - self.need, u, pa, pb

    def rows(self, u: np.ndarray, pa: np.ndarray, pb: np.ndarray, free: np.ndarray, omega: np.ndarray,
             pivot: np.ndarray) -> np.ndarray:
        """(P, n) derivative of each pair's clearance per free angle (flat ids (n,) into (16, 3)), with their
        world angular velocities omega (n, 3) and pivots (n, 3) in the frame of pa, pb."""
        moves = self.ancestors[:, free // 3].astype(np.float64)          # (C, n)
        a, b = self.pairs[:, 0], self.pairs[:, 1]
        return angle_rows(pa, u, moves[a], omega, pivot) - angle_rows(pb, u, moves[b], omega, pivot)



def digit_of(capsules: Capsules, ids: np.ndarray) -> str | None:
    """The FINGERS name of the first capsule of `ids` (its bone's chain), or None when ids is empty."""
    if len(ids) == 0:
        return None
    bone = int(capsules.bone[int(ids[0])])
    return next(f for f, chain in FINGER_JOINTS.items() if bone in chain)


def skin_radii(model: HandModel, bone: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """(C,) median distance (m) from each bone's own vertices (its largest skinning weight) to its segment."""
    owner = np.argmax(model.weights, axis=1)
    out = np.zeros(len(bone))
    for c, j in enumerate(bone):
        v = model.v_template[owner == j]
        out[c] = np.median(point_segment_distances(v, start[c], end[c]))
    return out


def point_segment_distances(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n,) distances (m) of points (n, 3) to the segment a-b."""
    ab = b - a
    t = np.clip((points - a) @ ab / max(float(ab @ ab), 1e-18), 0.0, 1.0)
    return np.linalg.norm(points - a - t[:, None] * ab, axis=1)


def segment_distances(a0, a1, b0, b1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(distance (P,), closest point on a (P, 3), closest point on b (P, 3)) of segment pairs a0-a1, b0-b1 (P, 3)
    each: the clamped solution of the 2x2 normal equations (Ericson, Real-Time Collision Detection 5.1.9)."""
    d1, d2, r = a1 - a0, b1 - b0, a0 - b0
    a = np.einsum("pi,pi->p", d1, d1)
    e = np.einsum("pi,pi->p", d2, d2)
    f = np.einsum("pi,pi->p", d2, r)
    c = np.einsum("pi,pi->p", d1, r)
    b = np.einsum("pi,pi->p", d1, d2)
    denom = a * e - b * b
    s = np.where(denom > 1e-18, np.clip((b * f - c * e) / np.where(denom > 1e-18, denom, 1.0), 0, 1), 0.0)
    t = (b * s + f) / np.maximum(e, 1e-18)
    a_safe = np.maximum(a, 1e-18)
    s = np.where(t < 0, np.clip(-c / a_safe, 0, 1), np.where(t > 1, np.clip((b - c) / a_safe, 0, 1), s))
    t = np.clip(t, 0, 1)
    pa = a0 + s[:, None] * d1
    pb = b0 + t[:, None] * d2
    return np.linalg.norm(pa - pb, axis=1), pa, pb


def ancestor_table(parents: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """(C, 16) bool: joint k is the bone itself or one of its parents (the root's -1 ends a chain)."""
    out = np.zeros((len(bones), len(parents)), bool)
    for c, j in enumerate(bones):
        while j >= 0:
            out[c, j] = True
            j = int(parents[j]) if j > 0 else -1
    return out
