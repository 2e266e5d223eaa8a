"""Accessory rules.

    acc.binding      an accessory is rigidly bound to exactly one joint (USD: constant-interpolation joint
                     influence; glTF: a child node of a joint node) or skinned per point (gloves)
    acc.bad-joint    the rigid joint is one the skeleton has
    acc.distance     at rest, the accessory's closest point is within MAX_GAP of the hand surface (an accessory the
                     fitting put on the hand touches it; one 5 cm away was moved or exported in the wrong frame)
    acc.unknown-id   accessory ids the package records are in the accessory catalogue (catalogs.py)
"""

from __future__ import annotations

import numpy as np

from darthand.validate.asset import Mesh, Package
from darthand.validate.catalogs import known_accessory_ids
from darthand.validate.findings import Finding, finding

MAX_GAP = 0.005          # metres
CANDIDATES = 256         # accessory points whose exact surface distance is computed


def check_accessories(pkg: Package) -> list[Finding]:
    out: list[Finding] = []
    hand = next((m for m in pkg.hand_meshes if m.layout_ok), None)
    num_joints = len(pkg.skeletons[0].names) if pkg.skeletons else 16
    tree = hand_tree(hand)
    for acc in pkg.accessories:
        out += check_binding(acc, num_joints)
        if tree is not None and acc.layout_ok:
            out += check_distance(acc, hand, tree)
    return out + check_ids(pkg)


def hand_tree(hand: Mesh | None):
    """A k-d tree of the hand's points (None when there is no usable hand surface)."""
    if hand is None or not hand.faces.size or not np.isfinite(hand.points).all() or hand.faces.min() < 0 or \
            hand.faces.max() >= len(hand.points):
        return None
    from scipy.spatial import cKDTree
    return cKDTree(hand.points)


def check_binding(acc: Mesh, num_joints: int) -> list[Finding]:
    label = f"accessory {acc.accessory_id!r}" if acc.accessory_id else "the accessory"
    if acc.skin is not None and (acc.skin.broken or not acc.skin.rigid):
        return []       # skinned (a glove): its influences are checked by the rig rules
    if acc.skin is not None:
        used = np.unique(acc.skin.indices[acc.skin.weights != 0])
        joints = used if len(used) else np.unique(acc.skin.indices)
    elif acc.rigid_joint is not None:
        joints = np.array([acc.rigid_joint])
    else:
        return [finding("acc.binding", acc.path, f"{label} is neither bound to a joint nor skinned")]
    if len(joints) != 1:
        return [finding("acc.binding", acc.path, f"{label} is rigidly bound to {len(joints)} joints "
                        f"({', '.join(map(str, joints[:5]))}), not one")]
    j = int(joints[0])
    if not 0 <= j < num_joints:
        return [finding("acc.bad-joint", acc.path, f"{label} is bound to joint {j}; the skeleton has joints "
                        f"0..{num_joints - 1}")]
    return []


def check_distance(acc: Mesh, hand: Mesh, tree) -> list[Finding]:
    label = f"accessory {acc.accessory_id!r}" if acc.accessory_id else "the accessory"
    pts = acc.points[np.isfinite(acc.points).all(axis=1)]
    if not len(pts):
        return []
    near = tree.query(pts, k=1)[0]
    if near.min() <= MAX_GAP:
        return []      # a surface point is at least as close as the nearest vertex
    gap = surface_gap(pts, hand.points, hand.faces, near)
    if gap > MAX_GAP:
        return [finding("acc.distance", acc.path, f"{label} is {gap * 1000:.1f} mm from the hand surface at rest "
                        f"(at most {MAX_GAP * 1000:.0f} mm)")]
    return []


def check_ids(pkg: Package) -> list[Finding]:
    if not pkg.accessory_ids:
        return []
    known, source = known_accessory_ids(pkg.root, pkg.side)
    return [finding("acc.unknown-id", where, f"accessory id {aid!r} is not in {source}")
            for aid, where in pkg.accessory_ids if aid not in known]


# ------------------------------------------------------------------------------------------------ distances


def surface_gap(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, near: np.ndarray | None = None) -> float:
    """Smallest distance (m) from `points` (P, 3) to the triangle surface (vertices (V, 3), faces (F, 3)).

    Exact for the points that can attain it: a point's surface distance lies between its nearest-vertex distance
    (`near`, (P,), computed when not given) minus the longest edge and that distance, so only the points within one
    longest edge of the best nearest-vertex distance (at most CANDIDATES of them) are measured against every
    triangle.
    """
    near = nearest_vertex_distance(points, vertices) if near is None else near
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    longest = float(np.sqrt(max((np.einsum("ij,ij->i", e, e).max() for e in (b - a, c - b, a - c)))))
    candidates = np.flatnonzero(near <= near.min() + longest)
    candidates = candidates[np.argsort(near[candidates])[:CANDIDATES]]
    # A candidate's closest surface point is within its nearest-vertex distance of it, so only triangles whose
    # bounding box meets the candidates' box grown by that much can hold it.
    p = points[candidates]
    lo, hi = p.min(axis=0) - near[candidates].max(), p.max(axis=0) + near[candidates].max()
    tri_lo, tri_hi = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    close = np.flatnonzero(((tri_hi >= lo) & (tri_lo <= hi)).all(axis=1))
    a, b, c = a[close], b[close], c[close]
    step = max(1, 2_000_000 // max(1, len(close)))          # keep the (P, F, 3) temporaries near 50 MB
    best = min((point_triangle_distance(p[s:s + step], a, b, c).min() for s in range(0, len(p), step)),
               default=np.inf)
    return float(min(best, near.min()))


def nearest_vertex_distance(points: np.ndarray, vertices: np.ndarray, chunk: int = 1024) -> np.ndarray:
    """(P,) distance of each point to its nearest vertex (brute force in chunks, for a one-off query)."""
    out = np.empty(len(points))
    vv = np.einsum("ij,ij->i", vertices, vertices)
    for s in range(0, len(points), chunk):
        p = points[s:s + chunk]
        d2 = np.einsum("ij,ij->i", p, p)[:, None] - 2.0 * p @ vertices.T + vv[None, :]
        out[s:s + chunk] = np.sqrt(np.maximum(d2.min(axis=1), 0.0))
    return out


def point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(P, F) distances from points p (P, 3) to triangles (a, b, c) (F, 3 each): the distance to the plane where
    the projection falls inside the triangle, else to the nearest edge."""
    p = p[:, None, :]
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("pfi,fi->pf", v2, v0), np.einsum("pfi,fi->pf", v2, v1)
    denom = d00 * d11 - d01 * d01
    with np.errstate(divide="ignore", invalid="ignore"):
        v = (d11 * d20 - d01 * d21) / denom
        w = (d00 * d21 - d01 * d20) / denom
        inside = (v >= 0) & (w >= 0) & (v + w <= 1) & (denom > 0)
        normal = np.cross(v0, v1)
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        plane = np.abs(np.einsum("pfi,fi->pf", v2, normal))
    best = np.where(inside, plane, np.inf)
    for s, e in ((a, b), (b, c), (c, a)):
        best = np.minimum(best, segment_distance(p, s, e))
    return best


def segment_distance(p: np.ndarray, s: np.ndarray, e: np.ndarray) -> np.ndarray:
    """(P, F) distances from points p (P, 1, 3) to the segments s -> e (F, 3)."""
    d = e - s
    dd = np.einsum("ij,ij->i", d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.einsum("pfi,fi->pf", p - s, d) / dd, 0.0, 1.0)
    t = np.nan_to_num(t)
    return np.linalg.norm(p - (s + t[..., None] * d), axis=-1)
