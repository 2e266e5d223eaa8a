"""Cutting the right hand off hm08 at an edge loop of the forearm, a few centimetres proximal of the wrist.

hm08's forearm is a tube of quad rings (20 vertices around, about 2 cm apart). Cutting through the quads with a
plane would leave slivers; instead the cut keeps whole quads: for a threshold t, a quad is kept when none of its
vertices lies more than t proximal of the wrist joint (along the elbow -> wrist axis) and it is connected to the
hand, and the boundary of what is kept is the wrist loop. Among the thresholds near the requested distance giving
one clean loop, the one scoring best on flatness (spread of the loop along the axis) plus distance from the request
wins: an edge ring of the mesh rather than a staircase across two rings. The loop is then pressed onto the plane
perpendicular to the forearm axis through its mean position, which moves its vertices along the axis by a few
millimetres and gives the wrist step a planar opening to extend.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from darthand.errors import InputError
from darthand.model.topology import boundary_loops


@dataclass(frozen=True)
class ForearmCut:
    """The kept part of the source mesh.

    quads       (F, 4) int64, source vertex ids of the kept quads
    quads_uv    (F, 4) int64, source UV ids per corner
    loop        (L,) int64, source vertex ids of the wrist boundary loop, in the faces' winding order
    offset      float, mean signed distance of the loop along the forearm axis from the wrist joint (source units,
                negative = proximal)
    flattened   (L, 3) float64, loop vertex positions pressed onto the cut plane (source frame and units)
    """

    quads: np.ndarray
    quads_uv: np.ndarray
    loop: np.ndarray
    offset: float
    flattened: np.ndarray


def cut_forearm(vertices: np.ndarray, quads: np.ndarray, quads_uv: np.ndarray, wrist: np.ndarray,
                elbow: np.ndarray, distance: float, window: float | None = None) -> ForearmCut:
    """Keep the hand and the forearm up to the edge loop nearest `distance` proximal of `wrist`.

    vertices (N, 3), quads (F, 4), quads_uv (F, 4); wrist, elbow (3,) joint centres; `distance` > 0 in the
    vertices' units. `window` bounds how far from `distance` a loop may lie (default distance / 2). Only faces
    connected to the fingertips through kept faces are kept, so the rest of the body drops out by itself.
    """
    axis = wrist - elbow
    length = np.linalg.norm(axis)
    axis = axis / length
    if not 0 < distance < length:
        raise InputError(f"cut distance {distance} must lie between 0 and the forearm length {length:.3f}")
    window = distance / 2 if window is None else window
    s = (vertices - wrist) @ axis

    # Seed: the quad nearest the wrist joint among those wholly distal of it (the hand side of every cut).
    gap = np.linalg.norm(vertices[quads].mean(1) - wrist, axis=1)
    seed = int(np.argmin(np.where((s[quads] >= 0).all(1), gap, np.inf)))
    widest = _component(quads, (s[quads] >= -(distance + window)).all(1), seed)
    best = None
    for t in np.unique(-s[quads[widest].reshape(-1)]):
        if not distance - window <= t <= distance + window:
            continue
        keep = _component(quads, widest & (s[quads] >= -t).all(1), seed)
        try:
            loops = boundary_loops(quads[keep])
        except ValueError:  # pinched boundary: not a clean cut
            continue
        if len(loops) != 1:
            continue
        loop_s = s[loops[0]]
        score = np.ptp(loop_s) + abs(loop_s.mean() + distance)
        if best is None or score < best[0]:
            best = (score, keep, loops[0])
    if best is None:
        raise InputError(f"no single clean edge loop lies {distance - window:.3f}..{distance + window:.3f} proximal "
                         "of the wrist joint")
    _, keep, loop = best
    offset = float(s[loop].mean())
    flattened = vertices[loop] + np.outer(offset - s[loop], axis)
    return ForearmCut(quads=quads[keep], quads_uv=quads_uv[keep], loop=loop, offset=offset, flattened=flattened)


def _component(quads: np.ndarray, mask: np.ndarray, seed: int) -> np.ndarray:
    """Mask of the quads within `mask` connected (through shared vertices) to quad `seed`."""
    idx = np.nonzero(mask)[0]
    if seed not in idx:
        raise InputError("the forearm cut removed the wrist itself: cut distance too small")
    q = quads[idx]
    a = np.repeat(np.arange(len(q)), 4)
    graph = coo_matrix((np.ones(len(a)), (a, q.reshape(-1))), shape=(len(q), int(quads.max()) + 1)).tocsr()
    _, labels = connected_components(graph @ graph.T, directed=False)
    out = np.zeros(len(quads), dtype=bool)
    out[idx[labels == labels[np.searchsorted(idx, seed)]]] = True
    return out
