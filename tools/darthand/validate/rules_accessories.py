"""Accessory rules.

    acc.binding      an accessory is rigidly bound to exactly one joint (USD: constant-interpolation, or per-point
                     with every point on one joint at weight 1,
                     influence; glTF: a child node of a joint node) or skinned per point (gloves)
    acc.bad-joint    the rigid joint is one the skeleton has
    acc.distance     at rest, the accessory's closest point is within MAX_GAP of the hand surface (an accessory the
                     fitting put on the hand touches it; one 5 cm away was moved or exported in the wrong frame)
    acc.unknown-id   accessory ids the package records are in the accessory catalogue (catalogs.py)
"""

from __future__ import annotations

import numpy as np

from darthand.accessories.collide import surface_distance, surface_trees
from darthand.validate.asset import Mesh, Package
from darthand.validate.catalogs import known_accessory_ids
from darthand.validate.findings import Finding, finding

MAX_GAP = 0.005          # metres


def check_accessories(pkg: Package) -> list[Finding]:
    out: list[Finding] = []
    hand = next((m for m in pkg.hand_meshes if m.layout_ok), None)
    num_joints = len(pkg.skeletons[0].names) if pkg.skeletons else 16
    trees = hand_trees(hand)
    for acc in pkg.accessories:
        out += check_binding(acc, num_joints)
        if trees is not None and hand is not None and acc.layout_ok:
            out += check_distance(acc, hand, trees)
    return out + check_ids(pkg)


def hand_trees(hand: Mesh | None):
    """accessories.collide.surface_trees of the hand (None when there is no usable hand surface)."""
    if hand is None or not hand.faces.size or not np.isfinite(hand.points).all() or hand.faces.min() < 0 or \
            hand.faces.max() >= len(hand.points):
        return None
    return surface_trees(hand.points[hand.faces])


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


def check_distance(acc: Mesh, hand: Mesh, trees) -> list[Finding]:
    label = f"accessory {acc.accessory_id!r}" if acc.accessory_id else "the accessory"
    pts = acc.points[np.isfinite(acc.points).all(axis=1)]
    if not len(pts):
        return []
    if trees[0].query(pts, k=1)[0].min() <= MAX_GAP:
        return []      # a surface point is at least as close as the nearest vertex
    gap = float(surface_distance(pts, hand.points, hand.faces, trees).min())
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
