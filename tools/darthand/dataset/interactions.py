"""Two hands of one person in one frame: the interaction types, each a sampler of the two poses and of the left
hand's placement relative to the right, resolved so that neither hand passes into the other (model/hand_pair.py).

The world is the right hand's model frame (MANO's: fingers toward -X, thumb toward +Z, palm facing -Y, wrist toward
+X); the right hand's placement is the identity and the left hand's (its own model frame into the world) is what a
type draws (issue 29's contract). Types:

- apart: DART poses, the left hand turned at random, 5-15 cm from the right, no contact;
- touching: palms facing; fingertips to fingertips (fingers slightly bent) or palm to palm (flat hands);
- clasped: palms facing, the left turned 70-110 deg about the palm normal, fingers curled over the other hand;
- interlaced: palms facing, fingers bent toward the other palm at the knuckles and fanned so that the webs at the
  distal phalanges are a finger wide, the left shifted along the fingers' row by half their spacing (its index and
  middle distal phalanges in the right's index-middle and middle-ring webs) and brought in on a fine grid, so that
  the fingers pass between each other (a rigid mesh cannot interlace deeper: at the proximal phalanges the webs,
  even fanned to the joint limits, are 3-13 mm for a 16-18 mm finger; the pinky is too short to flank the ring);
- holding: the left hand in a C grip around the right's wrist, its palm on the back of the wrist;
- overlapping: the left hand over the back of the right (1-4 cm above), both DART poses: one in front of the other;
- mirrored: the mirror-image DART pose side by side (thumbs toward each other, 1-5 cm apart);
- held, handover: both hands on one object of the catalogue, each in a grasp of it (dataset/object_pairs.py, which
  draws them on its own stream and redraws there); asked for by name only. A held or handover frame that cannot be
  drawn falls back as the others do.

The touching, clasped and interlaced pre-shapes are one draw of finger angles for both hands (the left's the right's
mirror image) when the left model is the right's mirror image, as a build's are: a mirrored hand self-crosses exactly
where the right one does, so one self-crossing test covers both.

With `fit_digits` (off by default) the resolution also fits both hands' digits (hand_pair.resolve's `digits`;
a hand wearing an accessory keeps its digits as drawn): the job carries the fitted poses, and each re-posed hand is
tested for self-crossing again (a draw whose fitted hand crosses itself is redrawn).

Each is placed by bringing the left hand along an approach direction to first contact (hand_pair.first_contact_shift)
and backing it off by the type's gap, then resolved by `hand_pair.resolve`, with the contacts the type asks for.
A draw that does not resolve is redrawn: attempt k of frame i draws from [seed, INTERACTION_STREAM, i, k]; after
ATTEMPTS the frame falls back to 'apart' with the plan's pose mirrored (no pre-shape to redraw, the hands 5-15 cm
apart along a line: it resolves by construction), so a frame is never emitted penetrating.
"""

from __future__ import annotations


import numpy as np
from scipy.spatial.transform import Rotation

from darthand.dataset.interaction_shares import OBJECT_TYPES, choose_type, parse_shares
from darthand.errors import InputError
from darthand.model import hand_pair
from darthand.model.anatomy import angles_to_axis_angle, joint_frames, limits_radians, rest_joints
from darthand.model.layout import FINGER_JOINTS, NUM_JOINTS
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.model.pair_digits import DigitHand
from darthand.model.preshape_crossing import PreshapeCrossing

INTERACTION_STREAM = 9
ATTEMPTS = 3
JITTER_DEG = 4.0
# The pre-shapes' thumb CMC spread (degrees): away from the index finger, which a bent index otherwise meets (the
# open hand, 20 draws per pre-shape: 0 self-crossing at -15 or -30, most at +15).
THUMB_AWAY_DEG = -15.0
FALLBACK = "apart-mirrored"    # the last draw of a frame: apart, the plan's pose mirrored (resolves by construction)
WRIST_HOLD_M = (0.0, 0.04)    # the holding hand's centre this far up the forearm (+X) from the wrist joint
PALM = (0,)
FINGERS = tuple(range(1, 16))
SPREAD_ORDER = ("index", "middle", "ring", "pinky")   # across the hand, from the thumb's side
# The interlaced pre-shape: the MCPs bent toward the other palm (the two hands' fingers cross between the palms), the
# PIPs a little, each finger's MCP spread (degrees, + toward the pinky's side) so that the three webs at the distal
# phalanges are alike, about 19 mm (the pinky apart most: it sits closest), the thumb turned back and out (its CMC
# bend and spread) to leave room for the other's.
INTERLACED: dict = {"mcp": (30, 45), "bend": (0, 15), "spreads": (-15.0, -9.0, -3.0, 20.0), "thumb_cmc": (-20.0, -30.0)}
# The grid (m) across the approach on which first contact is found: finer for interlaced, whose fingers pass a few
# mm from each other (the coarse grid's neighbouring cells would stop them at the fingertips).
APPROACH_CELL = {"interlaced": 1.0e-3}
PLAIN_TEXTURE = "plain"   # the texture a worn accessory's hand is posed with here: the geometry only (no maps loaded)
MIRROR_Y = np.diag([-1.0, -1.0, 1.0])   # a left hand's own frame -> palm facing the right's palm (+Y)
MIRROR_Z = np.diag([-1.0, 1.0, -1.0])   # -> lying beside the right, palm down, thumb toward -Z


class InteractionSampler:
    """Two-hand draws on a right model and a left model (each the model its side's source poses)."""

    def __init__(self, right, left, shares: dict, sources: dict | None = None, fit_digits: bool = False,
                 objects=None):
        """objects: the draws of the types with an object (dataset/object_pairs.ObjectPairs), needed when the
        shares give those types a share."""
        self.right, self.left, self.shares = right, left, parse_shares(shares)
        self.objects = objects
        if objects is None and any(self.shares.get(t, 0.0) for t in OBJECT_TYPES):
            raise InputError("interactions held/handover: give the object and grasp catalogues (--objects-catalog, "
                             "--grasps-catalog)")
        self.fit_digits = fit_digits
        self.sources = sources or {}     # {side: FrameSource}: the posed accessories of the hands that wear one
        self.frames = {"right": joint_frames(right), "left": joint_frames(left)}
        self.self_crossing = {"right": PreshapeCrossing(right), "left": PreshapeCrossing(left)}
        self.wrist = rest_joints(right)[0]
        self.limits = limits_radians()
        self.mirrored = _mirror_images(right, left)

    def sample(self, seed: int, index: int, u: float, dart_pose: np.ndarray, betas, accessory: str = "none",
               wearer: str = "right") -> dict:
        """Frame `index`'s two hands: {'type', 'right_pose' (48,), 'left_pose' (48,), 'placement' (4, 4) of the
        left hand, 'record', 'resolution'} (record: the job's interaction record; resolution: the last draw's
        hand_pair.Resolution, with its CPU time). u: the frame's uniform choosing the type;
        dart_pose: the plan's pose of the frame (right-handed, (48,)); betas: both hands' shape (or None); accessory:
        the catalogue id the `wearer` side's hand wears ('none': none), part of that hand in the penetration fit."""
        asked = choose_type(u, self.shares)
        # (kind, its draw's index on INTERACTION_STREAM, the attempts the frame took when it resolves)
        if asked in OBJECT_TYPES:
            held = self.with_object(asked, seed, index, betas)
            if held is not None:
                return held
            draws = [(FALLBACK, ATTEMPTS, self.objects.attempts + 1)]      # every object draw failed: apart
        else:
            draws = [(asked, k, k + 1) for k in range(ATTEMPTS)] + [(FALLBACK, ATTEMPTS, ATTEMPTS + 1)]
        for kind, k, attempts in draws:
            rng = np.random.default_rng([int(seed), INTERACTION_STREAM, int(index), k])
            out = self.draw(kind, rng, np.asarray(dart_pose, np.float64), betas, (accessory, wearer))
            kind = "apart" if kind == FALLBACK else kind
            if out is not None and out["resolution"].resolved:
                record = {"type": kind, "contact_parts": out["contact_parts"], "attempts": attempts,
                          "resolved": out["resolution"].figures()}
                if kind != asked:
                    record["redrawn_from"] = asked
                return {"type": kind, "right_pose": out["right_pose"], "left_pose": out["left_pose"],
                        "placement": out["placement"], "record": record, "resolution": out["resolution"]}
        raise InputError(f"frame {index}: two hands could not be placed apart")  # 'apart' resolves by construction

    def with_object(self, kind: str, seed: int, index: int, betas) -> dict | None:
        """A held or handover frame (sample's dict with 'object': {'id', 'category', 'placement' (4, 4)} and
        'grasps': a record per hand; 'resolution' None), or None when every attempt failed."""
        assert self.objects is not None
        draw, failed = self.objects.sample(kind, seed, index, betas)
        if draw is None:
            return None
        record = {"type": kind, "contact_parts": [["hand", "object"]] * 2, "attempts": failed + 1,
                  "object": {"id": draw.object_id, "category": draw.category},
                  "resolved": draw.figures}
        if draw.receiver is not None:
            record["receiver"] = draw.receiver
        return {"type": kind, "right_pose": draw.right_pose, "left_pose": draw.left_pose,
                "placement": draw.placement, "record": record, "resolution": None,
                "object": {"id": draw.object_id, "category": draw.category, "placement": draw.object_placement},
                "grasps": draw.grasps}

    # ------------------------------------------------------------------------------------------------ one draw
    def draw(self, kind: str, rng: np.random.Generator, dart_pose: np.ndarray, betas,
             worn: tuple = ("none", "right")) -> dict | None:
        """One attempt at type `kind`: poses, the placement and its resolution; None when a pre-shaped hand passes
        through itself (model/self_crossing.py: two digits inside each other). worn: (accessory id, the side
        wearing it): that hand is measured with its accessory (`wearing`)."""
        right_pose, left_pose, shaped = self.poses(kind, rng, dart_pose)
        a = hand_pair.pose_hand(self.right, right_pose, betas)
        b0 = hand_pair.pose_hand(self.left, left_pose, betas)
        if not self.fit_digits and self.crossing(shaped, (a, b0)):   # with the fit: tested on what it emits
            return None
        a, b0 = (self.wearing(side, hand, pose, betas, worn) for side, hand, pose in
                 (("right", a, right_pose), ("left", b0, left_pose)))
        R, offset, approach, gap, touch = self.arrangement("apart" if kind == FALLBACK else kind, rng, a, b0)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = a.vertices.mean(0) + offset - R @ b0.vertices.mean(0)
        b = b0.moved(T)
        shift = hand_pair.first_contact_shift(a, b, approach, APPROACH_CELL.get(kind, 2.5e-3))
        if not np.isfinite(shift):
            return None
        T[:3, 3] += (shift - gap) * approach
        res = hand_pair.resolve(a, b0.moved(T), touch, digits=self.digit_hands(a, b0, right_pose, left_pose, betas,
                                                                               T))
        if self.fit_digits:
            fitted = res.poses or (None, None)
            tested = [own if f is None else True for own, f in zip(shaped, fitted)]
            right_pose, left_pose = (p if f is None else f for p, f in zip((right_pose, left_pose), fitted))
            hands = [hand_pair.pose_hand(m, p, betas) if t else None
                     for m, p, t in ((self.right, right_pose, tested[0]), (self.left, left_pose, tested[1]))]
            if self.crossing(tested, hands):
                return None
        placement = res.T @ T
        return {"right_pose": right_pose, "left_pose": left_pose, "placement": placement, "resolution": res,
                "contact_parts": [[_region_name(jb), _region_name(ja)] for jb, ja in touch]}

    def digit_hands(self, a, b, right_pose, left_pose, betas, T: np.ndarray):
        """(right's, left's) pair_digits.DigitHand for the fit of both hands' digits, None for a hand that wears an
        accessory (its mesh is more than the model's) or all None when `fit_digits` is off."""
        if not self.fit_digits:
            return None
        return tuple(DigitHand(model, pose, betas, place, self.frames[side])
                     if len(hand.vertices) == model.num_vertices else None for side, model, hand, pose, place in
                     (("right", self.right, a, right_pose, None), ("left", self.left, b, left_pose, T)))

    def crossing(self, tested, hands) -> bool:
        """Whether a hand crosses itself (model/self_crossing.py), of the (right, left) `hands` (PosedHands as
        posed, without accessories) whose `tested` flag is set (the plan's own poses are its sampler's)."""
        return any(own and self.self_crossing[side].crossing(hand.vertices) is not None
                   for side, hand, own in zip(("right", "left"), hands, tested))

    def wearing(self, side: str, hand, pose: np.ndarray, betas, worn: tuple):
        """`hand` (a hand_pair.PosedHand) with the accessory it wears, when `worn` puts one on this side: the hand
        and its accessory as the side's source poses them for the renderer (render/assets.HandAssets.subject: a
        worn ring may move the hand's pose, so the hand is the source's too), one mesh whose accessory vertices
        and faces count as the joint it is attached to."""
        accessory, wearer = worn
        if accessory in (None, "none") or wearer != side or side not in self.sources:
            return hand
        subject = self.sources[side].subject(pose, texture=PLAIN_TEXTURE, accessory=accessory, betas=betas)
        parts = [s for s in subject.surfaces if s.role in ("hand", "accessory")]
        joint = subject.info.get("accessory_parent_joint") or 0
        return hand_pair.combined_hand(parts, hand, joint)

    def poses(self, kind: str, rng: np.random.Generator, dart_pose: np.ndarray):
        """(right (48,), left (48,), (right pre-shaped, left pre-shaped)): axis-angle poses, each of its own side's
        model, and which of them this module shaped (the others are the plan's pose or its mirror image)."""
        if kind in ("apart", "overlapping"):
            other = self.preshape("left", rng, {"bend": (0, 60), "spread": (-8, 8)})
            return dart_pose, other, (False, True)
        if kind in ("mirrored", FALLBACK):
            return dart_pose, mirror_pose(dart_pose), (False, False)
        shape: dict = {"touching": {"bend": (5, 30), "spread": (-5, 5)},
                       "clasped": {"bend": (50, 80), "spread": (-3, 3)},
                       "interlaced": INTERLACED,
                       "holding": {"bend": (45, 70), "spread": (-3, 3)}}[kind]
        if kind == "holding":
            return dart_pose, self.preshape("left", rng, shape), (False, True)
        right = self.preshape("right", rng, shape)
        if self.mirrored:             # the left hand the right's mirror image: its self-crossing test is the right's
            return right, mirror_pose(right), (True, False)
        return right, self.preshape("left", rng, shape), (True, True)

    def preshape(self, side: str, rng: np.random.Generator, shape: dict) -> np.ndarray:
        """(48,) a hand's pose: every finger joint bent by a draw from shape['bend'] (degrees; the DIP 0.7 of it;
        the MCPs by a draw from shape['mcp'] when given), fingers fanned by shape['spread'] (or each MCP spread by
        shape['spreads'], index to pinky), the thumb bent less (its CMC 0.2, MCP and IP 0.4 of it) and spread away
        from the index finger (or its CMC bend and spread shape['thumb_cmc']), each bend jittered by JITTER_DEG,
        within the limits."""
        angles = np.zeros((NUM_JOINTS, 3))
        bend = rng.uniform(*shape["bend"])
        spread = rng.uniform(*shape.get("spread", (0, 0)))
        knuckle = rng.uniform(*shape["mcp"]) if "mcp" in shape else bend
        for k, finger in enumerate(("index", "middle", "ring", "pinky")):
            mcp, pip, dip = FINGER_JOINTS[finger]
            angles[[mcp, pip, dip], 2] = [knuckle, bend, 0.7 * bend]
            angles[mcp, 1] = shape["spreads"][k] if "spreads" in shape else spread * (k - 1.5) / 1.5
        cmc, mcp, ip = FINGER_JOINTS["thumb"]
        angles[[cmc, mcp, ip], 2] = [0.2 * bend, 0.4 * bend, 0.4 * bend]
        angles[cmc, 1] = THUMB_AWAY_DEG
        if "thumb_cmc" in shape:
            angles[cmc, 2], angles[cmc, 1] = shape["thumb_cmc"]
        angles[:, 2] += JITTER_DEG * rng.standard_normal(NUM_JOINTS) * (angles[:, 2] != 0)
        angles = np.clip(np.deg2rad(angles), self.limits[..., 0], self.limits[..., 1])
        angles[0] = 0.0
        model = self.right if side == "right" else self.left
        return angles_to_axis_angle(model, angles, self.frames[side]).reshape(-1)

    def arrangement(self, kind: str, rng: np.random.Generator, a, b):
        """(R (3, 3) the left hand's turn, offset (3,) of its centre from the right's (m), approach (3,) unit
        direction it is brought in along, gap (m) it stops short of contact, touch: joint-set pairs (left's,
        right's) to bring into contact)."""
        jitter = Rotation.from_rotvec(np.deg2rad(JITTER_DEG) * rng.standard_normal(3)).as_matrix()
        up = np.array([0.0, 1.0, 0.0])
        if kind == "apart":
            R = Rotation.random(random_state=rng).as_matrix()
            return R, np.zeros(3), _unit(rng.standard_normal(3)), rng.uniform(0.05, 0.15), ()
        if kind == "overlapping":
            return jitter @ MIRROR_Z, rng.uniform(-0.02, 0.02, 3), -up, rng.uniform(0.01, 0.04), ()
        if kind == "mirrored":
            return jitter @ MIRROR_Z, np.array([0.0, 0.0, 0.1]), np.array([0.0, 0.0, -1.0]), \
                rng.uniform(0.01, 0.05), ()
        if kind == "touching":
            tips = rng.random() < 0.5
            touch = ((hand_pair.TIPS, hand_pair.TIPS),) if tips else ((PALM, PALM),)
            return jitter @ MIRROR_Y, np.array([0.0, -0.1, 0.0]), up, hand_pair.CONTACT_GAP, touch
        if kind == "clasped":
            turn = Rotation.from_rotvec(np.deg2rad(rng.uniform(70, 110)) * up).as_matrix()
            return turn @ jitter @ MIRROR_Y, np.array([0.0, -0.1, 0.0]), up, hand_pair.CONTACT_GAP, \
                ((FINGERS, None),)
        if kind == "interlaced":      # the jitter a quarter: a few degrees of yaw put a fingertip on another's
            R = Rotation.from_matrix(jitter).as_rotvec() * 0.25
            R = Rotation.from_rotvec(R).as_matrix() @ MIRROR_Y
            return R, interleaving_offset(a, b, R) - 0.15 * up, up, hand_pair.CONTACT_GAP, ((FINGERS, FINGERS),)
        # holding: the left's fingers across the right's wrist (toward -Z), its palm on the back of the wrist, its
        # centre WRIST_HOLD_M up the forearm from the wrist joint
        turn = Rotation.from_rotvec(np.deg2rad(90) * up).as_matrix()
        target = self.wrist + np.array([rng.uniform(*WRIST_HOLD_M), 0.1, 0.0]) - a.vertices.mean(0)
        return jitter @ turn, target, -up, hand_pair.CONTACT_GAP, ((PALM + FINGERS, PALM),)


def segment_centres(hand, segment: int) -> np.ndarray:
    """(4, 3) centres (m) of the index, middle, ring and pinky segment `segment` (0 proximal, 1 middle, 2 distal
    phalanx) of a posed hand: the mean of the vertices its joint moves most."""
    return np.stack([hand.vertices[hand.vertex_joint == FINGER_JOINTS[f][segment]].mean(0) for f in SPREAD_ORDER])


def interleaving_offset(a, b, R: np.ndarray) -> np.ndarray:
    """(3,) the offset (m) of the turned left hand's centre from the right's that puts its index, middle and ring
    distal phalanges (where the fingers first meet) midway along the spread axis Z between the right's index-middle,
    middle-ring and ring-pinky, and level with the right's along the fingers (X); Y (palm to palm) is left 0."""
    pa = segment_centres(a, 2)
    pb = (segment_centres(b, 2) - b.vertices.mean(0)) @ R.T
    z = np.mean((pa[:-1, 2] + pa[1:, 2]) / 2 - pb[:-1, 2])
    return np.array([np.mean(pa[:, 0] - pb[:, 0]), 0.0, z]) - a.vertices.mean(0) * [1, 0, 1]


def _mirror_images(right, left) -> bool:
    """Whether the left model is the right's mirror image (model/mirror.mirror_model), so that a mirrored pose on it
    is the mirrored hand, self-crossing exactly where the right hand does."""
    m = mirror_model(right)
    same = all(np.shape(getattr(m, f)) == np.shape(getattr(left, f)) and np.allclose(getattr(m, f), getattr(left, f),
                                                                                     rtol=0, atol=1e-9)
               for f in ("v_template", "faces", "weights", "posedirs", "shapedirs", "parents"))
    return same and abs(m.J_regressor - left.J_regressor).max() <= 1e-9


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _region_name(joints) -> str:
    if joints is None:
        return "hand"
    if tuple(joints) == hand_pair.TIPS:
        return "fingertips"
    if tuple(joints) == PALM:
        return "palm"
    if tuple(joints) == FINGERS:
        return "fingers"
    return "palm+fingers"
