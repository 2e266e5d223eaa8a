"""Adaptive anti-aliasing: supersample only the pixels on silhouettes and material edges.

After one sample per pixel, a pixel is an edge if a 4-neighbour differs from it in what it hit (background, hand,
accessory: geomID), or, on the same surface, in depth by more than DEPTH_STEP pixel footprints (one part in front
of another) or in shading normal by more than NORMAL_ANGLE_DEG (creases, contours). Both pixels of such a pair are
edges. Each edge pixel is re-traced with S sub-samples at Direct3D's standard multisample positions (4, 8 or
16) and resolved by averaging in linear light: colour = mean of the sub-samples' radiance over hits (premultiplied
by coverage), alpha = fraction of sub-samples that hit.

Shading, as a GPU's multisampling does it: once per pixel per triangle ('triangle', the default), not per
sub-sample ('sample'). The sub-samples of a pixel that hit the same triangle share one shaded colour: the pixel's
primary sample's when that sample hit the same triangle, else the shading of the first of them. Coverage and which
surface is in front stay exact per sub-sample; what is lost is variation of shading across one triangle inside one
pixel (a shadow or texture edge crossing an edge pixel). `make bench` reports the difference to 'sample' shading.
"""

from __future__ import annotations

import numpy as np

from darthand.errors import InputError
from darthand.jit import kernel
from darthand.render.trace import Context, intersect_parallel, shade_parallel

# Direct3D 11 standard sample patterns, in 1/16 pixel from the pixel centre.
PATTERNS = {
    1: [(0, 0)],
    4: [(-2, -6), (6, -2), (-6, 2), (2, 6)],
    8: [(1, -3), (-1, 3), (5, 1), (-3, -5), (-5, 5), (-7, -1), (3, 7), (7, -7)],
    16: [(1, 1), (-1, -3), (-3, 2), (4, -1), (-5, -2), (2, 5), (5, 3), (3, -5), (-2, 6), (0, -7), (-4, -6), (-6, 4),
         (-8, 0), (7, -4), (6, 7), (-7, -8)],
}
SHADING = ("triangle", "sample")
DEFAULT_SAMPLES = 8               # sub-samples per edge pixel of a single render (datasets: dataset/options.py)
DEPTH_STEP = 4.0
NORMAL_ANGLE_DEG = 40.0


def check_options(samples: int, shading: str) -> None:
    """InputError naming the option when `samples` or `shading` is not one the anti-aliasing knows."""
    if samples not in PATTERNS:
        raise InputError(f"samples: {samples} is not one of {sorted(PATTERNS)}")
    if shading not in SHADING:
        raise InputError(f"aa_shading: {shading!r} is not one of {', '.join(SHADING)}")


def sample_offsets(samples: int) -> np.ndarray:
    """(S, 2) sub-sample offsets in pixels (u, v) from the pixel centre."""
    check_options(samples, SHADING[0])
    return np.asarray(PATTERNS[samples], np.float64) / 16.0


def edge_pixels(geom: np.ndarray, depth: np.ndarray, normal: np.ndarray, focal: float) -> np.ndarray:
    """(H, W) bool edge mask from per-pixel geomID (H, W), camera depth (H, W) and shading normal (3, H, W).

    focal: focal length in pixels (a pixel footprint at depth z is z / focal metres).
    """
    edge = np.zeros(geom.shape, bool)
    cos_tol = np.float32(np.cos(np.deg2rad(NORMAL_ANGLE_DEG)))
    _edges_kernel(np.ascontiguousarray(geom), np.ascontiguousarray(depth), np.ascontiguousarray(normal),
                  np.float32(focal), cos_tol, edge)
    return edge


@kernel
def _edges_kernel(geom, depth, normal, focal, cos_tol, edge):
    """edge (H, W) |= both pixels of each 4-neighbour pair (a, b) that differ in geom, or on the same surface (geom
    >= 0) differ in depth by more than DEPTH_STEP x min depth / focal or in normal by cos < cos_tol; the numbers of
    edge_pixels' numpy formulas (same dtypes, same order)."""
    step_px = np.float32(4.0)          # DEPTH_STEP (a literal: a cached kernel would not see a changed global)
    H, W = geom.shape
    for r in range(H):
        for c in range(W):
            for axis in range(2):
                r2, c2 = (r + 1, c) if axis == 0 else (r, c + 1)
                if r2 >= H or c2 >= W:
                    continue
                ga, gb = geom[r, c], geom[r2, c2]
                differs = ga != gb
                if not differs and ga >= 0:
                    za, zb = depth[r, c], depth[r2, c2]
                    step = abs(za - zb) > step_px * (za if za < zb else zb) / focal
                    bent = (normal[0, r, c] * normal[0, r2, c2] + normal[1, r, c] * normal[1, r2, c2]
                            + normal[2, r, c] * normal[2, r2, c2]) < cos_tol
                    differs = step or bent
                if differs:
                    edge[r, c] = True
                    edge[r2, c2] = True


def resolve(radiance: np.ndarray, geom: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """Premultiplied colour (3, P) and coverage (P,) of P pixels from their sub-samples, laid out pixel-major:
    radiance (3, P * S) (0 for background samples), geom (P * S,) (-1 = background)."""
    hit = (geom >= 0).reshape(-1, samples)
    colour = radiance.reshape(3, -1, samples).mean(axis=2, dtype=np.float32)
    return colour, hit.mean(axis=1, dtype=np.float32)


def supersample(ctx: Context, centres: np.ndarray, centre_geom: np.ndarray, centre_prim: np.ndarray,
                centre_radiance: np.ndarray, samples: int, shading: str = "triangle",
                stats: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Premultiplied colour (3, P) and coverage (P,) of P edge pixels at pixel centres (P, 2), from S = `samples`
    sub-samples each. centre_geom, centre_prim (P,) and centre_radiance (3, P): the pixels' primary samples (reused
    by 'triangle' shading). stats: as trace.intersect_samples / shade_hits, plus 'aa_shaded' (samples shaded)."""
    check_options(samples, shading)
    P, S = len(centres), samples
    sub = intersect_parallel(ctx, (centres[:, None, :] + sample_offsets(S)[None]).reshape(-1, 2), stats)
    if shading == "sample":
        _, radiance = shade_parallel(ctx, sub, 1 / np.sqrt(S), stats)
        shaded = P * S
    else:
        radiance, shaded = _shade_per_triangle(ctx, sub, centre_geom, centre_prim, centre_radiance, S, stats)
    if stats is not None:
        stats["aa_shaded"] = stats.get("aa_shaded", 0) + int(shaded)
    return resolve(radiance, sub.geom, S)


def _shade_per_triangle(ctx: Context, sub, centre_geom, centre_prim, centre_radiance, S: int, stats):
    """(radiance (3, P * S), number shaded) of pixel-major sub-sample hits `sub`: one colour per (pixel, surface,
    triangle), the primary sample's when it hit that triangle."""
    n = len(sub.geom)
    mode, slot = np.empty(n, np.int8), np.empty(n, np.int64)
    shade_at = np.empty(n, np.int64)
    shaded = _triangle_groups_kernel(np.ascontiguousarray(sub.geom, np.int32), np.ascontiguousarray(sub.prim, np.int32),
                                     np.ascontiguousarray(centre_geom, np.int32),
                                     np.ascontiguousarray(centre_prim, np.int32), S, mode, slot, shade_at)
    shade_at = shade_at[:shaded]
    colour = np.empty((3, 0), np.float32)
    if shaded:
        _, colour = shade_parallel(ctx, sub.take(shade_at), 1.0, stats)
    radiance = np.empty((3, n), np.float32)
    _triangle_fill_kernel(mode, slot, np.ascontiguousarray(centre_radiance, np.float32),
                          np.ascontiguousarray(colour, np.float32), radiance)
    return radiance, shaded


BACKGROUND, CENTRE, OWN, COPY = 0, 1, 2, 3          # _triangle_groups_kernel's modes


@kernel
def _triangle_groups_kernel(geom, prim, centre_geom, centre_prim, S, mode, slot, shade_at):
    """Which colour each of the P * S pixel-major sub-samples takes; returns M, the number to shade. mode per
    sub-sample: 0 background; 1 hit its pixel's primary triangle (slot: the pixel); 2 the first in its pixel to hit
    its triangle (slot: its place in shade_at[:M], ascending); 3 a later one (slot: the first one's place)."""
    m = 0
    for p in range(geom.shape[0] // S):
        for j in range(S):
            i = p * S + j
            if geom[i] < 0:
                mode[i] = 0
                slot[i] = 0
            elif geom[i] == centre_geom[p] and prim[i] == centre_prim[p]:
                mode[i] = 1
                slot[i] = p
            else:
                first = j
                for k in range(j):
                    if geom[p * S + k] == geom[i] and prim[p * S + k] == prim[i]:
                        first = k
                        break
                if first == j:
                    mode[i] = 2
                    slot[i] = m
                    shade_at[m] = i
                    m += 1
                else:
                    mode[i] = 3
                    slot[i] = slot[p * S + first]
    return m


@kernel
def _triangle_fill_kernel(mode, slot, centre_radiance, colour, radiance):
    """radiance (3, P * S) from the modes and slots of _triangle_groups_kernel: 0, the primary sample's colour
    (centre_radiance (3, P)) or a shaded one (colour (3, M))."""
    for i in range(mode.shape[0]):
        for c in range(3):
            if mode[i] == 0:
                radiance[c, i] = np.float32(0.0)
            elif mode[i] == 1:
                radiance[c, i] = centre_radiance[c, slot[i]]
            else:
                radiance[c, i] = colour[c, slot[i]]
