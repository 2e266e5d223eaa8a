"""The nearest point among candidate triangles, as one compiled loop (darthand.jit.kernel): the inner step of two
hands' signed distances (model/hand_pair.Surface), called some twenty times per two-hand frame on a few thousand
points, where the vectorised form (model/proximity._closest_barycentric: a dozen (P, k) temporaries) cost most of
the fit's time.

The maths is proximity._closest_barycentric's (Ericson, Real-Time Collision Detection 5.1.5: project onto the
plane, clamp to the edge or vertex region the projection falls outside of), in float64, point by point.
"""

from __future__ import annotations

import numpy as np

from darthand.jit import kernel


def nearest_on_candidates(tris: np.ndarray, cand: np.ndarray, points: np.ndarray):
    """Per point (P, 3) the nearest point on its candidate triangles: (column of `cand` (P, k) holding it (P,),
    barycentric coordinates (P, 3), distance (P,) m). tris (F, 3, 3) m, cand face ids into tris."""
    tris = np.ascontiguousarray(tris, np.float64)
    cand = np.ascontiguousarray(cand, np.int64)
    points = np.ascontiguousarray(points, np.float64)
    best = np.zeros(len(points), np.int64)
    bary = np.zeros((len(points), 3))
    dist = np.zeros(len(points))
    _nearest_kernel(tris, cand, points, best, bary, dist)
    return best, bary, dist


@kernel
def _nearest_kernel(tris, cand, points, best, bary, dist):   # pragma: no cover - compiled
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
            qx = u * ax + v * t[1, 0] + w * t[2, 0] - px
            qy = u * ay + v * t[1, 1] + w * t[2, 1] - py
            qz = u * az + v * t[1, 2] + w * t[2, 2] - pz
            d = np.sqrt(qx * qx + qy * qy + qz * qz)
            if d < dist[i]:
                dist[i] = d
                best[i] = j
                bary[i, 0], bary[i, 1], bary[i, 2] = u, v, w
