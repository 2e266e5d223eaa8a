"""Named gestures fitted to one model: the authored angles, changed as little as the model needs so that no two
parts of the hand pass through each other and the gesture's intended contacts touch.

The gestures (assets_src/poses) are anatomical angles tuned on one hand. On another -- MANO's, a remeshed hand,
even the same hand whose joint frames come out a degree or two differently -- a thumb meant to rest on a finger
ends up inside it. So each gesture is fitted per model, a small bounded least-squares problem over the
twist/spread/bend angles of the digits involved:

    minimise   sum_k (delta_k / sigma_k)^2                              stay near the authored angles
             + sum_i (max(0, c - d_i) / s)^2                            parts at least c apart (clearance)
             + sum_contacts ((softmin_i d_i - g) / s)^2                 intended contacts end g apart (touching)
    within     the joint limits and |delta_k| <= MAX_CHANGE_DEG

d_i are signed distances (m, negative inside) between samples of one part and the surface of another
(model/proximity), over the samples near the other part; s = PENALTY_SCALE. sigma_k (`freedom`) holds the
gesture's intent: hinge joints (PIP, DIP, thumb MCP and IP) never twist or spread, a finger that is straight in the
gesture keeps every bend (the point's index stays straight), and the thumb moves more freely than the fingers, so
a fist stays closed and the fingers make room only as much as they must. The Jacobian is analytic: an angle k
of joint j turns every joint transform G_m at or below j about the posed joint J_j with angular velocity w_k, so
an LBS point x = sum_m w_m G_m x0 moves by sum_{m below j} w_m w_k x (G_m x0 - J_j), and d(d_i)/d(angle_k) is
the signed offset direction (x_i - y_i)/|x_i - y_i| against the sample's motion less that of its nearest point
y_i on the other part (the correctives' small share left out).

The guard is MeshLab's face intersection test (model/intersections), which the gesture step checks again: when
faces of two digits still cross after a fit, clearance and contact gap grow by STEP and the gesture is fitted again,
up to ROUNDS times; a gesture that still fails is recorded as 'unresolved' with what stopped it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from darthand.model.anatomy import AXES, angles_to_axis_angle, angles_to_matrix, joint_frames, limits_radians
from darthand.model.forward import forward
from darthand.model.gestures import GESTURES_FORMAT, GESTURES_VERSION, angles_to_joints
from darthand.model.hand_model import HandModel
from darthand.model.intersections import PARTS, between_digits, face_parts, part_intersections
from darthand.model.layout import FINGER_JOINTS, FINGERS, JOINT_NAMES, NUM_JOINTS
from darthand.model.poses import gesture_angles, gesture_contacts, list_gestures
from darthand.model.proximity import PartSurfaces
from darthand.model.topology import vertex_normals

CLEARANCE = 0.5e-3       # m: parts not meant to touch stay at least this far apart
CONTACT_GAP = 0.25e-3    # m: parts meant to touch end this far apart (touching, not passing through)
STEP = 0.25e-3           # m: added to both when the guard still finds crossing faces
ROUNDS = 4
REACH = 3e-3             # m: samples farther than clearance + REACH from another part are left out of a fit
SOFTMIN = 0.1e-3         # m: temperature of the soft minimum over a contact's distances
PENALTY_SCALE = 0.05e-3  # m of violated clearance that costs as much as one sigma of change
MAX_CHANGE_DEG = 20.0
STRAIGHT_DEG = 6.0       # a finger whose three bends are all below this is straight in the gesture
# How freely each angle may move (degrees, one sigma): (twist, spread, bend) per joint of a chain, root first.
FINGER_FREEDOM = ((1.0, 3.0, 4.0), (0.0, 0.0, 4.0), (0.0, 0.0, 4.0))
THUMB_FREEDOM = ((5.0, 5.0, 6.0), (0.0, 0.0, 7.0), (0.0, 0.0, 7.0))


@dataclass
class FitResult:
    """One gesture fitted to a model. angles (16, 3) radians; changed: 'joint.axis' -> degrees added to the
    authored angle; status: 'kept' (the authored angles already fit), 'fitted', or
    'unresolved' (digits still cross; `at_bound` names the angles the fit pushed to a bound)."""

    name: str
    angles: np.ndarray
    changed: dict = field(default_factory=dict)
    contacts: list = field(default_factory=list)
    status: str = "kept"
    rounds: int = 0
    clearance_mm: float = CLEARANCE * 1e3
    crossing: dict = field(default_factory=dict)
    at_bound: list = field(default_factory=list)


def freedom(authored: np.ndarray) -> np.ndarray:
    """(16, 3) sigma (radians) of each angle for a gesture with these authored angles (16, 3); 0 = held."""
    sigma = np.zeros((NUM_JOINTS, 3))
    for finger in FINGERS:
        chain = list(FINGER_JOINTS[finger])
        table = np.array(THUMB_FREEDOM if finger == "thumb" else FINGER_FREEDOM)
        if finger != "thumb" and (np.abs(authored[chain, 2]) < np.deg2rad(STRAIGHT_DEG)).all():
            table[:, 2] = 0.0  # straight in the gesture: keep it straight
        sigma[chain] = np.deg2rad(table)
    return sigma


def angular_velocities(model: HandModel, frames: np.ndarray, angles: np.ndarray, posed,
                       free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World angular velocity (n, 3) of each angle `free` (indices into the flat (48,) angles (16, 3)) and the
    posed joint (n, 3) it turns about, for the first pose of `posed` (forward's result at those angles).

    R_local = F Rz(bend) Ry(spread) Rx(twist) F^T, composed onto the parent's world rotation W, so the twist
    turns about W F Rz Ry e_x, the spread about W F Rz e_y and the bend about W F e_z."""
    joints, axes = np.divmod(np.asarray(free), 3)
    W = np.asarray(posed.world_rotations[0], np.float64)
    omega = np.empty((len(joints), 3))
    for i, (j, a) in enumerate(zip(joints, axes)):
        _, s, b = angles[j]
        before = angles_to_matrix([0.0, s, b] if a == 0 else [0.0, 0.0, b if a == 1 else 0.0])  # Rz Ry, Rz, I
        omega[i] = W[model.parents[j]] @ frames[j] @ before[:, a]
    return omega, np.asarray(posed.joints[0, joints], np.float64)


def subtree_mask(parents: np.ndarray) -> np.ndarray:
    """(16, 16) D[j, k] = 1 when joint k is joint j or one of its ancestors (rotating k moves j's points)."""
    D = np.zeros((len(parents), len(parents)))
    for j in range(len(parents)):
        k = j
        while k >= 0:
            D[j, k] = 1.0
            k = parents[k]
    return D


class GestureProblem:
    """The least-squares problem of one gesture on one model (see the module docstring)."""

    def __init__(self, model: HandModel, surfaces: PartSurfaces, frames: np.ndarray, authored: np.ndarray,
                 contacts: list[tuple[int, int]], clearance: float, gap: float):
        self.model, self.surfaces, self.frames = model, surfaces, frames
        self.authored, self.clearance, self.gap = authored, clearance, gap
        self.contacts = {tuple(sorted(c)) for c in contacts}
        self.sigma = freedom(authored).reshape(-1)
        self.subtree = subtree_mask(model.parents)
        self.sets: dict[tuple[int, int], np.ndarray] = {}
        self.free = np.zeros(0, np.int64)
        self.x: np.ndarray | None = None
        self.bounds = (np.zeros(0), np.zeros(0))
        self._cache: tuple | None = None

    # ---------------------------------------------------------------- pose and measure
    def angles(self, x: np.ndarray) -> np.ndarray:
        a = self.authored.reshape(-1).copy()
        a[self.free] += x
        return a.reshape(NUM_JOINTS, 3)

    def pose(self, angles: np.ndarray):
        aa = angles_to_axis_angle(self.model, angles, self.frames).reshape(1, -1)
        posed = forward(self.model, aa)
        v = posed.vertices[0]
        return v, vertex_normals(v, self.model.faces), posed

    def hits(self, v: np.ndarray, n: np.ndarray, p: int, q: int, samples=None, reach=None):
        return self.surfaces.signed_distances(v, n, p, q, samples=samples, reach=reach)

    def select(self, v: np.ndarray, n: np.ndarray) -> bool:
        """Add to the fit every sample within clearance + REACH of another part (all of a contact pair's within
        its current distance + REACH); True if any sample was added."""
        added = False
        for p in range(len(PARTS)):
            for q in range(len(PARTS)):
                if p == q:
                    continue
                contact = tuple(sorted((p, q))) in self.contacts
                reach = self.clearance + REACH
                if contact:
                    h = self.hits(v, n, p, q)
                    reach = max(reach, float(h.distance.min(initial=np.inf)) + REACH) if len(h.sample) else reach
                h = self.hits(v, n, p, q, reach=reach)
                new = np.union1d(self.sets.get((p, q), np.zeros(0, np.int64)), h.sample)
                if len(new) > len(self.sets.get((p, q), ())):
                    self.sets[(p, q)] = new
                    added = True
        return added

    def involved(self) -> np.ndarray:
        """Free variables: the angles (sigma > 0) of every digit in a fitted pair."""
        digits = {p for pair in self.sets for p in pair if p > 0} | {p for pair in self.contacts for p in pair if p}
        mask = np.zeros((NUM_JOINTS, 3), bool)
        for d in digits:
            mask[list(FINGER_JOINTS[PARTS[d]])] = True
        return np.flatnonzero(mask.reshape(-1) & (self.sigma > 0))

    # ---------------------------------------------------------------- residuals and Jacobian
    def evaluate(self, x: np.ndarray):
        """(residuals (R,), Jacobian (R, n)) at x, cached for the last x."""
        if self._cache is not None and np.array_equal(self._cache[0], x):
            return self._cache[1], self._cache[2]
        angles = self.angles(x)
        v, n, posed = self.pose(angles)
        velocity = self.angular_velocities(angles, posed)                          # (n, 3), (n, 3) pivots
        res, jac = [x / self.sigma[self.free]], [np.diag(1.0 / self.sigma[self.free])]
        contact_terms: dict[tuple[int, ...], list] = {}
        for (p, q), ids in sorted(self.sets.items()):
            h = self.hits(v, n, p, q, samples=ids)
            d = np.full(len(ids), np.inf)
            grad = np.zeros((len(ids), len(self.free)))
            at = np.searchsorted(ids, h.sample)
            d[at] = h.distance
            grad[at] = self.distance_gradient(v, h, velocity, posed.transforms[0])
            key = tuple(sorted((p, q)))
            margin = 0.0 if key in self.contacts else self.clearance
            short = d < margin
            r = np.where(short, (margin - d) / PENALTY_SCALE, 0.0)
            res.append(r)
            jac.append(np.where(short[:, None], -grad / PENALTY_SCALE, 0.0))
            if key in self.contacts and len(h.sample):
                contact_terms.setdefault(key, []).append((h.distance, grad[at]))
        for key in sorted(self.contacts):
            terms = contact_terms.get(key)
            if not terms:
                res.append(np.zeros(1))
                jac.append(np.zeros((1, len(self.free))))
                continue
            d = np.concatenate([t[0] for t in terms])
            g = np.concatenate([t[1] for t in terms])
            w = np.exp(-(d - d.min()) / SOFTMIN)
            w /= w.sum()
            soft = d.min() - SOFTMIN * np.log(np.exp(-(d - d.min()) / SOFTMIN).sum())
            res.append(np.array([(soft - self.gap) / PENALTY_SCALE]))
            jac.append((w @ g)[None] / PENALTY_SCALE)
        r, J = np.concatenate(res), np.concatenate(jac)
        self._cache = (x.copy(), r, J)
        return r, J

    def angular_velocities(self, angles: np.ndarray, posed) -> tuple[np.ndarray, np.ndarray]:
        """World angular velocity (n, 3) of each free angle and the posed joint (n, 3) it turns about."""
        return angular_velocities(self.model, self.frames, angles, posed, self.free)

    def distance_gradient(self, v: np.ndarray, h, velocity, transforms: np.ndarray) -> np.ndarray:
        """(K, n) derivative of each hit's signed distance with respect to the free angles (transforms: the
        pose's skinning transforms (16, 4, 4))."""
        ids = h.sample
        x = self.surfaces.samples(v, ids)
        ux = self.point_velocities(self.surfaces.sample_corners[ids], self.surfaces.sample_bary[ids], transforms,
                                   velocity)
        uy = self.point_velocities(h.corners, h.bary, transforms, velocity)
        # d = sign |x - y|: it changes along the unit offset (x - y) sign, or along the normal when touching.
        offset = x - h.point
        length = np.linalg.norm(offset, axis=1, keepdims=True)
        direction = np.where(length > 1e-7, offset / np.maximum(length, 1e-300) * np.sign(h.distance)[:, None],
                             h.normal)
        return np.einsum("kd,knd->kn", direction, ux - uy)

    def point_velocities(self, corners: np.ndarray, bary: np.ndarray, transforms: np.ndarray,
                         velocity) -> np.ndarray:
        """(K, n, 3) velocity of surface points (corner vertices (K, 3), barycentrics (K, 3)) per unit change of
        each free angle: LBS x = sum_j w_j G_j x0, and turning angle i (joint k, angular velocity w, posed joint
        J) moves G_j x0 by w x (G_j x0 - J) for every joint j at or below k."""
        omega, pivot = velocity
        weighted = bary[..., None] * self.model.weights[corners]                         # (K, 3, 16)
        rest = np.concatenate([self.model.v_template[corners], np.ones(corners.shape + (1,))], axis=-1)
        bound = np.einsum("jab,kcb->kcja", transforms[:, :3, :], rest)                  # (K, 3, 16, 3) G_j x0
        below = self.subtree[:, self.free // 3]                                          # (16, n)
        moved = np.einsum("kcj,kcja,jn->kna", weighted, bound, below)                  # (K, n, 3)
        share = np.einsum("kcj,jn->kn", weighted, below)                                # (K, n)
        return np.cross(omega[None], moved - share[..., None] * pivot[None])

    # ---------------------------------------------------------------- solve
    def solve(self) -> np.ndarray:
        """The fitted angles (16, 3): least squares over the involved angles, re-selecting samples until no new
        one comes near another part."""
        x = np.zeros(0)
        v, n, _ = self.pose(self.authored)
        for _ in range(4):
            if not self.select(v, n) and len(x) == len(self.involved()):
                break
            free = self.involved()
            x = self._carry(x, free)
            self.free, self._cache = free, None
            if len(free) == 0:
                break
            lim = limits_radians().reshape(-1, 2)[free]
            base = self.authored.reshape(-1)[free]
            change = np.deg2rad(MAX_CHANGE_DEG)
            lo = np.minimum(np.maximum(lim[:, 0] - base, -change), 0.0)
            hi = np.maximum(np.minimum(lim[:, 1] - base, change), 0.0)
            x = np.clip(x, lo, hi)
            fit = least_squares(lambda z: self.evaluate(z)[0], x, jac=lambda z: self.evaluate(z)[1],
                                bounds=(lo, hi), method="trf", x_scale=self.sigma[free], max_nfev=100,
                                xtol=1e-10, ftol=1e-8)
            x = fit.x
            self.x, self.bounds = x, (lo, hi)
            v, n, _ = self.pose(self.angles(x))
        return self.angles(x)

    def at_bound(self) -> list[str]:
        """'joint.axis' of the free angles the last solve left at a bound (a joint limit or MAX_CHANGE_DEG)."""
        if self.x is None or not len(self.free):
            return []
        lo, hi = self.bounds
        at = ((self.x <= lo + 1e-9) & (lo < 0)) | ((self.x >= hi - 1e-9) & (hi > 0))
        return [f"{JOINT_NAMES[k // 3]}.{AXES[k % 3]}" for k in self.free[at]]

    def _carry(self, x: np.ndarray, free: np.ndarray) -> np.ndarray:
        """x re-indexed onto a new set of free angles (new ones start at 0)."""
        out = np.zeros(len(free))
        if len(self.free):
            pos = {int(k): i for i, k in enumerate(self.free)}
            for i, k in enumerate(free):
                if int(k) in pos:
                    out[i] = x[pos[int(k)]]
        return out


def fit_gestures(model: HandModel, names: list[str] | None = None, poses_dir=None) -> dict:
    """Fit the named gestures (all of assets_src/poses, or `names` from `poses_dir`) to `model`; return the record
    `model.gestures` reads back (GESTURES_FORMAT): per gesture its fitted angles ('joints', the pose files'
    layout), contacts, status, what changed (degrees), the clearance it was fitted with, the digit pairs still
    crossing and the angles left at a bound."""
    names = list_gestures(poses_dir) if names is None else list(names)
    surfaces, frames, face_part = PartSurfaces(model), joint_frames(model), face_parts(model)
    out = {}
    for name in names:
        # One BLAS thread: the fit's products are small, and threaded BLAS spin-waits cost 5-20x on two busy cores.
        with threadpool_limits(limits=1, user_api="blas"):
            r = fit_gesture(model, surfaces, frames, name, gesture_angles(name, poses_dir),
                            gesture_contacts(name, poses_dir), face_part)
        out[name] = {"joints": angles_to_joints(r.angles), "contacts": r.contacts, "status": r.status,
                     "changed_deg": r.changed, "rounds": r.rounds, "clearance_mm": round(r.clearance_mm, 4),
                     "crossing": r.crossing, "at_bound": r.at_bound}
    return {"format": GESTURES_FORMAT, "version": GESTURES_VERSION,
            "settings": {"clearance_mm": CLEARANCE * 1e3, "contact_gap_mm": CONTACT_GAP * 1e3,
                         "step_mm": STEP * 1e3, "rounds": ROUNDS, "max_change_deg": MAX_CHANGE_DEG},
            "gestures": out}


def with_fitted_gestures(model: HandModel) -> HandModel:
    """A copy of `model` carrying its fitted gestures (`meta["gestures"]`)."""
    return model.replace(meta=dict(model.meta, gestures=fit_gestures(model)))


def fit_gesture(model: HandModel, surfaces: PartSurfaces, frames: np.ndarray, name: str, authored: np.ndarray,
                contacts: list[tuple[str, str]], face_part: np.ndarray) -> FitResult:
    """Fit one gesture (authored angles (16, 3) radians, contact pairs of part names) to `model`: solve, check
    with the guard, and fit again with more clearance while digits still cross and that helps."""
    pairs = [(PARTS.index(a), PARTS.index(b)) for a, b in contacts]
    best = None
    for round_ in range(ROUNDS):
        clearance, gap = CLEARANCE + round_ * STEP, CONTACT_GAP + round_ * STEP
        problem = GestureProblem(model, surfaces, frames, authored, pairs, clearance, gap)
        angles = problem.solve()
        v = problem.pose(angles)[0]
        crossing = {k: n for k, n in part_intersections(v, model.faces, face_part)["between"].items()
                    if "palm" not in k}
        changed = changed_angles(authored, angles)
        result = FitResult(name, angles, changed, [list(c) for c in contacts], "fitted" if changed else "kept",
                           round_ + 1, clearance * 1e3, crossing, problem.at_bound())
        if not crossing:
            return result
        if best is not None and between_digits(crossing) >= between_digits(best.crossing):
            break  # more clearance did not help: the crossing is not one the fit can move apart
        best = result
    assert best is not None, "ROUNDS > 0"
    best.status = "unresolved"
    return best


def changed_angles(authored: np.ndarray, fitted: np.ndarray, tol_deg: float = 1e-3) -> dict:
    """{'joint.axis': degrees added} for every angle the fit moved by more than tol_deg."""
    delta = np.rad2deg(fitted - authored)
    return {f"{JOINT_NAMES[j]}.{AXES[a]}": round(float(delta[j, a]), 3)
            for j, a in zip(*np.nonzero(np.abs(delta) > tol_deg))}
