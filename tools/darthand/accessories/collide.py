"""Penetration measures between the posed hand and its accessories (metres; callers report mm).

Rigid accessories: the overlap depth of the two closed surfaces, measured both ways at the vertices -- hand
vertices inside the accessory (depth: distance to the accessory's surface) and accessory vertices inside the hand
(depth: distance to the hand's surface; the hand's open forearm end is capped for the inside test). Both ways,
because hand vertices are sparser than a thin band is wide. The accessory is static in its own frame, so the hand
is moved into it (one ray scene per accessory for all poses).

Gloves: the hand must stay inside the glove's hollow. From each covered hand vertex a ray along its posed normal
must first meet the glove's inner layer from the hollow side; if it first meets a face from inside the glove's
material (or meets nothing), the vertex is in or through the glove, and its depth is the distance back along -n to
the glove's inner surface (into the material) or outer surface (through it).

Closest-point distances: KD-trees (scipy) pick candidate triangles, trimesh's point-triangle routine measures them
(trimesh's own proximity query needs rtree, which is not a dependency).
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from trimesh.ray.ray_pyembree import RayMeshIntersector

from darthand.model.topology import boundary_loops


def surface_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, trees=None) -> np.ndarray:
    """(K,) distance from each point to the nearest triangle.

    The nearest vertex bounds the distance from above (d0), so only triangles whose centroid lies within
    d0 + the largest centroid-to-corner distance can hold the closest point; those candidate pairs go through
    trimesh's exact point-triangle closest point. `trees` = (vertex KD-tree, centroid KD-tree, reach) may be
    passed in to reuse them.
    """
    tris = vertices[faces]
    if trees is None:
        trees = surface_trees(vertices, tris)
    vtree, ctree, reach = trees
    d0, _ = vtree.query(points)
    cands = ctree.query_ball_point(points, d0 + reach + 1e-12)
    counts = np.array([len(c) for c in cands])
    pid = np.repeat(np.arange(len(points)), counts)
    tid = np.concatenate([np.asarray(c, dtype=np.int64) for c in cands]) if len(pid) else np.zeros(0, np.int64)
    closest = trimesh.triangles.closest_point(tris[tid], points[pid])
    d = np.linalg.norm(closest - points[pid], axis=1)
    out = d0.copy()
    np.minimum.at(out, pid, d)
    return out


def surface_trees(vertices: np.ndarray, tris: np.ndarray):
    """(vertex KD-tree, face-centroid KD-tree, reach) of a mesh, for repeated `surface_distance` queries."""
    centroids = tris.mean(1)
    reach = float(np.linalg.norm(tris - centroids[:, None], axis=2).max())
    return cKDTree(vertices), cKDTree(centroids), reach


class Solid:
    """A closed mesh with an Embree scene for inside tests and depths of points inside it."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices, self.faces = np.asarray(vertices, float), np.asarray(faces)
        self.mesh = trimesh.Trimesh(self.vertices, self.faces, process=False)
        self.ray = RayMeshIntersector(self.mesh)
        self.lo, self.hi = self.vertices.min(0), self.vertices.max(0)
        self._trees = None

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Indices of the points inside the solid (bounding-box filter, then Embree ray parity)."""
        near = np.where(((points >= self.lo) & (points <= self.hi)).all(1))[0]
        return near[self.ray.contains_points(points[near])] if len(near) else near

    def max_depth(self, points: np.ndarray, batch: int = 32) -> float:
        """Largest depth (m) of any point inside the solid, 0 if none is.

        The nearest vertex's distance bounds each depth from above, so points are measured exactly in decreasing
        order of that bound until the best exact depth beats every remaining bound.
        """
        inside = self.inside(points)
        if len(inside) == 0:
            return 0.0
        if self._trees is None:
            self._trees = surface_trees(self.vertices, self.vertices[self.faces])
        bound, _ = self._trees[0].query(points[inside])
        order = np.argsort(-bound)
        best = 0.0
        for s in range(0, len(order), batch):
            if bound[order[s]] <= best:
                break
            sel = inside[order[s:s + batch]]
            best = max(best, float(surface_distance(points[sel], self.vertices, self.faces, self._trees).max()))
        return best


class ClosedHand:
    """The hand mesh with its boundary loops capped by fans around their centroids, re-posable per pose."""

    def __init__(self, faces: np.ndarray, num_vertices: int):
        self.loops = boundary_loops(faces)
        caps, n = [faces], num_vertices
        for loop in self.loops:
            caps.append(np.stack([np.roll(loop, -1), loop, np.full(len(loop), n)], 1))
            n += 1
        self.faces = np.concatenate(caps)

    def vertices(self, posed: np.ndarray) -> np.ndarray:
        """(V + loops, 3) posed vertices with the cap centres appended."""
        return np.concatenate([posed] + [posed[lp].mean(0, keepdims=True) for lp in self.loops])

    def solid(self, posed: np.ndarray) -> Solid:
        return Solid(self.vertices(posed), self.faces)


def rigid_penetration(accessory: Solid, hand_local: np.ndarray, hand: Solid, inner_world: np.ndarray,
                      own: np.ndarray, hand_world: np.ndarray) -> tuple[float, float]:
    """Overlap depth (m) of one rigid accessory and the posed hand, the larger of both directions, as
    (with the hand part it is fitted to, with any other part -- a neighbouring finger, the palm).

    accessory: the accessory's solid in its local frame; hand_local: the posed hand vertices in that frame;
    hand: the posed, capped hand (world); inner_world: the accessory's inward-facing vertices, posed (world);
    own: (V,) bool, the hand vertices of the part it is fitted to; hand_world: the posed hand vertices (an
    accessory vertex inside the hand counts for the part of its nearest hand vertex).
    """
    fit = accessory.max_depth(hand_local[own])
    other = accessory.max_depth(hand_local[~own])
    inside = hand.inside(inner_world)
    if len(inside):
        _, nearest = cKDTree(hand_world).query(inner_world[inside])
        mine = own[nearest]
        fit = max(fit, hand.max_depth(inner_world[inside[mine]]))
        other = max(other, hand.max_depth(inner_world[inside[~mine]]))
    return fit, other


def inward_vertices(vertices: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Indices of an accessory's vertices (local frame, axis +X) whose normals point toward the axis."""
    radial = vertices.copy()
    radial[:, 0] = 0.0
    return np.where((normals * radial).sum(1) < 0)[0]


def glove_penetration(glove_vertices: np.ndarray, glove_faces: np.ndarray, inner_mask: np.ndarray,
                      hand_points: np.ndarray, hand_normals: np.ndarray, reach: float = 0.01,
                      local=None) -> tuple[float, float]:
    """(max depth into the glove beyond its inner surface, max depth through its outer surface), metres.

    glove_vertices (G, 3) posed; inner_mask (F,) True for the glove's inner-layer faces; hand_points/normals (K, 3)
    the covered hand vertices and their unit outward normals, posed. local: optional function
    (ray ids (H,), face ids (H,)) -> (H,) bool keeping only the glove faces over the hand vertex's own
    neighbourhood, so a finger's glove pressed against the palm's glove (hand-on-hand contact, not a glove
    fault) is not read as the finger being through its own glove.
    """
    mesh = trimesh.Trimesh(glove_vertices, glove_faces, process=False)
    ray = RayMeshIntersector(mesh)
    fn = mesh.face_normals
    eps = 1e-7
    keep = local if local is not None else (lambda r, t: np.ones(len(r), bool))
    tri, rid, loc = ray.intersects_id(hand_points + eps * hand_normals, hand_normals, multiple_hits=True,
                                      return_locations=True)
    ok = keep(rid, tri)
    tri, rid, loc = tri[ok], rid[ok], loc[ok]
    dist = np.linalg.norm(loc - hand_points[rid], axis=1)
    first = np.full(len(hand_points), -1)
    best = np.full(len(hand_points), np.inf)
    for t, r, d in zip(tri, rid, dist):
        if d < best[r]:
            best[r], first[r] = d, t
    hollow = np.zeros(len(hand_points), bool)
    hit = first >= 0
    # From the hollow, the first face met is the inner layer, seen from its front (its normal faces the hand).
    hollow[hit] = inner_mask[first[hit]] & ((fn[first[hit]] * hand_normals[hit]).sum(1) < 0)
    bad = np.where(~hollow)[0]
    if len(bad) == 0:
        return 0.0, 0.0
    tri, rid, loc = ray.intersects_id(hand_points[bad] - eps * hand_normals[bad], -hand_normals[bad],
                                      multiple_hits=True, return_locations=True)
    ok = keep(bad[rid], tri)
    tri, rid, loc = tri[ok], rid[ok], loc[ok]
    d = np.linalg.norm(loc - hand_points[bad][rid], axis=1)
    into = through = 0.0
    for k in range(len(bad)):
        sel = (rid == k) & (d < reach)
        if not sel.any():
            continue
        dk, tk = d[sel], tri[sel]
        order = np.argsort(dk)
        dk, tk = dk[order], tk[order]
        inner_hits, outer_hits = dk[inner_mask[tk]], dk[~inner_mask[tk]]
        if len(inner_hits):
            into = max(into, float(inner_hits[0]))
        if len(outer_hits) and (not len(inner_hits) or outer_hits[0] < inner_hits[0]):
            through = max(through, float(outer_hits[0]))
    return into, through


def neighbourhood(faces: np.ndarray, num_vertices: int, rings: int = 3):
    """(V, V) sparse bool: vertex pairs at most `rings` edges apart on the mesh."""
    import scipy.sparse as sp

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    A = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(num_vertices, num_vertices)).tocsr()
    A = ((A + A.T + sp.eye(num_vertices)) > 0).astype(np.float32)
    R = A
    for _ in range(rings - 1):
        R = ((R @ A) > 0).astype(np.float32)
    return R.tocsr()
