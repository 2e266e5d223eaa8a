"""Mesh rules, on numpy arrays (both formats feed their meshes through `check_mesh`).

    mesh.nonfinite-point     a point is NaN or infinite
    mesh.face-index          a face indexes a point outside the mesh (the other topology rules are then skipped)
    mesh.degenerate-face     a face has zero area: repeated corners, or cross-product length below
                             DEGENERATE_RATIO times its longest edge squared (sliver angle < ~1e-6 rad)
    mesh.duplicate-face      two faces use the same three points (in any order)
    mesh.non-manifold-edge   an edge is shared by more than two faces
    mesh.open-boundary       a hand mesh has a boundary loop besides the one forearm opening
    mesh.winding             two faces sharing an edge traverse it in the same direction
    mesh.uv-index / mesh.uv-nonfinite / mesh.uv-range    face-corner UVs out of their array, NaN, outside [0, 1]

Topology is computed on the points welded by exact position, so that a mesh split along UV seams (every glTF
mesh) is judged as the surface it draws; degenerate and repeated faces are left out of the topology rules so one
defect is reported once.
"""

from __future__ import annotations

import numpy as np

from darthand.model.topology import boundary_loops, inconsistent_edges, non_manifold_edges
from darthand.validate.asset import Mesh
from darthand.validate.findings import Finding, examples, finding

DEGENERATE_RATIO = 1e-6
UV_TOLERANCE = 1e-6


def check_mesh(mesh: Mesh) -> list[Finding]:
    """Every mesh rule on one mesh."""
    out: list[Finding] = []
    points, faces = mesh.points, mesh.faces
    bad_points = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if len(bad_points):
        out.append(finding("mesh.nonfinite-point", mesh.path,
                           f"points NaN or infinite: {examples(bad_points)}"))
    if faces.size and (faces.min() < 0 or faces.max() >= len(points)):
        bad = np.flatnonzero(((faces < 0) | (faces >= len(points))).any(axis=1))
        out.append(finding("mesh.face-index", mesh.path, f"faces indexing points outside 0..{len(points) - 1}: "
                           f"{examples(bad)}"))
        return out
    welded = weld(points)[faces]
    degenerate = degenerate_faces(points, welded, faces)
    if len(degenerate):
        out.append(finding("mesh.degenerate-face", mesh.path,
                           f"faces with zero area: {examples(degenerate)}"))
    keep = np.ones(len(faces), bool)
    keep[degenerate] = False
    duplicates = duplicate_faces(welded, keep)
    if len(duplicates):
        out.append(finding("mesh.duplicate-face", mesh.path,
                           f"faces repeating an earlier face: {examples(duplicates)}"))
    keep[duplicates] = False
    # NaN points weld to nothing, which would open spurious holes: their faces stay out of the boundary rule.
    out += check_topology(mesh, welded[keep], boundaries=not len(bad_points))
    return out + check_uvs(mesh)


def weld(points: np.ndarray) -> np.ndarray:
    """(N,) id of each point's position class: points at exactly the same position share an id (NaN points get ids
    of their own). A lexicographic sort of the coordinates: np.unique(axis=0) sorts rows as opaque records, ~10x
    slower, and a pipeline package checks ~0.5M accessory faces."""
    if not len(points):
        return np.zeros(0, np.int64)
    order = np.lexsort(points.T[::-1])
    p = points[order]
    new = np.ones(len(p), bool)
    new[1:] = (p[1:] != p[:-1]).any(axis=1)
    ids = np.empty(len(p), np.int64)
    ids[order] = np.cumsum(new) - 1
    return ids


def edge_keys(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """One int64 per (a, b) pair of point ids below n, so that rows can be counted with a 1-D np.unique."""
    return a.astype(np.int64) * n + b


def degenerate_faces(points: np.ndarray, welded: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Indices of faces with repeated (welded) corners or (near) zero area."""
    repeated = (welded[:, 0] == welded[:, 1]) | (welded[:, 1] == welded[:, 2]) | (welded[:, 0] == welded[:, 2])
    a, b, c = (points[faces[:, k]] for k in range(3))
    with np.errstate(invalid="ignore", over="ignore"):
        cross = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        longest = np.max([np.einsum("ij,ij->i", e, e) for e in (b - a, c - b, a - c)], axis=0)
        flat = cross <= DEGENERATE_RATIO * longest      # NaN corners compare False: reported as non-finite instead
    return np.flatnonzero(repeated | flat)


def duplicate_faces(welded: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Indices of kept faces whose sorted corners equal an earlier kept face's."""
    ids = np.flatnonzero(keep)
    if not len(ids):
        return ids
    f = np.sort(welded[ids], axis=1)
    n = int(f.max()) + 1
    if n < 2 ** 21:                    # three ids fit one int64 key
        _, first = np.unique(edge_keys(edge_keys(f[:, 0], f[:, 1], n), f[:, 2], n), return_index=True)
    else:
        _, first = np.unique(f, axis=0, return_index=True)
    repeat = np.ones(len(ids), bool)
    repeat[first] = False
    return ids[repeat]


def edge_problems(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undirected edges (K, 2) used by more than two faces, and directed edges (M, 2) that both faces of a
    two-face edge traverse the same way (topology's inconsistent edges, less those of the first kind)."""
    fans = non_manifold_edges(faces)
    flipped = inconsistent_edges(faces)
    if len(fans) and len(flipped):
        fan_set = {tuple(e) for e in fans.tolist()}
        flipped = flipped[[tuple(sorted(e)) not in fan_set for e in flipped.tolist()]]
    return fans, flipped


def check_topology(mesh: Mesh, faces: np.ndarray, boundaries: bool = True) -> list[Finding]:
    """Manifold edges, consistent winding and (for the hand, with `boundaries`) a single boundary loop, on welded,
    clean faces."""
    if not len(faces):
        return []
    out = []
    fans, flipped = edge_problems(faces)
    if len(fans):
        out.append(finding("mesh.non-manifold-edge", mesh.path, f"edges shared by more than two faces: {len(fans)} "
                           f"(first between welded points {fans[0][0]} and {fans[0][1]})"))
    if len(flipped):
        out.append(finding("mesh.winding", mesh.path, f"edges both faces traverse in the same direction: "
                           f"{len(flipped)} (first between welded points {flipped[0][0]} and {flipped[0][1]})"))
    if boundaries and mesh.role == "hand" and not len(fans):
        try:
            loops = boundary_loops(faces)
        except ValueError as e:
            out.append(finding("mesh.open-boundary", mesh.path, f"the boundary is not a set of simple loops ({e})"))
        else:
            if len(loops) > 1:
                sizes = ", ".join(str(len(lp)) for lp in loops[1:6])
                out.append(finding("mesh.open-boundary", mesh.path,
                                   f"open boundaries besides the forearm opening ({len(loops[0])} "
                                   f"edges): {len(loops) - 1}, of {sizes} edges"))
    return out


def check_uvs(mesh: Mesh) -> list[Finding]:
    """UVs used by the faces: indices in range, finite, inside [0, 1]."""
    if mesh.uvs is None or mesh.uv_faces is None or not mesh.uv_faces.size:
        return []
    uvs, idx = mesh.uvs, mesh.uv_faces
    if idx.min() < 0 or idx.max() >= len(uvs):
        bad = np.flatnonzero(((idx < 0) | (idx >= len(uvs))).any(axis=1))
        return [finding("mesh.uv-index", mesh.path, f"faces indexing UVs outside 0..{len(uvs) - 1}: "
                        f"{examples(bad)}")]
    mask = np.zeros(len(uvs), bool)
    mask[idx.reshape(-1)] = True
    used = np.flatnonzero(mask)
    out = []
    nonfinite = used[~np.isfinite(uvs[used]).all(axis=1)]
    if len(nonfinite):
        out.append(finding("mesh.uv-nonfinite", mesh.path, f"UVs NaN or infinite: {examples(nonfinite)}"))
    with np.errstate(invalid="ignore"):
        outside = used[((uvs[used] < -UV_TOLERANCE) | (uvs[used] > 1 + UV_TOLERANCE)).any(axis=1)]
    if len(outside):
        u = uvs[outside[0]]
        out.append(finding("mesh.uv-range", mesh.path, f"UVs outside [0, 1]: {examples(outside)} (UV {outside[0]} is "
                           f"({u[0]:.4g}, {u[1]:.4g}))"))
    return out
