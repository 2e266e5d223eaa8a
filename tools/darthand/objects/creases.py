"""Normals for drawing a closed mesh: smooth across gentle bends, split where faces meet at a crease, so a box or a
card is drawn with flat sides and a bottle smooth."""

from __future__ import annotations

import numpy as np


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit normals (F, 3), areas (F,)) of counter-clockwise triangles; degenerate faces get a zero normal."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(cross, axis=1)
    unit = np.divide(cross, length[:, None], out=np.zeros_like(cross), where=length[:, None] > 0)
    return unit, 0.5 * length


def split_at_creases(vertices: np.ndarray, faces: np.ndarray,
                     crease_deg: float = 35.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (n, 3), faces (f, 3), normals (n, 3)) for drawing `faces` (a subset of a mesh's triangles).

    Each face corner's normal is the area-weighted mean of the normals of the faces around its vertex that turn
    from this corner's face by at most `crease_deg` degrees; corners of one vertex with equal normals share a drawn
    vertex, others get their own (a box's corner becomes three vertices, a smooth bottle's stay one)."""
    unit, area = face_normals(vertices, faces)
    corner_vertex = faces.ravel()
    corner_face = np.repeat(np.arange(len(faces)), 3)
    order = np.argsort(corner_vertex, kind="stable")
    sorted_vertex = corner_vertex[order]
    starts = np.flatnonzero(np.r_[True, sorted_vertex[1:] != sorted_vertex[:-1]])
    sizes = np.diff(np.r_[starts, len(order)])
    group = np.repeat(np.arange(len(starts)), sizes)               # each sorted corner's vertex group
    # every pair (corner, corner of the same vertex): sum(size^2) pairs
    reps = sizes[group]
    first = np.repeat(np.arange(len(order)), reps)
    offset = np.arange(len(first)) - np.repeat(np.cumsum(reps) - reps, reps)
    second = starts[group[first]] + offset
    fa, fb = corner_face[order[first]], corner_face[order[second]]
    near = np.einsum("ij,ij->i", unit[fa], unit[fb]) >= np.cos(np.radians(crease_deg)) - 1e-9
    summed = np.zeros((len(order), 3))
    np.add.at(summed, first[near], (unit[fb] * area[fb, None])[near])
    corner_normal = np.empty((len(order), 3))
    corner_normal[order] = summed
    corner_normal = _normalised(corner_normal, unit[corner_face])
    key = np.column_stack([corner_vertex, np.round(corner_normal * 1e5).astype(np.int64)])
    uniq, first_corner, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    new_vertices = vertices[corner_vertex[first_corner]]
    new_normals = corner_normal[first_corner]
    return new_vertices, inverse.reshape(-1, 3).astype(np.int64), new_normals


def _normalised(n: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-20, n / np.maximum(length, 1e-300), fallback)
