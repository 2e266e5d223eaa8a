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
from darthand.model.proximity import closest_surface_points


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
