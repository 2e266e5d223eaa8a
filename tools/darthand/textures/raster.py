"""Triangle rasterisation into a pixel grid: which triangle covers each pixel centre, and where in it.

Used twice: baking surface maps into UV space (`key="distance"`, with a margin so that texels just outside an
island get the value of the nearest point of their triangle: a gutter of true surface values), and the contact
sheet's preview renders (`key="depth"`, a z-buffer).

Pixel (row r, column c) has its centre at (x, y) = (c + 0.5, r + 0.5); triangles are given in those pixel units.
Written here rather than taken from a library because none of the listed ones exposes per-pixel triangle ids and
barycentrics on the CPU; the work is vectorised over all (triangle, pixel-in-bounding-box) pairs, in chunks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_CHUNK_PAIRS = 1 << 21  # (triangle, pixel) candidates per vectorised chunk: bounds the temporary memory


@dataclass(frozen=True)
class Fragments:
    """The winning triangle at each covered pixel (N covered pixels).

    pixel     (N,)   int64, flat index r * width + c, ascending
    face      (N,)   int64, triangle index
    bary      (N, 3) float64, barycentric coordinates of the pixel centre (or of its nearest point on the
                     triangle when it lies outside, within the margin); rows sum to 1, entries in [0, 1]
    distance  (N,)   float64, pixel distance from the centre to the triangle (0 inside)
    """

    pixel: np.ndarray
    face: np.ndarray
    bary: np.ndarray
    distance: np.ndarray

    @property
    def inside(self) -> np.ndarray:
        """(N,) bool: the pixel centre lies in its triangle (coverage proper, not the margin)."""
        return self.distance == 0.0


def rasterize(tri: np.ndarray, width: int, height: int, *, margin: float = 0.0,
              depth: np.ndarray | None = None) -> Fragments:
    """Rasterise triangles `tri` (F, 3, 2) given in pixel units into a `height` x `width` grid.

    A pixel belongs to every triangle whose closed area contains its centre or, with `margin` > 0, lies within
    `margin` pixels of it. Among the candidates of one pixel the winner has the smallest distance (ties: the
    smallest interpolated `depth` (F, 3) if given, then the smallest face index), so results do not depend on
    chunking. Degenerate (zero-area) triangles are skipped.
    """
    tri = np.asarray(tri, dtype=np.float64)
    if len(tri) >= 1 << _FACE_BITS:
        raise ValueError(f"rasterize: at most {(1 << _FACE_BITS) - 1} triangles")
    faces = np.nonzero(np.abs(_signed_area(tri)) > 1e-12)[0]
    lo = np.ceil(tri[faces].min(1) - margin - 0.5).astype(np.int64)  # first centre c + 0.5 >= min - margin
    hi = np.floor(tri[faces].max(1) + margin - 0.5).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [width - 1, height - 1])
    keep = (hi >= lo).all(1)
    faces, lo, hi = faces[keep], lo[keep], hi[keep]
    counts = (hi - lo + 1).prod(1)
    depth01 = None
    if depth is not None:
        depth = np.asarray(depth, dtype=np.float64)
        span = max(float(np.ptp(depth)), 1e-300)
        depth01 = (depth - depth.min()) / span
    # Height of each vertex over its opposite edge: bary_i * height_i is the distance to that edge's line.
    edge_len = np.linalg.norm(tri[:, [2, 0, 1]] - tri[:, [1, 2, 0]], axis=2)
    heights = 2 * np.abs(_signed_area(tri))[:, None] / np.maximum(edge_len, 1e-300)
    best = np.full(width * height, np.iinfo(np.int64).max, dtype=np.int64)
    chunk = (np.cumsum(counts) - counts) // _CHUNK_PAIRS  # chunk of each face, by the pairs before it
    splits = np.nonzero(np.diff(chunk))[0] + 1
    kept = []
    for f, a, b, c in zip(*(np.split(x, splits) for x in (faces, lo, hi, counts))):
        if len(f):
            pixel, face, bary, distance, key = _candidates(tri, heights, f, a, b, c, width, margin, depth01)
            np.minimum.at(best, pixel, key)
            win = key == best[pixel]  # may still lose to a later chunk: filtered again below
            kept.append((pixel[win], face[win], bary[win], distance[win], key[win]))
    if not kept:
        empty = np.zeros(0, np.int64)
        return Fragments(empty, empty, np.zeros((0, 3)), np.zeros(0))
    pixel, face, bary, distance, key = (np.concatenate(k) for k in zip(*kept))
    win = key == best[pixel]
    order = np.argsort(pixel[win], kind="stable")
    return Fragments(pixel[win][order], face[win][order], bary[win][order], distance[win][order])


# Candidates of one pixel are ranked by one int64: quantised distance, quantised depth, face index.
_FACE_BITS, _DEPTH_BITS, _DIST_BITS = 24, 19, 18


def _rank_key(distance, depth01, face, margin):
    q_dist = np.rint(distance / max(margin, 1.0) * ((1 << _DIST_BITS) - 1)).astype(np.int64)
    q_depth = (np.zeros(len(face), np.int64) if depth01 is None
               else np.rint(depth01 * ((1 << _DEPTH_BITS) - 1)).astype(np.int64))
    return (q_dist << (_DEPTH_BITS + _FACE_BITS)) | (q_depth << _FACE_BITS) | face


def _signed_area(tri: np.ndarray) -> np.ndarray:
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def _candidates(tri, heights, faces, lo, hi, counts, width, margin, depth01):
    """All (face, pixel) pairs of the bounding boxes of `faces` that the face covers (or nearly, within
    `margin`): pixel, face, barycentrics, distance and ranking key."""
    face = np.repeat(faces, counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    box_w = np.repeat(hi[:, 0] - lo[:, 0] + 1, counts)
    px = np.repeat(lo[:, 0], counts) + local % box_w
    py = np.repeat(lo[:, 1], counts) + local // box_w
    p = np.stack([px + 0.5, py + 0.5], 1)
    t = tri[face]
    bary = _barycentric(p, t)
    inside = (bary >= 0).all(1)
    if margin > 0:
        # Within `margin` of the triangle implies within `margin` of every edge's line: a cheap first cut.
        line_dist = bary * heights[face]
        near = ~inside & (line_dist >= -margin).all(1)
        keep = inside | near
        face, px, py, p, t, bary = face[keep], px[keep], py[keep], p[keep], t[keep], bary[keep]
        distance = np.zeros(len(face))
        out = np.nonzero(~inside[keep])[0]
        distance[out], bary[out] = _nearest_on_triangle(p[out], t[out])
        keep = distance <= margin
    else:
        keep = inside
        distance = np.zeros(len(face))
    face, bary, distance = face[keep], bary[keep], distance[keep]
    pixel = py[keep] * width + px[keep]
    face_depth = None if depth01 is None else np.einsum("ij,ij->i", bary, depth01[face])
    return pixel, face, bary, distance, _rank_key(distance, face_depth, face, margin)


def _barycentric(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(N, 3) barycentric coordinates of points p (N, 2) in triangles t (N, 3, 2)."""
    v0, v1 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    v2 = p - t[:, 0]
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    b1 = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
    b2 = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    return np.stack([1.0 - b1 - b2, b1, b2], 1)


def _nearest_on_triangle(p: np.ndarray, t: np.ndarray):
    """Distance from points p (N, 2) outside triangles t (N, 3, 2) to their boundary, and the barycentric
    coordinates of the nearest boundary point."""
    best_d = np.full(len(p), np.inf)
    best_b = np.zeros((len(p), 3))
    for i in range(3):
        j = (i + 1) % 3
        a, e = t[:, i], t[:, j] - t[:, i]
        s = np.clip(np.einsum("ij,ij->i", p - a, e) / np.maximum(np.einsum("ij,ij->i", e, e), 1e-300), 0.0, 1.0)
        d = np.hypot(*(a + s[:, None] * e - p).T)
        better = d < best_d
        best_d[better] = d[better]
        best_b[better] = 0.0
        best_b[better, i], best_b[better, j] = 1.0 - s[better], s[better]
    return best_d, best_b
