"""Where two hands touch: the vertices of one hand within CONTACT_M of the other's surface, or inside it.

The distance is a point's exact distance to the nearest triangle (closest point on a triangle: the region tests of
Ericson, Real-Time Collision Detection, 5.1.5). Inside is the generalised winding number (Jacobson et al. 2013: the
sum of the solid angles of the triangles seen from the point, over 4 pi) above one half, which holds for a hand mesh
open at its wrist cut. Both sums run over clusters of nearby triangles (`Clusters`): the distance skips a cluster
that cannot hold a nearer point (exact), the winding number counts a far one as its area vector (Barill et al.
2018's first-order far field). Only points that can be near or inside are measured: the distance for those whose
nearest vertex of the other mesh is within the distance plus its longest edge (a triangle's points lie within its
longest edge of a corner), the winding number for those within INSIDE_REACH_M of a vertex (no point inside a hand,
its forearm stump included, is farther than that from its surface).

Units: metres; vertices (N, 3), faces (F, 3) int; float64 throughout.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from darthand.jit import kernel

CONTACT_M = 0.003
INSIDE_REACH_M = 0.04
CLUSTER_SIZE = 16          # triangles per cluster (Clusters)
GROUP = 16                 # clusters per group (the winding number's far field, second level)
FAR_FIELD = 3.0            # a cluster counts as its area vector beyond this many of its radii


class Clusters(NamedTuple):
    """A mesh's triangles (F, 3, 3) float64 in cluster order, and per level (clusters of CLUSTER_SIZE, then groups of
    GROUP clusters) the boundaries (K + 1,) int64 of each cluster in that order, its area-weighted centre (K, 3), summed
    area vector (K, 3) and radius (K,) (the farthest corner from its centre)."""

    triangles: np.ndarray
    starts: np.ndarray
    centre: np.ndarray
    normal: np.ndarray
    radius: np.ndarray
    g_starts: np.ndarray
    g_centre: np.ndarray
    g_normal: np.ndarray
    g_radius: np.ndarray


def clusters(triangles: np.ndarray) -> Clusters:
    """The triangles (F, 3, 3) split by halving at the median of their centroids' longest extent until at most
    CLUSTER_SIZE are left in a part; the parts in depth-first order (neighbours in space are neighbours in it), a
    group every GROUP of them."""
    tri = np.asarray(triangles, np.float64)
    centroids, parts, done = tri.mean(axis=1), [np.arange(len(tri))], []
    while parts:
        ids = parts.pop()
        if len(ids) <= CLUSTER_SIZE:
            done.append(ids)
            continue
        axis = int(np.ptp(centroids[ids], axis=0).argmax())
        ranked = ids[np.argsort(centroids[ids, axis], kind="stable")]
        parts += [ranked[len(ranked) // 2:], ranked[:len(ranked) // 2]]
    tri = np.ascontiguousarray(tri[np.concatenate(done)] if done else tri)
    starts = np.cumsum([0] + [len(d) for d in done]).astype(np.int64)
    g_starts = np.unique(np.append(starts[::GROUP], starts[-1]))
    return Clusters(tri, *_cluster_fields(tri, starts), *_cluster_fields(tri, g_starts))


def _cluster_fields(tri: np.ndarray, starts: np.ndarray) -> tuple:
    """(starts, centres, area vectors, radii) of the clusters tri[starts[k]:starts[k + 1]]."""
    if len(tri) == 0:
        return starts, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    area = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    weight = np.linalg.norm(area, axis=1) + 1e-30
    first = starts[:-1]
    centre = np.add.reduceat(tri.mean(axis=1) * weight[:, None], first) / np.add.reduceat(weight, first)[:, None]
    member = np.repeat(np.arange(len(first)), np.diff(starts))
    corner = np.linalg.norm(tri - centre[member][:, None, :], axis=2).max(axis=1)
    return starts, centre, np.add.reduceat(area, first), np.maximum.reduceat(corner, first)


def contact_vertices(vertices: np.ndarray, other_vertices: np.ndarray, other_faces: np.ndarray,
                     within: float = CONTACT_M) -> np.ndarray:
    """(K,) sorted int64 ids of `vertices` (N, 3) within `within` metres of the mesh (other_vertices (M, 3),
    other_faces (F, 3)) or inside it."""
    points = np.asarray(vertices, np.float64)
    mesh_v = np.asarray(other_vertices, np.float64)
    triangles = mesh_v[np.asarray(other_faces, np.int64)]
    longest = float(np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=2).max())
    nearest, _ = cKDTree(mesh_v).query(points, distance_upper_bound=max(within + longest, INSIDE_REACH_M))
    near = np.flatnonzero(nearest <= within + longest)
    mesh = clusters(triangles)
    touching = near[surface_distance(points[near], mesh) <= within]
    reach = np.setdiff1d(np.flatnonzero(nearest <= INSIDE_REACH_M), touching)
    inside = reach[winding_number(points[reach], mesh) > 0.5]
    return np.union1d(touching, inside).astype(np.int64)


def surface_distance(points: np.ndarray, mesh) -> np.ndarray:
    """(N,) each point's (N, 3) exact distance to the nearest triangle of `mesh` (Clusters, or triangles (F, 3, 3))."""
    return nearest_surface_points(points, mesh)[1]


def nearest_surface_points(points: np.ndarray, mesh) -> tuple[np.ndarray, np.ndarray]:
    """((N, 3) the nearest point of `mesh` (Clusters, or triangles (F, 3, 3)) to each point (N, 3), (N,) its exact
    distance)."""
    c = mesh if isinstance(mesh, Clusters) else clusters(mesh)
    out, nearest = np.empty(len(points)), np.empty((len(points), 3))
    _distance_kernel(np.ascontiguousarray(points, np.float64), c.triangles, c.starts, c.centre, c.radius, out,
                     nearest)
    return nearest, out


def winding_number(points: np.ndarray, mesh) -> np.ndarray:
    """(N,) the generalised winding number of `mesh` (Clusters, or triangles (F, 3, 3), outward-facing
    counter-clockwise) at each point (N, 3): about 1 inside a closed mesh, 0 outside. A cluster or group farther
    than FAR_FIELD times its radius counts as its summed area vector (off the exact sum by about (radius /
    distance)^2 of its share: under 0.03 around a hand, tests/render/test_contacts.py), nearer ones triangle by
    triangle."""
    c = mesh if isinstance(mesh, Clusters) else clusters(mesh)
    out = np.empty(len(points))
    _winding_kernel(np.ascontiguousarray(points, np.float64), c.triangles, c.g_starts, c.g_centre, c.g_normal,
                    FAR_FIELD * c.g_radius, c.starts, c.centre, c.normal, FAR_FIELD * c.radius, out)
    return out


@kernel
def _distance_kernel(points, triangles, starts, centre, radius, out, nearest):
    """out[i] = the distance of points[i] to the nearest triangle, nearest[i] that triangle's closest point: per
    triangle (a, b, c) the closest point by Ericson's regions (a corner, an edge, or the interior from barycentric
    v, w), in scalars (no temporaries); a cluster k (triangles starts[k]:starts[k + 1]) whose sphere (centre, radius)
    lies farther than the best so far is skipped."""
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        qx, qy, qz = px, py, pz
        for k in range(centre.shape[0]):
            gap = np.sqrt((centre[k, 0] - px) ** 2 + (centre[k, 1] - py) ** 2 + (centre[k, 2] - pz) ** 2) - radius[k]
            if gap > 0 and gap * gap > best:
                continue
            for f in range(starts[k], starts[k + 1]):
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
                    qx, qy, qz = px - dx, py - dy, pz - dz
        out[i] = np.sqrt(best)
        nearest[i, 0], nearest[i, 1], nearest[i, 2] = qx, qy, qz


@kernel
def _winding_kernel(points, triangles, g_starts, g_centre, g_normal, g_far, starts, centre, normal, far, out):
    """out[i] = the sum of the triangles' solid angles seen from points[i] over 4 pi. A group of clusters (triangles
    g_starts[g]:g_starts[g + 1]) or a cluster k (starts[k]:starts[k + 1]; a group holds whole clusters) farther than
    its far distance counts as normal . (centre - p) / |centre - p|^3; the triangles of a near cluster one by one
    (Van Oosterom and Strackee: tan(omega / 2) = a . (b x c) / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|), a, b,
    c the corners relative to the point), in scalars (no temporaries)."""
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        total = 0.0
        k = 0
        for g in range(g_centre.shape[0]):
            dx, dy, dz = g_centre[g, 0] - px, g_centre[g, 1] - py, g_centre[g, 2] - pz
            d2 = dx * dx + dy * dy + dz * dz
            if d2 > g_far[g] * g_far[g]:
                total += (g_normal[g, 0] * dx + g_normal[g, 1] * dy + g_normal[g, 2] * dz) / (d2 * np.sqrt(d2))
                while k < centre.shape[0] and starts[k] < g_starts[g + 1]:
                    k += 1
                continue
            while k < centre.shape[0] and starts[k] < g_starts[g + 1]:
                dx, dy, dz = centre[k, 0] - px, centre[k, 1] - py, centre[k, 2] - pz
                d2 = dx * dx + dy * dy + dz * dz
                if d2 > far[k] * far[k]:
                    total += (normal[k, 0] * dx + normal[k, 1] * dy + normal[k, 2] * dz) / (d2 * np.sqrt(d2))
                    k += 1
                    continue
                for f in range(starts[k], starts[k + 1]):
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
                k += 1
        out[i] = total / (4.0 * np.pi)
