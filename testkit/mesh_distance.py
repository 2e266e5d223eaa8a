"""Distances from points to a triangle mesh, computed from the triangles' closed forms (no renderer code): what the
tests and benchmarks compare a subdivided surface with its control mesh by."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def point_triangle_distance(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(M,) distances (the points' units) of points p (M, 3) to triangles tri (M, 3, 3): the nearest of the
    triangle's inside (where the projection onto its plane falls in it) and its three edges."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    plane = np.einsum("ij,ij->i", p - a, n)
    q = p - plane[:, None] * n
    inside = np.ones(len(p), bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, q - u), n) >= 0
    best = np.where(inside, np.abs(plane), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        t = np.clip(np.einsum("ij,ij->i", p - u, v - u) / np.einsum("ij,ij->i", v - u, v - u), 0, 1)
        best = np.minimum(best, np.linalg.norm(p - (u + t[:, None] * (v - u)), axis=1))
    return best


def distance_to_mesh(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, candidates: int = 24) -> np.ndarray:
    """(M,) distance of each point (M, 3) to the mesh (vertices (N, 3), faces (F, 3)): the nearest of its
    `candidates` faces nearest by centroid (exact for points near a mesh of even triangles)."""
    points, vertices = np.asarray(points, np.float64), np.asarray(vertices, np.float64)
    _, near = cKDTree(vertices[faces].mean(axis=1)).query(points, candidates)
    d = np.stack([point_triangle_distance(points, vertices[faces[near[:, k]]]) for k in range(candidates)])
    return d.min(axis=0)
