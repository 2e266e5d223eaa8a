"""How close the parts of a posed hand come to each other: signed distances between the palm and the five digits.

A part's surface is sampled at its vertices and face centroids (rest-time barycentric samples, so they follow any
pose). The signed distance of a sample of part p to part q is its distance to the nearest point of q's surface,
negative when it lies behind that surface (against the normal interpolated there), i.e. inside q.

Neighbouring parts meet along seams (a finger's base, the web between two fingers), where "distance to the other
part" says nothing about contact. So each pair compares only what lies farther than `exclude` (geodesically, along
the rest mesh's edges) from the other part, on both sides; and a sample whose nearest point is off to the side of
the surface there (the offset making more than ~45 degrees with the normal, as at the cut edge of the compared
region) is dropped as not facing it. What remains is contact between parts that are apart on the skin: a thumb on
a finger, two fingers side by side, a fingertip on the palm. The measure is what the gesture fit solves against
(model/gesture_fit); the guard it answers to is MeshLab's face intersection test (model/intersections).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from darthand.model.hand_model import HandModel
from darthand.model.intersections import PARTS, face_parts, joint_parts

EXCLUDE = 0.012     # m: parts are compared only where they lie this far apart along the skin
FACING_COS = 0.7    # a sample counts only if its offset is within ~45 deg of the surface normal ...
TOUCHING = 0.5e-3   # ... or it is this close (m), where the direction of a tiny offset means nothing


def closest_surface_points(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, candidates: int = 24):
    """Nearest point on a triangle mesh for each of `points` (P, 3).

    Returns (face index (P,), barycentric coordinates (P, 3), distance (P,)). Candidate faces are the `candidates`
    faces with the nearest centroids (exact for meshes whose triangles are small against the query distances,
    as here: trimesh's exact query needs rtree, which the project does not depend on).
    """
    tris = vertices[faces]
    k = min(candidates, len(faces))
    _, cand = cKDTree(tris.mean(1)).query(points, k=k)
    cand = cand.reshape(len(points), k)
    bary = _closest_barycentric(tris[cand], points[:, None, :])  # (P, k, 3)
    closest = np.einsum("pkc,pkcd->pkd", bary, tris[cand])
    dist = np.linalg.norm(closest - points[:, None, :], axis=2)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(points))
    return cand[rows, best], bary[rows, best], dist[rows, best]


def _closest_barycentric(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (..., 3) of the point of triangle `tri` (..., 3, 3) nearest `p` (..., 3).

    Ericson, Real-Time Collision Detection 5.1.5, vectorised: project onto the plane, then clamp to the edge or
    vertex region the projection falls outside of.
    """
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    ab, ac, ap = b - a, c - a, p - a
    bp, cp = p - b, p - c
    d1, d2 = (ab * ap).sum(-1), (ac * ap).sum(-1)
    d3, d4 = (ab * bp).sum(-1), (ac * bp).sum(-1)
    d5, d6 = (ab * cp).sum(-1), (ac * cp).sum(-1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = va + vb + vc
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.where(denom != 0, vb / denom, 0.0)
        w = np.where(denom != 0, vc / denom, 0.0)
        out = np.stack([1 - v - w, v, w], -1)
        regions = [  # (condition, barycentrics), later entries win
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
             lambda t: np.stack([0 * t, 1 - t, t], -1), (d4 - d3) / ((d4 - d3) + (d5 - d6))),  # edge bc
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), lambda t: np.stack([1 - t, 0 * t, t], -1), d2 / (d2 - d6)),  # ac
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), lambda t: np.stack([1 - t, t, 0 * t], -1), d1 / (d1 - d3)),  # ab
            ((d6 >= 0) & (d5 <= d6), lambda t: np.stack([0 * t, 0 * t, 1 + 0 * t], -1), d6),  # vertex c
            ((d3 >= 0) & (d4 <= d3), lambda t: np.stack([0 * t, 1 + 0 * t, 0 * t], -1), d3),  # vertex b
            ((d1 <= 0) & (d2 <= 0), lambda t: np.stack([1 + 0 * t, 0 * t, 0 * t], -1), d1),  # vertex a
        ]
        for cond, make, t in regions:
            out = np.where(cond[..., None], make(np.nan_to_num(t)), out)
    return out


@dataclass(frozen=True)
class Hits:
    """Signed distances of samples of one part to another part's surface, with where they land.

    sample (K,) sample ids; distance (K,) m, negative inside; point (K, 3) nearest surface points; normal (K, 3)
    unit interpolated normals there; corners (K, 3) vertex ids and bary (K, 3) barycentrics of those points.
    """

    sample: np.ndarray
    distance: np.ndarray
    point: np.ndarray
    normal: np.ndarray
    corners: np.ndarray
    bary: np.ndarray


class PartSurfaces:
    """Rest-time sampling of a model's parts (palm + digits) for `signed_distances` in any pose.

    samples: vertices, then face centroids; `sample_corners` (S, 3) vertex ids and `sample_bary` (S, 3) weights.
    """

    def __init__(self, model: HandModel, exclude: float = EXCLUDE):
        self.faces = model.faces
        self.face_part = face_parts(model)
        V, F = model.num_vertices, model.num_faces
        vertex_part = joint_parts()[np.argmax(model.weights, axis=1)]
        self.sample_corners = np.concatenate([np.repeat(np.arange(V)[:, None], 3, 1), model.faces])
        self.sample_bary = np.concatenate([np.tile([1.0, 0.0, 0.0], (V, 1)), np.full((F, 3), 1 / 3)])
        self.sample_part = np.concatenate([vertex_part, self.face_part])
        along_skin = part_geodesics(model, self.face_part)                       # (P, V)
        self.sample_far = along_skin[:, self.sample_corners].min(axis=2) > exclude  # (P, S)
        self.face_far = along_skin[:, model.faces].min(axis=2) > exclude          # (P, F)

    def samples(self, vertices: np.ndarray, ids: np.ndarray | None = None) -> np.ndarray:
        """(S, 3) sample positions on posed vertices (V, 3), or only the samples `ids`."""
        corners = self.sample_corners if ids is None else self.sample_corners[ids]
        bary = self.sample_bary if ids is None else self.sample_bary[ids]
        return np.einsum("sk,skd->sd", bary, vertices[corners])

    def comparable(self, p: int, q: int) -> tuple[np.ndarray, np.ndarray]:
        """Sample ids of part p and face ids of part q that lie apart from each other along the skin."""
        samples = np.flatnonzero((self.sample_part == p) & self.sample_far[q])
        faces = np.flatnonzero((self.face_part == q) & self.face_far[p])
        return samples, faces

    def signed_distances(self, vertices: np.ndarray, normals: np.ndarray, p: int, q: int,
                         samples: np.ndarray | None = None, reach: float | None = None) -> Hits:
        """Signed distances of part p's samples (all comparable ones, or `samples`) to part q's surface, on
        posed vertices (V, 3) with unit vertex normals (V, 3). reach: keep only samples nearer than this (m).
        Samples not facing q's surface are dropped (see the module docstring)."""
        ids, faces = self.comparable(p, q)
        ids = ids if samples is None else np.asarray(samples, dtype=np.int64)
        if len(ids) == 0 or len(faces) == 0:
            return _no_hits()
        points = self.samples(vertices, ids)
        if reach is not None:
            corners = np.unique(self.faces[faces])
            d0, _ = cKDTree(vertices[corners]).query(points, distance_upper_bound=reach + _longest_edge(
                vertices, self.faces[faces]))
            near = np.isfinite(d0)
            ids, points = ids[near], points[near]
            if len(ids) == 0:
                return _no_hits()
        tri, bary, dist = closest_surface_points(vertices, self.faces[faces], points, candidates=8)
        corners = self.faces[faces[tri]]
        on = np.einsum("pk,pkd->pd", bary, vertices[corners])
        n = np.einsum("pk,pkd->pd", bary, normals[corners])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        along = np.einsum("pd,pd->p", points - on, n)
        facing = (np.abs(along) >= FACING_COS * dist) | (dist < TOUCHING)
        if reach is not None:
            facing &= dist < reach
        signed = np.where(along < 0, -dist, dist)
        return Hits(ids[facing], signed[facing], on[facing], n[facing], corners[facing], bary[facing])


    def distance(self, vertices: np.ndarray, normals: np.ndarray, p: int, q: int, reach: float = 5e-3) -> float:
        """Smallest signed distance (m) between parts p and q, measured both ways (negative: one inside the
        other); inf when they come no nearer than `reach`."""
        both = [self.signed_distances(vertices, normals, a, b, reach=reach).distance for a, b in ((p, q), (q, p))]
        return float(np.concatenate(both).min(initial=np.inf))


def part_geodesics(model: HandModel, face_part: np.ndarray) -> np.ndarray:
    """(P, V) distance (m) along the rest mesh's edges from each part's faces to every vertex."""
    f = model.faces
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    length = np.linalg.norm(model.v_template[edges[:, 0]] - model.v_template[edges[:, 1]], axis=1)
    V = model.num_vertices
    graph = sp.coo_matrix((np.r_[length, length], (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                          shape=(V, V)).tocsr()
    out = np.full((len(PARTS), V), np.inf)
    for p in range(len(PARTS)):
        own = np.unique(f[face_part == p])
        if len(own):
            out[p] = dijkstra(graph, indices=own, min_only=True)
    return out


def _longest_edge(vertices: np.ndarray, faces: np.ndarray) -> float:
    tri = vertices[faces]
    return float(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max())


def _no_hits() -> Hits:
    z = np.zeros(0)
    return Hits(np.zeros(0, np.int64), z, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3), np.int64),
                np.zeros((0, 3)))
