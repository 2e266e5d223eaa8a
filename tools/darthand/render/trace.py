"""Tracing and shading batches of image samples, in parallel over chunks.

A sample is a position (u, v) in pixels; its ray leaves the camera centre through it. Only the pixels inside the
projected bounding box of the scene are traced (`scene_bounds`); every other pixel is background without a ray.
Chunks of samples are traced, shadowed and shaded on a ThreadPoolExecutor: embreex's ray loop releases the GIL and
so do numpy's large array operations, so two chunks run at once on two cores. The scene is committed before
(scene.Scene), never by a parallel query.
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import ThreadpoolController

from darthand.jit import kernel
from darthand.model.layout import FACE_LABEL_IDS
from darthand.render.camera import Camera, point_bounds
from darthand.render.environment import FrameEnvironment
from darthand.render.indirect import VertexLight
from darthand.render.raster import camera_hits
from darthand.render.scene import Scene, interpolate_columns
from darthand.render.shade import DEFAULT_SKIN, shade, surface_hits
from darthand.render.shadows import hit_corners
from darthand.render.skin import surface_radius
from darthand.render.skin_detail import detail_at

NAIL = FACE_LABEL_IDS["nail"]
MIN_CHUNK = 4096          # samples per parallel task, at least
TILE = 4                  # pixels: primary rays are traced only in tiles some projected triangle touches (4: 5 %
                          # fewer rays than 8, the same image: an untouched tile sees nothing)
_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOL_LOCK = threading.Lock()


def default_threads() -> int:
    """Both cores of the reference machine (os.cpu_count(), at most 8)."""
    return max(1, min(8, os.cpu_count() or 1))


def single_threaded_blas():
    """A context in which the BLAS libraries loaded in the process (numpy's, scipy's) run on one thread.

    The renderer parallelises over its own pool; BLAS worker threads for the many small matrix products of a frame
    (skinning, projections, ray transforms) spin-wait on the cores that pool needs, which on two cores costs more
    than they save. The libraries are looked up once per process (a lookup costs milliseconds)."""
    global _BLAS
    if _BLAS is None:
        _BLAS = ThreadpoolController()
    return _BLAS.limit(limits=1, user_api="blas")


_BLAS: ThreadpoolController | None = None


def pool(threads: int) -> ThreadPoolExecutor:
    """A process-wide executor with `threads` workers (created once)."""
    with _POOL_LOCK:
        if threads not in _POOLS:
            _POOLS[threads] = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="darthand-render")
        return _POOLS[threads]


@dataclass
class Context:
    """What every sample batch of one frame shares; indirect: the frame's indirect light at the vertices
    (indirect.VertexLight), or None; skin: the skin model (shade.SKIN_MODELS); environment: the frame's environment
    map lighting (environment.FrameEnvironment; its lights are among `lights`), or None; skin_specular,
    skin_detail and shadows: shade.ShadingOptions' (the skin's specular model, the strength of its relief, shadow
    rays per sample or per vertex)."""

    scene: Scene
    camera: Camera
    lights: list
    ambient: np.ndarray
    threads: int = 1
    indirect: VertexLight | None = None
    skin: str = DEFAULT_SKIN
    environment: FrameEnvironment | None = None
    skin_specular: str = "single"
    skin_detail: float = 0.0
    shadows: str = "pixel"
    dDdx: np.ndarray = field(init=False)
    dDdy: np.ndarray = field(init=False)

    def __post_init__(self):
        dx, dy = self.camera.direction_derivatives()
        self.dDdx, self.dDdy = dx.astype(np.float32), dy.astype(np.float32)
        self.D0 = self.camera.directions(np.zeros((1, 2)))[0].astype(np.float32)

    def directions(self, uv: np.ndarray) -> np.ndarray:
        """(3, N) float32 world ray directions (camera z = 1) of pixel positions uv (N, 2): affine in (u, v)."""
        u = uv[:, 0].astype(np.float32)
        v = uv[:, 1].astype(np.float32)
        return np.stack([self.D0[c] + u * self.dDdx[c] + v * self.dDdy[c] for c in range(3)])


@dataclass
class Samples:
    """Per sample (N): geom (int32, -1 = background), prim (int32), depth (float32 camera z, inf for background),
    normal (3, N) float32 shading normal (world, facing the camera), radiance (3, N) float32 linear."""

    geom: np.ndarray
    prim: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    radiance: np.ndarray

    @staticmethod
    def concat(parts: list["Samples"]) -> "Samples":
        return Samples(*(np.concatenate([getattr(p, f) for p in parts], axis=-1) for f in
                         ("geom", "prim", "depth", "normal", "radiance")))


def scene_bounds(camera: Camera, points: np.ndarray, pad: float = 1.0) -> tuple[int, int, int, int]:
    """(r0, r1, c0, c1): the pixel rows [r0, r1) and columns [c0, c1) that the projection of `points` (N, 3) can
    touch, padded by `pad` pixels and clipped to the image; the whole image when a point is behind the camera."""
    uv, z = camera.project(points)
    if (z <= 1e-9).any() or not np.isfinite(uv).all():
        return 0, camera.height, 0, camera.width
    lo, hi = point_bounds(uv)
    lo = np.floor(lo - pad).astype(int)
    hi = np.ceil(hi + pad).astype(int)
    c0, r0 = np.maximum(lo, 0)
    c1, r1 = np.minimum(hi, [camera.width, camera.height])
    return int(r0), int(max(r0, r1)), int(c0), int(max(c0, c1))


@dataclass
class RayHits:
    """Closest hits of N camera rays: geom (N,) int32 surface index (-1 background), prim (N,) int32, barycentrics
    u, v (N,) float32, depth (N,) float32 camera z (inf for background), directions (3, N) float32 (camera z = 1)."""

    geom: np.ndarray
    prim: np.ndarray
    u: np.ndarray
    v: np.ndarray
    depth: np.ndarray
    directions: np.ndarray

    def take(self, index: np.ndarray | slice) -> "RayHits":
        return RayHits(self.geom[index], self.prim[index], self.u[index], self.v[index], self.depth[index],
                       self.directions[:, index])

    @staticmethod
    def concat(parts: list["RayHits"]) -> "RayHits":
        return RayHits(*(np.concatenate([getattr(p, f) for p in parts], axis=-1) for f in
                         ("geom", "prim", "u", "v", "depth", "directions")))


def intersect_samples(ctx: Context, uv: np.ndarray, stats: dict | None = None) -> RayHits:
    """Closest hits of the camera rays through pixel positions uv (N, 2): rasterised (raster.py) when that is on
    and applies, else Embree's. stats: adds seconds 'trace', counts 'rays' and 'rasterised' (of them)."""
    t0 = time.perf_counter()
    n = len(uv)
    directions = np.empty((3, n), np.float32)
    _directions_kernel(np.ascontiguousarray(uv, np.float64), ctx.D0, ctx.dDdx, ctx.dDdy, directions)
    rasterised = camera_hits(ctx.scene, ctx.camera, uv, directions)      # None: off, or Embree must answer
    if rasterised is not None:
        geom, prim, u, v, depth = rasterised
    else:
        origins = np.empty((n, 3), np.float32)
        origins[:] = ctx.camera.centre.astype(np.float32)
        hit = ctx.scene.intersect(origins, np.ascontiguousarray(directions.T))
        prim, u, v = hit["primID"].astype(np.int32), hit["u"], hit["v"]
        geom, depth = np.empty(n, np.int32), np.empty(n, np.float32)
        _closest_kernel(np.ascontiguousarray(hit["geomID"], np.int32), prim,
                        np.ascontiguousarray(hit["tfar"], np.float32), geom, depth)
    if stats is not None:
        stats["trace"] = stats.get("trace", 0.0) + time.perf_counter() - t0
        stats["rays"] = stats.get("rays", 0) + n
        if rasterised is not None:
            stats["rasterised"] = stats.get("rasterised", 0) + n
    return RayHits(geom, prim, u, v, depth, directions)


@kernel
def _directions_kernel(uv, D0, dDdx, dDdy, directions):
    """directions (3, N) float32 of the camera rays through pixel positions uv (N, 2) float64: D0 + u dDdx + v dDdy
    (u, v rounded to float32 first), as Context.directions computes them."""
    for i in range(uv.shape[0]):
        u, v = np.float32(uv[i, 0]), np.float32(uv[i, 1])
        for c in range(3):
            directions[c, i] = D0[c] + u * dDdx[c] + v * dDdy[c]


@kernel
def _closest_kernel(geom_id, prim, tfar, geom, depth):
    """Per ray: geom the surface index (-1 where primID < 0) and depth tfar (inf for background)."""
    for i in range(prim.shape[0]):
        g = geom_id[i] if prim[i] >= 0 else -1
        geom[i] = g
        depth[i] = tfar[i] if g >= 0 else np.float32(np.inf)


def shade_hits(ctx: Context, hits: RayHits, footprint: float = 1.0,
               stats: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(normal (3, N), radiance (3, N)) float32 at ray hits (zero for background): shading normal facing the
    camera, and outgoing radiance (linear) with shadows.

    footprint: the sample's share of a pixel's width (1 for one sample per pixel), for the texture filter. stats:
    adds seconds 'shade' (incl. shadow rays) and count 'shadow_rays'."""
    t0 = time.perf_counter()
    n = len(hits.geom)
    normal = np.zeros((3, n), np.float32)
    radiance = np.zeros((3, n), np.float32)
    counters: dict = {}
    pixel_angle = footprint / float(np.sqrt(abs(np.linalg.det(ctx.camera.K[:2, :2]))))
    for g, surface in enumerate(ctx.scene.surfaces):
        idx, on = hits_on(hits, g)
        if not len(idx):
            continue
        at = surface_hits(ctx.scene.faces[g], on.prim, on.u, on.v, on.directions, on.depth, pixel_angle)
        if ctx.indirect is not None:
            at.indirect, at.visible = ctx.indirect.at(g, on.prim, on.u, on.v)
        elif ctx.environment is not None:               # no indirect rays: the environment unoccluded
            at.indirect = ctx.environment.irradiance(at.normal) + ctx.ambient[:, None]
        if ctx.skin == "subsurface" and surface.material.kind == "skin":
            skin_at(at, surface, on.prim, on.u, on.v)
        _put_columns_kernel(idx, np.ascontiguousarray(at.normal, np.float32), normal)
        occlusion = skin_surface_at(ctx, at, surface, ctx.scene.faces[g].table, on.prim)
        if ctx.shadows == "vertex":
            at.corners = hit_corners(surface.faces, ctx.scene.faces[g].table, surface.vertices, surface.normals,
                                     on.prim, at.view)
        colour = shade(surface.material, at, ctx.lights, ctx.ambient, ctx.scene.occluded, ctx.scene.extent,
                       counters, ctx.skin, ctx.environment, ctx.skin_specular)
        if occlusion is not None:
            colour *= occlusion
        _put_columns_kernel(idx, np.ascontiguousarray(colour, np.float32), radiance)
    if stats is not None:
        stats["shade"] = stats.get("shade", 0.0) + time.perf_counter() - t0
        stats["shadow_rays"] = stats.get("shadow_rays", 0) + counters.get("shadow_rays", 0)
    return normal, radiance


def hits_on(hits: RayHits, g: int) -> tuple[np.ndarray, RayHits]:
    """(idx (M,) int64 ascending, hits.take(idx)) of the hits on surface g, in one pass."""
    idx, *fields = _hits_on_kernel(np.ascontiguousarray(hits.geom, np.int32), np.int32(g),
                                   np.ascontiguousarray(hits.prim, np.int32), np.ascontiguousarray(hits.u, np.float32),
                                   np.ascontiguousarray(hits.v, np.float32),
                                   np.ascontiguousarray(hits.depth, np.float32),
                                   np.ascontiguousarray(hits.directions, np.float32))
    return idx, RayHits(*fields)


@kernel
def _hits_on_kernel(geom, g, prim, u, v, depth, directions):
    """(idx, prim, u, v, depth, directions) of the rays whose geom is g, in ray order."""
    m = 0
    for i in range(geom.shape[0]):
        if geom[i] == g:
            m += 1
    idx = np.empty(m, np.int64)
    out_geom, out_prim = np.empty(m, np.int32), np.empty(m, np.int32)
    out_u, out_v, out_depth = np.empty(m, np.float32), np.empty(m, np.float32), np.empty(m, np.float32)
    out_dir = np.empty((3, m), np.float32)
    k = 0
    for i in range(geom.shape[0]):
        if geom[i] == g:
            idx[k] = i
            out_geom[k], out_prim[k], out_u[k], out_v[k], out_depth[k] = geom[i], prim[i], u[i], v[i], depth[i]
            for c in range(3):
                out_dir[c, k] = directions[c, i]
            k += 1
    return idx, out_geom, out_prim, out_u, out_v, out_depth, out_dir


@kernel
def _put_columns_kernel(idx, values, out):
    """out[:, idx] = values ((C, M) float32 into (C, N))."""
    for c in range(values.shape[0]):
        for k in range(idx.shape[0]):
            out[c, idx[k]] = values[c, k]


def prepare_shading(ctx: Context, hits: RayHits, stats: dict | None = None) -> None:
    """Before hits are shaded in parallel: the indirect light at the vertices of the faces they hit (this thread).
    stats: adds seconds 'indirect'."""
    if ctx.indirect is None:
        return
    t0 = time.perf_counter()
    for g in range(len(ctx.scene.surfaces)):
        prim = hits.prim[hits.geom == g]
        if len(prim):
            ctx.indirect.ensure(g, prim)
    if stats is not None:
        stats["indirect"] = stats.get("indirect", 0.0) + time.perf_counter() - t0


def skin_at(at, surface, prim: np.ndarray, bu: np.ndarray, bv: np.ndarray) -> None:
    """Fill the subsurface skin model's inputs of hits `at` on a skin surface: curvature radius, and which hits are
    skin rather than nail."""
    radius = surface_radius(surface)
    if radius is None:
        return
    at.radius = interpolate_columns(radius[None], surface.faces, prim, bu, bv)[0]
    if surface.face_labels is not None:
        at.skin = surface.face_labels[prim] != NAIL


def skin_surface_at(ctx: Context, at, surface, table: np.ndarray, prim: np.ndarray) -> np.ndarray | None:
    """The skin options' inputs of hits `at` on faces `prim` of a surface (after the truth normal was taken, so
    the frame's normals and edges stay the mesh's): its face labels for the dual-lobe specular, and its shading
    normal bumped by the skin's relief (the hand's own atlas only: not the forearm cap). Returns the relief's
    cavity factor on the hits' radiance (M,), or None."""
    if surface.material.kind != "skin":
        return None
    if ctx.skin_specular == "dual" and surface.face_labels is not None:
        at.region = surface.face_labels[prim]
    detail = surface.material.detail
    if not (ctx.skin_detail and detail is not None and surface.role == "hand" and at.uv is not None):
        return None
    at.normal, occlusion = detail_at(at, table, prim, detail.texture(), ctx.skin_detail)
    return occlusion


def trace_samples(ctx: Context, uv: np.ndarray, footprint: float = 1.0, stats: dict | None = None) -> Samples:
    """Trace, shade and shadow the samples at pixel positions uv (N, 2) (one chunk, this thread); see
    `intersect_samples` and `shade_hits` for footprint and stats."""
    hits = intersect_samples(ctx, uv, stats)
    prepare_shading(ctx, hits, stats)
    normal, radiance = shade_hits(ctx, hits, footprint, stats)
    return Samples(hits.geom, hits.prim, hits.depth, normal, radiance)


def in_chunks(ctx: Context, n: int, work, stats: dict | None = None) -> list:
    """[work(a, b, chunk_stats), ...] over consecutive chunks [a, b) of n items, on `ctx.threads` threads, in
    order; the chunks' stats are added into `stats`.

    One chunk per thread: the per-chunk Python and small-array numpy work holds the GIL, so fewer, larger chunks
    let the GIL-free parts (Embree's ray loop, numpy's big element-wise ops) overlap."""
    chunks = max(1, min(ctx.threads, n // MIN_CHUNK))
    if chunks == 1:
        return [work(0, n, stats)]
    bounds = np.linspace(0, n, chunks + 1).astype(int)
    part_stats: list[dict] = [dict() for _ in range(chunks)]
    futures = [pool(ctx.threads).submit(work, a, b, s) for a, b, s in zip(bounds[:-1], bounds[1:], part_stats)]
    parts = [f.result() for f in futures]
    if stats is not None:
        for s in part_stats:
            for k, v in s.items():
                stats[k] = stats.get(k, 0) + v
    return parts


def trace_parallel(ctx: Context, uv: np.ndarray, footprint: float = 1.0, stats: dict | None = None) -> Samples:
    """`trace_samples` of uv (N, 2) over chunks on `ctx.threads` threads; results in input order. With indirect
    light, all samples are intersected first, then the vertices they need are lit, then they are shaded."""
    if ctx.indirect is None:
        return Samples.concat(in_chunks(ctx, len(uv), lambda a, b, s: trace_samples(ctx, uv[a:b], footprint, s),
                                        stats))
    hits = intersect_parallel(ctx, uv, stats)
    normal, radiance = shade_parallel(ctx, hits, footprint, stats)
    return Samples(hits.geom, hits.prim, hits.depth, normal, radiance)


def intersect_parallel(ctx: Context, uv: np.ndarray, stats: dict | None = None) -> RayHits:
    """`intersect_samples` of uv (N, 2) over chunks on `ctx.threads` threads."""
    return RayHits.concat(in_chunks(ctx, len(uv), lambda a, b, s: intersect_samples(ctx, uv[a:b], s), stats))


def shade_parallel(ctx: Context, hits: RayHits, footprint: float = 1.0,
                   stats: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """`shade_hits` over chunks on `ctx.threads` threads: (normal (3, N), radiance (3, N))."""
    prepare_shading(ctx, hits, stats)
    parts = in_chunks(ctx, len(hits.geom), lambda a, b, s: shade_hits(ctx, hits.take(slice(a, b)), footprint, s),
                      stats)
    normal, radiance = (np.concatenate(p, axis=1) for p in zip(*parts))
    return normal, radiance


def touched_tiles(camera: Camera, surfaces, bounds: tuple[int, int, int, int], tile: int = TILE) -> np.ndarray:
    """(rows, cols) bool over the tiles (tile x tile pixels) of the bounds (r0, r1, c0, c1): True where the
    projected bounding box of some triangle (padded by a pixel) overlaps the tile. Pixels of other tiles cannot see
    any geometry and are not traced. All True when a vertex is behind the camera."""
    r0, r1, c0, c1 = bounds
    rows, cols = -(-(r1 - r0) // tile), -(-(c1 - c0) // tile)
    touched = np.zeros((rows, cols), bool)
    for s in surfaces:
        uv, z = camera.project(s.vertices)
        if (z <= 1e-9).any() or not np.isfinite(uv).all():
            return np.ones((rows, cols), bool)
        _touch_kernel(np.ascontiguousarray(uv, np.float64), np.ascontiguousarray(s.faces, np.int64),
                      float(c0), float(r0), float(tile), touched)
    return touched


@kernel
def _touch_kernel(uv, faces, c0, r0, tile, touched):
    """Mark in touched (rows, cols) the tiles that each face's projected box (uv (N, 2) pixels, padded by a pixel,
    relative to column c0, row r0) overlaps: tiles floor(lo / tile) .. floor(hi / tile), clipped to the grid."""
    rows, cols = touched.shape
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        lo_u = min(min(uv[a, 0], uv[b, 0]), uv[c, 0]) - (c0 + 1.0)
        lo_v = min(min(uv[a, 1], uv[b, 1]), uv[c, 1]) - (r0 + 1.0)
        hi_u = max(max(uv[a, 0], uv[b, 0]), uv[c, 0]) - (c0 - 1.0)
        hi_v = max(max(uv[a, 1], uv[b, 1]), uv[c, 1]) - (r0 - 1.0)
        tx0 = int(min(max(np.floor(lo_u / tile), 0.0), float(cols)))
        ty0 = int(min(max(np.floor(lo_v / tile), 0.0), float(rows)))
        tx1 = int(min(max(np.floor(hi_u / tile) + 1.0, 0.0), float(cols)))
        ty1 = int(min(max(np.floor(hi_v / tile) + 1.0, 0.0), float(rows)))
        for ty in range(ty0, ty1):
            for tx in range(tx0, tx1):
                touched[ty, tx] = True


def tile_pixels(tiles: np.ndarray, h: int, w: int, tile: int = TILE) -> np.ndarray:
    """(M,) int64 ascending row-major indices of the pixels of an h x w region whose tile (tile x tile pixels) is
    True in `tiles` (ceil(h / tile), ceil(w / tile)) bool."""
    if tiles.shape != (-(-h // tile), -(-w // tile)):
        raise ValueError(f"tiles {tiles.shape} do not cover {h} x {w} pixels in tiles of {tile}")
    out = np.empty(h * w, np.int64)
    return out[:_tile_pixels_kernel(np.ascontiguousarray(tiles, np.bool_), h, w, tile, out)]


@kernel
def _tile_pixels_kernel(tiles, h, w, tile, out):
    """tile_pixels' indices into out, row by row and, in a row, run by run of a True tile's columns (no division
    per pixel); returns how many."""
    m = 0
    for r in range(h):
        row, base = r // tile, r * w
        for t in range(tiles.shape[1]):
            if tiles[row, t]:
                for c in range(t * tile, min(w, (t + 1) * tile)):
                    out[m] = base + c
                    m += 1
    return m


def pixel_positions(index: np.ndarray, r0: int, c0: int, w: int) -> np.ndarray:
    """(M, 2) float64 pixel-centre positions (u, v) of flat indices (M,) >= 0 into the region of width w whose first
    pixel is (row r0, column c0): as pixel_centres(r0, r1, c0, c1)[index]."""
    index = np.ascontiguousarray(index, np.int64)
    out = np.empty((len(index), 2), np.float64)
    if len(index):
        _pixel_positions_kernel(index, float(r0 + 0.5), float(c0 + 0.5), int(w), out)
    return out


@kernel
def _pixel_positions_kernel(index, v0, u0, w, out):
    """pixel_positions in one pass: numpy's (column + (c0 + 0.5), row + (r0 + 0.5)), the integer column and row of
    each index converted to float64 before the one addition, so the same numbers."""
    for i in range(index.shape[0]):
        k = index[i]
        r = k // w
        out[i, 0] = float(k - r * w) + u0
        out[i, 1] = float(r) + v0


def pixel_centres(r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    """(H*W, 2) float64 pixel-centre positions (c + 0.5, r + 0.5) of rows [r0, r1), columns [c0, c1), row-major."""
    rows, cols = np.mgrid[r0:r1, c0:c1]
    return np.stack([cols.ravel() + 0.5, rows.ravel() + 0.5], axis=1).astype(np.float64)
