"""Cross-sections of the hand across a bone, and the smallest circle or ellipse around them.

A bone frame is a 4x4 transform (columns x = bone axis, y = dorsal, z = x cross y, origin on the axis). A section
is the hand surface cut by planes x_local = const, kept to the loop around the axis (a finger's cut also meets its
neighbours), in plane coordinates (y, z) relative to the frame origin, metres.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import trimesh
from scipy.sparse.csgraph import connected_components

from darthand.errors import InputError


def section_points(vertices: np.ndarray, faces: np.ndarray, frame: np.ndarray, offsets=(0.0,),
                   what: str = "section", own_faces: np.ndarray | None = None,
                   skip_open: bool = False) -> np.ndarray:
    """(K, 2) points of the loops around the frame's axis cut at each x_local in `offsets` (metres).

    own_faces: optional (F,) bool, the faces of the part being measured (a finger's own skin); where the plane also
    crosses the web into a neighbour, the whole-mesh loop would run around both, so the loops are cut from these
    faces, and from the whole mesh only if they give none (or, without skip_open, not one at every plane).
    skip_open: leave out planes that give no closed loop (a slab reaching into a finger's web), as long as one
    plane does. Raises InputError naming `what` if a plane (with skip_open: every plane) gives no closed loop.
    """
    local = (vertices - frame[:3, 3]) @ frame[:3, :3]          # rest vertices in the bone frame
    whole = trimesh.Trimesh(local, faces, process=False)
    if own_faces is not None and own_faces.any():
        own = trimesh.Trimesh(local, faces[own_faces], process=False)
        loops = [_cut(own, x) for x in offsets]
        if skip_open and any(lp is not None for lp in loops):
            return np.concatenate([lp for lp in loops if lp is not None])
        if all(lp is not None for lp in loops):
            return np.concatenate([lp for lp in loops if lp is not None])
    out = []
    for x in offsets:
        loop = _cut(whole, x)
        if loop is None and not skip_open:
            raise InputError(f"{what}: no closed section of the hand around the axis {x * 1000:.1f} mm along it")
        if loop is not None:
            out.append(loop)
    if not out:
        raise InputError(f"{what}: no closed section of the hand around the axis")
    return np.concatenate(out)


def _cut(mesh: trimesh.Trimesh, x: float) -> np.ndarray | None:
    segs = trimesh.intersections.mesh_plane(mesh, [1.0, 0.0, 0.0], [float(x), 0.0, 0.0])
    return _loop_around_origin(segs[:, :, 1:]) if len(segs) else None


def _loop_around_origin(segs: np.ndarray) -> np.ndarray | None:
    """Endpoints of the closed loop of 2D segments (S, 2, 2) that winds around (0, 0); the smallest if several."""
    pts = segs.reshape(-1, 2)
    _, ids = np.unique(np.round(pts / 1e-9).astype(np.int64), axis=0, return_inverse=True)
    ids = ids.reshape(-1, 2)
    n = int(ids.max()) + 1
    graph = sp.coo_matrix((np.ones(len(ids)), (ids[:, 0], ids[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    seg_label = label[ids[:, 0]]
    degree = np.bincount(ids.ravel(), minlength=n)
    best, best_r = None, np.inf
    for c in np.unique(seg_label):
        s = segs[seg_label == c]
        closed = (degree[np.unique(ids[seg_label == c])] == 2).all()   # a loop, not a chain cut short
        if closed and _crossings(s) % 2 == 1:
            r = np.linalg.norm(s.reshape(-1, 2), axis=1).max()
            if r < best_r:
                best, best_r = s.reshape(-1, 2), r
    return best


def _crossings(segs: np.ndarray) -> int:
    """How many segments cross the ray from the origin along +y (half-open rule, so shared endpoints count once)."""
    a, b = segs[:, 0], segs[:, 1]
    straddle = (a[:, 1] > 0) != (b[:, 1] > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = a[:, 1] / (a[:, 1] - b[:, 1])
        x = a[:, 0] + t * (b[:, 0] - a[:, 0])
    return int((straddle & (x > 0)).sum())


def enclosing_circle(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (2,) and radius of the smallest circle containing the 2D points (trimesh's minimum n-sphere)."""
    centre, radius = trimesh.nsphere.minimum_nsphere(np.asarray(points, float))
    return np.asarray(centre, float), float(radius)


def enclosing_ellipse(points: np.ndarray, aspects: int = 241) -> tuple[np.ndarray, float, float]:
    """Centre (2,) and half-axes (a along y, b along z) of the smallest-area axis-aligned ellipse that contains the
    points, centred on their bounding box: for each aspect k = a / b on a grid, the smallest b is
    max sqrt((y / k)^2 + z^2); keep the k with the least area k b^2."""
    p = np.asarray(points, float)
    centre = (p.min(0) + p.max(0)) / 2
    q = p - centre
    k0 = max(np.abs(q[:, 0]).max(), 1e-9) / max(np.abs(q[:, 1]).max(), 1e-9)
    ks = k0 * np.geomspace(0.6, 1.6, aspects)
    b = np.sqrt((q[None, :, 0] / ks[:, None]) ** 2 + q[None, :, 1] ** 2).max(1)
    i = int(np.argmin(ks * b ** 2))
    return centre, float(ks[i] * b[i]), float(b[i])
