"""Closing a pre-shaped hand on an object: one bounded least-squares problem per (object, grasp type, approach).

    minimise   sum_parts ((min_{i in part} d_i - GAP) / CONTACT_SCALE)^2          each contact part touches
             + sum_i (max(0, CLEARANCE - d_i) / PENETRATION_SCALE)^2             no hand vertex inside the object
             + sum_k ((a_k - a*_k) / sigma_k)^2                                  stay near the pre-shape a*
             + |w / TURN_SIGMA|^2 + |t / SHIFT_SIGMA|^2                          and near the start placement
             + sum_pairs (max(0, -clearance) / digit_clearance.SCALE)^2          no phalanx into another digit's
             + sum_b (max(0, BONE_CLEARANCE - d_b) / PENETRATION_SCALE)^2         no finger through a thin wall
    within     the joint limits (model/anatomy) and the rigid bounds

over the hand's rigid placement relative to the object (w a rotation vector about the hand's grasp centre, t a
translation, both in the object frame) and the anatomical angles of the digits (model/anatomy's twist, spread,
bend; sigma from model/gesture_fit.freedom scaled by PRESHAPE_FREEDOM: hinges never twist or spread). d_i is the
object's signed distance field (grasps/field.py) at the posed, placed hand vertex i.

The Jacobian is analytic (model/pair_digits' derivation): a distance d = u . (q - y) with u the field's unit
gradient moves by u . dq; a rigid turn dw about c moves q by dw x (q - c), a shift dt by dt, and an angle k turning
about the posed joint J_k with world angular velocity w_k moves an LBS vertex by s_k(q) w_k x (q - J_k)
(pair_digits.angle_rows; the correctives' small share left out, the rotation vector's own curvature too: both only
slow the solve, they do not move its answer).

The digits' clearances are grasps/digit_clearance's phalanx capsules (their Jacobian is derived there; the rigid
placement does not move them); d_b is the field at points b along the capsules' bone segments (fixed in their
bones: the rigid rows, and angle rows with a share of 1 for the bone's joint and its parents). A fit leaving more
than MAX_PENETRATION inside the object, a bone's centreline inside it (a finger through a thin wall: its skin is
never deep), or a contact part farther than MAX_CONTACT from it is dropped, with why. Digits passing through each
other are still checked after the fit by the build (MeshLab through model/self_crossing: the independent guard).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from darthand.grasps import digit_clearance
from darthand.grasps.digit_clearance import Capsules
from darthand.grasps.field import SPACING, ObjectField, merged
from darthand.grasps.parts import contact_patches
from darthand.model.anatomy import angles_to_axis_angle, joint_frames, limits_radians, palm_normal
from darthand.model.forward import forward
from darthand.model.gesture_fit import freedom, subtree_mask
from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS
from darthand.model.pair_digits import angle_rows, turn_axes

GAP = 0.2e-3                # m: a contact part ends this far out of the surface (touching, not inside)
CLEARANCE = 0.3e-3          # m: every hand vertex stays this far out
CONTACT_SCALE = 0.5e-3      # m of contact gap that costs one sigma of pre-shape change
PENETRATION_SCALE = 0.1e-3  # m of penetration that costs one sigma
PRESHAPE_FREEDOM = 4.0      # sigma of an angle = gesture_fit.freedom x this (a finger bend: 16 deg)
TURN_SIGMA = np.deg2rad(30.0)
SHIFT_SIGMA = 0.03          # m
MAX_TURN = np.deg2rad(60.0)
MAX_SHIFT = 0.08            # m
REACH = 0.02                # m: vertices farther than this from the object are left out of a solve
RESEARCH = 0.001            # m: a vertex that moved this far has its candidate faces searched again
OPEN = 0.35                 # the start opens the pre-shape to this fraction of its angles
BACKOFF_STEP = 0.002        # m
ROUNDS = 3                  # solves, each with the vertices near the object re-selected
MAX_NFEV = 12
MAX_PENETRATION = 2e-3      # m: a fit leaving more is dropped
MAX_CONTACT = 5e-3          # m: a fit whose contact part ends farther is dropped
BONE_SAMPLES = 6            # points per phalanx's bone kept out of the object
BONE_CLEARANCE = 1e-3       # m: a bone's centreline stays this far out of the object (3 mm: a lateral pinch
                            # of a card cannot close, the middle finger's bone held off the card's edge)
BONE_REACH = 0.7            # share of a segment's length sampled from its joint


@dataclass
class HandRig:
    """What a model's fits share, computed once: its joint frames (16, 3, 3), contact patches {part: vertex ids},
    skinning share (V, 16, ) of each joint's subtree, and its phalanx capsules (None: digits free to cross)."""

    model: HandModel
    frames: np.ndarray
    patches: dict
    subtree_share: np.ndarray
    capsules: Capsules | None = None

    @classmethod
    def of(cls, model: HandModel, parts, clearance: bool = True) -> "HandRig":
        share = model.weights @ subtree_mask(model.parents)
        capsules = Capsules.of(model) if clearance else None
        return cls(model, joint_frames(model), contact_patches(model, parts), share, capsules)

    def pose(self, angles: np.ndarray):
        """forward's result for angles (16, 3) radians (the root left at the identity)."""
        aa = angles_to_axis_angle(self.model, angles, self.frames).reshape(1, -1)
        return forward(self.model, aa)


@dataclass
class GraspFit:
    """A fitted grasp: angles (16, 3) radians, pose (48,) axis-angle, placement (4, 4) object frame -> hand model
    frame, per contact part its vertex and object point, figures, and `dropped` (why, or None)."""

    angles: np.ndarray
    pose: np.ndarray
    placement: np.ndarray
    contact_vertices: np.ndarray
    contact_points: np.ndarray
    figures: dict = field(default_factory=dict)
    dropped: str | None = None


class GraspProblem:
    """The least-squares problem of one grasp (see the module docstring): the hand starts at `start` (4, 4: hand
    model frame -> object frame) with angles `angles` (16, 3), pulled toward the pre-shape `preshape` (16, 3)."""

    def __init__(self, rig: HandRig, field_: ObjectField, contacts, preshape: np.ndarray, angles: np.ndarray,
                 start: np.ndarray, free_scale: float = PRESHAPE_FREEDOM):
        self.rig, self.field, self.contacts = rig, field_, list(contacts)
        self.preshape, self.base, self.start = preshape, angles.reshape(-1).copy(), start
        sigma = freedom(preshape).reshape(-1) * free_scale
        sigma[:3] = 0.0
        self.free = np.flatnonzero(sigma > 0)
        self.sigma = sigma[self.free]
        lim = limits_radians().reshape(-1, 2)[self.free]
        self.lo = np.concatenate([[-MAX_TURN] * 3, [-MAX_SHIFT] * 3, lim[:, 0] - self.base[self.free]])
        self.hi = np.concatenate([[MAX_TURN] * 3, [MAX_SHIFT] * 3, lim[:, 1] - self.base[self.free]])
        self.share = rig.subtree_share[:, self.free // 3]
        patch_ids = np.concatenate([rig.patches[p] for p in self.contacts])
        self.centre = (rig.pose(angles).vertices[0][patch_ids] @ start[:3, :3].T + start[:3, 3]).mean(0)
        self.ids = np.arange(rig.model.num_vertices)
        self.cand: np.ndarray | None = None          # candidate faces (n, k) of the fitted vertices ...
        self.cand_at = np.zeros((0, 3))              # ... found where they were then (n, 3)
        self._cache: tuple | None = None

    def angles(self, y: np.ndarray) -> np.ndarray:
        a = self.base.copy()
        a[self.free] += y[6:]
        return a.reshape(16, 3)

    def transform(self, y: np.ndarray) -> np.ndarray:
        """(4, 4) hand model frame -> object frame at the variables y."""
        R = Rotation.from_rotvec(y[:3]).as_matrix()
        M = np.eye(4)
        M[:3, :3] = R @ self.start[:3, :3]
        M[:3, 3] = R @ (self.start[:3, 3] - self.centre) + self.centre + y[3:6]
        return M

    def placed(self, points: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.placed_points(points, self.transform(y))

    def select(self, y: np.ndarray) -> None:
        """Fit only the vertices within REACH of the object (and every contact part's) at y, keeping their
        candidate faces (field.candidates) until a vertex moves RESEARCH away from where they were found."""
        v = self.placed(self.rig.pose(self.angles(y)).vertices[0], y)
        contact = np.zeros(len(v), bool)
        contact[np.concatenate([self.rig.patches[p] for p in self.contacts])] = True
        ids = np.flatnonzero(self.field.in_box(v, REACH) | contact)
        first, cand = self.field.candidates(v[ids], exact=False)
        keep = (first < REACH + SPACING) | contact[ids]
        self.ids, self.cand, self.cand_at = ids[keep], cand[keep], v[ids[keep]]
        self._cache = None

    def candidate_faces(self, q: np.ndarray) -> np.ndarray:
        """(n, k) candidate faces of the fitted vertices at q (n, 3): those kept, searched again for the vertices
        that moved more than RESEARCH since."""
        assert self.cand is not None
        moved = np.flatnonzero(np.linalg.norm(q - self.cand_at, axis=1) > RESEARCH)
        if len(moved):
            fresh = self.field.candidates(q[moved], exact=False)[1]
            self.cand = merged(self.cand, moved, fresh)
            self.cand_at[moved] = q[moved]
        return self.cand

    def evaluate(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(residuals, Jacobian) at y, cached for the last y."""
        if self._cache is not None and np.array_equal(self._cache[0], y):
            return self._cache[1], self._cache[2]
        angles = self.angles(y)
        posed = self.rig.pose(angles)
        M = self.transform(y)
        q = self.placed_points(posed.vertices[0][self.ids], M)
        d, u, _ = self.field.query(q, self.candidate_faces(q))
        omega = turn_axes(self.rig.frames, angles, posed.world_rotations[0], self.rig.model.parents, self.free)
        pivot = self.placed_points(posed.joints[0, self.free // 3], M)
        rows = np.hstack([np.cross(q - self.centre - y[3:6], u), u,
                          angle_rows(q, u, self.share[self.ids], omega @ M[:3, :3].T, pivot)])   # (n, 6 + k)
        inside = d < CLEARANCE
        res = [np.where(inside, (CLEARANCE - d) / PENETRATION_SCALE, 0.0)]
        jac = [np.where(inside[:, None], -rows / PENETRATION_SCALE, 0.0)]
        where = {v: i for i, v in enumerate(self.ids)}
        for p in self.contacts:
            at = np.array([where[v] for v in self.rig.patches[p]])
            best = at[np.argmin(d[at])]
            res.append(np.array([(d[best] - GAP) / CONTACT_SCALE]))
            jac.append(rows[best][None] / CONTACT_SCALE)
        k = len(self.free)
        res.append((self.base[self.free] + y[6:] - self.preshape.reshape(-1)[self.free]) / self.sigma)
        jac.append(np.hstack([np.zeros((k, 6)), np.diag(1.0 / self.sigma)]))
        res.append(np.concatenate([y[:3] / TURN_SIGMA, y[3:6] / SHIFT_SIGMA]))
        jac.append(np.hstack([np.diag([1 / TURN_SIGMA] * 3 + [1 / SHIFT_SIGMA] * 3), np.zeros((6, k))]))
        if self.rig.capsules is not None:
            for r, j in (self.digit_terms(posed, omega), self.bone_terms(posed, M, y, omega @ M[:3, :3].T, pivot)):
                res.append(r)
                jac.append(j)
        out = (np.concatenate([np.ravel(r) for r in res]), np.vstack(jac))
        self._cache = (y.copy(), *out)
        return out

    def digit_terms(self, posed, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(residuals (P,), Jacobian (P, 6 + k)) of the digits' capsule clearances (hand model frame: the placement
        moves both digits alike); omega (k, 3) the free angles' world axes in the hand model frame."""
        caps = self.rig.capsules
        assert caps is not None
        clear, u, pa, pb = caps.clearances(posed.transforms[0])
        rows = caps.rows(u, pa, pb, self.free, omega, posed.joints[0, self.free // 3])
        hit = clear < 0
        res = np.where(hit, -clear / digit_clearance.SCALE, 0.0)
        jac = np.where(hit[:, None], -rows / digit_clearance.SCALE, 0.0)
        return res, np.hstack([np.zeros((len(res), 6)), jac])

    def bone_points(self, posed) -> np.ndarray:
        """(C x BONE_SAMPLES, 3) points along the capsules' bone segments up to BONE_REACH of their length (a distal
        segment ends at the tip vertex, on the skin), hand model frame."""
        assert self.rig.capsules is not None
        start, end = self.rig.capsules.segments(posed.transforms[0])
        t = np.linspace(0.0, BONE_REACH, BONE_SAMPLES)[None, :, None]
        return (start[:, None] + t * (end - start)[:, None]).reshape(-1, 3)

    def bone_terms(self, posed, M: np.ndarray, y: np.ndarray, omega: np.ndarray,
                   pivot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(residuals, Jacobian (n, 6 + k)) keeping the bones' centrelines BONE_CLEARANCE out of the object (a
        finger would otherwise close through a wall thinner than it, whose depth never shows on the skin); M the
        placement, omega (k, 3) and pivot (k, 3) the free angles' axes and joints in the object frame."""
        assert self.rig.capsules is not None
        q = self.placed_points(self.bone_points(posed), M)
        res, jac = np.zeros(len(q)), np.zeros((len(q), 6 + len(self.free)))
        near = np.flatnonzero(self.field.in_box(q, BONE_CLEARANCE))
        if len(near) == 0:
            return res, jac
        d, u, _ = self.field.query(q[near])
        hit = d < BONE_CLEARANCE
        at, qh, uh = near[hit], q[near][hit], u[hit]
        moves = self.rig.capsules.ancestors[at // BONE_SAMPLES][:, self.free // 3].astype(np.float64)
        rows = np.hstack([np.cross(qh - self.centre - y[3:6], uh), uh, angle_rows(qh, uh, moves, omega, pivot)])
        res[at] = (BONE_CLEARANCE - d[hit]) / PENETRATION_SCALE
        jac[at] = -rows / PENETRATION_SCALE
        return res, jac

    @staticmethod
    def placed_points(points: np.ndarray, M: np.ndarray) -> np.ndarray:
        """(n, 3) points (n, 3) of the hand model frame placed by M (4, 4) into the object frame."""
        return points @ M[:3, :3].T + M[:3, 3]

    def solve(self, rounds: int | None = None, nfev: int | None = None) -> tuple[np.ndarray, int]:
        """(variables y, evaluations) after `rounds` solves (ROUNDS) of at most `nfev` evaluations (MAX_NFEV),
        the vertices near the object re-selected before each."""
        rounds, nfev = ROUNDS if rounds is None else rounds, MAX_NFEV if nfev is None else nfev
        y, evaluations = np.zeros(6 + len(self.free)), 0
        scale = np.concatenate([[0.05] * 3, [0.005] * 3, np.full(len(self.free), 0.1)])
        for _ in range(rounds):
            self.select(y)
            r = least_squares(lambda x: self.evaluate(x)[0], y, jac=lambda x: self.evaluate(x)[1],
                              bounds=(self.lo, self.hi), method="trf", x_scale=scale, max_nfev=nfev,
                              xtol=1e-6, ftol=1e-6)
            y, evaluations = r.x, evaluations + r.nfev
        return y, evaluations

    def result(self, y: np.ndarray, evaluations: int, seconds: float) -> GraspFit:
        """The fit at y, measured over every hand vertex, with its figures and the drop rule applied."""
        angles = self.angles(y)
        posed = self.rig.pose(angles)
        M = self.transform(y)
        q = self.placed_points(posed.vertices[0], M)
        d, near = np.full(len(q), np.inf), q.copy()    # outside the object's box: outside it
        inside = self.field.in_box(q, MAX_CONTACT)
        d[inside], _, near[inside] = self.field.query(q[inside])
        vertices, points, gaps = [], [], []
        for p in self.contacts:
            ids = self.rig.patches[p]
            best = ids[np.argmin(d[ids])]
            vertices.append(best)
            points.append(near[best])
            gaps.append(float(d[best]))
        depth = np.maximum(0.0, -d)
        figures = {"penetration_max_mm": round(float(depth.max()) * 1e3, 3),
                   "penetration_p99_mm": round(float(np.percentile(depth, 99)) * 1e3, 3),
                   "contact_mm": {p: round(g * 1e3, 3) for p, g in zip(self.contacts, gaps)},
                   "iterations": int(evaluations), "seconds": round(seconds, 4)}
        dropped = None
        through = self.bone_inside(posed, M)
        if through:
            dropped = f"{through} through the object (its bone inside)"
        elif depth.max() > MAX_PENETRATION:
            dropped = f"penetration {depth.max() * 1e3:.1f} mm over {MAX_PENETRATION * 1e3:g} mm"
        elif max(abs(g) for g in gaps) > MAX_CONTACT:
            worst = max(zip(gaps, self.contacts), key=lambda x: abs(x[0]))
            dropped = f"contact {worst[1]} {worst[0] * 1e3:.1f} mm from the surface (over {MAX_CONTACT * 1e3:g} mm)"
        aa = angles_to_axis_angle(self.rig.model, angles, self.rig.frames).reshape(-1)
        return GraspFit(angles, aa, np.linalg.inv(M), np.array(vertices, np.int64), np.array(points), figures,
                        dropped)


    def bone_inside(self, posed, M: np.ndarray) -> str | None:
        """The first digit (FINGERS name) whose bone centreline (the capsules' segments, BONE_SAMPLES points each)
        lies inside the object, or None: a finger through a thin wall, which the skin's shallow depth misses."""
        caps = self.rig.capsules
        if caps is None:
            return None
        points = self.placed_points(self.bone_points(posed), M)
        near = np.flatnonzero(self.field.in_box(points, 0.0))
        if len(near) == 0:
            return None
        inside = near[self.field.distance(points[near]) < 0]
        return digit_clearance.digit_of(caps, inside // BONE_SAMPLES)


def start_transform(rig: HandRig, field_: ObjectField, contacts, opened: np.ndarray, approach: np.ndarray,
                    across: np.ndarray, target: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) hand model frame -> object frame: the opened hand's palm facing the object from `approach` (unit,
    object frame, pointing from the object to the hand), its knuckle line along `across` (unit, orthogonal to the
    approach), its contact parts' centre at `target` (3,) (default the object frame's origin, its centre), then
    backed off along the approach until no vertex is inside the object."""
    posed = rig.pose(opened)
    v, joints = posed.vertices[0], posed.joints[0]
    centre = np.concatenate([v[rig.patches[p]] for p in contacts]).mean(0)
    palm = palm_normal(rig.model, joints)
    knuckles = joints[FINGER_JOINTS["index"][0]] - joints[FINGER_JOINTS["pinky"][0]]
    R = frame_between(palm, knuckles, -approach, across)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ centre + (0.0 if target is None else np.asarray(target))
    placed = v @ R.T + T[:3, 3]
    for _ in range(int(0.2 / BACKOFF_STEP)):
        near = field_.in_box(placed, CLEARANCE)
        deepest = -field_.distance(placed[near]).min(initial=np.inf) + CLEARANCE
        if deepest <= 0:
            break
        step = max(BACKOFF_STEP, 0.5 * deepest)   # at least half the deepest way out: a few steps, not hundreds
        T[:3, 3] += step * approach
        placed += step * approach
    return T


def frame_between(a: np.ndarray, b: np.ndarray, a_to: np.ndarray, b_to: np.ndarray) -> np.ndarray:
    """(3, 3) the rotation taking direction a to a_to and b (made orthogonal to a) to b_to (made orthogonal to
    a_to)."""
    def basis(x, y):
        x = x / np.linalg.norm(x)
        y = y - (y @ x) * x
        y = y / np.linalg.norm(y)
        return np.stack([x, y, np.cross(x, y)], 1)
    return basis(a_to, b_to) @ basis(a, b).T


def fit_grasp(rig: HandRig, field_: ObjectField, contacts, preshape: np.ndarray, approach: np.ndarray,
              across: np.ndarray, target: np.ndarray | None = None) -> GraspFit:
    """Close the pre-shape (16, 3) on the object from `approach` at `target` (see start_transform) and measure the
    result."""
    t0 = time.perf_counter()
    opened = preshape * OPEN
    start = start_transform(rig, field_, contacts, opened, approach, across, target)
    problem = GraspProblem(rig, field_, contacts, preshape, opened, start)
    y, evaluations = problem.solve()
    return problem.result(y, evaluations, time.perf_counter() - t0)


def refine(rig: HandRig, field_: ObjectField, contacts, preshape: np.ndarray, angles: np.ndarray,
           start: np.ndarray, rounds: int = 1, nfev: int = 4) -> GraspFit:
    """A few iterations of the same problem from given angles and start (4, 4, hand -> object): a refit."""
    t0 = time.perf_counter()
    problem = GraspProblem(rig, field_, contacts, preshape, angles, start)
    y, evaluations = problem.solve(rounds, nfev)
    return problem.result(y, evaluations, time.perf_counter() - t0)

