"""The ray-tracing scene: one Embree triangle mesh per posed surface (geomID = its index in the subject).

embreex builds static scenes only (no vertex-buffer updates, no instancing), so a pose change means a new scene
for the skinned hand; a rigid accessory keeps one scene in its joint's frame and the rays are moved into it (see
Scene). What did not move is not recomputed on the numpy side (see assets.HandAssets), and a scene whose surfaces
are the same arrays is reused (only the camera or the lights changed). Meshes reach Embree by a buffer copy
(embree_mesh.add_triangles), not embreex's per-element one.

The scene is committed on construction (a one-ray query) so that the parallel queries of trace.py start from a
committed scene.
"""

from __future__ import annotations

import copy

import numpy as np
from embreex import rtcore_scene

from darthand.jit import kernel
from darthand.render.camera import point_bounds
from darthand.render.embree_mesh import add_triangles, device
from darthand.render.subject import Subject, Surface


class FaceData:
    """Per-face shading data of one posed surface, laid out for one gather per batch of hits: `table` (K, F)
    float32, its rows (component-major, so that the gathered (K, M) rows are contiguous vectors):

        0..8    corner positions, corner k coordinate c at row 3k + c
        9..17   corner vertex normals, likewise
        18..20  unit geometric normal
        21..26  corner uvs, corner k (u, v) at rows 21 + 2k, 22 + 2k          (with UVs)
        27      uv scale sqrt(uv area / surface area): uv units per metre on the face   (with UVs)
    """

    POSITION, NORMAL, GEOMETRIC, UV, UV_SCALE = 0, 9, 18, 21, 27

    def __init__(self, surface: Surface):
        self.has_uvs = surface.uvs is not None
        self.table = np.empty((28 if self.has_uvs else 21, len(surface.faces)), np.float32)
        f32 = lambda a: np.ascontiguousarray(a, np.float32)
        uvs = ((f32(surface.uvs), np.ascontiguousarray(surface.faces_uv, np.int64)) if self.has_uvs
               else (np.empty((0, 2), np.float32), np.empty((0, 3), np.int64)))
        _face_table_kernel(f32(surface.vertices), f32(surface.normals), np.ascontiguousarray(surface.faces, np.int64),
                           *uvs, self.table)

    def gather(self, prim: np.ndarray) -> np.ndarray:
        """(K, M) float32 rows of the faces `prim` (M,)."""
        return np.take(self.table, prim, axis=1)


@kernel
def _face_table_kernel(vertices, normals, faces, uvs, faces_uv, table):
    """FaceData's table (K, F) of float32 vertices, normals (N, 3), faces (F, 3), uvs (T, 2) and faces_uv (F, 3)
    (empty: no UVs), in one pass; float32 arithmetic in the order of the numpy version (np.cross's a1 b2 - a2 b1,
    |n| = sqrt(x^2 + y^2 + z^2), n / max(|n|, 1e-30), sqrt(|uv cross| / max(|n|, 1e-30)))."""
    tiny = np.float32(1e-30)
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        for k in range(3):
            i = faces[f, k]
            for c in range(3):
                table[3 * k + c, f] = vertices[i, c]
                table[9 + 3 * k + c, f] = normals[i, c]
        ax = vertices[i1, 0] - vertices[i0, 0]
        ay = vertices[i1, 1] - vertices[i0, 1]
        az = vertices[i1, 2] - vertices[i0, 2]
        bx = vertices[i2, 0] - vertices[i0, 0]
        by = vertices[i2, 1] - vertices[i0, 1]
        bz = vertices[i2, 2] - vertices[i0, 2]
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        area2 = np.sqrt(nx * nx + ny * ny + nz * nz)
        d = max(area2, tiny)
        table[18, f] = nx / d
        table[19, f] = ny / d
        table[20, f] = nz / d
        if uvs.shape[0]:
            j0, j1, j2 = faces_uv[f, 0], faces_uv[f, 1], faces_uv[f, 2]
            for k in range(3):
                j = faces_uv[f, k]
                table[21 + 2 * k, f] = uvs[j, 0]
                table[22 + 2 * k, f] = uvs[j, 1]
            d1u, d1v = uvs[j1, 0] - uvs[j0, 0], uvs[j1, 1] - uvs[j0, 1]
            d2u, d2v = uvs[j2, 0] - uvs[j0, 0], uvs[j2, 1] - uvs[j0, 1]
            table[27, f] = np.sqrt(abs(d1u * d2v - d1v * d2u) / d)


def interpolate(values: np.ndarray, faces: np.ndarray, prim: np.ndarray, bu: np.ndarray, bv: np.ndarray) -> np.ndarray:
    """Per-vertex values (N, ...) interpolated at hits on faces `prim` (M,) with barycentrics (1 - bu - bv, bu, bv):
    (M, ...)."""
    f = faces[prim]
    a, b, c = values[f[:, 0]], values[f[:, 1]], values[f[:, 2]]
    if a.ndim > 1:
        bu, bv = bu[:, None], bv[:, None]
    return a + bu * (b - a) + bv * (c - a)


def interpolate_columns(values: np.ndarray, faces: np.ndarray, prim: np.ndarray, bu: np.ndarray, bv: np.ndarray,
                        rays: np.ndarray | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """Per-vertex values (C, N) float32 interpolated at hits on faces `prim` (R,) with float32 barycentrics bu, bv
    (R,), as `interpolate` (a + bu (b - a) + bv (c - a), float32, in that order), in one pass: (C, R) float32.
    rays (M,): only those hits, written into their columns of `out` (C, R) (the other columns left as they are)."""
    prim = np.ascontiguousarray(prim, np.int32)
    if out is None:
        out = np.empty((len(values), len(prim)), np.float32)
    rays = np.arange(len(prim), dtype=np.int64) if rays is None else np.ascontiguousarray(rays, np.int64)
    _interpolate_kernel(np.ascontiguousarray(values, np.float32), np.ascontiguousarray(faces, np.int32), prim,
                        np.ascontiguousarray(bu, np.float32), np.ascontiguousarray(bv, np.float32), rays, out)
    return out


@kernel
def _interpolate_kernel(values, faces, prim, bu, bv, rays, out):
    """out[:, r] = a + bu[r] (b - a) + bv[r] (c - a) of the rows of values (C, N) at the corners a, b, c of face
    prim[r], for each r in rays."""
    for i in range(rays.shape[0]):
        r = rays[i]
        f = prim[r]
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        u, v = bu[r], bv[r]
        for row in range(values.shape[0]):
            x = values[row, a]
            out[row, r] = x + u * (values[row, b] - x) + v * (values[row, c] - x)


class Scene:
    """The Embree scenes of a subject's surfaces, committed, with the scene's size for ray offsets and the per-face
    shading data of each surface.

    Skinned surfaces (the hand) go into one scene built for the pose. A rigid surface (a ring: `Surface.transform`)
    keeps its own scene, built once in its joint's frame (`Surface.local`) and reused for every pose: rays are
    moved into that frame by the inverse transform and the nearer hit wins. The transform is rigid, so a ray
    parameter (tfar) means the same distance in both frames, and barycentrics and primID are those of the posed
    face."""

    def __init__(self, subject: Subject):
        self.subject = subject
        self.surfaces = subject.surfaces
        self.faces = [FaceData(s) for s in self.surfaces]
        self.embree = rtcore_scene.EmbreeScene(device())
        # (surface index, embree scene, R (3, 3) float32, t (3,) float32, world bounding-sphere centre (3,), radius)
        self.rigid = []
        baked = []
        for i, s in enumerate(self.surfaces):
            if _is_rigid(s):
                G = np.asarray(s.transform, np.float64)
                embree, centre, radius = _local_scene(s.local, s.faces)
                R, t = G[:3, :3].astype(np.float32), G[:3, 3].astype(np.float32)
                self.rigid.append((i, embree, R, t, (R @ centre + t).astype(np.float32), radius))
            else:
                add_triangles(self.embree, s.vertices, s.faces)
                baked.append(i)
        self.baked = np.array(baked + [-1], np.int32)     # geomID of the baked scene -> surface index (-1 -> -1)
        pts = subject.all_vertices()
        self.lo, self.hi = point_bounds(pts)
        self.extent = float(np.linalg.norm(self.hi - self.lo))
        _commit(self.embree)

    def intersect(self, origins: np.ndarray, directions: np.ndarray, tfar=None) -> dict:
        """Closest hits of rays (N, 3) float32: {'primID', 'geomID' (surface index, -1 for a miss), 'u', 'v',
        'tfar'}."""
        n = len(origins)
        d = np.full(n, np.inf, np.float32) if tfar is None else np.array(
            np.broadcast_to(np.asarray(tfar, np.float32), (n,)), np.float32, copy=True)
        hit = self.embree.run(origins, directions, dists=d, output=1)
        hit["geomID"] = self.baked[np.where(hit["primID"] >= 0, hit["geomID"], -1)]
        for i, embree, R, t, centre, radius in self.rigid:
            near_sphere = _rays_near_sphere(origins, directions, centre, radius)
            if not len(near_sphere):
                continue
            o, dl = _to_local(origins[near_sphere], directions[near_sphere], R, t)
            near = np.array(hit["tfar"][near_sphere], np.float32, copy=True)
            local = embree.run(o, dl, dists=near, output=1)
            hits = np.flatnonzero(local["primID"] >= 0)
            if len(hits):
                won = near_sphere[hits]
                for key in ("primID", "u", "v", "tfar"):
                    hit[key][won] = local[key][hits]
                hit["geomID"][won] = i
        return hit

    def occluded(self, origins: np.ndarray, directions: np.ndarray, tfar) -> np.ndarray:
        """(N,) bool: something lies along each ray within (0, tfar)."""
        d = np.array(np.broadcast_to(np.asarray(tfar, np.float32), (len(origins),)), np.float32, copy=True)
        blocked = self.embree.run(origins, directions, dists=d.copy(), query="OCCLUDED") >= 0
        for _, embree, R, t, centre, radius in self.rigid:
            rest = _rays_near_sphere(origins, directions, centre, radius, blocked)
            if not len(rest):
                continue
            o, dl = _to_local(origins[rest], directions[rest], R, t)
            blocked[rest] = embree.run(o, dl, dists=d[rest], query="OCCLUDED") >= 0
        return blocked

    def matches(self, subject: Subject) -> bool:
        """The same surfaces (same vertex arrays): the scene can be reused."""
        return len(subject.surfaces) == len(self.surfaces) and all(
            a.vertices is b.vertices and a.faces is b.faces for a, b in zip(subject.surfaces, self.surfaces))


_LOCAL_SCENES: dict = {}


def _is_rigid(surface: Surface) -> bool:
    """A surface with a local mesh and a transform whose 3x3 part is a rotation (no scale: tfar must carry over)."""
    if surface.local is None or surface.transform is None:
        return False
    R = np.asarray(surface.transform, np.float64)[:3, :3]
    return bool(np.allclose(R.T @ R, np.eye(3), atol=1e-5))


def _local_scene(local: np.ndarray, faces: np.ndarray):
    """(committed Embree scene, bounding-sphere centre (3,) float32, radius) of a rigid surface's local mesh, built
    once per (vertex array, face array)."""
    key = (id(local), id(faces))
    entry = _LOCAL_SCENES.get(key)
    if entry is None or entry[0] is not local or entry[1] is not faces:
        if len(_LOCAL_SCENES) > 64:
            _LOCAL_SCENES.clear()
        embree = rtcore_scene.EmbreeScene(device())
        add_triangles(embree, local, faces)
        _commit(embree)
        centre = (local.min(0) + local.max(0)) / 2
        radius = float(np.linalg.norm(local - centre, axis=1).max())
        entry = _LOCAL_SCENES[key] = (local, faces, embree, centre.astype(np.float32), radius)
    return entry[2:]


def _rays_near_sphere(origins: np.ndarray, directions: np.ndarray, centre: np.ndarray, radius: float,
                      skip: np.ndarray | None = None) -> np.ndarray:
    """Indices (ascending) of the rays (N, 3) float32 (origin + s direction, s > 0), other than those `skip` (N,)
    bool marks, that pass within `radius` of `centre`: the only rays that can hit a mesh inside that sphere.
    Culling the others before a small rigid surface's own Embree query saves moving every ray into its frame and a
    query per ray. Conservative: the radius is padded for float32 rounding, which in |w|^2 |d|^2 - (w.d)^2 grows
    with |w|^2 (hence the 1e-6 |w|^2 term)."""
    r2 = np.float32((radius * (1 + 1e-3) + 1e-6) ** 2)
    out = np.empty(len(origins), np.int64)
    skip = np.zeros(len(origins), np.bool_) if skip is None else np.ascontiguousarray(skip, np.bool_)
    return out[:_near_sphere_kernel(np.ascontiguousarray(origins, np.float32),
                                    np.ascontiguousarray(directions, np.float32),
                                    np.ascontiguousarray(centre, np.float32), r2, skip, out)]


@kernel
def _near_sphere_kernel(origins, directions, centre, r2, skip, out):
    """`_rays_near_sphere` per ray, float32 in the order of the numpy version it replaced (w = centre - origin;
    dots summed x, y, z): ray i (not skipped) is near when |w|^2 |d|^2 - (w.d)^2 < (r2 + 1e-6 |w|^2) |d|^2 and
    (w.d > 0 or |w|^2 < r2); its index goes to out; returns how many."""
    tol = np.float32(1e-6)
    m = 0
    for i in range(origins.shape[0]):
        if skip[i]:
            continue
        w0, w1, w2 = centre[0] - origins[i, 0], centre[1] - origins[i, 1], centre[2] - origins[i, 2]
        d0, d1, d2 = directions[i, 0], directions[i, 1], directions[i, 2]
        wd = w0 * d0 + w1 * d1 + w2 * d2
        dd = d0 * d0 + d1 * d1 + d2 * d2
        ww = w0 * w0 + w1 * w1 + w2 * w2
        if ww * dd - wd * wd < (r2 + tol * ww) * dd and (wd > 0 or ww < r2):
            out[m] = i
            m += 1
    return m


def _to_local(origins: np.ndarray, directions: np.ndarray, R: np.ndarray, t: np.ndarray):
    """Rays (N, 3) moved by the inverse of the rigid transform x -> R x + t: o' = R^T (o - t), d' = R^T d."""
    return (np.ascontiguousarray((origins - t) @ R, np.float32), np.ascontiguousarray(directions @ R, np.float32))


def _commit(embree) -> None:
    """Commit a scene now, single-threaded, before any parallel query (a one-ray query)."""
    one = np.zeros((1, 3), np.float32)
    embree.run(one, np.array([[0, 0, 1]], np.float32), output=1)


def scene_for(subject: Subject, previous: Scene | None = None) -> Scene:
    """`previous`'s Embree scenes when it holds the same posed surfaces (in a copy carrying the new subject: the
    materials may differ, and `previous` may still be tracing an earlier frame), else a new scene."""
    if previous is not None and previous.matches(subject):
        scene = copy.copy(previous)
        scene.subject, scene.surfaces = subject, subject.surfaces
        return scene
    return Scene(subject)
