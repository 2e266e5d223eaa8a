"""An object's signed distance field: exact point-to-mesh distances on the object's closed mesh, negative inside.

Candidate faces come from a KD-tree over samples of every face (at most SPACING apart along its longest edge, at
most MAX_SPLIT steps: a face's centroid alone misleads on long thin triangles, a cylinder cap's fan or a revolved
cup's side), built once per object. For a point within EXACT_REACH of the surface the candidates are the faces of
every sample within d0 + gap (d0 its nearest sample's distance, gap the farthest any face point lies from its own
nearest sample): the true nearest face has a sample there, so the distance is exact. Farther points, and every
point of a solve's iterations (`candidates(exact=False)`), take the faces of their CANDIDATES nearest samples: a
missed face only makes a distance too large. The nearest point on the candidates is found exactly
(model/pair_kernels' compiled closest-point loop). The sign is that of the offset against the surface's
pseudo-normal at the nearest point: the face normal where that point lies inside a face, the area-weighted vertex
normals interpolated there when it lies on an edge or a corner (where the face normal alone can say "outside" for
a point inside a convex corner). Measured against exact brute-force distances and winding numbers in
tests/grasps/test_field.py.
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from darthand.errors import InputError
from darthand.model.pair_kernels import nearest_on_candidates
from darthand.model.topology import face_normals, vertex_normals

CANDIDATES = 12
SPACING = 0.004     # m: largest gap between a face's samples
EXACT_REACH = 0.006  # m: points this near a sample get every candidate that can hold their nearest point
MAX_SPLIT = 24      # a face is sampled on at most this many steps per edge
INTERIOR = 1e-6     # barycentric coordinate above which the nearest point lies inside its face


class ObjectField:
    """The signed distance of one object's closed mesh: vertices (N, 3) float64 m, faces (F, 3), object frame."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, name: str = "object"):
        v = np.asarray(vertices, np.float64)
        f = np.asarray(faces, np.int64)
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise InputError(f"{name}: the mesh is not (N, 3) vertices and (F, 3) faces")
        if not np.isfinite(v).all():
            raise InputError(f"{name}: the mesh has a non-finite vertex")
        self.name = name
        self.vertices, self.faces = v, f
        self.tris = v[f]
        self.face_normals = face_normals(v, f)
        self.vertex_normals = vertex_normals(v, f)
        samples, self.sample_face, self.gap = face_samples(self.tris)
        self.tree = cKDTree(samples)
        self.k = min(CANDIDATES, len(samples))
        self.box = (v.min(0), v.max(0))

    def candidates(self, points: np.ndarray, exact: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """(distance to the nearest surface sample (P,) m, candidate faces (P, k) padded with repeats) of points
        (P, 3): with `exact`, every face that can hold the nearest point of a point within EXACT_REACH (see the
        module docstring); else only its CANDIDATES nearest samples' (a quarter of the time: what a solve's
        iterations use, the measured result being exact)."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        dist, nearest = self.tree.query(p, k=self.k)
        dist, nearest = dist.reshape(len(p), self.k), nearest.reshape(len(p), self.k)
        cand = self.sample_face[nearest]
        close = np.flatnonzero(dist[:, 0] < EXACT_REACH) if exact else np.zeros(0, np.int64)
        if len(close):
            balls = self.tree.query_ball_point(p[close], dist[close, 0] + self.gap)
            cand = merged(cand, close, self.ball_faces(balls))
        return dist[:, 0], cand

    def ball_faces(self, balls) -> np.ndarray:
        """(m, w) the distinct faces of each list of sample ids in `balls` (m lists), padded with the first."""
        lengths = np.fromiter((len(b) for b in balls), np.int64, len(balls))
        ids = np.fromiter(itertools.chain.from_iterable(balls), np.int64, int(lengths.sum()))
        F = len(self.faces)
        key = np.unique(np.repeat(np.arange(len(balls)), lengths) * F + self.sample_face[ids])
        row, face = np.divmod(key, F)
        start = np.searchsorted(row, np.arange(len(balls)))
        width = int(np.bincount(row, minlength=len(balls)).max())
        out = np.repeat(face[start][:, None], width, axis=1)
        out[row, np.arange(len(row)) - start[row]] = face
        return out

    def query(self, points: np.ndarray, cand: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(signed distance (P,) m, unit gradient (P, 3), nearest surface point (P, 3)) of points (P, 3), exact
        (`candidates`); `cand` (P, k): candidate faces found earlier for points near these, to skip the search."""
        p = np.asarray(points, np.float64).reshape(-1, 3)
        if cand is None:
            cand = self.candidates(p)[1]
        best, b, d = nearest_on_candidates(self.tris, cand, p)
        face = cand[np.arange(len(p)), best]
        y = np.einsum("pc,pcd->pd", b, self.tris[face])
        normal = self.pseudo_normals(face, b)
        offset = p - y
        sign = np.where(np.einsum("pd,pd->p", offset, normal) < 0, -1.0, 1.0)
        grad = np.where(d[:, None] > 1e-9, sign[:, None] * offset / np.maximum(d, 1e-12)[:, None], normal)
        return sign * d, grad, y

    def in_box(self, points: np.ndarray, margin: float) -> np.ndarray:
        """(P,) bool: points (P, 3) inside the object's bounding box grown by `margin` (m); a point outside it is
        farther than `margin` from the object, and outside it."""
        p = np.asarray(points).reshape(-1, 3)
        return ((p >= self.box[0] - margin) & (p <= self.box[1] + margin)).all(axis=1)

    def distance(self, points: np.ndarray) -> np.ndarray:
        """(P,) signed distances (m) of points (P, 3)."""
        return self.query(points)[0]

    def pseudo_normals(self, face: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(P, 3) the direction that signs an offset from the nearest point (faces (P,), barycentrics (P, 3))."""
        corners = self.vertex_normals[self.faces[face]]
        smooth = np.einsum("pc,pcd->pd", bary, corners)
        inside = np.all(bary > INTERIOR, axis=1)
        return np.where(inside[:, None], self.face_normals[face], smooth)


def merged(cand: np.ndarray, rows: np.ndarray, new: np.ndarray) -> np.ndarray:
    """cand (P, k) with its rows `rows` (m,) replaced by `new` (m, w), both padded with each row's first face."""
    width = max(cand.shape[1], new.shape[1])
    out = padded(cand, width)
    out[rows] = padded(new, width)
    return out


def padded(cand: np.ndarray, width: int) -> np.ndarray:
    """cand (n, k) widened to (n, width) by repeating each row's first face."""
    if cand.shape[1] == width:
        return cand
    return np.concatenate([cand, np.repeat(cand[:, :1], width - cand.shape[1], axis=1)], axis=1)


def face_samples(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(samples (S, 3), the face of each (S,), gap m): each triangle of tris (F, 3, 3) on a barycentric grid of n
    steps per edge, n = its longest edge / SPACING (1..MAX_SPLIT); gap bounds how far any point of a face lies
    from its nearest sample (a grid cell's longest edge: the face's over n)."""
    edges = np.linalg.norm(tris - np.roll(tris, 1, axis=1), axis=2).max(1)
    steps = np.clip(np.ceil(edges / SPACING), 1, MAX_SPLIT).astype(int)
    points, owners = [], []
    for n in np.unique(steps):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        bary = np.stack([i[keep], j[keep], n - i[keep] - j[keep]], 1) / n          # (m, 3)
        ids = np.flatnonzero(steps == n)
        points.append(np.einsum("mc,fcd->fmd", bary, tris[ids]).reshape(-1, 3))
        owners.append(np.repeat(ids, len(bary)))
    return np.concatenate(points), np.concatenate(owners), float((edges / steps).max())
