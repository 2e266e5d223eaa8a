"""Loop subdivision at render time: a fixed sparse matrix per mesh topology, applied to the posed vertices.

Loop's scheme (Loop 1987; boundary rules of Hoppe et al. 1994) splits every triangle into four. A new vertex on an
interior edge (a, b) with opposite vertices c, d is 3/8 (a + b) + 1/8 (c + d); on a boundary edge the midpoint. An
old interior vertex of valence n moves to (1 - n beta) v + beta sum(neighbours), beta = (5/8 - (3/8 + 1/4
cos(2 pi / n))^2) / n; an old boundary vertex to 3/4 v + 1/8 (its two boundary neighbours), so an open end's outline
depends on the boundary alone (the hand and the forearm cap, subdivided apart, still meet). After the last level
every vertex goes to its point on the limit surface: interior (1 - n chi) v + chi sum(neighbours), chi = 1 / (3 /
(8 beta) + n); boundary 2/3 v + 1/6 (its boundary neighbours).

All of that is linear in the control vertices, so one level or two plus the limit step are one (N', N) sparse
matrix, built once per topology (`SubdivisionPlan`), and a frame's subdivided hand is one product with its posed
vertices. UVs are subdivided on their own topology (faces_uv), linearly (a new UV is its UV edge's midpoint), so
seams stay where they are. Face f's children are faces 4 f .. 4 f + 3 (per level), so per-face data (skinning
joint, labels) repeat and the model's face ranges scale by 4 per level.

Shapes: N control vertices, F faces, E edges; a level gives N + E vertices and 4 F faces.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from darthand.model.topology import vertex_normals
from darthand.render.subject import Surface

MAX_LEVEL = 2
SMOOTHED_ROLES = ("hand", "cap", "arm")    # skinned skin surfaces; accessories keep their own meshes


@dataclass(frozen=True)
class Edges:
    """The undirected edges of a triangle mesh: ends (E, 2) int64 (a < b), face_edges (F, 3) the edge of each
    corner k's side (k -> k + 1), opposite (E, 2) the vertex across the edge in its first two faces (-1: none),
    count (E,) faces on each edge (1: boundary)."""

    ends: np.ndarray
    face_edges: np.ndarray
    opposite: np.ndarray
    count: np.ndarray


def mesh_edges(faces: np.ndarray) -> Edges:
    """The edges of `faces` (F, 3)."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    a = faces.reshape(-1)
    b = np.roll(faces, -1, axis=1).reshape(-1)
    c = np.roll(faces, -2, axis=1).reshape(-1)              # the corner across the side a -> b
    pairs = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
    ends, edge_of = np.unique(pairs, axis=0, return_inverse=True)
    edge_of = edge_of.reshape(-1)
    count = np.bincount(edge_of, minlength=len(ends))
    opposite = np.full((len(ends), 2), -1, np.int64)
    order = np.argsort(edge_of, kind="stable")
    first = np.searchsorted(edge_of[order], np.arange(len(ends)))
    opposite[:, 0] = c[order[first]]
    second = first + 1
    has_second = count >= 2
    opposite[has_second, 1] = c[order[second[has_second]]]
    return Edges(ends, edge_of.reshape(-1, 3), opposite, count)


def loop_beta(n: np.ndarray) -> np.ndarray:
    """Loop's neighbour weight for interior valence n (>= 3): (5/8 - (3/8 + 1/4 cos(2 pi / n))^2) / n."""
    n = np.asarray(n, np.float64)
    return (5 / 8 - (3 / 8 + np.cos(2 * np.pi / np.maximum(n, 1)) / 4) ** 2) / np.maximum(n, 1)


def _vertex_stencils(n_vertices: int, edges: Edges, boundary_own: float, boundary_side: float,
                     interior_neighbour) -> sp.csr_matrix:
    """(N, N) matrix moving old vertices: boundary vertices (exactly two boundary edges) keep `boundary_own` of
    themselves and `boundary_side` of each boundary neighbour; interior ones of valence n spread
    interior_neighbour(n) to each neighbour and keep the rest; others (unused, corners of a pinched boundary)
    stay."""
    a, b = edges.ends[:, 0], edges.ends[:, 1]
    boundary = edges.count == 1
    valence = np.bincount(np.concatenate([a, b]), minlength=n_vertices)
    b_valence = np.bincount(np.concatenate([a[boundary], b[boundary]]), minlength=n_vertices)
    on_boundary = b_valence > 0
    smooth_boundary = b_valence == 2
    interior = (~on_boundary) & (valence >= 3)
    w = np.zeros(n_vertices)
    w[interior] = interior_neighbour(valence[interior])
    rows, cols, vals = [], [], []
    for u, v in ((a, b), (b, a)):                        # each edge gives both ends a neighbour
        inner = interior[u]
        rows.append(u[inner])
        cols.append(v[inner])
        vals.append(w[u[inner]])
        side = boundary & smooth_boundary[u]
        rows.append(u[side])
        cols.append(v[side])
        vals.append(np.full(int(side.sum()), boundary_side))
    own = np.ones(n_vertices)
    own[interior] = 1 - valence[interior] * w[interior]
    own[smooth_boundary] = boundary_own
    rows.append(np.arange(n_vertices))
    cols.append(np.arange(n_vertices))
    vals.append(own)
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(n_vertices, n_vertices))


def _edge_stencils(n_vertices: int, edges: Edges) -> sp.csr_matrix:
    """(E, N) matrix of the new edge vertices: 3/8 (a + b) + 1/8 (c + d) inside, the midpoint on a boundary (or
    a non-manifold edge)."""
    E = len(edges.ends)
    inner = edges.count == 2
    rows = np.concatenate([np.arange(E), np.arange(E), np.flatnonzero(inner), np.flatnonzero(inner)])
    cols = np.concatenate([edges.ends[:, 0], edges.ends[:, 1], edges.opposite[inner, 0], edges.opposite[inner, 1]])
    end_w = np.where(inner, 3 / 8, 1 / 2)
    vals = np.concatenate([end_w, end_w, np.full(2 * int(inner.sum()), 1 / 8)])
    return sp.csr_matrix((vals, (rows, cols)), shape=(E, n_vertices))


def split_faces(faces: np.ndarray, face_edges: np.ndarray, n_vertices: int) -> np.ndarray:
    """(4 F, 3) children of faces (F, 3) whose edge vertices are n_vertices + edge index: face f's corner
    triangles at 4 f, 4 f + 1, 4 f + 2 (corners 0, 1, 2) and its middle at 4 f + 3, wound as f."""
    v0, v1, v2 = (faces[:, k] for k in range(3))
    m01, m12, m20 = (n_vertices + face_edges[:, k] for k in range(3))
    children = np.stack([np.stack([v0, m01, m20], 1), np.stack([m01, v1, m12], 1), np.stack([m20, m12, v2], 1),
                         np.stack([m01, m12, m20], 1)], axis=1)
    return children.reshape(-1, 3)


def loop_level(faces: np.ndarray, n_vertices: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """One Loop level: ((N + E, N) matrix, (4 F, 3) faces)."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    edges = mesh_edges(faces)
    old = _vertex_stencils(n_vertices, edges, 3 / 4, 1 / 8, loop_beta)
    M = sp.vstack([old, _edge_stencils(n_vertices, edges)]).tocsr()
    return M, split_faces(faces, edges.face_edges, n_vertices)


def limit_matrix(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """(N, N) matrix taking vertices to their Loop limit points: interior chi = 1 / (3 / (8 beta) + n) per neighbour,
    boundary 2/3 v + 1/6 per boundary neighbour."""
    edges = mesh_edges(faces)
    chi = lambda n: 1.0 / (3.0 / (8.0 * loop_beta(n)) + n)
    return _vertex_stencils(n_vertices, edges, 2 / 3, 1 / 6, chi)


def linear_level(faces_uv: np.ndarray, n_uvs: int) -> tuple[sp.csr_matrix, np.ndarray]:
    """One level of linear (midpoint) subdivision on the UV topology: ((T + E_uv, T) matrix, (4 F, 3) faces_uv)."""
    faces_uv = np.asarray(faces_uv, np.int64).reshape(-1, 3)
    edges = mesh_edges(faces_uv)
    E = len(edges.ends)
    mid = sp.csr_matrix((np.full(2 * E, 0.5), (np.tile(np.arange(E), 2), edges.ends.T.reshape(-1))),
                        shape=(E, n_uvs))
    return sp.vstack([sp.identity(n_uvs, format="csr"), mid]).tocsr(), split_faces(faces_uv, edges.face_edges, n_uvs)


@dataclass(frozen=True, eq=False)
class SubdivisionPlan:
    """A topology's subdivision at `level`: matrix (N', N) float32 CSR (positions: Loop levels then limit points),
    faces (4^level F, 3) int32, uv_matrix (T', T) and faces_uv (4^level F, 3) int32 when there are UVs, parent
    (4^level F,) int64 the control face of each face."""

    level: int
    matrix: sp.csr_matrix
    faces: np.ndarray
    uv_matrix: sp.csr_matrix | None
    faces_uv: np.ndarray | None
    parent: np.ndarray

    @classmethod
    def build(cls, faces: np.ndarray, n_vertices: int, level: int, faces_uv: np.ndarray | None = None,
              n_uvs: int = 0) -> "SubdivisionPlan":
        """The plan for faces (F, 3) over n_vertices, `level` (1..MAX_LEVEL) Loop levels (float64 maths, stored
        float32)."""
        M: sp.csr_matrix = sp.identity(n_vertices, format="csr")
        U = None if faces_uv is None else sp.identity(n_uvs, format="csr")
        f = np.asarray(faces, np.int64)
        fuv = None if faces_uv is None else np.asarray(faces_uv, np.int64)
        for _ in range(level):
            step, f = loop_level(f, M.shape[0])
            M = (step @ M).tocsr()
            if fuv is not None and U is not None:
                uv_step, fuv = linear_level(fuv, U.shape[0])
                U = (uv_step @ U).tocsr()
        M = (limit_matrix(f, M.shape[0]) @ M).tocsr()
        parent = np.repeat(np.arange(len(faces)), 4 ** level)
        return cls(level, _float32(M), np.ascontiguousarray(f, np.int32), None if U is None else _float32(U),
                   None if fuv is None else np.ascontiguousarray(fuv, np.int32), parent)

    def positions(self, vertices: np.ndarray) -> np.ndarray:
        """(N', 3) float32 subdivided limit positions of control vertices (N, 3)."""
        return np.ascontiguousarray(self.matrix @ np.asarray(vertices, np.float32), np.float32)


def _float32(M: sp.csr_matrix) -> sp.csr_matrix:
    M = M.tocsr()
    M.eliminate_zeros()
    M.sort_indices()
    return M.astype(np.float32)


class Subdivider:
    """Subdivides a subject's skin surfaces, keeping a plan per (topology, level) and the last result per surface
    name, so a surface whose vertex array did not change comes back as the same arrays (the renderer then reuses its
    Embree scene)."""

    def __init__(self) -> None:
        self._plans: dict = {}
        self._last: dict = {}
        self._rests: dict = {}

    def plan(self, surface: Surface, level: int) -> SubdivisionPlan:
        """The plan of a surface's topology (faces and faces_uv, hashed) at `level`."""
        faces = np.ascontiguousarray(surface.faces)
        h = hashlib.sha1(faces.tobytes())
        if surface.faces_uv is not None and surface.uvs is not None:
            h.update(np.ascontiguousarray(surface.faces_uv).tobytes())
            h.update(str(len(surface.uvs)).encode())
        key = (h.hexdigest(), len(surface.vertices), level)
        plan = self._plans.get(key)
        if plan is None:
            if len(self._plans) > 16:
                self._plans.clear()
            has_uv = surface.faces_uv is not None and surface.uvs is not None
            plan = self._plans[key] = SubdivisionPlan.build(
                faces, len(surface.vertices), level, surface.faces_uv if has_uv else None,
                len(surface.uvs) if has_uv and surface.uvs is not None else 0)
        return plan

    def surface(self, surface: Surface, level: int) -> Surface:
        """`surface` subdivided `level` times (its own arrays for level 0)."""
        if level == 0:
            return surface
        last = self._last.get(surface.name)
        if last is not None and last[0] is surface.vertices and last[1] == level and last[2] is surface.material:
            return last[3]
        plan = self.plan(surface, level)
        out = subdivided_surface(surface, plan, self.rest(surface, plan))
        self._last[surface.name] = (surface.vertices, level, surface.material, out)
        return out

    def rest(self, surface: Surface, plan: SubdivisionPlan) -> np.ndarray | None:
        """The subdivided rest mesh of a surface, the same array while its rest array and plan are (the skin
        model's curvature, skin.surface_radius, is computed once per rest array)."""
        if surface.rest is None:
            return None
        key = (id(surface.rest), id(plan))
        entry = self._rests.get(key)
        if entry is None or entry[0] is not surface.rest or entry[1] is not plan:
            if len(self._rests) > 16:
                self._rests.clear()
            entry = self._rests[key] = (surface.rest, plan, plan.positions(surface.rest))
        return entry[2]


def subdivided_surface(surface: Surface, plan: SubdivisionPlan, rest: np.ndarray | None = None) -> Surface:
    """A skinned surface through its topology's plan: positions Loop, normals of the subdivided mesh, UVs linear on
    their own topology, per-face data repeated over each face's children. rest: its subdivided rest mesh (None:
    subdivided here)."""
    v = plan.positions(surface.vertices)
    uvs = None
    if plan.uv_matrix is not None and surface.uvs is not None:
        uvs = np.ascontiguousarray(plan.uv_matrix @ np.asarray(surface.uvs, np.float32), np.float32)
    per_face = lambda a: None if a is None else np.ascontiguousarray(np.asarray(a)[plan.parent])
    if rest is None and surface.rest is not None:
        rest = plan.positions(surface.rest)
    return dataclasses.replace(surface, vertices=v, faces=plan.faces, normals=vertex_normals(v, plan.faces),
                               uvs=uvs, faces_uv=plan.faces_uv if uvs is not None else None, rest=rest,
                               face_joints=per_face(surface.face_joints), face_labels=per_face(surface.face_labels),
                               local=None, transform=None)
