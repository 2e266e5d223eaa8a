"""The two-hand fit with the digits free: model/hand_pair's rigid problem over the second hand's placement, plus the
anatomical angles (model/anatomy: twist, spread, bend) of both hands' digits, so that a clasp or an interlace that
comes too close closes by bending fingers, not only by moving the hand away.

    minimise   sum (x_k / sigma_k)^2 + sum (delta_k / sigma_k)^2       near the sampled placement and angles
             + clearance and contact terms on the re-posed vertices   (as model/hand_pair)
    within     the rigid bounds, the joint limits and |delta_k| <= gesture_fit.MAX_CHANGE_DEG

sigma_k of an angle is gesture_fit.freedom's for the sampled angles (hinges never twist or spread, a straight
finger stays straight, the thumb moves more freely). The Jacobian of a distance d = u . (p - y) (u the unit
direction along which it grows, p the moving point, y its nearest point on the other hand) is u . (dp - dy): an
angle k turning about the posed joint J_k with world angular velocity w_k moves an LBS point p by
s_k(p) w_k x (p - J_k), s_k(p) the skinning weight p carries from joint k and the joints below it (gesture_fit's
derivation with the points bound to those joints taken at p itself; the correctives' share left out). y moves with
the weights of the vertex nearest to it.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from darthand.model.anatomy import angles_to_axis_angle, axis_angle_to_angles, joint_frames, limits_radians
from darthand.model.forward import forward
from darthand.model.gesture_fit import MAX_CHANGE_DEG, freedom, subtree_mask
from darthand.model.hand_model import HandModel
from darthand.model.layout import FINGER_JOINTS
from darthand.model.topology import vertex_normals

MAX_NFEV = 6          # least-squares evaluations per solve (as the rigid fit's; 4: contacts end short)
SELECTIONS = 2        # sample selections (each then a solve) per round (one: contacts end ~2 mm short)


@dataclass
class DigitHand:
    """One hand whose digits the pair fit may bend: its model, sampled pose (48,) axis-angle, betas (or None), and
    its placement T (4, 4: the model frame into the world, before the fit's rigid move); frames: the model's
    joint_frames (16, 3, 3) when already at hand."""

    model: HandModel
    pose: np.ndarray
    betas: np.ndarray | None = None
    T: np.ndarray | None = None
    frames: np.ndarray | None = None

    def __post_init__(self):
        self.axes: np.ndarray = joint_frames(self.model) if self.frames is None else self.frames
        self.angles = axis_angle_to_angles(self.model, np.asarray(self.pose, np.float64).reshape(16, 3),
                                           self.axes)
        self.sigma = freedom(self.angles).reshape(-1)
        self.sigma[:3] = 0.0                               # the root: the placement is the rigid part's
        self.free = np.flatnonzero(self.sigma > 0)
        self.share = self.model.weights @ subtree_mask(self.model.parents)[:, self.free // 3]   # (V, n)
        self.place = np.eye(4) if self.T is None else np.asarray(self.T, np.float64)
        lim = limits_radians().reshape(-1, 2)[self.free]
        base = self.angles.reshape(-1)[self.free]
        change = np.deg2rad(MAX_CHANGE_DEG)
        self.lo = np.minimum(np.maximum(lim[:, 0] - base, -change), 0.0)
        self.hi = np.maximum(np.minimum(lim[:, 1] - base, change), 0.0)
        held = self.hi <= self.lo                         # at a limit on both sides: nothing to move
        self.hi[held] = self.lo[held] + 1e-12

    def only(self, joints) -> "DigitHand | None":
        """This hand with only the angles of `joints` (ids) free (None when none of its free angles is there)."""
        keep = np.isin(self.free // 3, list(joints))
        if not keep.any():
            return None
        out = copy.copy(self)
        out.free, out.share, out.lo, out.hi = self.free[keep], self.share[:, keep], self.lo[keep], self.hi[keep]
        return out

    def fitted_angles(self, delta: np.ndarray) -> np.ndarray:
        """(16, 3) radians: the sampled angles plus `delta` (n,) on the free ones."""
        a = self.angles.reshape(-1).copy()
        a[self.free] += delta
        return a.reshape(16, 3)

    def fitted_pose(self, delta: np.ndarray) -> np.ndarray:
        """(48,) axis-angle of the fitted angles."""
        return angles_to_axis_angle(self.model, self.fitted_angles(delta), self.axes).reshape(-1)

    def posed(self, delta: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(vertices (V, 3), normals (V, 3), angular velocities (n, 3), pivots (n, 3)) in the world, the hand
        re-posed by `delta` and placed by T @ its placement."""
        angles = self.fitted_angles(delta)
        aa = angles_to_axis_angle(self.model, angles, self.axes).reshape(1, -1)
        out = forward(self.model, aa, None if self.betas is None else np.asarray(self.betas).reshape(1, -1),
                      dtype=np.float64)
        omega = turn_axes(self.axes, angles, out.world_rotations[0], self.model.parents, self.free)
        pivot = np.asarray(out.joints[0, self.free // 3], np.float64)
        M = T @ self.place
        v = np.asarray(out.vertices[0], np.float64) @ M[:3, :3].T + M[:3, 3]
        return v, vertex_normals(v, self.model.faces), omega @ M[:3, :3].T, pivot @ M[:3, :3].T + M[:3, 3]


def turn_axes(frames: np.ndarray, angles: np.ndarray, world: np.ndarray, parents: np.ndarray,
              free: np.ndarray) -> np.ndarray:
    """(n, 3) unit world axis (angular velocity per radian) of each free angle (flat index into (16, 3)):
    gesture_fit.angular_velocities' W_parent F Rz(bend) Ry(spread) e_x for a twist, W_parent F Rz(bend) e_y for a
    spread, W_parent F e_z for a bend, in closed form for all at once. frames (16, 3, 3), angles (16, 3) radians,
    world (16, 3, 3) the posed joints' world rotations."""
    joints, axes = np.divmod(np.asarray(free), 3)
    s, b = angles[joints, 1], angles[joints, 2]
    local = np.zeros((len(joints), 3))
    twist, spread, bend = axes == 0, axes == 1, axes == 2
    local[twist] = np.stack([np.cos(b) * np.cos(s), np.sin(b) * np.cos(s), -np.sin(s)], 1)[twist]
    local[spread] = np.stack([-np.sin(b), np.cos(b), np.zeros_like(b)], 1)[spread]
    local[bend, 2] = 1.0
    return np.einsum("nab,nbc,nc->na", world[parents[joints]], frames[joints], local)


def near_digits(vertex_joint: np.ndarray, vertices: np.ndarray, other: np.ndarray, reach: float) -> list[int]:
    """The joints (ids) of the digits (MANO's chains, wrist excluded) that own a vertex of `vertices` (V, 3) within
    `reach` (m) of the point set `other` (M, 3) (vertex_joint (V,): each vertex's dominant joint)."""
    near = np.isfinite(cKDTree(other).query(vertices, distance_upper_bound=reach)[0])
    owners = set(vertex_joint[near].tolist())
    return [j for chain in FINGER_JOINTS.values() if owners & set(chain) for j in chain]


def angle_rows(p: np.ndarray, u: np.ndarray, share: np.ndarray, omega: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """(K, n) derivative of u . p per free angle: points p (K, 3) m, unit directions u (K, 3), their skinning share
    (K, n) of each angle's joint subtree, angular velocities omega (n, 3) and pivots (n, 3): s (w x (p - J)) . u,
    written (p x u) . w - u . (w x J)."""
    return share * (np.cross(p, u) @ omega.T - u @ np.cross(omega, pivot).T)


def digit_changes(hands, deltas) -> tuple[float, float]:
    """(max, mean) |change| in degrees over the free angles of `hands` (DigitHand or None) by `deltas`."""
    moved = [np.abs(d) for h, d in zip(hands, deltas) if h is not None and len(d)]
    if not moved:
        return 0.0, 0.0
    every = np.rad2deg(np.concatenate(moved))
    return float(every.max()), float(every.mean())


def nearest_share(tree: cKDTree, share: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(K, n) the skinning share of the vertex nearest each point (K, 3) (`tree` over the hand's vertices)."""
    return share[tree.query(points)[1]]


def solve_bounds(rigid_lim: np.ndarray, hands) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the stacked variables (rigid 6, then each fitted hand's free angles)."""
    lo = [-rigid_lim] + [h.lo for h in hands if h is not None]
    hi = [rigid_lim] + [h.hi for h in hands if h is not None]
    return np.concatenate(lo), np.concatenate(hi)


def split(y: np.ndarray, hands) -> tuple[np.ndarray, list[np.ndarray]]:
    """(rigid x (6,), per hand its angle changes (n,) (empty for a held hand)) from the stacked variables."""
    out, at = [], 6
    for h in hands:
        n = 0 if h is None else len(h.free)
        out.append(y[at:at + n])
        at += n
    return y[:6], out


def least_squares_fit(evaluate, y0: np.ndarray, lo: np.ndarray, hi: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """The bounded trust-region solve of `evaluate` (y -> (residuals, Jacobian)) from y0."""
    return least_squares(lambda y: evaluate(y)[0], np.clip(y0, lo, hi), jac=lambda y: evaluate(y)[1],
                         bounds=(lo, hi), method="trf", x_scale=scale, max_nfev=MAX_NFEV, xtol=1e-5,
                         ftol=1e-5).x
