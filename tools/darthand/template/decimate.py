"""Decimation of the hand with pymeshlab's texture-aware quadric edge collapse, and attribute transfer.

The collapse keeps UV seams (per-corner texture coordinates), the wrist boundary loop, and any faces marked
protected (the nails and the ring around them, so their outline survives). Vertices stay at source positions
(no optimal placement), so every surviving vertex lies exactly on the source surface and the nearest-surface-point
transfer of per-vertex data (skin weights...) is exact for it.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pymeshlab
from scipy.spatial import cKDTree

from darthand.model import topology


def decimate(vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray, faces_uv: np.ndarray, target_vertices: int,
             protect: np.ndarray | None = None, quality: float = 0.5):
    """Collapse edges until about `target_vertices` remain.

    vertices (V, 3), faces (F, 3), uvs (T, 2), faces_uv (F, 3); `protect` (F,) bool marks faces never collapsed.
    Returns (vertices (V', 3), faces (F', 3), uvs (T', 2), faces_uv (F', 3)).
    """
    loops = topology.boundary_loops(faces)
    target_faces = 2 * target_vertices - 2 - sum(len(loop) for loop in loops)  # Euler, for a disc-like surface
    ms = pymeshlab.MeshSet()
    _load_textured(ms, vertices, faces, uvs, faces_uv, protect)
    if protect is not None:
        ms.compute_selection_by_condition_per_face(condselect="fq < 0.5")  # collapse only unprotected faces
    ms.meshing_decimation_quadric_edge_collapse_with_texture(
        targetfacenum=int(target_faces), qualitythr=quality, preserveboundary=True, boundaryweight=10.0,
        optimalplacement=False, preservenormal=True, planarquadric=True, selected=protect is not None)
    ms.meshing_remove_unreferenced_vertices()
    out = ms.current_mesh()
    new_vertices = out.vertex_matrix().astype(np.float64)
    new_faces = out.face_matrix().astype(np.int64)
    wedge = out.wedge_tex_coord_matrix().reshape(-1, 3, 2)
    new_uvs, inverse = np.unique(wedge.reshape(-1, 2), axis=0, return_inverse=True)
    return new_vertices, new_faces, new_uvs, inverse.reshape(-1, 3).astype(np.int64)


def _load_textured(ms: pymeshlab.MeshSet, vertices, faces, uvs, faces_uv, protect) -> None:
    """Load the mesh through a PLY file with per-wedge UVs, a texture index per face and the protection flag as
    face quality: pymeshlab's in-memory `Mesh` leaves the wedge texture index undefined, which the
    texture-aware collapse refuses."""
    wedge = uvs[faces_uv].reshape(len(faces), 6)
    quality = np.zeros(len(faces)) if protect is None else protect.astype(np.float64)
    header = "\n".join([
        "ply", "format ascii 1.0", "comment TextureFile hand_atlas.png", f"element vertex {len(vertices)}",
        "property double x", "property double y", "property double z", f"element face {len(faces)}",
        "property list uchar int vertex_indices", "property list uchar float texcoord", "property int texnumber",
        "property float quality", "end_header"])
    lines = [" ".join(f"{c:.17g}" for c in v) for v in vertices]
    lines += [f"3 {f[0]} {f[1]} {f[2]} 6 " + " ".join(f"{t:.9g}" for t in w) + f" 0 {q:g}"
              for f, w, q in zip(faces, wedge, quality)]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "hand.ply"
        path.write_text(header + "\n" + "\n".join(lines) + "\n")
        ms.load_new_mesh(str(path))


def transfer_vertex_attributes(src_vertices: np.ndarray, src_faces: np.ndarray, src_values: np.ndarray,
                               points: np.ndarray) -> np.ndarray:
    """Values (P, ...) at `points` (P, 3) from per-vertex `src_values` (V, ...) on the source triangle mesh,
    interpolated barycentrically at each point's nearest point on the source surface."""
    tri, bary, _ = closest_surface_points(src_vertices, src_faces, points)
    return np.einsum("pk,pk...->p...", bary, src_values[src_faces[tri]])


def source_vertices(src_vertices: np.ndarray, points: np.ndarray, tolerance: float = 1e-9) -> np.ndarray:
    """(P,) index of the source vertex each of `points` (P, 3) sits on: the decimation keeps source positions, so
    every surviving vertex is one of them (raises if one is not, within `tolerance`)."""
    dist, idx = cKDTree(src_vertices).query(points)
    if dist.max() > tolerance:
        raise ValueError(f"decimated vertex {int(np.argmax(dist))} is {dist.max():.3g} from every source vertex")
    return idx


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
