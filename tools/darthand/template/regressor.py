"""A sparse, non-negative joint regressor fitted to known joint centres.

For each joint, the candidate vertices form a ring around it: surface vertices of the two segments that meet at the
joint (its own and its parent's, judged by their dominant skin weight; palm vertices are handed to the nearest
finger root) lying in a thin slab through the joint across the bone, within a radius. Non-negative weights over that
ring that sum to one and reproduce the joint centre are found by NNLS (scipy.optimize.nnls) with a small ridge term
that spreads the weight around the ring. A convex combination of a ring around the joint stays inside the finger when
the mesh is posed, which is what keeps regressed joints of posed meshes (and of shaped ones) where they belong.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.optimize import nnls

from darthand.errors import DarthandError
from darthand.model.layout import FINGER_JOINTS, MANO_PARENTS, NUM_JOINTS

ROOTS = (0,) + tuple(chain[0] for chain in FINGER_JOINTS.values())  # the wrist and the five finger roots
MM = 1000.0  # the fit runs in millimetres
DEEP = (0, FINGER_JOINTS["thumb"][0])  # wrist and thumb CMC: far from the skin


def fit_regressor(vertices: np.ndarray, weights: np.ndarray, joints: np.ndarray, tips: np.ndarray,
                  tolerance: float = 0.1e-3, ridge: float = 1.0, prune: float = 1e-3,
                  slab: float = 2.5e-3, radius: float = 0.02, deep_radius: float = 0.045) -> tuple[sp.csr_matrix, dict]:
    """(16, V) CSR regressor R with R @ vertices ~= joints, and a report.

    vertices (V, 3) m; weights (V, 16) skin weights; joints (16, 3) m, the target centres in MANO order; tips (5, 3)
    fingertip points in FINGERS order (thumb, index, middle, ring, pinky), which give the last bone's direction.
    tolerance: largest accepted reproduction error (m); the slab (half-thickness, m) widens until it is met.
    ridge: weight of |w|^2 relative to the joint-position residual in mm^2; prune: weights below it are dropped and
    the rest refitted. radius: farthest candidate vertex from a finger joint (m); deep_radius: the same for the
    wrist and the thumb's CMC joint (thumb1), which lie 1-1.5 cm under the skin.
    The report holds the error (mm), slab (mm) and number of vertices of every joint.
    """
    owner = dominant_segment(vertices, weights, joints)
    axes = joint_axes(joints, tips)
    rows, cols, vals, report = [], [], [], {}
    for j in range(NUM_JOINTS):
        r_max = deep_radius if j in DEEP else radius
        # A root's ring is its own segment plus its share of the palm; any other joint's ring spans the two
        # segments meeting at it.
        members = owner == j if j in ROOTS else np.isin(owner, (j, MANO_PARENTS[j]))
        dist = np.linalg.norm(vertices - joints[j], axis=1)
        along = np.abs((vertices - joints[j]) @ axes[j])
        half = slab
        while True:
            cand = np.nonzero(members & (dist < r_max) & (along < half))[0]
            w, err = solve_ring(vertices[cand], joints[j], ridge, prune)
            if err <= tolerance or half > r_max:
                break
            half *= 1.5
        if err > tolerance:
            raise DarthandError(f"joint regressor: joint {j} cannot be reproduced within {tolerance * MM:.2f} mm "
                                f"by its ring of vertices (error {err * MM:.3f} mm)")
        keep = w > 0
        rows += [j] * int(keep.sum())
        cols += cand[keep].tolist()
        vals += w[keep].tolist()
        report[j] = {"error_mm": float(err * MM), "slab_mm": float(half * MM), "vertices": int(keep.sum())}
    regressor = sp.csr_matrix((vals, (rows, cols)), shape=(NUM_JOINTS, len(vertices)))
    return regressor, report


def solve_ring(points: np.ndarray, target: np.ndarray, ridge: float, prune: float) -> tuple[np.ndarray, float]:
    """Non-negative weights (k,) over `points` (k, 3) summing to one with weights @ points ~= target; and the
    remaining error (m). Minimises |P^T w - t|^2 (mm^2) + ridge |w|^2 with the sum held by a stiff extra row."""
    if len(points) < 4:
        return np.zeros(len(points)), np.inf
    w = _nnls(points, target, ridge)
    small = w < prune
    if small.any() and (~small).sum() >= 4:
        w = np.zeros(len(points))
        w[~small] = _nnls(points[~small], target, ridge)
    err = float(np.linalg.norm(w @ points - target))
    return w, err


def _nnls(points: np.ndarray, target: np.ndarray, ridge: float) -> np.ndarray:
    k = len(points)
    stiff = 1e3  # sum-to-one row weight: makes the regressor translation-equivariant
    A = np.vstack([points.T * MM, stiff * np.ones((1, k)), np.sqrt(ridge) * np.eye(k)])
    b = np.concatenate([target * MM, [stiff], np.zeros(k)])
    w, _ = nnls(A, b, maxiter=50 * k)
    return w / w.sum()


def dominant_segment(vertices: np.ndarray, weights: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(V,) segment of each vertex: its dominant joint, except that wrist-dominated (palm) vertices go to the
    nearest of the wrist and the five finger roots, so each finger root gets its own share of the palm."""
    owner = np.argmax(weights, axis=1)
    palm = owner == 0
    roots = np.array(ROOTS)
    d = np.linalg.norm(vertices[palm, None, :] - joints[None, roots, :], axis=2)
    owner[palm] = roots[np.argmin(d, axis=1)]
    return owner


def joint_axes(joints: np.ndarray, tips: np.ndarray) -> np.ndarray:
    """(16, 3) unit normal of each joint's slab: the bisector of the bone into the joint and the bone out of it
    (the wrist uses the direction toward the middle finger's root)."""
    child = {int(MANO_PARENTS[j]): j for j in range(1, NUM_JOINTS) if MANO_PARENTS[j] != 0}
    tip_of = {chain[2]: k for k, chain in enumerate(FINGER_JOINTS.values())}
    axes = np.zeros((NUM_JOINTS, 3))
    axes[0] = _unit(joints[FINGER_JOINTS["middle"][0]] - joints[0])
    for j in range(1, NUM_JOINTS):
        into = _unit(joints[j] - joints[MANO_PARENTS[j]])
        nxt = joints[child[j]] if j in child else tips[tip_of[j]]
        axes[j] = _unit(into + _unit(nxt - joints[j]))
    return axes


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)
