"""Independent truth for the grasp tests: exact signed distances to a closed mesh by brute force, trimesh's exact
point-triangle closest points over every face (trimesh's `proximity.signed_distance` needs rtree, which the project
does not install) and the sign from the generalised winding number (Van Oosterom and Strackee's solid angle)."""

from __future__ import annotations

import numpy as np
import trimesh


def winding_numbers(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P,) generalised winding number of each point (1 inside a closed outward mesh, 0 outside)."""
    out = np.zeros(len(points))
    for s in range(0, len(points), 256):
        a, b, c = (vertices[faces[:, k]][None] - points[s:s + 256, None] for k in range(3))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = np.einsum("pfd,pfd->pf", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("pfd,pfd->pf", a, b) * lc + np.einsum("pfd,pfd->pf", b, c) * la
               + np.einsum("pfd,pfd->pf", c, a) * lb)
        out[s:s + 256] = np.arctan2(det, den).sum(1) / (2 * np.pi)
    return out


def signed_distances(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P,) exact signed distance (m, negative inside) of points (P, 3) to the closed mesh (its zero-area faces,
    which bound nothing, left out)."""
    tris = vertices[faces]
    faces = faces[np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]), axis=1) > 1e-14]
    tris = vertices[faces]
    d = np.empty(len(points))
    for i, p in enumerate(points):
        near = trimesh.triangles.closest_point(tris, np.repeat(p[None], len(tris), 0))
        d[i] = np.linalg.norm(near - p, axis=1).min()
    return np.where(winding_numbers(vertices, faces, points) > 0.5, -d, d)
