"""Two posed hands in one world: how far one passes into the other, and the rigid move that resolves it.

Penetration is measured as the signed distances (m, negative inside) of each hand's vertices to the other hand's
surface: the distance to the nearest surface point (model/proximity.closest_surface_points), negative when the
vertex lies behind the surface there (against the normal interpolated at that point). As in model/proximity, a
vertex whose offset makes more than ~45 degrees with that normal (at the open wrist's cut edge, say) says nothing
about inside or out and is left out. The guard is MeshLab's face intersection test on the two meshes together
(model/intersections.self_intersecting), less the faces each hand crosses on its own.

The resolution follows model/gesture_fit's model: a small bounded least-squares problem,

    minimise   sum (x_k / sigma_k)^2                                  stay near the sampled placement
             + sum_i (max(0, c - d_i) / s)^2                          the hands at least c apart (clearance)
             + sum_contacts ((softmin_i d_i - g) / s)^2               the asked-for regions end g apart (touching)
    within     |rotation| <= MAX_TURN_DEG per axis, |translation| <= MAX_SHIFT_M per axis

over x = (rotation vector (3, radians, about the moved hand's centre), translation (3, m)) of the second hand (the
left, in the right hand's frame). The Jacobian is the rigid motion's: a vertex p of the moved hand at distance d
along the unit direction u moves d by u . (dt + dw x (p - c)), a nearest point y on the moved hand's surface by
minus that. The samples in the fit are those within clearance + REACH of the other hand, re-selected after each
solve until none comes near. When MeshLab still finds crossing faces the clearance grows by STEP, up to ROUNDS.

A hand may carry what it wears (`combined_hand`: the hand's and its accessory's posed meshes as one, the accessory
labelled with the joint it is attached to), so that a ring or watch is kept out of the other hand like the skin.
The nearest-point search and its signing run compiled (model/pair_kernels.py).

By default the digits' angles are not moved: the poses stay as sampled (the interaction types choose pre-shapes
that leave room, dataset/interactions.py), so "how far the poses moved" is the rigid move only (degrees of turn).
With `digits` (a pair_digits.DigitHand per hand, or None to hold one) the same problem also fits the digits' angles
of both hands (DigitPairProblem, model/pair_digits.py): the terms act on the re-posed vertices, the result carries
both fitted poses and the digits' movement.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation
from threadpoolctl import ThreadpoolController

from darthand.model.forward import forward
from darthand.model.hand_model import HandModel
from darthand.model.intersections import self_intersecting
from darthand.model.pair_digits import (SELECTIONS, angle_rows, digit_changes, least_squares_fit, near_digits,
                                        nearest_share, solve_bounds, split)
from darthand.model.pair_kernels import signed_on_candidates
from darthand.model.proximity import FACING_COS, TOUCHING
from darthand.model.topology import face_joints, vertex_normals

CLEARANCE = 0.5e-3       # m: hands not asked to touch stay at least this far apart
CONTACT_GAP = 0.5e-3     # m: regions asked to touch end this far apart (touching, not inside)
STEP = 0.5e-3            # m: added to the clearance when the guard still finds crossing faces
ROUNDS = 3
REACH = 6e-3             # m: samples farther than clearance + REACH from the other hand are left out of a fit
TOUCH_REACH = 2e-3       # m: a contact's fit holds its vertices within this of its nearest one (the soft minimum's)
SOFTMIN = 0.1e-3         # m: temperature of the soft minimum over a contact's distances
PENALTY_SCALE = 0.05e-3  # m of violated clearance that costs as much as one sigma of move
TURN_SIGMA_DEG = 3.0
SHIFT_SIGMA_M = 3e-3
MAX_TURN_DEG = 30.0
MAX_SHIFT_M = 0.06
PREFILTER_M = 0.015      # m: a contact's samples are chosen among those this near the other hand's vertices
SPACING_M = 0.006        # m: more than a hand mesh's longest edge (a surface point is this near a corner)
CANDIDATES = 8           # nearest face centroids whose triangles are searched for a point's nearest point
TIPS = (3, 6, 9, 12, 15)  # MANO's distal joints: the fingertips' segments
DIGIT_REACH = 0.02       # m: a digit this near the other hand at the start has its angles fitted (with `digits`)


@dataclass
class PosedHand:
    """One posed hand in the world: vertices (V, 3) m, faces (F, 3), unit vertex normals (V, 3), the dominant
    joint of each vertex (V,) and of each face (F,)."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    vertex_joint: np.ndarray
    face_joint: np.ndarray
    _alone: np.ndarray | None = field(default=None, repr=False)

    def moved(self, T: np.ndarray) -> "PosedHand":
        """This hand under the rigid transform T (4, 4) (its own crossings carried over: a rigid move keeps them)."""
        v = self.vertices @ T[:3, :3].T + T[:3, 3]
        return PosedHand(v, self.faces, self.normals @ T[:3, :3].T, self.vertex_joint, self.face_joint, self._alone)

    def crossing_alone(self) -> np.ndarray:
        """(F,) bool faces crossing another face of this same hand (MeshLab), computed once."""
        if self._alone is None:
            self._alone = self_intersecting(self.vertices, self.faces)
        return self._alone

    def region(self, joints) -> tuple[np.ndarray, np.ndarray]:
        """(vertex ids, face ids) whose dominant joint is one of `joints` (all of them for None)."""
        if joints is None:
            return np.arange(len(self.vertices)), np.arange(len(self.faces))
        return np.flatnonzero(np.isin(self.vertex_joint, joints)), np.flatnonzero(np.isin(self.face_joint, joints))


def pose_hand(model: HandModel, pose, betas=None, T: np.ndarray | None = None) -> PosedHand:
    """`model` posed by the (48,) axis-angle `pose` and `betas` (model forward), placed by T (4, 4; None: identity)."""
    v = forward(model, np.asarray(pose, np.float64).reshape(1, -1),
                None if betas is None else np.asarray(betas, np.float64).reshape(1, -1)).vertices[0]
    v = np.asarray(v, np.float64)
    vj, fj = _joint_labels(model)
    hand = PosedHand(v, model.faces, vertex_normals(v, model.faces), vj, fj)
    return hand if T is None else hand.moved(T)


_LABELS: dict = {}    # id(model) -> (model, vertex joints, face joints): a model's labels, the same every pose


def _joint_labels(model: HandModel) -> tuple[np.ndarray, np.ndarray]:
    """The dominant joint of each vertex (V,) and of each face (F,) of `model`, computed once per model."""
    held = _LABELS.get(id(model))
    if held is None or held[0] is not model:
        if len(_LABELS) >= 8:            # a plan poses two models; tests and tools make more, kept no longer
            _LABELS.clear()
        held = _LABELS[id(model)] = (model, np.argmax(model.weights, axis=1), face_joints(model.faces, model.weights))
    return held[1], held[2]


def combined_hand(surfaces, hand: PosedHand, joint: int) -> PosedHand:
    """A hand and what it wears as one PosedHand: `surfaces` (objects with vertices (N, 3) m, faces (F, 3), unit
    normals (N, 3) and a role: 'hand' or the item's), the 'hand' one of the same topology as `hand` (whose joint
    labels it takes); the others' vertices and faces labelled `joint` (the joint the item is attached to)."""
    verts, faces, normals, vj, fj, base = [], [], [], [], [], 0
    for s in surfaces:
        v = np.asarray(s.vertices, np.float64)
        verts.append(v)
        faces.append(np.asarray(s.faces, np.int64) + base)
        normals.append(np.asarray(s.normals, np.float64))
        is_hand = s.role == "hand"
        vj.append(hand.vertex_joint if is_hand else np.full(len(v), joint, np.int64))
        fj.append(hand.face_joint if is_hand else np.full(len(s.faces), joint, np.int64))
        base += len(v)
    return PosedHand(np.concatenate(verts), np.concatenate(faces), np.concatenate(normals), np.concatenate(vj),
                     np.concatenate(fj))


def rigid(x: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(4, 4) transform of x = (rotation vector (3,) about `centre` (3,), translation (3,) m)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(x[:3]).as_matrix()
    T[:3, 3] = centre - T[:3, :3] @ centre + x[3:]
    return T


@dataclass
class Distances:
    """Signed distances of points to a hand's surface: distance (K,) m, negative inside (inf: not facing it),
    direction (K, 3) the unit direction along which the distance grows, nearest (K, 3) the surface points."""

    distance: np.ndarray
    direction: np.ndarray
    nearest: np.ndarray


class Surface:
    """A hand's surface (or only its faces `faces`), indexed once for signed-distance queries in any rigid placement
    of the hand: the k-d tree of its face centroids that proximity.closest_surface_points builds on every call."""

    def __init__(self, hand: PosedHand, faces: np.ndarray | None = None):
        self.hand = hand
        self.faces = hand.faces if faces is None else hand.faces[faces]
        self.tris = hand.vertices[self.faces]
        self.tri_normals = hand.normals[self.faces]
        self.tree = cKDTree(self.tris.mean(1)) if len(self.faces) else None

    def signed_distances(self, points: np.ndarray, T: np.ndarray | None = None) -> Distances:
        """Signed distances of `points` (K, 3) to the surface moved by T (4, 4; None: as indexed)."""
        if T is None:
            return self._signed(points)
        local = self._signed((points - T[:3, 3]) @ T[:3, :3])
        return Distances(local.distance, local.direction @ T[:3, :3].T, local.nearest @ T[:3, :3].T + T[:3, 3])

    def _signed(self, points: np.ndarray) -> Distances:
        if len(points) == 0 or self.tree is None:
            return Distances(np.full(len(points), np.inf), np.zeros((len(points), 3)), np.zeros((len(points), 3)))
        k = min(CANDIDATES, len(self.faces))
        cand = self.tree.query(points, k=k)[1].reshape(len(points), k)
        _, _, _, signed, direction, on = signed_on_candidates(self.tris, self.tri_normals, cand, points, FACING_COS,
                                                             TOUCHING)
        return Distances(signed, direction, on)


def signed_distances(points: np.ndarray, hand: PosedHand, faces: np.ndarray | None = None) -> Distances:
    """Signed distances of `points` (K, 3) to `hand`'s surface (or its `faces` ids only); see the module docstring."""
    return Surface(hand, faces).signed_distances(points)


def in_box(points: np.ndarray, other: np.ndarray, margin: float = 0.0) -> np.ndarray:
    """Ids of `points` (K, 3) inside the bounding box of `other` (M, 3) grown by `margin` (m)."""
    lo, hi = other.min(0) - margin, other.max(0) + margin
    return np.flatnonzero(((points >= lo) & (points <= hi)).all(1))


def near_ids(points: np.ndarray, other: np.ndarray, reach: float) -> np.ndarray:
    """Ids of `points` (K, 3) within `reach` (m, plus the other's vertex spacing) of the point set `other` (M, 3).
    (Not for points deep inside a closed surface: they may lie farther than that from every vertex.)"""
    inside = in_box(points, other, reach + 0.01)
    if len(inside) == 0:
        return inside
    d, _ = cKDTree(other).query(points[inside], distance_upper_bound=reach + 0.006)
    return inside[np.isfinite(d)]


# ------------------------------------------------------------------------------------------------ measures


@dataclass
class Penetration:
    """How far two hands pass into each other: max and p99 (over the vertices inside) depth (m), the vertices
    inside, MeshLab's crossing faces between the hands."""

    max_m: float
    p99_m: float
    inside: int
    crossing_faces: int

    @property
    def clear(self) -> bool:
        return self.inside == 0 and self.crossing_faces == 0


def depths(a: PosedHand, b: PosedHand) -> np.ndarray:
    """Depths (m, > 0) of every vertex of either hand lying inside the other."""
    out = []
    for p, q in ((a, b), (b, a)):
        ids = in_box(p.vertices, q.vertices)
        d = signed_distances(p.vertices[ids], q).distance
        out.append(-d[d < 0])
    return np.concatenate(out)


def crossing_faces(a: PosedHand, b: PosedHand) -> int:
    """Faces of either hand crossing a face of the other (MeshLab's test on the two meshes, less each one's own).

    Only the faces inside the other hand's bounding box (grown by a few mm) can cross it, so the test runs on
    those: the two crops together, less what each crop crosses alone."""
    fa, fb = _faces_near(a, b), _faces_near(b, a)
    if len(fa) == 0 or len(fb) == 0:
        return 0
    va, vb = a.vertices, b.vertices
    both = self_intersecting(np.concatenate([va, vb]), np.concatenate([a.faces[fa], b.faces[fb] + len(va)]))
    alone_a = self_intersecting(va, a.faces[fa])
    alone_b = self_intersecting(vb, b.faces[fb])
    return int((both[:len(fa)] & ~alone_a).sum() + (both[len(fa):] & ~alone_b).sum())


def _faces_near(a: PosedHand, b: PosedHand, margin: float = 3e-3) -> np.ndarray:
    """Ids of a's faces with a corner inside b's bounding box grown by `margin` (m)."""
    lo, hi = b.vertices.min(0) - margin, b.vertices.max(0) + margin
    inside = ((a.vertices >= lo) & (a.vertices <= hi)).all(1)
    return np.flatnonzero(inside[a.faces].any(1))


def first_contact_shift(a: PosedHand, b: PosedHand, direction: np.ndarray, cell: float = 2.5e-3) -> float:
    """How far (m) hand `b` moves along the unit `direction` (3,) until it first touches hand `a` (negative: it
    must move back): both vertex sets are binned on a grid of `cell` (m) across the direction, and in every cell
    (and its neighbours) b's front must stay behind a's back. inf when they never meet."""
    u = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    e1 = np.cross(u, [1.0, 0, 0] if abs(u[0]) < 0.9 else [0, 1.0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    basis = np.stack([e1, e2], 1)
    ka = np.floor(a.vertices @ basis / cell).astype(np.int64)
    kb = np.floor(b.vertices @ basis / cell).astype(np.int64)
    codes, inverse = np.unique(_cell_code(ka), return_inverse=True)
    back = np.full(len(codes), np.inf)              # per cell: a's smallest height along u
    np.minimum.at(back, inverse.reshape(-1), a.vertices @ u)
    front = b.vertices @ u
    best = np.inf
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            code = _cell_code(kb + [di, dj])
            at = np.minimum(np.searchsorted(codes, code), len(codes) - 1)
            hit = codes[at] == code
            if hit.any():
                best = min(best, float((back[at[hit]] - front[hit]).min()))
    return best


def _cell_code(k: np.ndarray) -> np.ndarray:
    """One int64 per 2D grid cell (K, 2) (cells within +-2^20 of the origin)."""
    return (k[:, 0] + (1 << 20)) * (1 << 21) + (k[:, 1] + (1 << 20))


def penetration(a: PosedHand, b: PosedHand) -> Penetration:
    """The penetration measures of two posed hands."""
    d = depths(a, b)
    return Penetration(float(d.max(initial=0.0)), float(np.percentile(d, 99)) if len(d) else 0.0, len(d),
                       crossing_faces(a, b))


def region_gap(a: PosedHand, b: PosedHand, joints_a, joints_b) -> float:
    """Smallest signed distance (m) from `a`'s vertices of region joints_a to `b`'s faces of region joints_b.

    Measured first on the vertices within PREFILTER_M of the region's corners: when the smallest there is under
    PREFILTER_M - SPACING_M it is the smallest of all (a farther vertex is at least that far from the surface, for
    hands apart: a vertex deep inside may lie farther from every corner, and a fit's figures are kept only for
    hands apart); else all are measured."""
    va, _ = a.region(joints_a)
    _, fb = b.region(joints_b)
    surface = Surface(b, fb)
    near = cKDTree(b.vertices[np.unique(b.faces[fb])]).query(a.vertices[va], distance_upper_bound=PREFILTER_M)[0]
    gap = surface.signed_distances(a.vertices[va[np.isfinite(near)]]).distance.min(initial=np.inf)
    if gap < PREFILTER_M - SPACING_M:
        return float(gap)
    return float(surface.signed_distances(a.vertices[va]).distance.min(initial=np.inf))


# ------------------------------------------------------------------------------------------------ resolution


@dataclass
class Resolution:
    """The outcome of `resolve`: T (4, 4) the move applied to the second hand (world to world); resolved: no
    vertex inside and no crossing face; penetration before/after; turn_deg, shift_m: the move; contacts: per asked
    pair the final gap (m); rounds; cpu_s."""

    T: np.ndarray
    resolved: bool
    before: Penetration
    after: Penetration
    turn_deg: float
    shift_m: float
    contacts: list
    rounds: int
    cpu_s: float
    poses: tuple | None = None      # with the digits fitted: (a's, b's) fitted (48,) axis-angle (None: held)
    digits_max_deg: float = 0.0
    digits_mean_deg: float = 0.0

    def figures(self) -> dict:
        """The plain-JSON record of the resolution (what a job's interaction record carries: no CPU time, so that
        a frame's job depends only on (seed, index))."""
        out = {"resolved": self.resolved, "rounds": self.rounds,
               "max_mm": round(self.after.max_m * 1e3, 4), "p99_mm": round(self.after.p99_m * 1e3, 4),
               "crossing_faces": self.after.crossing_faces, "before_max_mm": round(self.before.max_m * 1e3, 3),
               "turn_deg": round(self.turn_deg, 3), "shift_mm": round(self.shift_m * 1e3, 3),
               "contact_gaps_mm": [round(g * 1e3, 3) for g in self.contacts]}
        if self.poses is not None:
            out.update(digits_max_deg=round(self.digits_max_deg, 3), digits_mean_deg=round(self.digits_mean_deg, 3))
        return out


class PairProblem:
    """The least-squares problem of placing hand `b` against hand `a` (module docstring). touch: pairs of joint
    sets (b's region, a's region) to bring into contact."""

    def __init__(self, a: PosedHand, b: PosedHand, touch, clearance: float):
        self.a, self.b, self.clearance = a, b, clearance
        self.centre = b.vertices.mean(0)
        self.touch = [(b.region(jb)[0], a.region(ja)[1]) for jb, ja in touch]
        self.touch_ids = [np.zeros(0, np.int64) for _ in self.touch]   # per contact: b's vertices in its fit
        self.surface_a, self.surface_b = Surface(a), Surface(b)
        self.vertex_tree_a, self.vertex_tree_b = cKDTree(a.vertices), cKDTree(b.vertices)   # for `select`
        self.touch_surfaces = [self.surface_a if ja is None else Surface(a, fa) for (_, fa), (_, ja) in
                               zip(self.touch, touch)]
        self.touch_trees = [cKDTree(a.vertices[np.unique(t.faces)]) for t in self.touch_surfaces]
        self.sigma = np.r_[np.full(3, np.deg2rad(TURN_SIGMA_DEG)), np.full(3, SHIFT_SIGMA_M)]
        self.b_ids = np.zeros(0, np.int64)   # b's vertices tested against a's surface
        self.a_ids = np.zeros(0, np.int64)   # a's vertices tested against b's surface

    def select(self, x: np.ndarray) -> bool:
        """Add the samples within clearance + REACH of the other hand at x; True if any was added."""
        T = rigid(x, self.centre)
        b = self.b.moved(T)
        bound = self.clearance + REACH + SPACING_M       # near_ids' reach: plus the other's vertex spacing
        near_b = np.flatnonzero(np.isfinite(self.vertex_tree_a.query(b.vertices, distance_upper_bound=bound)[0]))
        local_a = (self.a.vertices - T[:3, 3]) @ T[:3, :3]                 # a in b's frame as given
        near_a = np.flatnonzero(np.isfinite(self.vertex_tree_b.query(local_a, distance_upper_bound=bound)[0]))
        b_new, a_new = np.union1d(self.b_ids, near_b), np.union1d(self.a_ids, near_a)
        added = len(b_new) > len(self.b_ids) or len(a_new) > len(self.a_ids)
        self.b_ids, self.a_ids = b_new, a_new
        for k, (vb, _) in enumerate(self.touch):            # a contact's vertices within REACH of its nearest
            vb = self.nearest_first(k, b.vertices, vb)
            d = self.touch_surfaces[k].signed_distances(b.vertices[vb]).distance
            new = np.union1d(self.touch_ids[k], vb[d < d.min(initial=np.inf) + TOUCH_REACH])
            added |= len(new) > len(self.touch_ids[k])
            self.touch_ids[k] = new
        return added

    def nearest_first(self, k: int, vertices: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """Of b's vertices `ids` of contact k, those that can be within TOUCH_REACH of the nearest to a's region:
        nearer a corner of it than the nearest one is plus TOUCH_REACH and the vertex spacing (all of them when
        none comes within PREFILTER_M)."""
        d = self.touch_trees[k].query(vertices[ids], distance_upper_bound=PREFILTER_M)[0]
        if not np.isfinite(d).any():
            return ids
        return ids[d < d.min() + TOUCH_REACH + SPACING_M]

    def residuals(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(residuals (R,), Jacobian (R, 6)) at x."""
        T = rigid(x, self.centre)
        b = self.b.moved(T)
        c = T[:3, :3] @ self.centre + T[:3, 3]
        res, jac = [x / self.sigma], [np.diag(1.0 / self.sigma)]
        pb = b.vertices[self.b_ids]
        hb = self.surface_a.signed_distances(pb)                       # b's vertices on a: they move
        gb = _moment_rows(pb - c, hb.direction)
        ha = self.surface_b.signed_distances(self.a.vertices[self.a_ids], T)   # a's on b: b's surface moves
        ga = -_moment_rows(ha.nearest - c, ha.direction)
        for h, g in ((hb, gb), (ha, ga)):
            short = h.distance < self.clearance
            res.append(np.where(short, (self.clearance - h.distance) / PENALTY_SCALE, 0.0))
            jac.append(np.where(short[:, None], -g / PENALTY_SCALE, 0.0))
        for vb, surface in zip(self.touch_ids, self.touch_surfaces):
            p = b.vertices[vb]
            h = surface.signed_distances(p)
            ok = np.isfinite(h.distance)
            if not ok.any():
                res.append(np.zeros(1))
                jac.append(np.zeros((1, 6)))
                continue
            d, g = h.distance[ok], _moment_rows(p - c, h.direction)[ok]
            w = np.exp(-(d - d.min()) / SOFTMIN)
            soft = d.min() - SOFTMIN * np.log(w.sum())
            res.append(np.array([(soft - CONTACT_GAP) / PENALTY_SCALE]))
            jac.append((w / w.sum()) @ g / PENALTY_SCALE)
        return np.concatenate(res), np.vstack(jac)

    def solve(self, x0: np.ndarray) -> np.ndarray:
        """The fitted x: least squares, re-selecting the samples until none new comes near."""
        x = x0.copy()
        lim = np.r_[np.full(3, np.deg2rad(MAX_TURN_DEG)), np.full(3, MAX_SHIFT_M)]
        cache: dict = {}

        def evaluate(y):
            key = y.tobytes()
            if key not in cache:
                cache.clear()
                cache[key] = self.residuals(y)
            return cache[key]

        for k in range(2):
            if not self.select(x) and k > 0:
                break
            cache.clear()
            x = least_squares(lambda y: evaluate(y)[0], np.clip(x, -lim, lim), jac=lambda y: evaluate(y)[1],
                              bounds=(-lim, lim), method="trf", x_scale=self.sigma, max_nfev=6,
                              xtol=1e-5, ftol=1e-5).x
        return x


class DigitPairProblem:
    """PairProblem with the digits' angles of both hands free too (module docstring; model/pair_digits.py).
    digits: (a's, b's) pair_digits.DigitHand, None to hold that hand as posed; a and b: the hands as posed at
    zero change (b already placed by its DigitHand's T)."""

    def __init__(self, a: PosedHand, b: PosedHand, digits, touch, clearance: float, centre: np.ndarray):
        self.a, self.b, self.digits, self.clearance, self.centre = a, b, tuple(digits), clearance, centre
        self.touch = list(touch)
        self.sigma = np.concatenate([np.r_[np.full(3, np.deg2rad(TURN_SIGMA_DEG)), np.full(3, SHIFT_SIGMA_M)]]
                                    + [h.sigma[h.free] for h in self.digits if h is not None])
        self.b_ids = np.zeros(0, np.int64)
        self.a_ids = np.zeros(0, np.int64)
        self.touch_ids = [np.zeros(0, np.int64) for _ in self.touch]
        self.touch_faces = [np.zeros(0, np.int64) for _ in self.touch]     # per contact: a's faces in its fit
        self.faces_a = np.zeros(0, np.int64)      # a's faces b's samples are measured against (`select`)
        self.faces_b = np.zeros(0, np.int64)
        self._cache: tuple | None = None

    def hands_at(self, y: np.ndarray):
        """(a, b) PosedHands at y, and per hand (angular velocities, pivots) of its free angles (None: held)."""
        x, deltas = split(y, self.digits)
        T = rigid(x, self.centre)
        out: list = []
        motion: list = []
        for hand, digit, delta, move in ((self.a, self.digits[0], deltas[0], np.eye(4)),
                                         (self.b, self.digits[1], deltas[1], T)):
            if digit is None:
                out.append(hand.moved(move) if move is T else hand)
                motion.append(None)
                continue
            v, n, omega, pivot = digit.posed(delta, move)
            out.append(PosedHand(v, hand.faces, n, hand.vertex_joint, hand.face_joint))
            motion.append((omega, pivot))
        return out[0], out[1], motion

    def select(self, y: np.ndarray) -> bool:
        """Add the samples within clearance + REACH of the other hand at y, and the faces their nearest points can
        lie on during a solve (a corner within that, a longest edge and another REACH: the hands move a few mm in
        one); True if any sample was added."""
        a, b, _ = self.hands_at(y)
        bound = self.clearance + REACH + SPACING_M
        tree_a, tree_b = cKDTree(a.vertices), cKDTree(b.vertices)
        d_b, d_a = tree_a.query(b.vertices, distance_upper_bound=bound + SPACING_M + REACH)[0], \
            tree_b.query(a.vertices, distance_upper_bound=bound + SPACING_M + REACH)[0]
        b_new, a_new = np.union1d(self.b_ids, np.flatnonzero(d_b < bound)), np.union1d(self.a_ids,
                                                                                       np.flatnonzero(d_a < bound))
        self.faces_a = np.union1d(self.faces_a, np.flatnonzero(np.isfinite(d_a)[a.faces].any(1)))
        self.faces_b = np.union1d(self.faces_b, np.flatnonzero(np.isfinite(d_b)[b.faces].any(1)))
        added = len(b_new) > len(self.b_ids) or len(a_new) > len(self.a_ids)
        self.b_ids, self.a_ids = b_new, a_new
        for k, (jb, ja) in enumerate(self.touch):
            vb = b.region(jb)[0]
            fa = a.region(ja)[1]
            d = Surface(a, fa).signed_distances(b.vertices[vb]).distance
            new = np.union1d(self.touch_ids[k], vb[d < d.min(initial=np.inf) + TOUCH_REACH])
            added |= len(new) > len(self.touch_ids[k])
            self.touch_ids[k] = new
            far = d[np.isin(vb, new) & np.isfinite(d)].max(initial=0.0) + SPACING_M + REACH
            near = np.isfinite(cKDTree(b.vertices[new]).query(a.vertices, distance_upper_bound=far)[0])
            self.touch_faces[k] = np.union1d(self.touch_faces[k], fa[near[a.faces[fa]].any(1)])
        return added

    def rows(self, own: int, p: np.ndarray, ids: np.ndarray, h: Distances, c: np.ndarray, motions,
             tree: cKDTree) -> np.ndarray:
        """(K, 6 + n) derivative of the distances h of points p (K, 3) (vertex ids `ids`) of hand `own` (0: a,
        1: b) to the other hand's surface: the rigid part moves b (`c` its turned centre), each free hand's angles
        (`motions`: its angular velocities and pivots) move its own points or the nearest points on it (`tree`:
        the other hand's vertices)."""
        u = h.direction
        rig = _moment_rows((p if own == 1 else h.nearest) - c, u)
        blocks = [rig if own == 1 else -rig]
        for k, (digit, motion) in enumerate(zip(self.digits, motions)):
            if digit is None:
                continue
            if k == own:
                blocks.append(angle_rows(p, u, digit.share[ids], *motion))
            else:
                blocks.append(-angle_rows(h.nearest, u, nearest_share(tree, digit.share, h.nearest), *motion))
        return np.hstack(blocks)

    def evaluate(self, y: np.ndarray):
        """(residuals (R,), Jacobian (R, 6 + n)) at y, cached for the last y."""
        if self._cache is not None and np.array_equal(self._cache[0], y):
            return self._cache[1], self._cache[2]
        a, b, motions = self.hands_at(y)
        T = rigid(y[:6], self.centre)
        c = T[:3, :3] @ self.centre + T[:3, 3]
        tree_a, tree_b = cKDTree(a.vertices), cKDTree(b.vertices)
        res, jac = [y / self.sigma], [np.diag(1.0 / self.sigma)]
        hb = Surface(a, self.faces_a).signed_distances(b.vertices[self.b_ids])
        ha = Surface(b, self.faces_b).signed_distances(a.vertices[self.a_ids])
        for own, h, p, ids, tree in ((1, hb, b.vertices, self.b_ids, tree_a), (0, ha, a.vertices, self.a_ids, tree_b)):
            g = self.rows(own, p[ids], ids, h, c, motions, tree)
            short = h.distance < self.clearance
            res.append(np.where(short, (self.clearance - h.distance) / PENALTY_SCALE, 0.0))
            jac.append(np.where(short[:, None], -g / PENALTY_SCALE, 0.0))
        for vb, faces in zip(self.touch_ids, self.touch_faces):
            h = Surface(a, faces).signed_distances(b.vertices[vb])
            ok = np.isfinite(h.distance)
            if not ok.any():
                res.append(np.zeros(1))
                jac.append(np.zeros((1, len(y))))
                continue
            g = self.rows(1, b.vertices[vb], vb, h, c, motions, tree_a)[ok]
            d = h.distance[ok]
            w = np.exp(-(d - d.min()) / SOFTMIN)
            soft = d.min() - SOFTMIN * np.log(w.sum())
            res.append(np.array([(soft - CONTACT_GAP) / PENALTY_SCALE]))
            jac.append(((w / w.sum()) @ g / PENALTY_SCALE)[None])
        r, J = np.concatenate(res), np.vstack(jac)
        self._cache = (y.copy(), r, J)
        return r, J

    def solve(self, y0: np.ndarray) -> np.ndarray:
        """The fitted variables (rigid 6, then the held-or-free hands' angle changes), re-selecting the samples
        until none new comes near."""
        lo, hi = solve_bounds(np.r_[np.full(3, np.deg2rad(MAX_TURN_DEG)), np.full(3, MAX_SHIFT_M)], self.digits)
        y = y0.copy()
        for k in range(SELECTIONS):
            if not self.select(y) and k > 0:
                break
            self._cache = None
            y = least_squares_fit(self.evaluate, y, lo, hi, self.sigma)
        return y


def _moment_rows(r: np.ndarray, u: np.ndarray) -> np.ndarray:
    """(K, 6) Jacobian rows [r x u, u] of distances along unit u (K, 3) at lever arms r (K, 3) (np.cross's
    axis handling costs more than the product at a few hundred rows)."""
    out = np.empty((len(r), 6))
    out[:, 0] = r[:, 1] * u[:, 2] - r[:, 2] * u[:, 1]
    out[:, 1] = r[:, 2] * u[:, 0] - r[:, 0] * u[:, 2]
    out[:, 2] = r[:, 0] * u[:, 1] - r[:, 1] * u[:, 0]
    out[:, 3:] = u
    return out


def _penetration_before(a: PosedHand, b: PosedHand, fitting: bool) -> Penetration:
    """The penetration of the sampled placement; MeshLab's test only when it decides whether to fit (no contact
    asked, no vertex inside), else its crossing faces are left at 0 (not measured)."""
    d = depths(a, b)
    crossing = 0 if fitting or len(d) else crossing_faces(a, b)
    return Penetration(float(d.max(initial=0.0)), float(np.percentile(d, 99)) if len(d) else 0.0, len(d), crossing)


_BLAS: list = []      # the process's ThreadpoolController, made at the first resolve (BLAS loaded by then)


def _one_blas_thread():
    """A context limiting BLAS to one thread (the fit's small solves; the plan's process runs beside workers).
    threadpool_limits would scan the loaded libraries on every call (~4 ms); the controller scans once."""
    if not _BLAS:
        _BLAS.append(ThreadpoolController())
    return _BLAS[0].limit(limits=1, user_api="blas")


def resolve(a: PosedHand, b: PosedHand, touch=(), rounds: int = ROUNDS, digits=None) -> Resolution:
    """Move hand `b` rigidly off hand `a` (and onto it where `touch` asks: pairs of joint sets (b's, a's)); see the
    module docstring. digits: (a's, b's) pair_digits.DigitHand or None: fit those hands' digits too (a and b
    must then be those DigitHands posed and placed). The result is checked by `penetration` (MeshLab's test
    included)."""
    if digits is not None and any(h is not None for h in digits):
        return resolve_digits(a, b, touch, rounds, tuple(digits))
    start = time.process_time()
    with _one_blas_thread():
        before = _penetration_before(a, b, bool(touch))
        x, after, moved = np.zeros(6), before, b
        used = 0
        if not before.clear or touch:
            for used in range(1, rounds + 1):
                problem = PairProblem(a, b, touch, CLEARANCE + (used - 1) * STEP)
                x = problem.solve(x)
                moved = b.moved(rigid(x, problem.centre))
                after = penetration(a, moved)
                if after.clear:
                    break
        T = rigid(x, b.vertices.mean(0))
        gaps = [region_gap(moved, a, jb, ja) for jb, ja in touch]
    return Resolution(T, after.clear, before, after, float(np.rad2deg(np.linalg.norm(x[:3]))),
                      float(np.linalg.norm(x[3:])), gaps, used, time.process_time() - start)


def resolve_digits(a: PosedHand, b: PosedHand, touch, rounds: int, digits: tuple) -> Resolution:
    """`resolve` with the digits of the hands in `digits` (a's, b's DigitHand or None) fitted too: those of them
    within DIGIT_REACH of the other hand (the others keep their angles: a hand with none near is not re-posed)."""
    start = time.process_time()
    digits = tuple(None if h is None else h.only(near_digits(p.vertex_joint, p.vertices, q.vertices, DIGIT_REACH))
                   for h, p, q in zip(digits, (a, b), (b, a)))
    if all(h is None for h in digits):
        return resolve(a, b, touch, rounds)
    with _one_blas_thread():
        before = _penetration_before(a, b, bool(touch))
        centre = b.vertices.mean(0)
        y = np.zeros(6 + sum(len(h.free) for h in digits if h is not None))
        after, fitted_a, fitted_b, used = before, a, b, 0
        if not before.clear or touch:
            for used in range(1, rounds + 1):
                problem = DigitPairProblem(a, b, digits, touch, CLEARANCE + (used - 1) * STEP, centre)
                y = problem.solve(y)
                fitted_a, fitted_b, _ = problem.hands_at(y)
                after = penetration(fitted_a, fitted_b)
                if after.clear:
                    break
        x, deltas = split(y, digits)
        gaps = [region_gap(fitted_b, fitted_a, jb, ja) for jb, ja in touch]
        poses = tuple(None if h is None else h.fitted_pose(d) for h, d in zip(digits, deltas)) if used else None
        most, mean = digit_changes(digits, deltas)
    return Resolution(rigid(x, centre), after.clear, before, after, float(np.rad2deg(np.linalg.norm(x[:3]))),
                      float(np.linalg.norm(x[3:])), gaps, used, time.process_time() - start, poses, most, mean)
