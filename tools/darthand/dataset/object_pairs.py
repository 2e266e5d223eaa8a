"""Two hands and one object: the `held` and `handover` interaction types (dataset/interactions.py asks for them).

Both hands take grasps of the grasp catalogue on the same object, each refitted to the frame's shaped model of its
side (grasps/refit.refit_grasp). The two grasps fix the hands' relation: a grasp's placement maps the object frame
into its hand's model frame, so with the right hand at the world's identity (issue 29's contract) the object sits
at the right grasp's placement P_R and the left hand at P_R inv(P_L).

- held: both hands in full grasps of the object (a box, a ball, a bottle, a tool held at both ends).
- handover: the giver (right or left, drawn) in a full grasp; the receiver in a grasp of another part of the
  object, still opening and a few cm short of it: its finger angles at RECEIVER_CLOSE of the grasp's (each joint's
  rotation scaled, the wrist kept), its hand backed off RECEIVER_SHORT_M from the object along the line from the
  object's centre to its hand's centre (the way it came in).

Which grasp pairs suit an object is decided once per object when the sampler is built (`PairTable`): an object
whose longest side is under MIN_EXTENT_M does not take two hands; a (right, left) pair of its catalogue grasps,
posed on the catalogue's own models in the object frame, is compatible when the hands do not pass into each other
(a quick test on the nearest vertices and their normals, `hands_apart`: the exact measure is the frame's) and the
forearms (FOREARM_M from each wrist along its hand's +X) keep FOREARM_CLEAR_M apart (crossed arms do not read as
one person's). A frame draws an object uniformly among those with
a compatible pair, then a pair uniformly; the refitted hands are measured again on the frame's shapes (each hand
into the object by the refit's penetration, the receiver's by render/object_contacts, hand into hand as above),
and a draw that fails is redrawn from [seed, PAIR_STREAM, i, attempt].

Units: metres; frames as dataset/interactions.py's.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from darthand.dataset.jobs import PASS_THROUGH_M
from darthand.dataset.objects import ObjectFrames
from darthand.errors import InputError
from darthand.grasps.digit_clearance import segment_distances
from darthand.grasps.refit import refit_grasp
from darthand.model import hand_pair
from darthand.render.object_contacts import object_contacts

PAIR_STREAM = 14
PAIR_UNIFORMS = 6              # object, pair, giver side, receiver closing, receiver distance, spare
ATTEMPTS = 6
MIN_EXTENT_M = 0.06
PAIR_CLEAR_M = 0.005
FOREARM_M = 0.2
FOREARM_CLEAR_M = 0.04
RECEIVER_CLOSE = (0.5, 0.85)
RECEIVER_SHORT_M = (0.01, 0.04)
SIDES = ("right", "left")


class PairDraw(NamedTuple):
    """One two-hands-and-object draw: poses (48,) of the right and left hands on their shaped models, the left
    hand's placement (4, 4) and the object's (4, 4) in the world (the right's model frame), the object's id and
    category, per hand its grasp record, the hand-hand and hand-object figures (mm) and the receiver's side (None
    for held)."""

    right_pose: np.ndarray
    left_pose: np.ndarray
    placement: np.ndarray
    object_placement: np.ndarray
    object_id: str
    category: str
    grasps: list
    figures: dict
    receiver: str | None


class PairTable:
    """Per object, the (right grasp, left grasp) index pairs that suit two hands (module docstring), computed
    once from the catalogue grasps on the plan's unshaped models. frames: a dataset/objects.ObjectFrames holding
    both sides' grasps and models."""

    def __init__(self, frames: ObjectFrames):
        start = time.process_time()
        self.frames = frames
        self.pairs: dict = {}
        self.tested = 0
        for object_id in sorted(frames.items):
            found = self.object_pairs(object_id)
            if found:
                self.pairs[object_id] = found
        self.seconds = time.process_time() - start
        if not self.pairs:
            raise InputError("held/handover: no object of the catalogue takes two hands (no compatible right/left "
                             "grasp pair)")

    def object_pairs(self, object_id: str) -> list:
        """[(k_right, k_left)] indices into frames.grasps[side][object_id] of the compatible pairs."""
        item = self.frames.items[object_id]
        extent = np.ptp(np.asarray(item.vertices, np.float64), axis=0).max()
        rights = self.frames.grasps["right"].get(object_id, [])
        lefts = self.frames.grasps["left"].get(object_id, [])
        if extent < MIN_EXTENT_M or not rights or not lefts:
            return []
        posed = {side: [table_hand(self.frames.models[side], g) for g in gs]
                 for side, gs in (("right", rights), ("left", lefts))}
        out = []
        for i, a in enumerate(posed["right"]):
            for j, b in enumerate(posed["left"]):
                self.tested += 1
                if forearms_apart(a, b) and hands_apart(a, b):
                    out.append((i, j))
        return out

    def describe(self) -> dict:
        return {"objects": len(self.pairs), "pairs": sum(map(len, self.pairs.values())), "tested": self.tested,
                "cpu_s": round(self.seconds, 3)}


class ObjectPairs:
    """Draws of the held and handover types (module docstring) from an object and a grasp catalogue on the right
    and left models (dataset/objects.ObjectFrames reads them)."""

    def __init__(self, objects, grasps, right, left, categories=None):
        self.frames = ObjectFrames(objects, grasps, {"right": right, "left": left}, categories)
        self.table = PairTable(self.frames)
        self.ids = sorted(self.table.pairs)
        self.attempts = ATTEMPTS

    def describe(self) -> dict:
        return {**self.frames.describe(), "pairs": self.table.describe()}

    def sample(self, kind: str, seed: int, index: int, betas) -> tuple[PairDraw | None, int]:
        """(the frame's draw of type `kind`, or None when every attempt failed; attempts that failed)."""
        models = {s: shaped(self.frames.models[s], betas) for s in SIDES}
        for k in range(ATTEMPTS):
            u = np.random.default_rng([int(seed), PAIR_STREAM, int(index), k]).random(PAIR_UNIFORMS)
            out = self.draw(kind, u, models)
            if out is not None:
                return out, k
        return None, ATTEMPTS

    def draw(self, kind: str, u: np.ndarray, models: dict) -> PairDraw | None:
        """One attempt: the object (u[0]), its pair (u[1]); for a handover the giver (u[2]), the receiver's
        closing (u[3]) and distance (u[4]). None when a refit or a measure fails."""
        object_id = self.ids[_choose(u[0], len(self.ids))]
        pair = self.table.pairs[object_id][_choose(u[1], len(self.table.pairs[object_id]))]
        item = self.frames.items[object_id]
        field = self.frames.field(item)
        grasps = [self.frames.grasps[s][object_id][k] for s, k in zip(SIDES, pair)]
        fits = [refit_grasp(models[s], item, g, field) for s, g in zip(SIDES, grasps)]
        if not all(f.ok and f.penetration_max_m <= PASS_THROUGH_M for f in fits):
            return None
        poses = [np.asarray(f.pose, np.float64) for f in fits]
        to_object = [np.linalg.inv(np.asarray(f.placement, np.float64)) for f in fits]   # hand model -> object
        receiver, posed = None, {}
        if kind == "handover":
            receiver = SIDES[int(u[2] >= 0.5)]
            r = SIDES.index(receiver)
            poses[r] = opened(poses[r], float(np.interp(u[3], (0, 1), RECEIVER_CLOSE)))
            hand = hand_pair.pose_hand(models[receiver], poses[r], None, to_object[r])
            away = _unit(hand.vertices.mean(0) - _centre(item))
            offset = float(np.interp(u[4], (0, 1), RECEIVER_SHORT_M)) * away
            to_object[r] = translated(to_object[r], offset)
            posed[r] = hand.moved(translated(np.eye(4), offset))       # backed off: the same pose, moved
        hands = [posed[k] if k in posed else hand_pair.pose_hand(models[s], p, None, T)
                 for k, (s, p, T) in enumerate(zip(SIDES, poses, to_object))]
        depth = [f.penetration_max_m for f in fits]
        if receiver is not None:
            r = SIDES.index(receiver)
            depth[r] = object_contacts(hands[r].vertices, item, np.eye(4)).penetration_max_m
            if depth[r] > PASS_THROUGH_M:
                return None
        pair_depth = hand_pair.penetration(*hands)
        if pair_depth.max_m > PASS_THROUGH_M or pair_depth.crossing_faces:
            return None
        object_placement = np.linalg.inv(to_object[0])
        figures = {"hand_hand_max_mm": round(1000 * pair_depth.max_m, 3),
                   "hand_hand_crossing_faces": int(pair_depth.crossing_faces),
                   "hand_object_max_mm": [round(1000 * d, 3) for d in depth]}
        records = [grasp_record(b, s, g, f, d, receiver) for b, (s, g, f, d) in enumerate(zip(SIDES, grasps, fits,
                                                                                            depth))]
        return PairDraw(poses[0], poses[1], object_placement @ to_object[1], object_placement, object_id,
                        item.category, records, figures, receiver)


def grasp_record(hand: int, side: str, grasp, fit, depth: float, receiver: str | None) -> dict:
    """A hand's grasp record: its index and side, the grasp's type and id, its role ('held', 'giver', 'receiver'),
    its deepest vertex in the object (mm) and, for a hand on it, the refit's p99."""
    role = "held" if receiver is None else ("receiver" if side == receiver else "giver")
    figures = {"penetration_max_mm": round(1000 * depth, 3)}
    if role != "receiver":
        figures["penetration_p99_mm"] = round(1000 * fit.penetration_p99_m, 3)
    return {"hand": hand, "side": side, "type": grasp.type, "id": grasp.id, "role": role, "figures": figures}


class TableHand(NamedTuple):
    """A catalogue grasp's hand in the object frame with what the pair table's tests read of it, made once per
    grasp (not per pair): the posed hand, a KD-tree of its vertices, its forearm segment (wrist, end)."""

    hand: hand_pair.PosedHand
    tree: cKDTree
    forearm: tuple


def table_hand(model, grasp) -> TableHand:
    """A catalogue grasp's TableHand on `model`: posed in the object frame (its placement inverted), its forearm
    FOREARM_M from the wrist along the hand model frame's +X."""
    H = np.linalg.inv(np.asarray(grasp.placement, np.float64))
    hand = hand_pair.pose_hand(model, grasp.pose, None, H)
    wrist = hand.vertices[hand.vertex_joint == 0].mean(0)
    return TableHand(hand, cKDTree(hand.vertices), (wrist, wrist + FOREARM_M * H[:3, 0]))


def hands_apart(a: TableHand, b: TableHand) -> bool:
    """The table's quick test that two posed hands do not pass into each other: no vertex of either lies more than
    PASS_THROUGH_M behind the other's nearest vertex along that vertex's normal (within PAIR_CLEAR_M + 5 mm of it).
    Approximate (the frame's draw measures exactly): pairs whose vertices stay PAIR_CLEAR_M apart pass at once."""
    for p, q in ((a, b), (b, a)):
        gap, at = q.tree.query(p.hand.vertices, k=1, distance_upper_bound=PAIR_CLEAR_M + 0.005)
        near = np.isfinite(gap)
        if not near.any():
            return True
        offset = ((p.hand.vertices[near] - q.hand.vertices[at[near]]) * q.hand.normals[at[near]]).sum(1)
        if (offset < -PASS_THROUGH_M).any():
            return False
    return True


def forearms_apart(a: TableHand, b: TableHand) -> bool:
    """Whether the forearms of two grasping hands (in the object frame) stay FOREARM_CLEAR_M apart."""
    ends = (np.asarray(p, np.float64)[None] for p in (*a.forearm, *b.forearm))
    return float(segment_distances(*ends)[0][0]) >= FOREARM_CLEAR_M


def opened(pose: np.ndarray, close: float) -> np.ndarray:
    """(48,) a grasp's pose with its finger rotations (joints 1-15) scaled by `close` (0: flat, 1: as gripped)."""
    out = np.array(pose, np.float64)
    out[3:] *= close
    return out


def translated(T: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """T (4, 4) followed by a translation `offset` (3,)."""
    out = np.array(T, np.float64)
    out[:3, 3] += offset
    return out


def shaped(model, betas):
    return model if betas is None else model.shaped(np.asarray(betas, np.float64))


def _centre(item) -> np.ndarray:
    v = np.asarray(item.vertices, np.float64)
    return 0.5 * (v.min(0) + v.max(0))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-12)


def _choose(u: float, n: int) -> int:
    return min(int(u * n), n - 1)
