"""Mesh helpers of the importer: quads -> triangles (per-corner attributes split alike), areas, surface checks."""

from __future__ import annotations

import numpy as np

from darthand.errors import DarthandError
from darthand.model import topology


def triangulate_quads(vertices: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Corner indices (2F, 3), values 0..3, splitting each of `quads` (F, 4) along its shorter diagonal.

    The split keeps each quad's winding. Apply it to any per-corner array with `split_quad_attribute`.
    """
    p = vertices[quads]
    d02 = np.linalg.norm(p[:, 0] - p[:, 2], axis=1)
    d13 = np.linalg.norm(p[:, 1] - p[:, 3], axis=1)
    along02 = np.array([[0, 1, 2], [0, 2, 3]])
    along13 = np.array([[0, 1, 3], [1, 2, 3]])
    corners = np.where((d02 <= d13)[:, None, None], along02, along13)  # (F, 2, 3)
    return corners.reshape(-1, 3)


def split_quad_attribute(quad_attr: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(F, 4) per-corner attribute + (2F, 3) corners from `triangulate_quads` -> (2F, 3) per-triangle attribute."""
    return np.take_along_axis(np.repeat(quad_attr, 2, axis=0), corners, axis=1)


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) triangle areas."""
    p = vertices[faces]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def check_surface(vertices: np.ndarray, faces: np.ndarray, what: str = "hand mesh") -> None:
    """Raise if the mesh is not one clean open surface: one boundary loop, manifold edges, consistent winding,
    no degenerate or repeated faces. The importer calls it on its result; a failure is a bug in the importer or an
    unexpected source, never silently passed on."""
    problems = []
    if len(topology.non_manifold_edges(faces)):
        problems.append(f"{len(topology.non_manifold_edges(faces))} non-manifold edges")
    try:
        n_loops = len(topology.boundary_loops(faces))
    except ValueError as e:
        n_loops = f"pinched ({e})"
    if n_loops != 1:
        problems.append(f"{n_loops} boundary loops (expected 1)")
    if len(topology.inconsistent_edges(faces)):
        problems.append("inconsistent winding")
    areas = face_areas(vertices, faces)
    if (areas < 1e-12).any():
        problems.append(f"{int((areas < 1e-12).sum())} degenerate faces")
    if len(np.unique(np.sort(faces, 1), axis=0)) != len(faces) or (np.diff(np.sort(faces, 1), axis=1) == 0).any():
        problems.append("repeated or collapsed faces")
    if problems:
        raise DarthandError(f"{what}: " + ", ".join(problems))
