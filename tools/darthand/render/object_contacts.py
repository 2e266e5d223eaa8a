"""Where a hand touches a held object: the hand's vertices within CONTACT_M of the object's closed mesh or inside it,
the nearest object point of each, and how deep the hand passes into the object.

Distances are exact point-to-triangle distances (render/contacts.surface_distance); inside is the generalised winding
number above one half (render/contacts.winding_number; the object's mesh is closed and outward-wound, so this holds
everywhere). Only hand vertices inside the object's bounding box grown by CONTACT_M can touch it, so only those are
measured. The nearest points (closest point on a triangle: Ericson, Real-Time Collision Detection, 5.1.5) are
computed for the contact vertices only.

Units: metres; points in the object's frame unless said otherwise.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from darthand.render.contacts import CONTACT_M, clusters, surface_distance, winding_number

CHUNK = 64                 # points per closest-point batch (a batch holds CHUNK x F triangle tests)
_CLUSTERS: dict = {}


class ObjectContacts(NamedTuple):
    """hand_vertices (K,) int64 sorted ids; object_points (K, 3) float64 the nearest object point of each (object
    frame); penetration_max_m: the deepest hand vertex inside the object (0 when none is)."""

    hand_vertices: np.ndarray
    object_points: np.ndarray
    penetration_max_m: float


def object_contacts(hand_vertices: np.ndarray, item, placement: np.ndarray,
                    within: float = CONTACT_M) -> ObjectContacts:
    """The contacts of a hand (its vertices (N, 3), world) with the object `item` (objects/loader.ObjectItem) at
    `placement` (4, 4) object frame -> world."""
    P = np.asarray(placement, np.float64)
    local = (np.asarray(hand_vertices, np.float64) - P[:3, 3]) @ P[:3, :3]
    vertices = np.asarray(item.vertices, np.float64)
    lo, hi = vertices.min(axis=0) - within, vertices.max(axis=0) + within
    near = np.flatnonzero(((local >= lo) & (local <= hi)).all(axis=1))
    if not len(near):
        return ObjectContacts(np.zeros(0, np.int64), np.zeros((0, 3)), 0.0)
    mesh = _clusters(item)
    distance = surface_distance(local[near], mesh)
    inside = winding_number(local[near], mesh) > 0.5
    touching = (distance <= within) | inside
    ids = near[touching]
    points, _ = closest_points(local[ids], vertices[np.asarray(item.faces, np.int64)])
    depth = float(distance[inside].max()) if inside.any() else 0.0
    return ObjectContacts(ids.astype(np.int64), points, depth)


def _clusters(item):
    """render/contacts.Clusters of an item's closed mesh, built once per item."""
    key = (item.id, id(item.vertices))
    if key not in _CLUSTERS:
        _CLUSTERS[key] = clusters(np.asarray(item.vertices, np.float64)[np.asarray(item.faces, np.int64)])
    return _CLUSTERS[key]


def closest_points(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N, 3) the nearest point on any triangle (F, 3, 3) to each point (N, 3), (N,) its distance)."""
    points = np.asarray(points, np.float64)
    out, dist = np.zeros_like(points), np.zeros(len(points))
    for s in range(0, len(points), CHUNK):
        p = points[s:s + CHUNK]
        q = closest_on_triangles(p[:, None, :], triangles[None])          # (n, F, 3)
        d = np.linalg.norm(q - p[:, None, :], axis=2)
        best = d.argmin(axis=1)
        out[s:s + CHUNK] = q[np.arange(len(p)), best]
        dist[s:s + CHUNK] = d[np.arange(len(p)), best]
    return out, dist


def closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(..., 3) the closest point to p (..., 3) on the triangle tri (..., 3, 3) (broadcast), by Voronoi regions."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    ab, ac, ap = b - a, c - a, p - a
    dot = lambda x, y: (x * y).sum(-1)
    d1, d2 = dot(ab, ap), dot(ac, ap)
    bp = p - b
    d3, d4 = dot(ab, bp), dot(ac, bp)
    cp = p - c
    d5, d6 = dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 / (va + vb + vc)
        v, w = vb * denom, vc * denom
        inner = a + ab * v[..., None] + ac * w[..., None]
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    edge = lambda start, vec, t: start + vec * np.nan_to_num(t)[..., None]
    # Regions in Ericson's order: each later test applies only where the earlier ones did not.
    regions = [
        ((d1 <= 0) & (d2 <= 0), a),
        ((d3 >= 0) & (d4 <= d3), b),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), edge(a, ab, t_ab)),
        ((d6 >= 0) & (d5 <= d6), c),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), edge(a, ac, t_ac)),
        ((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), edge(b, c - b, t_bc)),
    ]
    out = inner
    for where, value in reversed(regions):
        out = np.where(where[..., None], value, out)
    return out
