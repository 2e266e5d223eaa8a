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

import functools

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from embreex.rtcore import EmbreeDevice
from trimesh.ray.ray_pyembree import RayMeshIntersector

from darthand.model.topology import boundary_loops


_DEVICE: EmbreeDevice | None = None


def _device() -> EmbreeDevice:
    """One Embree device per process."""
    global _DEVICE
    if _DEVICE is None:
        _DEVICE = EmbreeDevice()
    return _DEVICE


def surface_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, trees=None) -> np.ndarray:
    """(K,) distance from each point to the nearest triangle.

    The nearest vertex bounds the distance from above (d0), so only triangles whose centroid lies within
    d0 + the largest centroid-to-corner distance can hold the closest point; those candidate pairs go through
    trimesh's exact point-triangle closest point. `trees` = (vertex KD-tree, centroid KD-tree, reach) may be
    passed in to reuse them.
    """
    tris = vertices[faces]
    if trees is None:
        trees = surface_trees(tris)
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


def surface_trees(tris: np.ndarray):
    """(vertex KD-tree, face-centroid KD-tree, reach) of a mesh, for repeated `surface_distance` queries. The vertex
    tree holds the corners of `tris` (T, 3, 3) only: the faces may be a part of the mesh (a glove's inner layer)."""
    centroids = tris.mean(1)
    reach = float(np.linalg.norm(tris - centroids[:, None], axis=2).max())
    return cKDTree(tris.reshape(-1, 3)), cKDTree(centroids), reach


class Solid:
    """A closed, outward-wound mesh with an Embree scene for inside tests and depths of points inside it.

    Inside test: a point is inside when the first face met by a ray from it is one the ray leaves through (its
    normal along the ray), checked along two opposite directions; the points where the two disagree (a grazing hit,
    a ray entering another overlapping part first) get trimesh's ray-parity test. One Embree query per direction
    instead of parity's repeated multi-hit queries, and where a posed hand's surface crosses itself (two fingers
    pressed into each other) a point inside both is inside, where parity alone would count it out.
    """

    DIRECTION = np.array([0.5774, 0.5772, 0.5776]) / np.linalg.norm([0.5774, 0.5772, 0.5776])  # off every axis

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices, self.faces = np.asarray(vertices, float), np.asarray(faces)
        tri = self.vertices[self.faces]
        self.face_normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.scene = rtcore_scene.EmbreeScene(_device())
        TriangleMesh(self.scene, np.ascontiguousarray(self.vertices, np.float32),
                     np.ascontiguousarray(self.faces, np.int32))
        self.lo, self.hi = self.vertices.min(0), self.vertices.max(0)
        self._trees: tuple | None = None
        self._ray: RayMeshIntersector | None = None

    @property
    def ray(self) -> RayMeshIntersector:
        """trimesh's Embree intersector of the same mesh (multi-hit queries, ray parity)."""
        if self._ray is None:
            self._ray = RayMeshIntersector(trimesh.Trimesh(self.vertices, self.faces, process=False))
        return self._ray

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Indices of the points (K, 3) inside the solid (bounding-box filter, then the exit test)."""
        near = np.where(((points >= self.lo) & (points <= self.hi)).all(1))[0]
        if len(near) == 0:
            return near
        forward, backward = (self._leaves_first(points[near], d) for d in (self.DIRECTION, -self.DIRECTION))
        inside = forward & backward
        unsure = np.flatnonzero(forward != backward)
        if len(unsure):
            inside[unsure] = self.ray.contains_points(points[near[unsure]])
        return near[inside]

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(face index, or -1 where nothing is met; distance) of the first face met by rays from `origins`
        (K, 3) along unit `directions` (K, 3)."""
        hit = self.scene.run(np.ascontiguousarray(origins, np.float32),
                             np.ascontiguousarray(np.broadcast_to(directions, origins.shape), np.float32), output=1)
        return hit["primID"], hit["tfar"]

    def all_hits(self, points: np.ndarray, directions: np.ndarray, reach: float,
                 eps: float = 1e-7) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every face met within `reach` metres by rays from `points` (K, 3) along unit `directions` (K, 3)
        (starting `eps` out): (ray index, face index, distance) arrays, nearest first per ray, by first-hit
        queries moved past each hit."""
        rays, faces, dists = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)], [np.zeros(0)]
        todo = np.arange(len(points))
        travelled = np.full(len(points), eps)
        while len(todo):
            hit, tfar = self.cast(points[todo] + travelled[todo, None] * directions[todo], directions[todo])
            ok = (hit >= 0) & (travelled[todo] + tfar <= reach)
            todo, hit = todo[ok], hit[ok]
            travelled[todo] += tfar[ok]
            rays.append(todo)
            faces.append(hit)
            dists.append(travelled[todo].copy())
            travelled[todo] += eps
        rays, faces, dists = np.concatenate(rays), np.concatenate(faces), np.concatenate(dists)
        order = np.lexsort((dists, rays))
        return rays[order].astype(np.int64), faces[order].astype(np.int64), dists[order].astype(np.float64)

    def _leaves_first(self, points: np.ndarray, direction: np.ndarray) -> np.ndarray:
        """(K,) bool: the first face a ray from each point along `direction` meets is one it leaves through."""
        prim, _ = self.cast(points, direction)
        out = np.zeros(len(points), bool)
        ok = prim >= 0
        out[ok] = self.face_normals[prim[ok]] @ direction > 0
        return out

    def max_depth(self, points: np.ndarray) -> float:
        """Largest depth (m) of any of `points` (K, 3) inside the solid, 0 if none is."""
        return self.deepest(points[self.inside(points)])

    def deepest(self, points: np.ndarray, batch: int = 32) -> float:
        """Largest distance (m) from the surface of any of `points` (K, 3) known to be inside the solid (0 if
        K = 0): their largest depth.

        The nearest vertex's distance bounds each depth from above, so points are measured exactly in decreasing
        order of that bound until the best exact depth beats every remaining bound.
        """
        if len(points) == 0:
            return 0.0
        if self._trees is None:
            self._trees = surface_trees(self.vertices[self.faces])
        bound, _ = self._trees[0].query(points)
        order = np.argsort(-bound)
        best = 0.0
        for s in range(0, len(order), batch):
            if bound[order[s]] <= best:
                break
            sel = order[s:s + batch]
            best = max(best, float(surface_distance(points[sel], self.vertices, self.faces, self._trees).max()))
        return best


class ClosedHand:
    """The hand mesh (or a part of it: a subset of its faces) with its boundary loops capped by fans around their
    centroids, re-posable per pose. Only the vertices its faces use are kept: the depth bounds come from the
    nearest vertex, which must lie on this surface."""

    def __init__(self, faces: np.ndarray):
        self.used, compact = np.unique(faces, return_inverse=True)
        faces = compact.reshape(faces.shape)
        self.loops = boundary_loops(faces)
        caps, n = [faces], len(self.used)
        for loop in self.loops:
            caps.append(np.stack([np.roll(loop, -1), loop, np.full(len(loop), n)], 1))
            n += 1
        self.faces = np.concatenate(caps)

    @staticmethod
    def of(faces: np.ndarray) -> "ClosedHand":
        """The ClosedHand of `faces`, made once per topology (a dataset wears a ring on a new hand shape nearly
        every ring frame: the capping, 7 ms, depends on the faces only)."""
        faces = np.ascontiguousarray(faces, np.int64)
        return _closed_hand(faces.tobytes(), faces.shape)

    def vertices(self, posed: np.ndarray) -> np.ndarray:
        """(used + loops, 3) the posed vertices (V, 3) it uses, with the cap centres appended."""
        mine = posed[self.used]
        return np.concatenate([mine] + [mine[lp].mean(0, keepdims=True) for lp in self.loops])

    def solid(self, posed: np.ndarray) -> Solid:
        return Solid(self.vertices(posed), self.faces)


@functools.lru_cache(maxsize=8)
def _closed_hand(faces_bytes: bytes, shape: tuple) -> ClosedHand:
    return ClosedHand(np.frombuffer(faces_bytes, np.int64).reshape(shape))


def inward_vertices(vertices: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N,) bool: which of an accessory's vertices (local frame, axis +X) have normals pointing toward the axis."""
    radial = vertices.copy()
    radial[:, 0] = 0.0
    return (normals * radial).sum(1) < 0


def glove_penetration(glove_vertices: np.ndarray, glove_faces: np.ndarray, inner_mask: np.ndarray,
                      hand_points: np.ndarray, hand_normals: np.ndarray, reach: float = 0.01,
                      local=None) -> tuple[float, float]:
    """(max depth into the glove beyond its inner surface, max depth through its outer surface), metres.

    glove_vertices (G, 3) posed; inner_mask (F,) True for the glove's inner-layer faces; hand_points/normals (K, 3)
    the covered hand vertices and their unit outward normals, posed. local: optional function
    (ray ids (H,), face ids (H,)) -> (H,) bool keeping only the glove faces over the hand vertex's own
    neighbourhood, so a finger's glove pressed against the palm's glove (hand-on-hand contact, not a glove
    fault) is not read as the finger being through its own glove.

    A vertex whose normal first meets the inner layer from the hollow is inside the glove. Any other is into the
    glove when it lies inside the glove's material (the closed shell's inside test), and through it when, back
    along -n within `reach` (m), its glove's outer layer comes before the inner one; into-depths are distances to
    the inner surface, through-depths to the outer one along -n. Into-depths are not the distance back along -n to
    the inner layer: in a tight crease (a fully bent thumb) the layers of the crease's two sides lie within a few
    edges of each other, and that walk reaches the far side's inner layer, millimetres away (glove_06 read 2.41 mm
    so, at a vertex 0.02 mm from the inner layer and outside the glove's material by its winding number).
    """
    glove = Solid(glove_vertices, glove_faces)
    fn = glove.face_normals
    keep = local if local is not None else (lambda r, t: np.ones(len(r), bool))
    eps = 1e-7
    # From the hollow, the first face met along the hand's normal is the inner layer, seen from its front (its
    # normal faces the hand). One first-hit query; the rays whose first hit is not over their own neighbourhood
    # look past it.
    first, _ = glove.cast(hand_points + eps * hand_normals, hand_normals)
    hit = np.flatnonzero(first >= 0)
    foreign = hit[~keep(hit, first[hit])]
    if len(foreign):
        rid, tri, _ = glove.all_hits(hand_points[foreign], hand_normals[foreign], np.inf, eps)
        ok = keep(foreign[rid], tri)
        rid, tri = rid[ok], tri[ok]
        nearest = np.r_[True, rid[1:] != rid[:-1]][:len(rid)]   # hits come nearest first per ray
        first[foreign] = -1
        first[foreign[rid[nearest]]] = tri[nearest]
    hollow = np.zeros(len(hand_points), bool)
    hit = first >= 0
    hollow[hit] = inner_mask[first[hit]] & ((fn[first[hit]] * hand_normals[hit]).sum(1) < 0)
    bad = np.where(~hollow)[0]
    if len(bad) == 0:
        return 0.0, 0.0
    in_material = np.zeros(len(bad), bool)
    in_material[glove.inside(hand_points[bad])] = True
    # Out of the material, a vertex is through the glove when, back along -n, its glove's outer layer comes before
    # the inner one.
    rest = bad[~in_material]
    rid, tri, d = glove.all_hits(hand_points[rest], -hand_normals[rest], reach, eps)
    ok = keep(rest[rid], tri)
    rid, tri, d = rid[ok], tri[ok], d[ok]
    first_hit = np.r_[True, rid[1:] != rid[:-1]][:len(rid)]                   # hits come nearest first per ray
    outer_first = first_hit & ~inner_mask[tri]
    through_ids = rest[rid[outer_first]]
    through = float(d[outer_first].max(initial=0.0))
    beyond = np.concatenate([bad[in_material], through_ids])
    into = 0.0
    if len(beyond):
        into = float(surface_distance(hand_points[beyond], glove.vertices, glove.faces[inner_mask]).max())
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
