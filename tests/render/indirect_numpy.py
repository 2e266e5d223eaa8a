"""The numpy indirect-light pass that render/indirect.py's compiled kernels replaced (darthand at 5603c15), kept as
the reference its tests compare the kernels with bit for bit. Only the replaced code is here; the functions the
kernels did not change (disk_set, hash_uniform, local_directions, vertex_uvs) come from the module itself."""

from __future__ import annotations

import numpy as np

from darthand.render.indirect import (ACCESSORY_MIN_RAYS, ACCESSORY_RAY_SHARE, LIFT, MAX_BOUNCE_ALBEDO,
                                      direction_table, local_directions, vertex_uvs)
from darthand.render.scene import FaceData, interpolate

GEOMETRIC = FaceData.GEOMETRIC


def cached_local_directions(vertex_ids, count, rays, salt):
    return direction_table(count, rays, salt)[:, vertex_ids]


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tangent, bitangent, about_x) for unit normals (N, 3): tangent = e x n normalised, bitangent = n x tangent,
    with e the x axis (about_x True) or, for normals within 26 degrees of it, the y axis. Built from the x axis so
    that the frame of a mirrored normal (x -> -x, how a left hand is made from a right one) is the mirror of the
    frame, up to the sign of one local axis (`local_directions` flips it)."""
    n = np.asarray(normals, np.float32)
    about_x = np.abs(n[:, 0]) < 0.9
    e = np.zeros_like(n)
    e[about_x, 0] = 1
    e[~about_x, 1] = 1
    t = np.cross(e, n)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), np.float32(1e-30))
    return t, np.cross(n, t), about_x


def vertex_rays(vertices: np.ndarray, normals: np.ndarray, vertex_ids: np.ndarray, rays: int, lift: float,
                salt: int = 0, mirrored: bool = False, count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(origins, directions) (N * K, 3) float32, vertex-major: K cosine-distributed rays about each unit normal
    (N, 3), leaving from the vertex (N, 3) lifted by `lift` metres along its normal. mirrored: the surface is the
    x -> -x mirror image of the one the directions are defined for (a left hand): its rays are the mirror images of
    the right hand's, so that both hands render alike. count: the surface's vertex count, to reuse the directions
    of all its vertices (cached_local_directions)."""
    n = np.asarray(normals, np.float32)
    t, s, about_x = tangent_frames(n)
    local = (local_directions(vertex_ids, rays, salt) if count is None
             else cached_local_directions(vertex_ids, count, rays, salt).copy())
    if mirrored:
        # mirror(frame(n)) = (t, -s, n) about the x axis and (-t, s, n) about the y axis (tangent_frames)
        local[1][about_x] *= -1
        local[0][~about_x] *= -1
    dirs = local[0][..., None] * t[:, None] + local[1][..., None] * s[:, None] + local[2][..., None] * n[:, None]
    origins = np.repeat(np.asarray(vertices, np.float32) + np.float32(lift) * n, rays, axis=0)
    return origins, np.ascontiguousarray(dirs.reshape(-1, 3))


def sphere_bounce(visible: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """(..., 3) the integrating-sphere factor 1 / (1 - rho (1 - V)) for open fractions V (...,) and albedos rho
    (..., 3) (clipped to MAX_BOUNCE_ALBEDO)."""
    rho = np.minimum(albedo, np.float32(MAX_BOUNCE_ALBEDO))
    return 1 / (1 - rho * (1 - np.asarray(visible)[..., None]))


class VertexLight:
    """One frame's indirect light at the vertices of every surface of a committed scene.Scene.

    Per vertex, made when first needed: the diffuse albedo rho (3) and the direct light the vertex reflects,
    rho x irradiance (3) (all lights, cos-weighted, one shadow ray per shadowed light) -- only at the vertices of
    faces the indirect rays hit, so that the cost follows what a frame sees, not the accessory's vertex count.
    `ensure(g, prim)` computes E and V (above) for the vertices of faces `prim` of surface g that have none yet;
    `at(g, prim, bu, bv)` interpolates them at hits: (E (3, M), V (M,)). Not thread-safe: `ensure` runs before a
    batch is shaded in parallel."""

    def __init__(self, scene, lights: list[dict], ambient: np.ndarray, rays: int, interreflection: bool = True,
                 counters: dict | None = None):
        self.scene, self.lights, self.rays = scene, lights, int(rays)
        self.interreflection = bool(interreflection)
        self.ambient = np.asarray(ambient, np.float32)
        self.lift = LIFT * max(scene.extent, 1e-3)
        self.counters = counters if counters is not None else {}
        sizes = [len(s.vertices) for s in scene.surfaces]
        self.albedo = [np.zeros((n, 3), np.float32) for n in sizes]
        self.reflected = [np.zeros((n, 3), np.float32) for n in sizes]     # albedo x direct irradiance
        self.lit = [np.zeros(n, bool) for n in sizes]                      # albedo and reflected made
        self.values = [np.zeros((4, n), np.float32) for n in sizes]        # E (3), V; by row
        self.done = [np.zeros(n, bool) for n in sizes]

    def _light_vertices(self, g: int, ids: np.ndarray) -> None:
        """Make albedo and reflected light of surface g's vertices `ids` that have none yet."""
        from darthand.render.shade import vertex_albedo

        ids = ids[~self.lit[g][ids]]
        if not len(ids):
            return
        s = self.scene.surfaces[g]
        uvs = vertex_uvs(s)
        self.albedo[g][ids] = vertex_albedo(s.material, None if uvs is None else uvs[ids], len(ids))
        if self.interreflection:
            self.reflected[g][ids] = self.albedo[g][ids] * self._direct(s.vertices[ids], s.normals[ids])
        self.lit[g][ids] = True

    def _direct(self, vertices: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """(N, 3) float32 irradiance (pi folded) of the lights at vertices (N, 3) with normals (N, 3), shadowed."""
        v = np.asarray(vertices, np.float32)
        n = np.asarray(normals, np.float32)
        out = np.zeros((len(v), 3), np.float32)
        for light in self.lights:
            if light["type"] == "directional":
                l = np.broadcast_to((-light["direction"]).astype(np.float32), v.shape)
                scale = np.broadcast_to(light["radiance"], v.shape)
                tfar = np.inf
            else:
                d = light["position"].astype(np.float32) - v
                dist = np.linalg.norm(d, axis=1)
                l = d / np.maximum(dist, 1e-9)[:, None]
                scale = light["radiance"][None, :] / np.maximum(dist * dist, 1e-12)[:, None]
                tfar = np.maximum(dist - self.lift, 0)
            cos = np.einsum("ij,ij->i", n, l)
            lit = np.flatnonzero(cos > 0)
            if light["shadows"] and len(lit):
                origins = np.ascontiguousarray(v[lit] + np.float32(self.lift) * n[lit])
                far = tfar if np.isscalar(tfar) else tfar[lit]
                lit = lit[~self.scene.occluded(origins, np.ascontiguousarray(l[lit]), far)]
                self.counters["indirect_rays"] = self.counters.get("indirect_rays", 0) + len(origins)
            out[lit] += cos[lit, None] * scale[lit]
        return out

    def ensure(self, g: int, prim: np.ndarray) -> None:
        """Compute E and V for the vertices of faces `prim` of surface g that have none yet."""
        faces = self.scene.surfaces[g].faces
        hit = np.zeros(len(faces), bool)
        hit[prim] = True
        needed = np.zeros(len(self.done[g]), bool)
        needed[faces[hit].ravel()] = True
        todo = np.flatnonzero(needed & ~self.done[g])
        if len(todo):
            self.values[g][:, todo] = self._compute(g, todo).T
            self.done[g][todo] = True

    def _compute(self, g: int, ids: np.ndarray) -> np.ndarray:
        """(len(ids), 4) float32: E (3) and V of surface g's vertices `ids`."""
        s = self.scene.surfaces[g]
        k = self.rays if s.role == "hand" else max(ACCESSORY_MIN_RAYS, self.rays // ACCESSORY_RAY_SHARE)
        self._light_vertices(g, ids)
        origins, dirs = vertex_rays(s.vertices[ids], s.normals[ids], ids, k, self.lift, salt=977 * g + 1,
                                    mirrored=self.scene.subject.side == "left", count=len(s.vertices))
        self.counters["indirect_rays"] = self.counters.get("indirect_rays", 0) + len(origins)
        out = np.empty((len(ids), 4), np.float32)
        if not self.interreflection:
            blocked = self.scene.occluded(origins, dirs, np.inf).reshape(-1, k)
            out[:, 3] = 1 - blocked.mean(axis=1)
            out[:, :3] = self.ambient * out[:, 3:]
            return out
        hit = self.scene.intersect(origins, dirs)
        geom = hit["geomID"]
        bounce = np.zeros((len(geom), 3), np.float32)
        for h, surface in enumerate(self.scene.surfaces):
            at = np.flatnonzero(geom == h)
            if len(at):
                prim = hit["primID"][at]
                # A ray that meets the back of a face started inside a surface (where fingers press into the palm)
                # or went through a gap in it: it brings nothing back.
                facing = np.einsum("ij,ji->i", dirs[at], self.scene.faces[h].table[GEOMETRIC:GEOMETRIC + 3, prim]) < 0
                at, prim = at[facing], prim[facing]
                self._light_vertices(h, np.unique(surface.faces[prim]))
                bu, bv = hit["u"][at], hit["v"][at]
                bounce[at] = interpolate(self.reflected[h], surface.faces, prim, bu, bv)
        visible = (geom < 0).reshape(-1, k).mean(axis=1, dtype=np.float32)
        gathered = bounce.reshape(-1, k, 3).mean(axis=1)
        out[:, 3] = visible
        out[:, :3] = (self.ambient * visible[:, None] + gathered) * sphere_bounce(visible, self.albedo[g][ids])
        return out

    def at(self, g: int, prim: np.ndarray, bu: np.ndarray, bv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(E (3, M) float32 indirect irradiance, V (M,) open fraction) at hits on surface g (faces ensured)."""
        f = self.scene.surfaces[g].faces[prim]
        values = self.values[g]
        a = np.take(values, f[:, 0], axis=1)
        v = a + bu * (np.take(values, f[:, 1], axis=1) - a) + bv * (np.take(values, f[:, 2], axis=1) - a)
        return v[:3], v[3]
