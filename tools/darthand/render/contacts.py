"""Where two hands touch: the vertices of one hand within CONTACT_M of the other's surface, or inside it.

The distance is a point's exact distance to the nearest triangle (closest point on a triangle: the region tests
of Ericson, Real-Time Collision Detection, 5.1.5), computed only for vertices whose nearest vertex of the other mesh
is close enough that a triangle could be within reach (a triangle's points lie within its longest edge of one of
its corners). Inside is the generalised winding number (Jacobson et al. 2013: the sum of the solid angles of the
triangles seen from the point, over 4 pi) above one half, which holds for a hand mesh open at its wrist cut.

Units: metres; vertices (N, 3), faces (F, 3) int.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

CONTACT_M = 0.003
_CHUNK = 64               # points per batch of the (points x triangles) computations


def contact_vertices(vertices: np.ndarray, other_vertices: np.ndarray, other_faces: np.ndarray,
                     within: float = CONTACT_M) -> np.ndarray:
    """(K,) sorted int64 ids of `vertices` (N, 3) within `within` metres of the mesh (other_vertices (M, 3),
    other_faces (F, 3)) or inside it."""
    points = np.asarray(vertices, np.float64)
    mesh_v = np.asarray(other_vertices, np.float64)
    faces = np.asarray(other_faces, np.int64)
    triangles = mesh_v[faces]
    longest = float(np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max())
    nearest, _ = cKDTree(mesh_v).query(points)
    near = np.flatnonzero(nearest <= within + longest)
    touching = near[surface_distance(points[near], triangles) <= within]
    inside = np.flatnonzero(winding_number(points, triangles) > 0.5)
    return np.union1d(touching, inside).astype(np.int64)


def surface_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N,) each point's (N, 3) distance to the nearest of `triangles` (F, 3, 3)."""
    out = np.empty(len(points))
    for s in range(0, len(points), _CHUNK):
        p = points[s:s + _CHUNK, None, :]
        out[s:s + _CHUNK] = np.linalg.norm(p - closest_points(p, triangles), axis=2).min(axis=1)
    return out


def closest_points(p: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N, F, 3) the closest point of each triangle (F, 3, 3) to each point p (N, 1, 3) (Ericson's regions: a
    corner, an edge or the face's interior)."""
    a, b, c = triangles[None, :, 0], triangles[None, :, 1], triangles[None, :, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp, cp = p - b, p - c
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    safe = lambda x: np.where(np.abs(x) > 1e-30, x, 1e-30)
    v = vb / safe(denom)
    w = vc / safe(denom)
    out = a + ab * v[..., None] + ac * w[..., None]                   # the interior, overwritten below
    on_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
    t_bc = (d4 - d3) / safe((d4 - d3) + (d5 - d6))
    out = np.where(on_bc[..., None], b + (c - b) * t_bc[..., None], out)
    on_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
    out = np.where(on_ac[..., None], a + ac * (d2 / safe(d2 - d6))[..., None], out)
    on_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
    out = np.where(on_ab[..., None], a + ab * (d1 / safe(d1 - d3))[..., None], out)
    out = np.where(((d6 >= 0) & (d5 <= d6))[..., None], c, out)
    out = np.where(((d3 >= 0) & (d4 <= d3))[..., None], b, out)
    return np.where(((d1 <= 0) & (d2 <= 0))[..., None], a, out)


def winding_number(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N,) the generalised winding number of the triangles (F, 3, 3) (outward-facing counter-clockwise) at each
    point (N, 3): about 1 inside a closed mesh, 0 outside (Van Oosterom and Strackee's solid angle per triangle)."""
    out = np.empty(len(points))
    for s in range(0, len(points), _CHUNK):
        r = triangles[None] - points[s:s + _CHUNK, None, None, :]          # (n, F, 3, 3)
        a, b, c = r[:, :, 0], r[:, :, 1], r[:, :, 2]
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        det = _dot(a, np.cross(b, c))
        div = la * lb * lc + _dot(a, b) * lc + _dot(b, c) * la + _dot(c, a) * lb
        out[s:s + _CHUNK] = 2 * np.arctan2(det, div).sum(axis=1) / (4 * np.pi)
    return out


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.einsum("...k,...k->...", x, y)
