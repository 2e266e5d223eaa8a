"""Indirect light per vertex: the part of the ambient light that the hand and accessory do not hide (ambient
occlusion), and light reflected from one surface onto another (interreflection).

The ambient light (lights.Lighting.ambient) is a uniform environment: a Lambert surface that sees all of it reflects
albedo x ambient. Inside a fist, between fingers or under a ring part of that environment is hidden; the visible
part, weighted by the cosine to the normal, is the open fraction

    V(x) = 1/pi * integral over the hemisphere of n of visible(x, w) (n . w) dw          (1 = open sky, 0 = enclosed)

and what hides the sky is lit skin, which sends light back: in the path-traced reference a palm facing curled
fingers is lit by them (benchmarks/render_reference.py). Both are estimated per VERTEX with K cosine-weighted rays,
closest hits, then interpolated across faces at shading time:

    E(v) = (ambient V(v) + S(v)) / (1 - rho(v) (1 - V(v)))        indirect irradiance (pi folded in, as lights.py)
    S(v) = 1/K * sum over the rays that hit something of rho(hit) E_direct(hit)

V is the share of rays that escape; S is one bounce of the direct lights: E_direct is every light's cos-weighted,
shadowed irradiance at the vertices (one shadow ray per vertex and light), rho the diffuse albedo at the vertices,
both interpolated at the hit. The denominator adds the further bounces with the integrating-sphere model: a point
whose open fraction is V, among surfaces of its own albedo rho that see the same fraction, receives the geometric
series 1 + rho (1 - V) + ... of what arrives directly (exact inside a sphere with an opening). Without
interreflection (`ShadingOptions.interreflection` False) E = ambient V: plain ambient occlusion.

Per vertex rather than per pixel because its cost does not grow with the image (1,769 hand vertices at K = 16 are
28k rays, a fifth of a 512^2 frame's), it is free of pixel noise, and indirect light varies slowly across a surface;
only the vertices of faces a frame's rays hit are computed (VertexLight.ensure), and an accessory's vertices, far
denser than the hand's, get K / 4 rays (at least 4). What it loses is indirect light
that changes inside one triangle (sharp contact shadows), measured by `make bench` against the reference.

Directions: one stratified set of K cosine-weighted directions (a Fibonacci spiral on the unit disk lifted to the
hemisphere, Malley's method), turned about each vertex's normal and shifted radially by amounts hashed from (surface
index, vertex index), mirrored for a left hand. No random state: a frame's result depends only on its geometry and lights, whatever the
process, thread or order it is rendered in, and which of its vertices happen to be computed; a vertex gets the same
directions in every frame (no flicker in a sequence).
"""

from __future__ import annotations

import numpy as np

from darthand.render.scene import FaceData, interpolate

GEOMETRIC = FaceData.GEOMETRIC

GOLDEN = (np.sqrt(5.0) - 1) / 2      # Fibonacci spiral angle step, in turns
LIFT = 2e-3                          # ray origins lifted off the surface by this x the scene's diagonal (shade.SHADOW_LIFT)
MAX_BOUNCE_ALBEDO = 0.95             # keeps the sphere series finite where an albedo texel is white and V is 0
# Accessory meshes are far denser than the hand (a ring's 3,216 vertices on 2 cm, a chain's 9,408): their vertices
# get a quarter of the rays (at least 4), so that a chain does not cost several hands.
ACCESSORY_RAY_SHARE, ACCESSORY_MIN_RAYS = 4, 4


def disk_set(rays: int) -> tuple[np.ndarray, np.ndarray]:
    """(u (K,), turn (K,)): a Fibonacci spiral of K points on the unit disk, point k at radius sqrt(u_k) and angle
    2 pi turn_k, with u_k = (k + 0.5) / K (equal-area rings). Lifted to the hemisphere (z = sqrt(1 - u)) the points
    are cosine-distributed."""
    k = np.arange(rays, dtype=np.float64)
    return (k + 0.5) / rays, (k * GOLDEN) % 1.0


def hash_uniform(keys: np.ndarray, salt: int) -> np.ndarray:
    """(N,) float64 in [0, 1) from integer keys (N,) and a salt: a 32-bit integer mix, so the value of a key never
    depends on which other keys are hashed with it."""
    x = (np.asarray(keys, np.uint64) * np.uint64(0x9E3779B1) + np.uint64(salt & 0xFFFFFFFF) * np.uint64(0x85EBCA77))
    x &= np.uint64(0xFFFFFFFF)
    for shift, mult in ((16, 0x7FEB352D), (15, 0x846CA68B)):
        x ^= x >> np.uint64(shift)
        x = (x * np.uint64(mult)) & np.uint64(0xFFFFFFFF)
    x ^= x >> np.uint64(16)
    return x.astype(np.float64) / 2.0 ** 32


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


def local_directions(vertex_ids: np.ndarray, rays: int, salt: int) -> np.ndarray:
    """(3, N, K) float32 cosine-distributed directions in each vertex's tangent frame (x, y tangent, z normal): the
    disk set turned by a per-vertex angle and shifted by a per-vertex radial offset (Cranley-Patterson rotation),
    both hashed from the vertex ids (N,) and `salt`."""
    u, turn = disk_set(rays)
    uu = (u[None, :] + hash_uniform(vertex_ids, salt)[:, None]) % 1.0
    phi = 2 * np.pi * ((turn[None, :] + hash_uniform(vertex_ids, salt ^ 0x5BD1E995)[:, None]) % 1.0)
    r = np.sqrt(uu)
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - uu)]).astype(np.float32)


_LOCAL: dict = {}


def cached_local_directions(vertex_ids: np.ndarray, count: int, rays: int, salt: int) -> np.ndarray:
    """`local_directions` of the ids (N,) among `count` vertices, from a table of all of them made once per
    (count, rays, salt) (the hashes and trigonometry are most of the cost of making rays)."""
    key = (int(count), int(rays), int(salt))
    table = _LOCAL.get(key)
    if table is None:
        if len(_LOCAL) > 32:
            _LOCAL.clear()
        table = _LOCAL[key] = local_directions(np.arange(count), rays, salt)
    return table[:, vertex_ids]


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


def vertex_occlusion(vertices: np.ndarray, normals: np.ndarray, occluded, rays: int, lift: float,
                     salt: int = 0, mirrored: bool = False) -> np.ndarray:
    """(N,) float32 open fraction V of N vertices (N, 3) with unit normals (N, 3): the share of `rays` cosine-
    distributed rays per vertex that hit nothing. occluded(origins (R, 3), directions (R, 3), tfar) -> (R,) bool."""
    n = len(vertices)
    if n == 0 or rays <= 0:
        return np.ones(n, np.float32)
    origins, dirs = vertex_rays(vertices, normals, np.arange(n), rays, lift, salt, mirrored)
    blocked = occluded(origins, dirs, np.inf)
    return (1 - blocked.reshape(n, rays).mean(axis=1)).astype(np.float32)


def sphere_bounce(visible: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """(..., 3) the integrating-sphere factor 1 / (1 - rho (1 - V)) for open fractions V (...,) and albedos rho
    (..., 3) (clipped to MAX_BOUNCE_ALBEDO)."""
    rho = np.minimum(albedo, np.float32(MAX_BOUNCE_ALBEDO))
    return 1 / (1 - rho * (1 - np.asarray(visible)[..., None]))


_UVS: dict = {}


def vertex_uvs(surface) -> np.ndarray | None:
    """(N, 2) float32 one uv per vertex (a seam vertex takes one of its corners' uvs), or None without UVs; made once
    per (uvs, faces) arrays (the same every frame)."""
    if surface.uvs is None:
        return None
    key = (id(surface.uvs), id(surface.faces_uv), id(surface.faces), len(surface.vertices))
    entry = _UVS.get(key)
    if entry is None or entry[0] is not surface.uvs or entry[1] is not surface.faces:
        if len(_UVS) > 64:
            _UVS.clear()
        uv = np.zeros((len(surface.vertices), 2), np.float32)
        uv[surface.faces.ravel()] = surface.uvs[surface.faces_uv.ravel()]
        entry = _UVS[key] = (surface.uvs, surface.faces, uv)
    return entry[2]


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
