"""A ring worn in a given pose: where on its bone it sits, and how far the digits around it make room.

A rigid ring follows its bone, but the skin around it does not: with linear blend skinning the palm's skin folds
over a ring on a finger flexed at its knuckle, and a neighbouring finger pressed against the ring's finger (or a
thumb pressed into the palm) passes through the band. A real ring is pushed along its phalanx by the fold, and a
real neighbour is pushed aside by the band. So, per pose, for a hand that wears a ring:

1. slide: the ring moves along its bone axis to the smallest of the offsets `SLIDES` (metres from its fitted place,
   + toward the fingertip) that leaves it at most `TARGET` deep in the posed hand, else to the one that leaves it
   least deep (ties: the smaller move);
2. make room: if that still leaves more than `TARGET`, the digits turn aside -- the knuckle (MCP) spread of the
   ring's finger, of the fingers beside it and of any finger it touches, the thumb's base (CMC) on all three axes
   when the thumb wears it or touches it -- by the least change that clears the ring by `CLEARANCE`, the slide
   being one more unknown: Gauss-Newton steps of the linearised depths (the gesture fit's point velocities,
   model/gesture_fit), weighted by `SIGMA` and `SLIDE_SIGMA`, within the joint limits, `MAX_CHANGE_DEG` and the
   range of `SLIDES`, each measured again, up to `ROUNDS` times. Points outside the hand join the step once it
   would bring them within `CLEARANCE` (an active set), so a finger turned from one neighbour is not turned into
   the other. The shallowest round wins, unless its turn made two digits pass through each other
   (model/self_crossing): then the next, and failing all, the pose as given (the ring keeps what sliding left);
   when two fingers crossed (a middle finger turned from the ring into the index), the rounds are run again with
   that pair's knuckles turning together; when a finger crossed the thumb, with that finger held; up to
   `MAX_RETRIES` times.

The result is the pose the frame shows (its labels come from it) and the ring's placement on its bone; both are a
function of the pose alone, and a hand without a ring is never changed. The rig's forward pass is not touched: the
corrected pose is an ordinary pose. Depth here is a fast estimate (the ring's sample points inside the hand's closed
surface by Embree, their depth to the tangent plane of the nearest hand vertex, the shallowest of the nearest few);
the pose sweep measures the result exactly (accessories/sweep).
"""

from __future__ import annotations

from typing import Any

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from darthand.accessories.attach import to_local
from darthand.accessories.collide import ClosedHand, Solid
from darthand.model.anatomy import angles_to_axis_angle, axis_angle_to_angles, joint_frames, limits_radians
from darthand.model.forward import forward
from darthand.model.gesture_fit import angular_velocities, subtree_mask
from darthand.model.hand_model import HandModel
from darthand.model.intersections import joint_parts
from darthand.model.layout import FINGER_JOINTS, FINGERS, JOINT_NAMES, NUM_JOINTS
from darthand.model.topology import vertex_normals

SLIDES = np.round(np.arange(-0.004, 0.0080001, 0.001), 6)   # m along the bone from the fitted place
TARGET = 0.0004           # m: deeper than this after sliding, the digits make room
CLEARANCE = 0.0003        # m: how far outside the hand the room made puts the ring's points
ROUNDS = 5
MAX_RETRIES = 2           # times a turn that crossed two digits is tried again (the pair linked, or one held)
CHECKED = 2               # turned rounds tested for crossing digits per try (each test costs about 20 ms)
SAMPLE_SPACING = 0.001    # m: the ring's sample points, one per cell of this size (at first)
MAX_SAMPLES = 900         # ... grown until at most this many remain
NEAREST = 4               # hand vertices whose tangent planes bound a point's depth
MAX_CHANGE_DEG = {"finger": 14.0, "thumb": 15.0}
NEAR = 0.0015             # m: points outside the hand but this close join the room-making step once it nears them
# How freely each angle may turn (degrees, one sigma): finger MCP spread; thumb CMC twist, spread, bend.
SIGMA = {"finger": (0.0, 3.0, 0.0), "thumb": (5.0, 5.0, 5.0)}
SLIDE_SIGMA = 0.004       # m: one sigma of slide costs as much as one sigma of turn, when room is made
SCALE = 0.05e-3           # m of depth left that costs as much as one sigma of change
TIE = 0.05e-3             # m: slides whose depths differ by less are equal (the smaller move wins)


@dataclass(frozen=True)
class Worn:
    """A ring worn in one pose: `pose` (48,) the pose the hand takes (the given pose unless room was made),
    `slide` (m) along the bone (slide_matrix, applied before the ring's rest transform), `changed` {joint: (3,)
    degrees added}."""

    pose: np.ndarray
    slide: float
    changed: dict


def slide_matrix(s: float) -> np.ndarray:
    """(4, 4) translation by `s` metres along the ring's local x (its bone axis)."""
    m = np.eye(4)
    m[0, 3] = s
    return m


def sample_points(local_vertices: np.ndarray, spacing: float = SAMPLE_SPACING,
                  most: int = MAX_SAMPLES) -> np.ndarray:
    """(K, 3) one vertex per occupied cell of `spacing` metres (the first in vertex order), the cells grown until
    at most `most` remain: a ring's sample points in its local frame, evenly spread however its mesh is
    tessellated (a braid's strands are many vertices deep). Coordinates are rounded to 0.1 um, so a mesh carried
    to the rest frame and back (a catalogue's file) gives the same samples, bit for bit."""
    rounded = np.round(local_vertices, 7)
    while True:
        first = first_in_cells(np.floor(rounded / spacing).astype(np.int64))
        if len(first) <= most:
            return rounded[first]
        spacing *= 1.2


def first_in_cells(cells: np.ndarray) -> np.ndarray:
    """Sorted indices of the first row of each distinct row of `cells` (N, D) int64: what
    np.unique(cells, axis=0, return_index=True) finds, sorted, from one int64 key per row (a ring's cells span a
    few hundred a side; unique over rows compares them as byte strings, ten times slower)."""
    lo = cells.min(0, initial=0)
    span = cells.max(0, initial=0) - lo + 1
    if np.prod(span.astype(float)) >= 2.0 ** 62:       # keys would overflow: compare rows
        return np.sort(np.unique(cells, axis=0, return_index=True)[1])
    key = (cells - lo) @ np.cumprod(np.concatenate([[1], span[:0:-1]]))[::-1]
    return np.sort(np.unique(key, return_index=True)[1])


class RingWear:
    """How one ring is worn on one model (hand of `betas`), set up once for any number of poses.

    joint: the ring's bone (MANO joint); rest (4, 4) its local frame in the rest hand; local_vertices (N, 3) its mesh
    in that frame. hands: a dict shared by the RingWears of one model and shape (the catalogue sweep's rings), in
    which the last posed hand is kept for the next ring worn in the same pose."""

    def __init__(self, model: HandModel, joint: int, rest: np.ndarray, local_vertices: np.ndarray, betas=None,
                 hands: dict | None = None):
        self.model, self.joint, self.rest = model, int(joint), np.asarray(rest, float)
        self.betas = betas
        self._hands = {} if hands is None else hands
        self.samples = sample_points(np.asarray(local_vertices, float))
        self.hand = ClosedHand.of(model.faces)
        self.frames = joint_frames(model)
        self.limits = limits_radians()
        self.vertex_part = joint_parts()[np.argmax(model.weights, axis=1)]
        self.subtree = subtree_mask(model.parents)
        self.digit = int(joint_parts()[self.joint]) - 1                  # index into FINGERS
        self._last: tuple | None = None
        self._crossing: Any = None   # model/self_crossing.SelfCrossing, made when a turn is first checked

    def worn_once(self, pose) -> Worn:
        """`worn`, remembered for the last pose (a frame rendered again from another view)."""
        key = np.asarray(pose, np.float64).tobytes()
        if self._last is None or self._last[0] != key:
            self._last = (key, self.worn(pose))
        return self._last[1]

    # ------------------------------------------------------------------------------------------- the result
    def worn(self, pose) -> Worn:
        """The ring worn in `pose` ((48,) MANO axis-angle, flat-hand relative)."""
        pose = np.asarray(pose, np.float64).reshape(-1)
        slid = self._slid(pose)                       # the same for every try: only the turns differ
        links: frozenset = frozenset()
        held: frozenset = frozenset()
        for _ in range(MAX_RETRIES + 1):
            choice, crossed = self._worn(pose, slid, links, held)
            retry = self._retry(crossed, links, held)
            if retry is None:
                break
            links, held = retry
        _, pose, s, _, changed = choice
        return Worn(pose, float(s), changed)

    def _retry(self, crossed: str | None, links: frozenset, held: frozenset) -> tuple | None:
        """(links, held) to try again with after a better turn crossed the digit pair `crossed` ('index-middle'):
        two fingers turn together; a finger that crossed the thumb is held (unless it wears the ring); None when
        there is nothing new to try."""
        if crossed is None:
            return None
        digits = [FINGERS.index(n) for n in crossed.split("-") if n in FINGERS]
        if len(digits) != 2:
            return None
        pair = frozenset(digits)
        if 0 not in pair:
            return None if pair in links else (links | {pair}, held)
        other = max(digits)
        if other == self.digit or other in held:
            return None
        return links, held | {other}

    def _worn(self, pose: np.ndarray, slid, links: frozenset, held: frozenset) -> tuple[tuple, str | None]:
        """((depth, pose, slide, posed, changed) chosen, the digit pair a better turn crossed or None) from the
        pose's best slide `slid` (`_slid`), with the finger pairs in `links` turned together and the digits in
        `held` (FINGERS indices) not turned."""
        posed, (s, depth, contact) = slid
        unturned: tuple = (depth, pose, s, posed, {})
        turned = []
        if depth > TARGET:
            start = axis_angle_to_angles(self.model, pose, self.frames)
            angles = start
            for _ in range(ROUNDS):
                step = self._room(angles, start, s, posed, contact, links, held)
                if step is None:
                    break
                angles, s = step
                current = self._pose(pose, angles, start)
                posed, (depth, contact) = self._at(current, s)
                changed = {int(j): np.rad2deg(angles[j] - start[j]) for j in range(NUM_JOINTS)
                           if np.any(angles[j] != start[j])}
                turned.append((depth, current, s, posed, changed))
                if depth <= TARGET:
                    break
        return self._choose(unturned, turned)

    def _choose(self, unturned: tuple, turned: list) -> tuple[tuple, str | None]:
        """The shallowest of the turned rounds that beats the unturned pose by more than TIE and does not make two
        digits pass through each other (model/self_crossing; the CHECKED shallowest are tested), else the unturned
        pose; with the pair ('index-middle') the shallowest such round crossed, if it crossed."""
        crossed = None
        for candidate in sorted(turned, key=lambda c: c[0])[:CHECKED]:
            if candidate[0] >= unturned[0] - TIE:
                break
            if self._crossing is None:
                from darthand.model.self_crossing import SelfCrossing  # lazy: kept off `darthand --help`'s path

                self._crossing = SelfCrossing(self.model)
            found = self._crossing.crossing(candidate[3].vertices[0])
            if found is None:
                return candidate, crossed
            crossed = crossed or found
        return unturned, crossed

    def _pose(self, pose: np.ndarray, angles: np.ndarray, start: np.ndarray) -> np.ndarray:
        """The pose with only the joints whose angles changed converted back (the others keep their exact values)."""
        out = pose.reshape(NUM_JOINTS, 3).copy()
        moved = np.flatnonzero(np.any(angles != start, axis=1))
        if len(moved):
            out[moved] = angles_to_axis_angle(self.model, angles, self.frames)[moved]
        return out.reshape(-1)

    # ------------------------------------------------------------------------------------------- measure
    def _posed(self, pose: np.ndarray):
        """(posed, (the hand's closed solid, vertex KD-tree, vertices (V, 3), normals (V, 3), ring base (4, 4)));
        the hand is kept for the last pose (in `hands`)."""
        key = pose.tobytes()
        hand = self._hands.get(key)
        if hand is None:
            posed = forward(self.model, pose[None], self.betas, dtype=np.float32)
            v = posed.vertices[0].astype(np.float64)
            hand = (posed, self.hand.solid(v), cKDTree(v), v, vertex_normals(v, self.model.faces))
            self._hands.clear()
            self._hands[key] = hand
        posed = hand[0]
        return posed, (*hand[1:], posed.transforms[0, self.joint].astype(np.float64) @ self.rest)

    def _contact(self, hand, s: float, outside: bool = True):
        """(depth (m), (sample points (K, 3), signed depths (K,), nearest hand vertices (K,))) of the ring slid by
        `s` against a posed hand (from `_posed`); without `outside`, the points outside the hand are left at
        -inf (the depth alone is wanted)."""
        solid, tree, v, normals, base = hand
        pts = self.samples @ base[:3, :3].T + (base[:3, :3] @ [s, 0.0, 0.0] + base[:3, 3])
        signed, nearest = _signed_depths(solid, tree, v, normals, pts, outside)
        return max(float(signed.max(initial=0.0)), 0.0), (pts, signed, nearest)

    def _at(self, pose: np.ndarray, s: float):
        posed, hand = self._posed(pose)
        return posed, self._contact(hand, s)

    def _slid(self, pose: np.ndarray):
        """(posed, (slide, depth, contact)) for a pose: the smallest slide in SLIDES that leaves at most TARGET,
        else the one that leaves least (ties: the smaller move)."""
        posed, hand = self._posed(pose)
        best = None
        for s in SLIDES[np.argsort(np.abs(SLIDES), kind="stable")]:
            depth = self._contact(hand, float(s), outside=False)[0]
            if best is None or depth < best[1] - TIE:
                best = (float(s), depth)
            if depth <= TARGET:
                break
        assert best is not None                       # SLIDES is not empty
        s, depth = best
        return posed, (s, depth, self._contact(hand, s)[1] if depth > TARGET else None)

    # ------------------------------------------------------------------------------------------- make room
    def _depth_gradient(self, angles: np.ndarray, posed, x: np.ndarray, nearest: np.ndarray, free: np.ndarray,
                        M: np.ndarray) -> np.ndarray:
        """(K, U + 1): how the signed depth (y - x) . n of each sample point x (K, 3) changes per unknown of the
        step -- the U columns of M (free angles (A,) tied into unknowns: (A, U)), radians, then the slide, metres
        -- linearised: y its nearest hand vertex (nearest (K,)) carried by the joints as skinned, x by the ring's
        bone, n held (the turn of the tangent plane and the correctives left out, as the gesture fit does)."""
        omega, pivot = angular_velocities(self.model, self.frames, angles, posed, free)
        v = posed.vertices[0].astype(np.float64)
        y = v[nearest]
        n = vertex_normals(v, self.model.faces)[nearest]
        ux = np.cross(omega[None], x[:, None] - pivot[None]) * self.subtree[self.joint, free // 3][None, :, None]
        shares = self.model.weights[nearest] @ self.subtree[:, free // 3]           # (K, A)
        uy = np.cross(omega[None], y[:, None] - pivot[None]) * shares[..., None]
        axis = posed.transforms[0, self.joint, :3, :3].astype(np.float64) @ self.rest[:3, 0]
        return np.concatenate([np.einsum("kd,knd->kn", n, uy - ux) @ M, -(n @ axis)[:, None]], 1)

    def _room(self, angles: np.ndarray, start: np.ndarray, s: float, posed, contact, links: frozenset = frozenset(),
              held: frozenset = frozenset()):
        """(angles, slide) one Gauss-Newton step closer to clearing the ring by CLEARANCE (None when nothing
        moves). The slide is one more unknown (sigma SLIDE_SIGMA from the fitted place, within SLIDES' range).

        The residuals are the ring's sample points inside the hand or within NEAR of it: the points inside from
        the start, the ones outside (active set) only once the step would bring them closer than CLEARANCE, so that
        a finger turned away from one neighbour is not turned into the other. Fingers linked in pairs (`links`,
        FINGERS indices) turn their knuckles' spread together, as one unknown; digits `held` do not turn."""
        pts, signed, nearest = contact
        near = signed > -NEAR
        part = self.vertex_part[nearest]
        free, sigma, reach = self._free(set(part[signed > TARGET].tolist()), links, held)
        if len(free) == 0:
            return None
        M = _tied(free, links)                                             # (free angles, unknowns)
        grad = self._depth_gradient(angles, posed, pts[near], nearest[near], free, M)
        depth = signed[near]
        first = np.argmax(M, axis=0)                                      # each unknown's first angle
        x0 = np.append(angles.reshape(-1)[free][first], s)
        home = np.append(start.reshape(-1)[free][first], 0.0)
        sig = np.append(sigma[first] / np.sqrt(M.sum(0)), SLIDE_SIGMA)    # a linked pair: two angles' cost
        lim = self.limits.reshape(-1, 2)[free]
        now = angles.reshape(-1)[free]
        low = np.maximum(lim[:, 0], start.reshape(-1)[free] - reach) - now     # per angle, as a step
        high = np.minimum(lim[:, 1], start.reshape(-1)[free] + reach) - now
        lo = np.append([low[M[:, k] > 0].max() for k in range(M.shape[1])], SLIDES[0] - s)
        hi = np.append([high[M[:, k] > 0].min() for k in range(M.shape[1])], SLIDES[-1] - s)
        lo, hi = np.minimum(lo, 0.0), np.maximum(hi, 0.0)
        active = depth > 0
        step = np.zeros(len(x0))
        for _ in range(4):
            A = np.concatenate([grad[active] / SCALE, np.diag(1.0 / sig)])
            b = np.concatenate([-(depth[active] + CLEARANCE) / SCALE, -(x0 - home) / sig])
            step = box_least_squares(A, b, lo, hi)
            more = active | (depth + grad @ step > -CLEARANCE)
            if (more == active).all():
                break
            active = more
        if not np.any(np.abs(step) > 1e-7):
            return None
        out = angles.reshape(-1).copy()
        out[free] += M @ step[:-1]
        return out.reshape(NUM_JOINTS, 3), float(s + step[-1])

    def _free(self, touched: set, links: frozenset = frozenset(),
              held: frozenset = frozenset()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(angle indices into the flat (48,) angles, sigma (rad), largest change (rad)) of the digits that may
        make room: those touched (PARTS indices), the ring's own, the fingers beside it and those linked to any,
        less those `held`."""
        digits = {p - 1 for p in touched if p > 0} | {self.digit}
        if self.digit > 0:
            digits |= {d for d in (self.digit - 1, self.digit + 1) if 1 <= d < len(FINGERS)}
        for _ in range(len(links)):
            digits |= {d for pair in links if digits & pair for d in pair}
        digits -= held
        free, sigma, reach = [], [], []
        for d in sorted(digits):
            kind = "thumb" if FINGERS[d] == "thumb" else "finger"
            root = FINGER_JOINTS[FINGERS[d]][0]
            for axis, sg in enumerate(SIGMA[kind]):
                if sg > 0:
                    free.append(3 * root + axis)
                    sigma.append(np.deg2rad(sg))
                    reach.append(np.deg2rad(MAX_CHANGE_DEG[kind]))
        return np.array(free), np.array(sigma), np.array(reach)


def box_least_squares(A: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """argmin |A x - b| with lo <= x <= hi, for a handful of unknowns (scipy's lsq_linear costs milliseconds a
    call here): solve for the free unknowns, hold those that leave their bounds at the bound, solve again."""
    n = A.shape[1]
    x = np.zeros(n)
    free = np.ones(n, bool)
    for _ in range(n + 1):
        if not free.any():
            break
        rhs = b - A[:, ~free] @ x[~free]
        x[free] = np.linalg.lstsq(A[:, free], rhs, rcond=None)[0]
        out = free & ((x < lo) | (x > hi))
        if not out.any():
            break
        x = np.clip(x, lo, hi)
        free &= ~out
    return np.clip(x, lo, hi)


def _tied(free: np.ndarray, links: frozenset) -> np.ndarray:
    """(n, k) 0/1: which unknown each free angle follows; the spread angles of linked fingers share one."""
    root_digit = {FINGER_JOINTS[f][0]: d for d, f in enumerate(FINGERS)}
    keys = []
    for angle in free:
        joint, axis = divmod(int(angle), 3)
        digit = root_digit.get(joint)
        group = next((pair for pair in links if digit in pair), None) if axis == 1 else None
        keys.append(("link", min(group)) if group is not None else ("angle", int(angle)))
    unique = list(dict.fromkeys(keys))
    M = np.zeros((len(free), len(unique)))
    M[np.arange(len(free)), [unique.index(k) for k in keys]] = 1.0
    return M


def _signed_depths(solid: Solid, tree: cKDTree, v: np.ndarray, normals: np.ndarray, pts: np.ndarray,
                   outside: bool = True):
    """(signed depth (K,) m, nearest hand vertex (K,)) of points (K, 3) against the posed hand (v, normals):
    inside the hand (by Embree) the depth below the tangent planes of the NEAREST hand vertices, the shallowest
    positive one; outside, minus the distance above the nearest vertex's tangent plane (at most 0), or -inf (and
    vertex -1) without `outside`."""
    signed = np.full(len(pts), -np.inf)
    nearest = np.full(len(pts), -1)
    if outside:
        _, nearest = tree.query(pts)
        signed = np.minimum(np.einsum("kd,kd->k", v[nearest] - pts, normals[nearest]), 0.0)
    ids = solid.inside(pts)
    if len(ids):
        _, near = tree.query(pts[ids], k=NEAREST)
        d = np.einsum("kmd,kmd->km", v[near] - pts[ids][:, None], normals[near])
        pick = np.argmin(np.where(d > 0, d, np.inf), axis=1)
        signed[ids] = np.maximum(d[np.arange(len(ids)), pick], 0.0)
        nearest[ids] = near[np.arange(len(ids)), pick]
    return signed, nearest


# ------------------------------------------------------------------------------------------------ for the renderer


@dataclass(frozen=True)
class WornRing:
    """What the renderer needs of a ring worn in a frame: `move` (4, 4) the rigid move in the rest frame that
    slides the catalogue's rest mesh along its bone (the posed ring is G_joint @ move @ rest vertices), and `record`
    (JSON): the slide (mm) and the angles turned to make room, by joint name (degrees: twist, spread, bend)."""

    move: np.ndarray
    record: dict


_WEARS: dict = {}      # (accessory key, betas) -> (model, RingWear): the rings of the last few shapes
_KEEP = 16


def wear_ring(model: HandModel, acc, key, pose: np.ndarray, betas=None) -> tuple[np.ndarray, WornRing | None]:
    """(the pose the frame shows (48,), WornRing) of a rigid ring `acc` (accessories.loader.Accessory, fitted to
    the hand of `betas`; `key` names that fit) worn in `pose` (48,) on `model`; (pose, None) for a ring without
    its local frame (rest_transform) or off a digit. The RingWear of each (model, fit) is set up once and kept."""
    if acc.rest_transform is None or acc.parent_joint is None or joint_parts()[acc.parent_joint] == 0:
        return pose, None
    shape = None if betas is None else np.asarray(betas, np.float64).tobytes()
    entry = _WEARS.get((key, shape))
    if entry is None or entry[0] is not model:
        if len(_WEARS) >= _KEEP:
            _WEARS.clear()
        local = to_local(acc.rest_transform, np.asarray(acc.vertices, np.float64))
        entry = _WEARS[key, shape] = (model, RingWear(model, acc.parent_joint, acc.rest_transform, local, betas))
    w = entry[1].worn_once(pose)
    rest = acc.rest_transform
    move = rest @ slide_matrix(w.slide) @ np.linalg.inv(rest)
    record = {"slide_mm": round(w.slide * 1000.0, 4),
              "turned_deg": {JOINT_NAMES[j]: [round(float(a), 4) for a in d] for j, d in sorted(w.changed.items())}}
    return w.pose, WornRing(move, record)
