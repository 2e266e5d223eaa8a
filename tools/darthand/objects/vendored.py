"""Meshes taken from packages (assets_src/objects/<package>/): their OBJ read with its texture coordinates, scaled as
the package says, and, where the item allows it, closed (MeshLab's non-manifold repair and hole filling) with what
was done recorded."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pymeshlab
import trimesh

from darthand.errors import InputError
from darthand.fileio import read_bytes


@dataclass
class MeshData:
    """vertices (N, 3) float64 metres, faces (F, 3) int64, uvs (T, 2) and faces_uv (F, 3) or None, and the repairs
    made (one line each)."""

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None = None
    faces_uv: np.ndarray | None = None
    repairs: list[str] = field(default_factory=list)


def read_obj(path: Path) -> MeshData:
    """A Wavefront OBJ's positions, triangles (polygons fanned) and texture coordinates; InputError naming the file
    when it is unreadable or indexes outside its vertices."""
    text = read_bytes(path, "object mesh", max_bytes=64 << 20).decode("utf-8", "replace")
    v, vt, f, ft = [], [], [], []
    try:
        for line in text.splitlines():
            tok = line.split()
            if not tok:
                continue
            if tok[0] == "v":
                v.append([float(x) for x in tok[1:4]])
            elif tok[0] == "vt":
                vt.append([float(x) for x in tok[1:3]])
            elif tok[0] == "f":
                corners = [c.split("/") for c in tok[1:]]
                for k in range(1, len(corners) - 1):
                    tri = (corners[0], corners[k], corners[k + 1])
                    f.append([int(c[0]) - 1 for c in tri])
                    ft.append([int(c[1]) - 1 if len(c) > 1 and c[1] else -1 for c in tri])
    except (ValueError, IndexError) as e:
        raise InputError(f"{path}: unreadable OBJ ({e})") from None
    vertices, faces = np.array(v, float).reshape(-1, 3), np.array(f, np.int64).reshape(-1, 3)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise InputError(f"{path}: faces index a vertex outside 0..{len(vertices) - 1}")
    faces_uv = np.array(ft, np.int64).reshape(-1, 3)
    textured = len(vt) > 0 and faces_uv.size > 0 and faces_uv.min() >= 0 and faces_uv.max() < len(vt)
    return MeshData(vertices, faces, np.array(vt, float) if textured else None, faces_uv if textured else None)


def closed(mesh: MeshData) -> bool:
    """Whether the mesh is watertight and consistently wound."""
    t = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    return bool(t.is_watertight and t.is_winding_consistent)


def repair(mesh: MeshData) -> MeshData:
    """The mesh closed: duplicate vertices welded, then (where edges are still shared by more than two faces) the
    faces spanning only such edges' vertices removed (an inner membrane, such as a wall between a bottle and its
    cap), then any hole left filled by MeshLab (no new vertices). Texture coordinates are per face corner and stay
    with their faces; a new face takes, per corner, the coordinate its vertex has elsewhere. Each step taken is
    recorded in `repairs`."""
    out = MeshData(mesh.vertices, mesh.faces, mesh.uvs, mesh.faces_uv, list(mesh.repairs))
    out = _welded(out)
    if not closed(out):
        out = _without_membranes(out)
    if not closed(out):
        out = _holes_filled(out)
    return out


def _welded(mesh: MeshData) -> MeshData:
    """Vertices at equal positions merged (the first of each kept, in order)."""
    _, first, inverse = np.unique(mesh.vertices, axis=0, return_index=True, return_inverse=True)
    if len(first) == len(mesh.vertices):
        return mesh
    keep = np.sort(first)
    index_of = np.empty(len(mesh.vertices), np.int64)
    index_of[keep] = np.arange(len(keep))
    faces = index_of[first[inverse.ravel()]][mesh.faces]
    repairs = mesh.repairs + [f"welded {len(mesh.vertices) - len(keep)} duplicate vertices"]
    return MeshData(mesh.vertices[keep], faces, mesh.uvs, mesh.faces_uv, repairs)


def _without_membranes(mesh: MeshData) -> MeshData:
    """Faces whose three vertices all lie on edges shared by more than two faces removed."""
    edges = np.sort(mesh.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    on_bad = np.zeros(len(mesh.vertices), bool)
    on_bad[unique[counts > 2].ravel()] = True
    membrane = on_bad[mesh.faces].all(axis=1)
    if not membrane.any():
        return mesh
    repairs = mesh.repairs + [f"removed {int(membrane.sum())} inner faces on edges shared by more than two faces"]
    faces_uv = None if mesh.faces_uv is None else mesh.faces_uv[~membrane]
    return MeshData(mesh.vertices, mesh.faces[~membrane], mesh.uvs, faces_uv, repairs)


def _holes_filled(mesh: MeshData) -> MeshData:
    """Every hole filled by MeshLab's hole closing (triangles over the existing vertices)."""
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(mesh.vertices, mesh.faces.astype(np.int32)))
    ms.meshing_close_holes(maxholesize=100000, newfaceselected=False)
    m = ms.current_mesh()
    vertices, faces = np.asarray(m.vertex_matrix(), float), np.asarray(m.face_matrix(), np.int64)
    if not np.array_equal(vertices, mesh.vertices):
        raise InputError("hole filling moved or renumbered vertices")
    old = {tuple(sorted(t)): k for k, t in enumerate(mesh.faces.tolist())}
    kept = np.array([old.get(tuple(sorted(t)), -1) for t in faces.tolist()])
    added = int((kept < 0).sum())
    faces_uv = None if mesh.faces_uv is None else _carried_uvs(mesh, faces, kept)
    return MeshData(vertices, faces, mesh.uvs, faces_uv, mesh.repairs + [f"filled holes with {added} faces"])


def _carried_uvs(mesh: MeshData, faces: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """faces_uv for `faces`: a kept face's own corners (matched by vertex), a new face's per-vertex coordinate."""
    assert mesh.faces_uv is not None
    per_vertex = np.zeros(len(mesh.vertices), np.int64)
    per_vertex[mesh.faces.ravel()[::-1]] = mesh.faces_uv.ravel()[::-1]      # each vertex's first corner wins
    out = per_vertex[faces]
    for i in np.flatnonzero(kept >= 0):
        src = kept[i]
        lookup = dict(zip(mesh.faces[src].tolist(), mesh.faces_uv[src].tolist()))
        out[i] = [lookup[v] for v in faces[i].tolist()]
    return out


def load_vendored(path: Path, scale, allow_repair: bool, where: str) -> MeshData:
    """The OBJ at `path` scaled by `scale` (3,); closed by `repair` when it is not and `allow_repair`, else
    InputError naming it."""
    mesh = read_obj(path)
    mesh.vertices = mesh.vertices * np.asarray(scale, float)
    if not closed(mesh):
        if not allow_repair:
            raise InputError(f"{where}: the mesh is not closed (edges not shared by exactly two faces)")
        mesh = repair(mesh)
    return mesh
