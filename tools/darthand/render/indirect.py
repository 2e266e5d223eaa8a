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
The loops over vertices and rays are compiled kernels (darthand/jit.py) between the Embree calls: about 1 ms of a
frame's CPU besides Embree's 3 (the numpy chains they replaced took 4-5 ms, with the same values to the bit).

Directions: one stratified set of K cosine-weighted directions (a Fibonacci spiral on the unit disk lifted to the
hemisphere, Malley's method), turned about each vertex's normal and shifted radially by amounts hashed from (surface
index, vertex index), mirrored for a left hand. No random state: a frame's result depends only on its geometry and
lights, whatever the process, thread or order it is rendered in, and which of its vertices happen to be computed; a
vertex gets the same directions in every frame (no flicker in a sequence).
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np

from darthand.jit import kernel
from darthand.render.lights import light_table
from darthand.render.scene import FaceData, interpolate_columns
from darthand.render.shade import vertex_albedo

GEOMETRIC = FaceData.GEOMETRIC

GOLDEN = (np.sqrt(5.0) - 1) / 2      # Fibonacci spiral angle step, in turns
LIFT = 2e-3                          # ray origins lifted off the surface by this x the scene's diagonal
                                     # (shade.SHADOW_LIFT)
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


def local_directions(vertex_ids: np.ndarray, rays: int, salt: int) -> np.ndarray:
    """(3, N, K) float32 cosine-distributed directions in each vertex's tangent frame (x, y tangent, z normal): the
    disk set turned by a per-vertex angle and shifted by a per-vertex radial offset (Cranley-Patterson rotation),
    both hashed from the vertex ids (N,) and `salt`."""
    u, turn = disk_set(rays)
    uu = (u[None, :] + hash_uniform(vertex_ids, salt)[:, None]) % 1.0
    phi = 2 * np.pi * ((turn[None, :] + hash_uniform(vertex_ids, salt ^ 0x5BD1E995)[:, None]) % 1.0)
    r = np.sqrt(uu)
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - uu)]).astype(np.float32)


_LOCAL: OrderedDict = OrderedDict()
LOCAL_BUDGET = 32 << 20     # bytes of direction tables kept: the hand's and all 50 accessories' at 16 rays take 11 MB


def direction_table(count: int, rays: int, salt: int) -> np.ndarray:
    """(3, count, K) float32 `local_directions` of vertices 0..count-1, made once per (count, rays, salt) and kept,
    least recently used dropped first beyond LOCAL_BUDGET (they depend on the mesh's vertex count only, and making
    them, hashes and trigonometry, costs 1-3 ms for an accessory: more than the rest of its indirect light)."""
    key = (int(count), int(rays), int(salt))
    table = _LOCAL.get(key)
    if table is None:
        table = _LOCAL[key] = local_directions(np.arange(count), rays, salt)
        while len(_LOCAL) > 1 and sum(t.nbytes for t in _LOCAL.values()) > LOCAL_BUDGET:
            _LOCAL.popitem(last=False)
    else:
        _LOCAL.move_to_end(key)
    return table


def vertex_rays(vertices: np.ndarray, normals: np.ndarray, vertex_ids: np.ndarray, rays: int, lift: float,
                salt: int = 0, mirrored: bool = False, count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(origins, directions) (N * K, 3) float32, vertex-major: K cosine-distributed rays about each unit normal
    (N, 3), leaving from the vertex (N, 3) lifted by `lift` metres along its normal; vertex_ids (N,) pick each
    vertex's directions (local_directions). mirrored: the surface is the x -> -x mirror image of the one the
    directions are defined for (a left hand): its rays are the mirror images of the right hand's, so that both hands
    render alike. count: the surface's vertex count, to reuse the directions of all its vertices (direction_table)."""
    if count is None:
        table, table_rows = local_directions(vertex_ids, rays, salt), np.arange(len(vertex_ids), dtype=np.int64)
    else:
        table, table_rows = direction_table(count, rays, salt), np.ascontiguousarray(vertex_ids, np.int64)
    return _rays_kernel(np.ascontiguousarray(vertices, np.float32), np.ascontiguousarray(normals, np.float32), table,
                        table_rows, np.float32(lift), bool(mirrored))


@kernel
def _rays_kernel(vertices, normals, table, table_rows, lift, mirrored):
    """(origins, directions) (N * K, 3) float32 of (N, 3) float32 vertices and unit normals: the i-th's directions
    table[:, table_rows[i]] (3, K), in its tangent frame.

    Tangent frame: t = e x n / max(|e x n|, 1e-30), s = n x t, with e the x axis where |n_x| < 0.9, else the y
    axis; built from the x axis so that the frame of a mirrored normal (x -> -x, how a left hand is made from a
    right one) is the mirror of the frame up to the sign of one local axis, which `mirrored` flips (y about the x
    axis, x about the y axis). Direction = (x t + y s) + z n; origin = vertex + lift n. Float32 arithmetic in the
    order of the numpy version it replaced (cross products as numpy's, sums x, y, z)."""
    k = table.shape[2]
    origins = np.empty((vertices.shape[0] * k, 3), np.float32)
    dirs = np.empty((vertices.shape[0] * k, 3), np.float32)
    zero, one, tiny, near_x = np.float32(0.0), np.float32(1.0), np.float32(1e-30), np.float32(0.9)
    for i in range(vertices.shape[0]):
        row = table_rows[i]
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        about_x = abs(n0) < near_x
        e0 = one if about_x else zero
        e1 = zero if about_x else one
        e2 = zero
        t0 = e1 * n2 - e2 * n1
        t1 = e2 * n0 - e0 * n2
        t2 = e0 * n1 - e1 * n0
        length = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        length = tiny if length < tiny else length          # np.maximum: NaN stays NaN
        t0, t1, t2 = t0 / length, t1 / length, t2 / length
        s0 = n1 * t2 - n2 * t1
        s1 = n2 * t0 - n0 * t2
        s2 = n0 * t1 - n1 * t0
        o0 = vertices[i, 0] + lift * n0
        o1 = vertices[i, 1] + lift * n1
        o2 = vertices[i, 2] + lift * n2
        for j in range(k):
            x, y, z = table[0, row, j], table[1, row, j], table[2, row, j]
            if mirrored:
                if about_x:
                    y = -y
                else:
                    x = -x
            r = i * k + j
            dirs[r, 0] = x * t0 + y * s0 + z * n0
            dirs[r, 1] = x * t1 + y * s1 + z * n1
            dirs[r, 2] = x * t2 + y * s2 + z * n2
            origins[r, 0], origins[r, 1], origins[r, 2] = o0, o1, o2
    return origins, dirs


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

    Per vertex, made when first needed: the diffuse albedo rho (3) (for the sphere factor of the vertices computed
    and the light reflected by the vertices hit), and the direct light the vertex reflects, rho x irradiance (3)
    (all lights, cos-weighted, one shadow ray per shadowed light) -- only at the vertices of faces the indirect rays
    hit, so that the cost follows what a frame sees, not the accessory's vertex count. `ensure(g, prim)` computes E
    and V (above) for the vertices of faces `prim` of surface g that have none yet; `at(g, prim, bu, bv)`
    interpolates them at hits: (E (3, M), V (M,)). Not thread-safe: `ensure` runs before a batch is shaded in
    parallel.

    The per-vertex loops are compiled kernels (darthand/jit.py) between the Embree calls, each in the float32 order
    of the numpy it replaced: the same values to the bit."""

    def __init__(self, scene, lights: list[dict], ambient: np.ndarray, rays: int, interreflection: bool = True,
                 counters: dict | None = None, environment=None):
        """lights: lights.world_lights' dicts (radiance (3,) float32); ambient (3,) float32; rays per hand vertex;
        counters: adds 'indirect_rays' (indirect and shadow rays cast); environment: the frame's
        environment.FrameEnvironment or None: the vertex sees its remainder's unoccluded irradiance
        (`irradiance`, the cosine-weighted mean of the sky over the normal's hemisphere) less what its blocked rays
        would have seen (`sky` along them), besides the ambient light: the mean of the sky over the escaping rays,
        with the unoccluded part exact (a control variate: an open vertex gets no noise)."""
        if int(rays) < 1:
            raise ValueError(f"VertexLight needs at least 1 ray per vertex, not {rays} (without indirect light, "
                             "make none)")
        self.scene, self.lights, self.rays = scene, lights, int(rays)
        self.environment = environment
        self.interreflection = bool(interreflection)
        self.ambient = np.ascontiguousarray(ambient, np.float32)
        self.lift = LIFT * max(scene.extent, 1e-3)
        self.counters = counters if counters is not None else {}
        sizes = [len(s.vertices) for s in scene.surfaces]
        self.meshes: list = [None] * len(sizes)                            # (vertices, normals, faces) for kernels
        self.albedo = [np.zeros((n, 3), np.float32) for n in sizes]
        self.has_albedo = [np.zeros(n, bool) for n in sizes]
        self.reflected = [np.zeros((3, n), np.float32) for n in sizes]     # albedo x direct irradiance; by row
        self.lit = [np.zeros(n, bool) for n in sizes]                      # reflected made
        self.values = [np.zeros((4, n), np.float32) for n in sizes]        # E (3), V; by row
        self.done = [np.zeros(n, bool) for n in sizes]
        self.light_table = light_table(lights)

    def _mesh(self, g: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Surface g's (vertices (N, 3) float32, normals (N, 3) float32, faces (F, 3) int32), contiguous."""
        mesh = self.meshes[g]
        if mesh is None:
            s = self.scene.surfaces[g]
            mesh = self.meshes[g] = (np.ascontiguousarray(s.vertices, np.float32),
                                     np.ascontiguousarray(s.normals, np.float32),
                                     np.ascontiguousarray(s.faces, np.int32))
        return mesh

    def _albedo(self, g: int, ids: np.ndarray) -> None:
        """Make the albedo of surface g's vertices `ids` that have none yet."""
        ids = ids[~self.has_albedo[g][ids]]
        if not len(ids):
            return
        s = self.scene.surfaces[g]
        uvs = vertex_uvs(s)
        self.albedo[g][ids] = vertex_albedo(s.material, None if uvs is None else uvs[ids], len(ids))
        self.has_albedo[g][ids] = True

    def _reflect(self, g: int, ids: np.ndarray) -> None:
        """Make the reflected light of surface g's vertices `ids` that have none yet: albedo x the irradiance (pi
        folded) of the lights, cos-weighted, shadowed (one shadow ray per vertex and shadowed light it faces)."""
        ids = ids[~self.lit[g][ids]]
        if not len(ids):
            return
        self._albedo(g, ids)
        vertices, normals, _ = self._mesh(g)
        state, contribution, origins, dirs, tfar = _lights_kernel(vertices, normals, ids, self.light_table,
                                                                  np.float32(self.lift))
        blocked = np.zeros(0, bool)
        if len(origins):
            blocked = self.scene.occluded(origins, dirs, tfar)
            self._count(len(origins))
        _reflect_kernel(ids, state, contribution, blocked, self.albedo[g], self.reflected[g])
        self.lit[g][ids] = True

    def ensure(self, g: int, prim: np.ndarray) -> None:
        """Compute E and V for the vertices of faces `prim` of surface g that have none yet."""
        todo = _todo_kernel(self._mesh(g)[2], np.ascontiguousarray(prim, np.int32), self.done[g])
        if len(todo):
            self._compute(g, todo)
            self.done[g][todo] = True

    def _compute(self, g: int, ids: np.ndarray) -> None:
        """Compute E and V of surface g's vertices `ids` (int64) into values[g]."""
        s = self.scene.surfaces[g]
        vertices, normals, _ = self._mesh(g)
        k = self.rays if s.role == "hand" else max(ACCESSORY_MIN_RAYS, self.rays // ACCESSORY_RAY_SHARE)
        origins, dirs = vertex_rays(vertices[ids], normals[ids], ids, k, self.lift, salt=977 * g + 1,
                                    mirrored=self.scene.subject.side == "left", count=len(vertices))
        self._count(len(origins))
        if not self.interreflection:
            blocked = self.scene.occluded(origins, dirs, np.inf)
            _open_kernel(blocked, k, self.ambient, ids, self.values[g])
            if self.environment is not None:
                self.values[g][:3, ids] += self._environment_seen(normals[ids], dirs, blocked, k).T
            return
        self._albedo(g, ids)
        hit = self.scene.intersect(origins, dirs)
        geom, prim = np.ascontiguousarray(hit["geomID"], np.int32), np.ascontiguousarray(hit["primID"], np.int32)
        u, v = np.ascontiguousarray(hit["u"], np.float32), np.ascontiguousarray(hit["v"], np.float32)
        bounce = np.zeros((3, len(geom)), np.float32)                      # the light each ray brings back
        for h in range(len(self.scene.surfaces)):
            faces = self._mesh(h)[2]
            rays, hit_vertices = _facing_kernel(geom, prim, dirs, h, self.scene.faces[h].table, GEOMETRIC, faces,
                                                len(self.done[h]))
            if len(rays):
                self._reflect(h, hit_vertices)
                interpolate_columns(self.reflected[h], faces, prim, u, v, rays=rays, out=bounce)
        if self.environment is not None:              # added to each of a vertex's k rays: to their mean
            bounce += np.repeat(self._environment_seen(normals[ids], dirs, geom >= 0, k), k, axis=0).T
        _gather_vertices_kernel(geom, bounce, k, self.ambient, self.albedo[g], np.float32(MAX_BOUNCE_ALBEDO), ids,
                                self.values[g])

    def _environment_seen(self, normals: np.ndarray, dirs: np.ndarray, blocked: np.ndarray, k: int) -> np.ndarray:
        """(N, 3) float32 the environment's pi-folded irradiance at N vertices with unit normals (N, 3) whose k rays
        each (dirs (N * k, 3), vertex-major) are `blocked` (N * k,) bool: the unoccluded irradiance times, per
        channel, the share of the rays' sky that the open rays see (1 for an open vertex: exact; the open fraction
        under a uniform map). A ratio, not the difference of the two estimates: the order-2 irradiance smooths a
        bright patch that the blocked rays' sky does not, and their difference went below zero in one channel
        (blue blotches between fingers under a blue sky)."""
        assert self.environment is not None
        blocked = np.ascontiguousarray(blocked, np.bool_)
        open_sky = np.ascontiguousarray(self.environment.irradiance(normals.T).T, np.float32)
        # a vertex whose rays all escape, or none, takes share 1 or 0 whatever the sky: looked up for the others only
        closed = blocked.reshape(-1, k).sum(axis=1)
        sky = self.environment.sky(dirs, np.repeat((closed > 0) & (closed < k), k))
        out = np.empty((len(normals), 3), np.float32)
        _sky_share_kernel(open_sky, sky, blocked, int(k), out)
        return out

    def at(self, g: int, prim: np.ndarray, bu: np.ndarray, bv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(E (3, M) float32 indirect irradiance, V (M,) open fraction) at hits on faces prim (M,) of surface g
        (ensured), barycentrics bu, bv (M,) float32."""
        v = interpolate_columns(self.values[g], self._mesh(g)[2], prim, bu, bv)
        return v[:3], v[3]

    def _count(self, rays: int) -> None:
        self.counters["indirect_rays"] = self.counters.get("indirect_rays", 0) + rays


# ------------------------------------------------------------------------------------------------ kernels
# Each does in one pass what a chain of numpy steps did, in their float32 order: tests/render/test_indirect_kernels.py
# compares them bit for bit with that numpy (tests/render/indirect_numpy.py).


@kernel
def _sky_share_kernel(open_sky, sky, blocked, k, out):
    """out (N, 3) float32 = max(open_sky, 0) x share, the share per vertex and channel of the sky its k rays see
    (sky (N * k, 3) float32 along each ray, `blocked` (N * k,) bool): the open rays' sky over all rays' sky, summed
    in float64 ray by ray, or where that sum is not over 1e-12 the open rays' fraction. numpy's
    where(blocked, 0, sky).sum(1) / sky.sum(1) and mean of the blocked, in the same order (_environment_seen's
    definition, tests/render/test_frame_fixed_costs.py)."""
    zero = np.float32(0)
    for n in range(out.shape[0]):
        first = n * k
        closed = 0
        for j in range(k):
            if blocked[first + j]:
                closed += 1
        open_fraction = 1.0 - closed / k
        for c in range(3):
            total = np.float64(sky[first, c])
            seen = 0.0 if blocked[first] else total
            for j in range(1, k):
                value = np.float64(sky[first + j, c])
                seen += 0.0 if blocked[first + j] else value
                total += value
            share = seen / total if total > 1e-12 else open_fraction
            o = open_sky[n, c]
            lit = o if (o > zero or o != o) else zero            # numpy's maximum(o, 0): NaN kept, -0 -> 0
            out[n, c] = np.float32(np.float64(lit) * share)


@kernel
def _todo_kernel(faces, prim, done):
    """(T,) int64 ascending: the vertices of faces `prim` (M,) int32 (faces (F, 3) int32) that are not `done` (N,).
    (Faces first: a frame's hits are many per face.)"""
    hit = np.zeros(faces.shape[0], np.bool_)
    for i in range(prim.shape[0]):
        hit[prim[i]] = True
    needed = np.zeros(done.shape[0], np.bool_)
    for f in range(faces.shape[0]):
        if hit[f]:
            needed[faces[f, 0]] = True
            needed[faces[f, 1]] = True
            needed[faces[f, 2]] = True
    count = 0
    for i in range(done.shape[0]):
        if needed[i] and not done[i]:
            count += 1
    todo = np.empty(count, np.int64)
    count = 0
    for i in range(done.shape[0]):
        if needed[i] and not done[i]:
            todo[count] = i
            count += 1
    return todo


@kernel
def _lights_kernel(vertices, normals, ids, lights, lift):
    """The lights (L, 8) (lights.light_table) at vertices `ids` (N,) int64 of
    (V, 3) float32 vertices and normals: (state (L, N) int64: -2 the vertex faces away from the light (cos <= 0), -1
    lit without a shadow ray, else its shadow ray's index; contributions cos x radiance (L, N, 3) float32; the shadow
    rays' origins (S, 3) (the vertex lifted by `lift` along its normal), unit directions (S, 3), tfar (S,) float32).
    A point light's radiance falls off as 1 / max(d^2, 1e-12) and its shadow ray stops `lift` short of it; a
    directional light's goes to infinity. Float32, in the order of the numpy it replaced (d / max(|d|, 1e-9))."""
    n, count_lights = ids.shape[0], lights.shape[0]
    state = np.empty((count_lights, n), np.int64)
    contribution = np.empty((count_lights, n, 3), np.float32)
    origins = np.empty((count_lights * n, 3), np.float32)
    dirs = np.empty((count_lights * n, 3), np.float32)
    tfar = np.empty(count_lights * n, np.float32)
    zero, tiny, tiny2 = np.float32(0.0), np.float32(1e-9), np.float32(1e-12)
    inf = np.float32(np.inf)
    count = 0
    for k in range(count_lights):
        for i in range(n):
            vi = ids[i]
            n0, n1, n2 = normals[vi, 0], normals[vi, 1], normals[vi, 2]
            s0, s1, s2 = lights[k, 4], lights[k, 5], lights[k, 6]
            if lights[k, 0] != zero:
                d0 = lights[k, 1] - vertices[vi, 0]
                d1 = lights[k, 2] - vertices[vi, 1]
                d2 = lights[k, 3] - vertices[vi, 2]
                dist = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                length = tiny if dist < tiny else dist             # np.maximum: NaN stays NaN
                l0, l1, l2 = d0 / length, d1 / length, d2 / length
                square = dist * dist
                square = tiny2 if square < tiny2 else square
                s0, s1, s2 = s0 / square, s1 / square, s2 / square
                far = dist - lift
                far = zero if far < zero else far
            else:
                l0, l1, l2 = lights[k, 1], lights[k, 2], lights[k, 3]
                far = inf
            cos = n0 * l0 + n1 * l1 + n2 * l2
            contribution[k, i, 0], contribution[k, i, 1], contribution[k, i, 2] = cos * s0, cos * s1, cos * s2
            if not cos > zero:
                state[k, i] = -2
            elif lights[k, 7] == zero:
                state[k, i] = -1
            else:
                state[k, i] = count
                origins[count, 0] = vertices[vi, 0] + lift * n0
                origins[count, 1] = vertices[vi, 1] + lift * n1
                origins[count, 2] = vertices[vi, 2] + lift * n2
                dirs[count, 0], dirs[count, 1], dirs[count, 2] = l0, l1, l2
                tfar[count] = far
                count += 1
    return state, contribution, origins[:count], dirs[:count], tfar[:count]


@kernel
def _reflect_kernel(ids, state, contribution, blocked, albedo, reflected):
    """reflected[:, ids[i]] = albedo[ids[i]] x the sum, light by light in order from 0, of the contributions (L, N, 3)
    of the lights that reach the vertex (state (L, N) from _lights_kernel, blocked (S,) bool of its shadow rays)."""
    for i in range(ids.shape[0]):
        e0, e1, e2 = np.float32(0.0), np.float32(0.0), np.float32(0.0)
        for k in range(state.shape[0]):
            ray = state[k, i]
            if ray == -2 or (ray >= 0 and blocked[ray]):
                continue
            e0 += contribution[k, i, 0]
            e1 += contribution[k, i, 1]
            e2 += contribution[k, i, 2]
        vi = ids[i]
        reflected[0, vi] = albedo[vi, 0] * e0
        reflected[1, vi] = albedo[vi, 1] * e1
        reflected[2, vi] = albedo[vi, 2] * e2


@kernel
def _facing_kernel(geom, prim, dirs, h, table, row, faces, count):
    """Of rays (R,) with hits geom, prim (R,) int32 and directions (R, 3) float32: (the rays (M,) int64 that hit
    the front of a face of surface h, the vertices (U,) int64 ascending of the faces they hit, among `count`). Front:
    direction . geometric normal < 0, the normal at rows row..row+2 of the FaceData table (K, F) float32; a ray that
    meets the back of a face started inside a surface (where fingers press into the palm) or went through a gap in
    it: it brings nothing back."""
    rays = np.empty(geom.shape[0], np.int64)
    used = np.zeros(count, np.bool_)
    m = 0
    zero = np.float32(0.0)
    for i in range(geom.shape[0]):
        if geom[i] != h:
            continue
        p = prim[i]
        if dirs[i, 0] * table[row, p] + dirs[i, 1] * table[row + 1, p] + dirs[i, 2] * table[row + 2, p] < zero:
            rays[m] = i
            m += 1
            used[faces[p, 0]] = True
            used[faces[p, 1]] = True
            used[faces[p, 2]] = True
    u = 0
    for i in range(count):
        if used[i]:
            u += 1
    vertices = np.empty(u, np.int64)
    u = 0
    for i in range(count):
        if used[i]:
            vertices[u] = i
            u += 1
    return rays[:m], vertices


@kernel
def _gather_vertices_kernel(geom, bounce, k, ambient, albedo, max_albedo, ids, values):
    """values[:, ids[i]] = (E (3), V) of the i-th vertex from its k rays i k .. i k + k - 1 (geom (R,) int32, -1
    missed; bounce (3, R) float32 the light each brings back): V = misses / k, gathered light S = mean bounce
    (summed in ray order, then divided in float64 as numpy's mean), E = (ambient V + S) / (1 - rho (1 - V)) with
    rho = min(albedo[ids[i]], max_albedo)."""
    one = np.float32(1.0)
    for i in range(ids.shape[0]):
        first = i * k
        misses = 0
        for j in range(k):
            if geom[first + j] < 0:
                misses += 1
        visible = np.float32(np.float64(misses) / np.float64(k))
        vi = ids[i]
        for ch in range(3):
            total = bounce[ch, first]
            for j in range(1, k):
                total += bounce[ch, first + j]
            gathered = np.float32(np.float64(total) / np.float64(k))
            rho = albedo[vi, ch]
            rho = max_albedo if rho > max_albedo else rho      # np.minimum: NaN stays NaN
            values[ch, vi] = (ambient[ch] * visible + gathered) * (one / (one - rho * (one - visible)))
        values[3, vi] = visible


@kernel
def _open_kernel(blocked, k, ambient, ids, values):
    """values[:, ids[i]] = (ambient V, V) with V = 1 - the share of the i-th vertex's k rays `blocked` (R,) bool
    (in float64, as numpy's mean of booleans, then float32): ambient occlusion without interreflection."""
    for i in range(ids.shape[0]):
        hits = 0
        for j in range(i * k, i * k + k):
            if blocked[j]:
                hits += 1
        visible = np.float32(1.0 - np.float64(hits) / np.float64(k))
        vi = ids[i]
        for ch in range(3):
            values[ch, vi] = ambient[ch] * visible
        values[3, vi] = visible
