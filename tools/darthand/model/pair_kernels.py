"""The nearest point among candidate triangles and the signed distance there, as one compiled loop
(darthand.jit.kernel): the inner step of two hands' signed distances (model/hand_pair.Surface), called some fifty
times per two-hand frame on a few hundred points each, where the vectorised form (model/proximity's
_closest_barycentric and the signing after it: some forty numpy passes, each mostly call overhead at that size)
cost most of the fit's time.

The nearest point is proximity._closest_barycentric's (Ericson, Real-Time Collision Detection 5.1.5: project onto
the plane, clamp to the edge or vertex region the projection falls outside of), the sign hand_pair's (module
docstring: behind the normal interpolated there; not facing it: no distance), in float64, point by point.
"""

from __future__ import annotations

import numpy as np

from darthand.jit import kernel


def nearest_on_candidates(tris: np.ndarray, cand: np.ndarray, points: np.ndarray):
    """Per point (P, 3) the nearest point on its candidate triangles: (column of `cand` (P, k) holding it (P,),
    barycentric coordinates (P, 3), distance (P,) m). tris (F, 3, 3) m, cand face ids into tris."""
    out = signed_on_candidates(tris, np.zeros_like(tris), cand, points, 0.0, 0.0)
    return out[0], out[1], out[2]


def signed_on_candidates(tris: np.ndarray, tri_normals: np.ndarray, cand: np.ndarray, points: np.ndarray,
                         facing_cos: float, touching: float):
    """`nearest_on_candidates`, then signed: (best (P,), bary (P, 3), dist (P,), signed (P,) m (negative behind
    the normal interpolated at the nearest point, inf where the offset is more than acos(facing_cos) off that
    normal and dist >= touching), direction (P, 3) unit, along which the signed distance grows, nearest (P, 3)).
    tri_normals (F, 3, 3): unit vertex normals at each triangle's corners."""
    tris = np.ascontiguousarray(tris, np.float64)
    tri_normals = np.ascontiguousarray(tri_normals, np.float64)
    cand = np.ascontiguousarray(cand, np.int64)
    points = np.ascontiguousarray(points, np.float64)
    P = len(points)
    best, dist, signed = np.zeros(P, np.int64), np.zeros(P), np.zeros(P)
    bary, direction, nearest = np.zeros((P, 3)), np.zeros((P, 3)), np.zeros((P, 3))
    _signed_kernel(tris, tri_normals, cand, points, float(facing_cos), float(touching), best, bary, dist, signed,
                   direction, nearest)
    return best, bary, dist, signed, direction, nearest


@kernel
def _signed_kernel(tris, tri_normals, cand, points, facing_cos, touching, best, bary, dist, signed, direction,
                   nearest):   # pragma: no cover - compiled
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        dist[i] = np.inf
        for j in range(cand.shape[1]):
            t = tris[cand[i, j]]
            ax, ay, az = t[0, 0], t[0, 1], t[0, 2]
            abx, aby, abz = t[1, 0] - ax, t[1, 1] - ay, t[1, 2] - az
            acx, acy, acz = t[2, 0] - ax, t[2, 1] - ay, t[2, 2] - az
            apx, apy, apz = px - ax, py - ay, pz - az
            bpx, bpy, bpz = px - t[1, 0], py - t[1, 1], pz - t[1, 2]
            cpx, cpy, cpz = px - t[2, 0], py - t[2, 1], pz - t[2, 2]
            d1 = abx * apx + aby * apy + abz * apz
            d2 = acx * apx + acy * apy + acz * apz
            d3 = abx * bpx + aby * bpy + abz * bpz
            d4 = acx * bpx + acy * bpy + acz * bpz
            d5 = abx * cpx + aby * cpy + abz * cpz
            d6 = acx * cpx + acy * cpy + acz * cpz
            va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
            if d1 <= 0 and d2 <= 0:                                   # vertex a
                u, v, w = 1.0, 0.0, 0.0
            elif d3 >= 0 and d4 <= d3:                                # vertex b
                u, v, w = 0.0, 1.0, 0.0
            elif d6 >= 0 and d5 <= d6:                                # vertex c
                u, v, w = 0.0, 0.0, 1.0
            elif vc <= 0 and d1 >= 0 and d3 <= 0:                     # edge ab
                s = d1 / (d1 - d3) if d1 != d3 else 0.0
                u, v, w = 1.0 - s, s, 0.0
            elif vb <= 0 and d2 >= 0 and d6 <= 0:                     # edge ac
                s = d2 / (d2 - d6) if d2 != d6 else 0.0
                u, v, w = 1.0 - s, 0.0, s
            elif va <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:           # edge bc
                den = (d4 - d3) + (d5 - d6)
                s = (d4 - d3) / den if den != 0 else 0.0
                u, v, w = 0.0, 1.0 - s, s
            else:                                                     # inside the face
                den = va + vb + vc
                v = vb / den if den != 0 else 0.0
                w = vc / den if den != 0 else 0.0
                u = 1.0 - v - w
            qx = u * ax + v * t[1, 0] + w * t[2, 0]
            qy = u * ay + v * t[1, 1] + w * t[2, 1]
            qz = u * az + v * t[1, 2] + w * t[2, 2]
            d = np.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
            if d < dist[i]:
                dist[i] = d
                best[i] = j
                bary[i, 0], bary[i, 1], bary[i, 2] = u, v, w
                nearest[i, 0], nearest[i, 1], nearest[i, 2] = qx, qy, qz
        nt = tri_normals[cand[i, best[i]]]
        nx = bary[i, 0] * nt[0, 0] + bary[i, 1] * nt[1, 0] + bary[i, 2] * nt[2, 0]
        ny = bary[i, 0] * nt[0, 1] + bary[i, 1] * nt[1, 1] + bary[i, 2] * nt[2, 1]
        nz = bary[i, 0] * nt[0, 2] + bary[i, 1] * nt[1, 2] + bary[i, 2] * nt[2, 2]
        nn = max(np.sqrt(nx * nx + ny * ny + nz * nz), 1e-300)
        nx, ny, nz = nx / nn, ny / nn, nz / nn
        ox, oy, oz = px - nearest[i, 0], py - nearest[i, 1], pz - nearest[i, 2]
        along = ox * nx + oy * ny + oz * nz
        sign = -1.0 if along < 0 else 1.0
        if dist[i] > 1e-7:
            k = sign / dist[i]
            direction[i, 0], direction[i, 1], direction[i, 2] = ox * k, oy * k, oz * k
        else:
            direction[i, 0], direction[i, 1], direction[i, 2] = nx, ny, nz
        facing = abs(along) >= facing_cos * dist[i] or dist[i] < touching
        signed[i] = sign * dist[i] if facing else np.inf
