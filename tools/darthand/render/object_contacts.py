"""Where a hand touches a held object: the hand's vertices within CONTACT_M of the object's closed mesh or inside it,
the nearest object point of each, and how deep the hand passes into the object.

Distances and nearest points are exact (render/contacts.nearest_surface_points: the closest point on a triangle,
Ericson, Real-Time Collision Detection, 5.1.5); inside is the generalised winding number above one half
(render/contacts.winding_number; the object's mesh is closed and outward-wound, so this holds everywhere). Only hand
vertices inside the object's bounding box grown by CONTACT_M can touch it, so only those are measured.

Units: metres; points in the object's frame unless said otherwise.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from darthand.render.contacts import CONTACT_M, clusters, nearest_surface_points, winding_number

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
    nearest, distance = nearest_surface_points(local[near], mesh)
    inside = winding_number(local[near], mesh) > 0.5
    touching = (distance <= within) | inside
    ids = near[touching]
    points = nearest[touching]
    depth = float(distance[inside].max()) if inside.any() else 0.0
    return ObjectContacts(ids.astype(np.int64), points, depth)


def _clusters(item):
    """render/contacts.Clusters of an item's closed mesh, built once per item."""
    entry = _CLUSTERS.get(item.id)
    if entry is None or entry[0] is not item.vertices:          # a catalogue read again: its arrays are new
        entry = _CLUSTERS[item.id] = (item.vertices, clusters(np.asarray(item.vertices, np.float64)
                                                              [np.asarray(item.faces, np.int64)]))
    return entry[1]
