"""Closed mesh primitives the object generators assemble: surfaces of revolution, rounded slabs (boxes, phones,
cards), capped tubes along a path, spheres, and their union. Every function returns (vertices (N, 3) float64 metres,
faces (F, 3) int64) of a closed mesh wound counter-clockwise seen from outside."""

from __future__ import annotations

import numpy as np
import pymeshlab
import trimesh
from scipy.spatial import ConvexHull

from darthand.errors import DarthandError


def revolve(profile, segments: int = 48, phase: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The surface swept by `profile` ((K, 2) array or list of (radius, z) points, metres) turned about +z. The
    first and last points lie on the axis (radius 0: the poles that close it); the others have radius > 0.
    `segments` around (6: a hexagonal pencil), the first at angle `phase` (radians)."""
    profile = np.asarray(profile, float)
    if profile[0, 0] != 0 or profile[-1, 0] != 0 or (profile[1:-1, 0] <= 0).any():
        raise DarthandError("revolve: the profile must start and end on the axis and stay off it between")
    rings = profile[1:-1]
    angle = phase + 2 * np.pi * np.arange(segments) / segments
    ring_xyz = np.stack([rings[:, :1] * np.cos(angle), rings[:, :1] * np.sin(angle),
                         np.repeat(rings[:, 1:], segments, axis=1)], axis=-1).reshape(-1, 3)
    bottom, top = len(ring_xyz), len(ring_xyz) + 1
    vertices = np.vstack([ring_xyz, [[0, 0, profile[0, 1]], [0, 0, profile[-1, 1]]]])
    j = np.arange(segments)
    jn = (j + 1) % segments
    faces = [np.column_stack([np.full(segments, bottom), jn, j])]
    for r in range(len(rings) - 1):
        a, b = r * segments + j, r * segments + jn
        c, d = a + segments, b + segments
        faces += [np.column_stack([a, b, d]), np.column_stack([a, d, c])]
    last = (len(rings) - 1) * segments
    faces.append(np.column_stack([np.full(segments, top), last + j, last + jn]))
    return outward(vertices, np.vstack(faces))


def rounded_slab(size, corner_r: float, edge_r: float, corner_steps: int = 8,
                 edge_steps: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A box of extents `size` (dx, dy, dz), metres, centred at the origin, its four vertical edges rounded with
    radius `corner_r` (seen from +z) and its top and bottom rims with `edge_r` <= corner_r (0: square rims, as a
    card's). corner_r = edge_r is a box rounded everywhere; corner_r = dx / 2 = dy / 2 a disc."""
    half = np.asarray(size, float) / 2
    corner_r = min(corner_r, half[0], half[1])
    edge_r = min(edge_r, corner_r, half[2])
    theta = np.linspace(0, np.pi / 2, corner_steps + 1)
    phi = np.linspace(0, np.pi / 2, edge_steps + 1) if edge_r > 0 else np.zeros(1)
    points = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            centre = np.array([sx * (half[0] - corner_r), sy * (half[1] - corner_r)])
            for sz in (-1, 1):
                for p in phi:
                    reach = corner_r - edge_r + edge_r * np.cos(p)
                    xy = centre + reach * np.column_stack([sx * np.cos(theta), sy * np.sin(theta)])
                    z = sz * (half[2] - edge_r + edge_r * np.sin(p))
                    points.append(np.column_stack([xy, np.full(len(xy), z)]))
    return convex_hull(np.vstack(points))


def convex_hull(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of `points` (P, 3) as a closed mesh (points inside it dropped)."""
    unique = np.unique(np.round(np.asarray(points, float), 12), axis=0)
    hull = ConvexHull(unique)
    simplices = hull.simplices.copy()
    tri = unique[simplices]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    inward = np.einsum("ij,ij->i", normal, hull.equations[:, :3]) < 0     # qhull's facet normals point outward
    simplices[inward] = simplices[inward][:, ::-1]
    used = np.unique(simplices)
    remap = np.full(len(unique), -1)
    remap[used] = np.arange(len(used))
    return outward(unique[used], remap[simplices])


def ellipsoid(radii, subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """An ellipsoid of semi-axes `radii` (3,), metres: a subdivided icosahedron, scaled."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    return outward(np.asarray(sphere.vertices) * np.asarray(radii, float), np.asarray(sphere.faces))


def tube(path: np.ndarray, radius: float, sides: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A tube of `radius` (metres) along `path` (K, 3), each end closed by a pole on the path's end point pushed
    out by the radius (a rounded-off cap)."""
    path = np.asarray(path, float)
    tangent = np.gradient(path, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    ref = np.array([0.0, 1.0, 0.0]) if abs(tangent[0, 1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    normal = np.cross(tangent, ref)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)
    angle = 2 * np.pi * np.arange(sides) / sides
    ring = (path[:, None] + radius * (np.cos(angle)[None, :, None] * normal[:, None]
                                      + np.sin(angle)[None, :, None] * binormal[:, None])).reshape(-1, 3)
    start, end = path[0] - tangent[0] * radius * 0.6, path[-1] + tangent[-1] * radius * 0.6
    vertices = np.vstack([ring, start, end])
    j = np.arange(sides)
    jn = (j + 1) % sides
    faces = [np.column_stack([np.full(sides, len(ring)), jn, j])]
    for k in range(len(path) - 1):
        a, b = k * sides + j, k * sides + jn
        faces += [np.column_stack([a, b, b + sides]), np.column_stack([a, b + sides, a + sides])]
    last = (len(path) - 1) * sides
    faces.append(np.column_stack([np.full(sides, len(ring) + 1), last + j, last + jn]))
    return outward(vertices, np.vstack(faces))


def boolean(meshes: list[tuple[np.ndarray, np.ndarray]], op: str = "union") -> tuple[np.ndarray, np.ndarray]:
    """The union of closed meshes (or, with op 'difference', the first minus the others), through MeshLab's exact
    boolean; DarthandError if the result is not closed."""
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(meshes[0][0], float), np.asarray(meshes[0][1], np.int32)))
    for v, f in meshes[1:]:
        current = ms.current_mesh_id()
        ms.add_mesh(pymeshlab.Mesh(np.asarray(v, float), np.asarray(f, np.int32)))
        other = ms.current_mesh_id()
        if op == "union":
            ms.generate_boolean_union(first_mesh=current, second_mesh=other)
        else:
            ms.generate_boolean_difference(first_mesh=current, second_mesh=other)
    m = ms.current_mesh()
    return outward(np.asarray(m.vertex_matrix(), float), np.asarray(m.face_matrix(), np.int64))


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """The enclosed volume (m^3): positive for an outward-wound closed mesh."""
    tri = vertices[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def outward(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with its winding reversed when its signed volume is negative (inside out)."""
    faces = np.asarray(faces, np.int64)
    if signed_volume(vertices, faces) < 0:
        faces = faces[:, ::-1]
    return np.asarray(vertices, float), np.ascontiguousarray(faces)


def transformed(mesh: tuple[np.ndarray, np.ndarray], rotation=None, offset=(0.0, 0.0, 0.0)):
    """The mesh rotated by `rotation` (3, 3) then moved by `offset` (3,) metres."""
    v, f = mesh
    R = np.eye(3) if rotation is None else np.asarray(rotation, float)
    return v @ R.T + np.asarray(offset, float), f


def rotation_y(angle: float) -> np.ndarray:
    """Rotation by `angle` radians about +y."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rotation_x(angle: float) -> np.ndarray:
    """Rotation by `angle` radians about +x."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
