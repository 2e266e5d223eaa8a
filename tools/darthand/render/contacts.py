"""Where two hands touch: the vertices of one hand within CONTACT_M of the other's surface, or inside it.

The distance is a point's exact distance to the nearest triangle (closest point on a triangle: the region tests
of Ericson, Real-Time Collision Detection, 5.1.5). Inside is the generalised winding number (Jacobson et al. 2013:
the sum of the solid angles of the triangles seen from the point, over 4 pi) above one half, which holds for a hand
mesh open at its wrist cut. Only points that can be near or inside are measured: the distance for those whose nearest
vertex of the other mesh is within the distance plus its longest edge (a triangle's points lie within its longest
edge of a corner), the winding number for those within INSIDE_REACH_M of a vertex (no point inside a hand, its
forearm stump included, is farther than that from its surface).

Units: metres; vertices (N, 3), faces (F, 3) int; float64 throughout.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from darthand.jit import kernel

CONTACT_M = 0.003
INSIDE_REACH_M = 0.04


def contact_vertices(vertices: np.ndarray, other_vertices: np.ndarray, other_faces: np.ndarray,
                     within: float = CONTACT_M) -> np.ndarray:
    """(K,) sorted int64 ids of `vertices` (N, 3) within `within` metres of the mesh (other_vertices (M, 3),
    other_faces (F, 3)) or inside it."""
    points = np.asarray(vertices, np.float64)
    mesh_v = np.asarray(other_vertices, np.float64)
    triangles = np.ascontiguousarray(mesh_v[np.asarray(other_faces, np.int64)])
    longest = float(np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max())
    nearest, _ = cKDTree(mesh_v).query(points, distance_upper_bound=max(within + longest, INSIDE_REACH_M))
    near = np.flatnonzero(nearest <= within + longest)
    reach = np.flatnonzero(nearest <= INSIDE_REACH_M)
    touching = near[surface_distance(points[near], triangles) <= within]
    inside = reach[winding_number(points[reach], triangles) > 0.5]
    return np.union1d(touching, inside).astype(np.int64)


def surface_distance(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N,) each point's (N, 3) distance to the nearest of `triangles` (F, 3, 3)."""
    out = np.empty(len(points))
    _distance_kernel(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(triangles, np.float64), out)
    return out


def winding_number(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(N,) the generalised winding number of the triangles (F, 3, 3) (outward-facing counter-clockwise) at each
    point (N, 3): about 1 inside a closed mesh, 0 outside."""
    out = np.empty(len(points))
    _winding_kernel(np.ascontiguousarray(points, np.float64), np.ascontiguousarray(triangles, np.float64), out)
    return out


@kernel
def _distance_kernel(points, triangles, out):
    """out[i] = the distance of points[i] to the nearest triangle: per triangle (a, b, c) the closest point by
    Ericson's regions (a corner, an edge, or the interior from barycentric v, w), in scalars (no temporaries)."""
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        for f in range(triangles.shape[0]):
            ax, ay, az = triangles[f, 0, 0], triangles[f, 0, 1], triangles[f, 0, 2]
            abx, aby, abz = triangles[f, 1, 0] - ax, triangles[f, 1, 1] - ay, triangles[f, 1, 2] - az
            acx, acy, acz = triangles[f, 2, 0] - ax, triangles[f, 2, 1] - ay, triangles[f, 2, 2] - az
            apx, apy, apz = px - ax, py - ay, pz - az
            d1 = abx * apx + aby * apy + abz * apz
            d2 = acx * apx + acy * apy + acz * apz
            bpx, bpy, bpz = apx - abx, apy - aby, apz - abz          # p - b
            d3 = abx * bpx + aby * bpy + abz * bpz
            d4 = acx * bpx + acy * bpy + acz * bpz
            cpx, cpy, cpz = apx - acx, apy - acy, apz - acz          # p - c
            d5 = abx * cpx + aby * cpy + abz * cpz
            d6 = acx * cpx + acy * cpy + acz * cpz
            va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
            if d1 <= 0 and d2 <= 0:                                    # corner a
                v, w = 0.0, 0.0
            elif d3 >= 0 and d4 <= d3:                                 # corner b
                v, w = 1.0, 0.0
            elif vc <= 0 and d1 >= 0 and d3 <= 0:                      # edge ab
                v, w = d1 / (d1 - d3), 0.0
            elif d6 >= 0 and d5 <= d6:                                 # corner c
                v, w = 0.0, 1.0
            elif vb <= 0 and d2 >= 0 and d6 <= 0:                      # edge ac
                v, w = 0.0, d2 / (d2 - d6)
            elif va <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:            # edge bc
                w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
                v = 1.0 - w
            else:                                                      # the interior
                v, w = vb / (va + vb + vc), vc / (va + vb + vc)
            dx, dy, dz = apx - abx * v - acx * w, apy - aby * v - acy * w, apz - abz * v - acz * w
            d = dx * dx + dy * dy + dz * dz
            if d < best:
                best = d
        out[i] = np.sqrt(best)


@kernel
def _winding_kernel(points, triangles, out):
    """out[i] = the sum over triangles of their solid angle seen from points[i] over 4 pi (Van Oosterom and
    Strackee: tan(omega / 2) = a . (b x c) / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|), a, b, c the corners
    relative to the point), in scalars (no temporaries)."""
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        total = 0.0
        for f in range(triangles.shape[0]):
            ax, ay, az = triangles[f, 0, 0] - px, triangles[f, 0, 1] - py, triangles[f, 0, 2] - pz
            bx, by, bz = triangles[f, 1, 0] - px, triangles[f, 1, 1] - py, triangles[f, 1, 2] - pz
            cx, cy, cz = triangles[f, 2, 0] - px, triangles[f, 2, 1] - py, triangles[f, 2, 2] - pz
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
            div = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la
                   + (cx * ax + cy * ay + cz * az) * lb)
            total += 2.0 * np.arctan2(det, div)
        out[i] = total / (4.0 * np.pi)
