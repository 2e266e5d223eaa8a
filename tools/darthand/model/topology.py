"""Mesh topology of triangle meshes: edges, boundary loops, manifoldness, winding consistency.

faces: (F, 3) int vertex indices. A directed edge (a, b) belongs to the face that lists b right after a.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.sparse as sp


def directed_edges(faces: np.ndarray) -> np.ndarray:
    """(3F, 2) directed edges (a, b) of every face, in face order."""
    f = np.asarray(faces)
    return np.stack([f, np.roll(f, -1, axis=1)], axis=-1).reshape(-1, 2)


def _unique_edges(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distinct (a, b) pairs (E, 2) and their counts, counted on one int64 key per pair: np.unique(axis=0) sorts
    rows as opaque records, about ten times slower on large meshes."""
    n = int(max(a.max(initial=0), b.max(initial=0))) + 1
    keys, counts = np.unique(a.astype(np.int64) * n + b, return_counts=True)
    return np.stack(np.divmod(keys, n), 1), counts


def edge_face_counts(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undirected edges (E, 2) with a < b, and how many faces use each."""
    d = directed_edges(faces)
    return _unique_edges(d.min(1), d.max(1))


def non_manifold_edges(faces: np.ndarray) -> np.ndarray:
    """(K, 2) undirected edges used by more than two faces."""
    edges, counts = edge_face_counts(faces)
    return edges[counts > 2]


def inconsistent_edges(faces: np.ndarray) -> np.ndarray:
    """(K, 2) directed edges that occur twice in the same direction (neighbouring faces wound oppositely)."""
    d = directed_edges(faces)
    edges, counts = _unique_edges(d[:, 0], d[:, 1])
    return edges[counts > 1]


def boundary_loops(faces: np.ndarray) -> list[np.ndarray]:
    """Boundary loops as vertex index arrays, each ordered along its faces' directed edges
    (so consecutive loop vertices (l_k, l_k+1) are a directed edge of a face), longest first.

    Raises ValueError if a boundary vertex has more than one outgoing boundary edge (a pinched boundary).
    """
    d = directed_edges(faces)
    key = np.sort(d, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    boundary = d[counts[inverse.reshape(-1)] == 1]
    nxt: dict[int, int] = {}
    for a, b in boundary.tolist():
        if a in nxt:
            raise ValueError(f"boundary is pinched at vertex {a}")
        nxt[a] = b
    loops, seen = [], set()
    for start in sorted(nxt):
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt.get(v, start)
        loops.append(np.array(loop, dtype=np.int64))
    return sorted(loops, key=len, reverse=True)


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume (m^3) enclosed by the faces (positive for outward winding of a closed mesh)."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def close_loops(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with every boundary loop closed by a fan around its centroid (for volume and inside tests)."""
    verts, new_faces = [vertices], [faces]
    n = len(vertices)
    for loop in boundary_loops(faces):
        verts.append(vertices[loop].mean(0, keepdims=True))
        # The loop runs along its faces' edges, so the cap runs the other way: (b, a, centre).
        new_faces.append(np.stack([np.roll(loop, -1), loop, np.full(len(loop), n)], 1))
        n += 1
    return np.concatenate(verts), np.concatenate(new_faces)


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(..., F, 3) unit face normals for vertices (..., V, 3); zero for degenerate faces."""
    a, b, c = (vertices[..., faces[:, k], :] for k in range(3))
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) area-weighted unit vertex normals, in the vertices' float dtype (zero for unused vertices).

    One sparse product with the vertex-face incidence matrix, built once per topology: faster than np.add.at's
    scatter, which matters because the renderer recomputes the hand's normals every frame."""
    v = np.asarray(vertices)
    if not np.issubdtype(v.dtype, np.floating):
        v = v.astype(np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int32)
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    n = _incidence(faces.tobytes(), len(v)) @ np.cross(b - a, c - a)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0).astype(v.dtype, copy=False)


@functools.lru_cache(maxsize=16)
def _incidence(faces_bytes: bytes, num_vertices: int) -> sp.csr_matrix:
    """(V, F) matrix with a 1 where vertex v is a corner of face f."""
    rows = np.frombuffer(faces_bytes, dtype=np.int32)
    cols = np.repeat(np.arange(len(rows) // 3), 3)
    return sp.csr_matrix((np.ones(len(rows), np.float32), (rows, cols)), shape=(num_vertices, len(rows) // 3))


def face_joints(faces: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(F,) int64 the joint with the largest skinning weight summed over each face's corners (weights (V, J))."""
    return np.argmax(weights[faces].sum(axis=1), axis=1)
