"""Textures for shading: mip pyramids, trilinear lookups in linear light, the mip level from a pixel's UV footprint.

UV convention (verified against the textures stage's baker, textures/bake.py, which rasterises a UV triangle at
pixel coordinates (u * res, (1 - v) * res) with texel centres at integer + 0.5): OpenGL-style st, u to the right,
v UP, v = 0 at the BOTTOM row of the image. Texel (row r, column c) of an H x W level has its centre at
u = (c + 0.5) / W, v = 1 - (r + 0.5) / H. Lookups clamp to the edge (the textures carry padded gutters).

Storage. Texture files of 8 bits per channel are kept as GPUs keep them (SRGB8 / UNORM8 formats): every mip level
as 8-bit codes, decoded to linear light at fetch time, before filtering, through a 256-entry table per channel --
the sRGB transfer function for colour channels, code / 255 for data channels (roughness, metallic). Levels >= 1 are
2x2 box averages in linear light (of the level-0 values they cover), re-encoded to 8 bits. Because the skin-tone
offset is added to the sRGB code before decoding (textures/color.encode_srgb8's convention), it is a different
table on the same codes: one pyramid per file serves every offset (`load_maps`). At level 0 this is exactly a
per-texel decode with the offset; at levels >= 1 the offset is applied to the re-encoded average rather than
averaged after it (the lossy part, with the 8-bit re-quantisation; benchmarks/textures_load.py measures both).

Textures made from float arrays (constants, the UV checker, the position textures of render/checks.py, tests) and
image files of more than 8 bits keep float32 storage: their values are not 8-bit codes (positions in metres, data
outside [0, 1], 16-bit precision), so quantising them would change what they hold; none of them is loaded often.

Written here rather than through OpenImageIO's TextureSystem because its Python binding samples one point per call;
these lookups are one compiled loop (darthand/jit.py) over every shaded sample of a batch.
"""

from __future__ import annotations

import copy
import functools
import os
import threading
from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.budget import check_memory
from darthand.errors import InputError
from darthand.fileio import regular_file
from darthand.jit import inlined, kernel
from darthand.render.png import Png8, open_png8
from darthand.textures.color import srgb8_table, srgb_to_linear

BLEND = 0.25     # half-width of the band of fractional mip levels (around .5) in which two levels are blended
# 8-bit pyramids kept by load_maps, least recently used dropped first, within a memory budget rather than a count:
# a skin texture (2048^2 RGB + roughness) is ~22 MB, an accessory's maps often under 1 MB, and a dataset that
# cycles through all 50 accessories with a few skins must not reload them (a count of 32 did: 8 ms a switch).
CACHE_BYTES = 512 << 20


class MipTexture:
    """A mip pyramid: level 0 the full image, each next level half the size, down to 1 x 1. All levels are kept in
    one flat (texels, C) array `flat` (level k's rows from offsets[k], row-major, heights[k] x widths[k]) so that a
    lookup at per-sample levels is one gather, whatever the levels.

    `flat` is float32 values (`decode` None), or uint8 codes with `decode` (C, 256) float32: channel c's code q
    reads as decode[c, q]. `levels` gives the (H_k, W_k, C) float32 values of each level (decoded on access).

    MipTexture(levels) stores float arrays (H_k, W_k, C) as given (any sizes); with `decode`, uint8 codes.
    """

    def __init__(self, levels, decode=None):
        dtype = np.float32 if decode is None else np.uint8
        shapes = [np.shape(a) for a in levels]
        self._allocate([s[:2] for s in shapes], shapes[0][2], dtype, decode)
        for k, a in enumerate(levels):
            self.texels(k)[...] = a

    @classmethod
    def empty(cls, height: int, width: int, channels: int, dtype=np.float32, decode=None) -> "MipTexture":
        """A full pyramid of a height x width image (sizes halved, rounded up, down to 1 x 1), storage uninitialised:
        write level 0 into texels(0), then call build_mips."""
        tex = cls.__new__(cls)
        tex._allocate(mip_sizes(height, width), channels, dtype, decode)
        return tex

    def _allocate(self, sizes, channels: int, dtype, decode) -> None:
        self.heights = np.array([s[0] for s in sizes], np.int64)
        self.widths = np.array([s[1] for s in sizes], np.int64)
        counts = self.heights * self.widths
        self.offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        self.flat = np.empty((int(counts.sum()), channels), dtype)
        self.decode = None
        if decode is not None:
            self.decode = _check_decode(decode, channels)

    def texels(self, k: int) -> np.ndarray:
        """(H_k, W_k, C) view of level k's storage (codes or float values)."""
        k = range(len(self.offsets))[k]
        start = int(self.offsets[k])
        h, w = int(self.heights[k]), int(self.widths[k])
        return self.flat[start:start + h * w].reshape(h, w, -1)

    def with_decode(self, decode) -> "MipTexture":
        """The same codes read through other tables (C, 256): a view, no copy of the pyramid."""
        if self.decode is None:
            raise ValueError("with_decode: a float texture has no decode table")
        out = copy.copy(self)
        out.decode = _check_decode(decode, self.channels)
        return out

    @property
    def levels(self) -> "Levels":
        return Levels(self)

    @property
    def width(self) -> int:
        return int(self.widths[0])

    @property
    def height(self) -> int:
        return int(self.heights[0])

    @property
    def channels(self) -> int:
        return int(self.flat.shape[1])

    @property
    def nbytes(self) -> int:
        """Bytes of the pyramid's storage (shared by every `with_decode` view of it)."""
        return int(self.flat.nbytes)

    # ---------------------------------------------------------------------------------------------- lookups

    def bilinear(self, uv: np.ndarray, level=0) -> np.ndarray:
        """(C, N) float32 bilinear lookup at uv (2, N) in mip level `level` (an int or (N,) ints, clamped to the
        pyramid). 8-bit textures are decoded before the interpolation (linear light)."""
        return self._lookup(uv, level, blend=False)

    def sample(self, uv: np.ndarray, lod: np.ndarray | float = 0.0) -> np.ndarray:
        """(C, N) float32 lookup at uv (2, N), mip level `lod` (N,): bilinear in the nearer level, blended with the
        other level around the middle between two levels (where frac(lod) is within BLEND of 0.5) -- trilinear
        filtering with a narrowed blend band ("brilinear"), half the texel reads of full trilinear."""
        return self._lookup(uv, lod, blend=True)

    def _lookup(self, uv: np.ndarray, lod, blend: bool) -> np.ndarray:
        uv = np.ascontiguousarray(uv, np.float32)
        n = uv.shape[1]
        lod = np.asarray(lod)
        lod = (np.full(n, lod, np.float32) if lod.ndim == 0 else np.ascontiguousarray(lod, np.float32))
        if lod.shape != (n,):
            raise ValueError(f"texture lookup: {n} uvs and {lod.shape} levels")
        out = np.empty((self.channels, n), np.float32)
        _lookup_kernel(self.flat, self.decode, self.offsets, self.heights, self.widths, uv, lod,
                       np.float32(BLEND if blend else 0.0), out)
        return out

    def lod_of_footprint(self, footprint: np.ndarray) -> np.ndarray:
        """(N,) mip level of footprints whose longer side is `footprint` (N,) uv units: log2 of it in level-0
        texels (of the longer image side), clamped at 0."""
        with np.errstate(divide="ignore"):
            lod = np.log2(footprint * np.float32(max(self.width, self.height)))
        return np.maximum(lod, 0).astype(np.float32)

    def lod(self, duv_dx: np.ndarray, duv_dy: np.ndarray) -> np.ndarray:
        """(N,) mip level of a footprint with UV derivatives per pixel step duv_dx, duv_dy (2, N): log2 of the
        longer side in level-0 texels (OpenGL's isotropic rule), clamped at 0."""
        w, h = np.float32(self.width), np.float32(self.height)
        ex = (duv_dx[0] * w) ** 2 + (duv_dx[1] * h) ** 2
        ey = (duv_dy[0] * w) ** 2 + (duv_dy[1] * h) ** 2
        with np.errstate(divide="ignore"):
            return np.maximum(np.float32(0.5) * np.log2(np.maximum(ex, ey)), 0).astype(np.float32)

    # ---------------------------------------------------------------------------------------------- mips

    def build_mips(self, colour: int = 0) -> "MipTexture":
        """Fill levels >= 1 from level 0 (in place; returns self). Float storage: 2x2 box averages of the values.
        8-bit storage: 2x2 box averages in linear light of the level-0 values each texel covers (the first `colour`
        channels decoded as sRGB, the others as code / 255), re-encoded to 8 bits (sRGB for colour) -- each level
        is quantised once, from unquantised averages, so errors do not accumulate down the pyramid."""
        if len(self.offsets) == 1:
            return self
        if self.decode is None:
            for k in range(1, len(self.offsets)):
                box_filter(self.texels(k - 1), self.texels(k))
            return self
        _code_mips_kernel(self.flat, self.offsets, self.heights, self.widths, decode_tables(self.channels, colour),
                          colour, srgb8_table(0.0))
        return self


class Levels(Sequence):
    """The levels of a MipTexture as (H_k, W_k, C) float32 arrays: views of float storage, decoded copies of 8-bit
    storage (made on access)."""

    def __init__(self, texture: MipTexture):
        self._texture = texture

    def __len__(self) -> int:
        return len(self._texture.offsets)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(len(self))[k]]
        stored = self._texture.texels(k)
        table = self._texture.decode
        if table is None:
            return stored
        out = np.empty(stored.shape, np.float32)
        for c in range(stored.shape[2]):
            out[..., c] = table[c][stored[..., c]]
        return out


def _check_decode(decode, channels: int) -> np.ndarray:
    decode = np.ascontiguousarray(decode, np.float32)
    if decode.shape != (channels, 256):
        raise ValueError(f"decode table of shape {decode.shape}, expected ({channels}, 256)")
    return decode


@kernel
def _lookup_kernel(flat, decode, offsets, heights, widths, uv, lod, band, out):
    """out (C, N) = the lookups of MipTexture.sample at uv (2, N) float32, levels lod (N,) float32, with the blend
    band `band` (BLEND; 0: bilinear in the nearest level only). flat (texels, C) uint8 codes read through decode
    (C, 256), or float32 values with decode None.

    Per sample: the level is clamped to the pyramid; the nearer level (round half up) is read bilinearly, at texel
    centres (c + 0.5) / W_k, 1 - (r + 0.5) / H_k, clamped to the edge; where frac(lod) is within `band` of 0.5 the
    other level's bilinear value is blended in, with weight rising linearly across the band. Float32 arithmetic in
    the order of the numpy lookup it replaced (uv * W - 0.5; top = a + (b - a) fx; ...), so the values are the
    same to the bit. Indices are unsigned (no negative-index wraparound to test) into the flat storage and
    tables (_level_table, _corners); both levels' corners are found before any texel is read."""
    n = uv.shape[1]
    channels = flat.shape[1]
    values = flat.reshape(-1)
    table = None if decode is None else decode.reshape(-1)
    sizes, starts = _level_table(offsets, heights, widths, channels)
    last = len(offsets) - 1
    lo, span = 0.5 - band, 2 * band
    one = np.float32(1.0)
    for i in range(n):
        near, other, t = _level_pair(lod[i], last, band, lo, span)
        u, down = uv[0, i], one - uv[1, i]
        pa, pb, pc, pd, fx, fy = _corners(sizes, starts, near, u, down, channels)
        if t > 0:
            qa, qb, qc, qd, gx, gy = _corners(sizes, starts, other, u, down, channels)
            for c in range(channels):
                value = _bilinear(values, table, pa, pb, pc, pd, fx, fy, c)
                second = _bilinear(values, table, qa, qb, qc, qd, gx, gy, c)
                out[c, i] = value + (second - value) * t
        else:
            for c in range(channels):
                out[c, i] = _bilinear(values, table, pa, pb, pc, pd, fx, fy, c)


@inlined
def _level_table(offsets, heights, widths, channels):
    """(sizes (L, 2) float32: W_k, H_k; starts (L, 4) int64: W_k - 1, H_k - 1, and in elements of the flat storage
    the row length W_k C and level k's start) of a pyramid's L levels, for _corners."""
    sizes = np.empty((len(offsets), 2), np.float32)
    starts = np.empty((len(offsets), 4), np.int64)
    for k in range(len(offsets)):
        sizes[k, 0], sizes[k, 1] = np.float32(widths[k]), np.float32(heights[k])
        starts[k, 0], starts[k, 1] = widths[k] - 1, heights[k] - 1
        starts[k, 2], starts[k, 3] = widths[k] * channels, offsets[k] * channels
    return sizes, starts


@inlined
def _level_pair(level, last, band, lo, span):
    """(near, other, t) of a sample at mip level `level` (float32) in a pyramid of levels 0..last: the nearer level
    (round half up; NaN and negative levels read 0, levels past the last the last), the other level and its blend
    weight t (float32, 0: near only) within `band` of the middle; lo, span = 0.5 - band, 2 band (float64)."""
    if not level > 0:                           # also NaN
        level = np.float32(0.0)
    if level > np.float32(last):
        level = np.float32(last)
    base = int(level)
    frac = float(level) - base
    near = base if frac < 0.5 else min(base + 1, last)
    if band > 0 and base < last and frac > lo:  # frac <= lo would give w <= 0
        w = min(max((frac - lo) / span, 0.0), 1.0)
        if 0 < w < 1:
            return (near, base + 1, np.float32(w)) if frac < 0.5 else (near, base, np.float32(1 - w))
    return near, near, np.float32(0.0)


@inlined
def _corners(sizes, starts, k, u, down, channels):
    """(pa, pb, pc, pd, fx, fy): the flat storage's element indices (uint64; `channels` elements a texel) of channel
    0 of the 2x2 texels around (u, v) in level k, down = 1 - v (float32): top-left, top-right, bottom-left,
    bottom-right, clamped to the edge; and the bilinear weights fx, fy float32 of the right and bottom ones."""
    half = np.float32(0.5)
    w_k, h_k = sizes[k, 0], sizes[k, 1]
    x = u * w_k - half
    y = down * h_k - half
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    # clamp in float first: the int conversion of a NaN or huge coordinate is undefined
    xi = int(min(max(x0, np.float32(-1)), w_k))
    yi = int(min(max(y0, np.float32(-1)), h_k))
    x_last, y_last, row, start = starts[k, 0], starts[k, 1], starts[k, 2], starts[k, 3]
    xa, xb = min(max(xi, 0), x_last) * channels, min(max(xi + 1, 0), x_last) * channels
    row_a = start + min(max(yi, 0), y_last) * row
    row_b = start + min(max(yi + 1, 0), y_last) * row
    return (np.uint64(row_a + xa), np.uint64(row_a + xb), np.uint64(row_b + xa), np.uint64(row_b + xb), fx, fy)


@inlined
def _bilinear(values, table, pa, pb, pc, pd, fx, fy, c):
    """Channel c's bilinear value (float32) of the 2x2 texels at element indices pa..pd (uint64, _corners) of the
    flat storage `values`: float32 values (table None) or uint8 codes read through table (C * 256,) float32."""
    cu = np.uint64(c)
    if table is None:
        a, b, cc, d = values[pa + cu], values[pb + cu], values[pc + cu], values[pd + cu]
    else:
        row = cu * np.uint64(256)
        a, b = table[row + np.uint64(values[pa + cu])], table[row + np.uint64(values[pb + cu])]
        cc, d = table[row + np.uint64(values[pc + cu])], table[row + np.uint64(values[pd + cu])]
    top = (b - a) * fx + a
    bottom = (d - cc) * fx + cc
    return (bottom - top) * fy + top


# ------------------------------------------------------------------------------------------------ pyramids


def mip_sizes(height: int, width: int) -> list[tuple[int, int]]:
    """(H_k, W_k) of every level: halved and rounded up (an odd last row or column is repeated), down to 1 x 1."""
    sizes = [(int(height), int(width))]
    while sizes[-1] != (1, 1):
        h, w = sizes[-1]
        sizes.append(((h + 1) // 2, (w + 1) // 2))
    return sizes


def box_filter(level: np.ndarray, out: np.ndarray) -> np.ndarray:
    """out (h, w, C) float32 = the 2x2 box average of level (H, W, C) float32, h = ceil(H / 2), w = ceil(W / 2) (an
    odd last row or column repeated; a side of 1 averaged along the other side only): the next mip level of a float
    pyramid, written in place. One compiled pass (_box_kernel)."""
    _box_kernel(np.ascontiguousarray(level, np.float32), out)
    return out


@kernel
def _box_kernel(level, out):
    """`box_filter`, with the float32 sums in the order of the numpy filter it replaced, so the pyramids are the
    same to the bit: ((a + b) + c) + d of the four quarters (top-left, top-right, bottom-left, bottom-right), times
    1/4 (1/2 of two texels where a side is 1)."""
    H, W = level.shape[0], level.shape[1]
    quarter, half, whole = np.float32(0.25), np.float32(0.5), np.float32(1.0)
    for i in range(out.shape[0]):
        ra, rb = 2 * i, min(2 * i + 1, H - 1)
        for j in range(out.shape[1]):
            ca, cb = 2 * j, min(2 * j + 1, W - 1)
            for c in range(out.shape[2]):
                a, b, d, e = level[ra, ca, c], level[ra, cb, c], level[rb, ca, c], level[rb, cb, c]
                if H > 1 and W > 1:
                    out[i, j, c] = (((a + b) + d) + e) * quarter
                elif H > 1:
                    out[i, j, c] = (a + d) * half
                elif W > 1:
                    out[i, j, c] = (a + b) * half
                else:
                    out[i, j, c] = a * whole


@kernel
def _code_mips_kernel(flat, offsets, heights, widths, decode, colour, table):
    """Levels >= 1 of an 8-bit pyramid (MipTexture.build_mips) in one streaming pass. Each texel is the 2x2 box
    average of the level above -- of level 0's codes read through `decode` (C, 256) for level 1, of the level
    above's unquantised values below it -- in float32, summed in the order the pyramids have always been made (so
    the codes are the same to the bit): at level 1 of an even width (a + b) + (c + d) of the top and bottom pairs,
    elsewhere ((a + b) + c) + d of the four quarters (top-left, top-right, bottom-left, bottom-right), times 1/4
    (1/2 of two texels where a side is 1; an odd last row or column repeated). It is written to `flat` as codes:
    the first `colour` channels sRGB-encoded through `table` (srgb8_table, as textures/color.encode_srgb8_into),
    the others rint(value x 255).

    Level 1 is made row by row (from two level-0 rows decoded to float32, or straight from the codes for a skin
    texture); a level's row is made as soon as the two rows above it are (the last row of an odd height twice), so
    the unquantised values live in two rows per level (`rows`, in cache), not in a float copy of the pyramid: no
    22 MB buffer to fault in per skin texture."""
    C = flat.shape[1]
    last = len(offsets) - 1
    quarter, half, whole, zero = np.float32(0.25), np.float32(0.5), np.float32(1.0), np.float32(0.0)
    top, scale = np.float32(len(table) - 1), np.float32(255)
    rows = np.empty((last + 1, 2, widths[1], C), np.float32)      # rows[k, r % 2]: row r of level k, unquantised
    H, W, w = heights[0], widths[0], widths[1]
    pairs = W % 2 == 0
    skin = pairs and H > 1 and C == 4 and colour == 3
    top0 = np.empty((W, C), np.float32)                 # two rows of level 0, decoded (but for a skin texture)
    bottom0 = np.empty((W, C), np.float32)
    for i in range(heights[1]):
        ra, rb = 2 * i * W, min(2 * i + 1, H - 1) * W   # level 0's two rows (the last repeated)
        if skin:
            # A skin texture (sRGB colour and roughness): level 1 is three quarters of the work; the channel loop
            # unrolled and the codes stored at once, 2-3x faster than the general loops.
            d0, d1, d2, d3 = decode[0], decode[1], decode[2], decode[3]
            out, at = rows[1, i % 2], offsets[1] + i * w
            for j in range(w):
                p, q = ra + 2 * j, rb + 2 * j
                v0 = ((d0[flat[p, 0]] + d0[flat[p + 1, 0]]) + (d0[flat[q, 0]] + d0[flat[q + 1, 0]])) * quarter
                v1 = ((d1[flat[p, 1]] + d1[flat[p + 1, 1]]) + (d1[flat[q, 1]] + d1[flat[q + 1, 1]])) * quarter
                v2 = ((d2[flat[p, 2]] + d2[flat[p + 1, 2]]) + (d2[flat[q, 2]] + d2[flat[q + 1, 2]])) * quarter
                v3 = ((d3[flat[p, 3]] + d3[flat[p + 1, 3]]) + (d3[flat[q, 3]] + d3[flat[q + 1, 3]])) * quarter
                out[j, 0], out[j, 1], out[j, 2], out[j, 3] = v0, v1, v2, v3
                flat[at + j, 0] = table[int(min(max(v0, zero), whole) * top + half)]
                flat[at + j, 1] = table[int(min(max(v1, zero), whole) * top + half)]
                flat[at + j, 2] = table[int(min(max(v2, zero), whole) * top + half)]
                flat[at + j, 3] = int(np.rint(v3 * scale))
            k, r = 1, i
        else:
            for j in range(W):
                for c in range(C):
                    top0[j, c], bottom0[j, c] = decode[c, flat[ra + j, c]], decode[c, flat[rb + j, c]]
            k, r = 0, 2 * i
        while True:
            if k > 0:
                # Row r of level k is made: store its codes (unless stored already), then make the row below it
                # if both its rows are made.
                src, at = rows[k, r % 2], offsets[k] + r * widths[k]
                for j in range(widths[k] if k > 1 or not skin else 0):
                    for c in range(colour):
                        v = min(max(src[j, c], zero), whole)            # finite: sums of decode-table values
                        flat[at + j, c] = table[int(v * top + half)]
                    for c in range(colour, C):
                        flat[at + j, c] = int(np.rint(src[j, c] * scale))
                if k == last or not (r % 2 == 1 or r == heights[k] - 1):
                    break
                upper, lower = rows[k, 0], rows[k, r % 2]   # rows 2r' and min(2r' + 1, H_k - 1) of level k
            else:
                upper, lower = top0, bottom0
            Hk, Wk, pair = heights[k], widths[k], k == 0 and pairs      # of the level above the new row
            k, r = k + 1, r // 2
            out = rows[k, r % 2]
            for j in range(widths[k]):
                p, q = 2 * j, min(2 * j + 1, Wk - 1)
                for c in range(C):
                    a, b, e, f = upper[p, c], upper[q, c], lower[p, c], lower[q, c]
                    if pair:
                        out[j, c] = ((a + b) + (e + f)) * quarter if Hk > 1 else (a + b) * half
                    elif Hk > 1 and Wk > 1:
                        out[j, c] = (((a + b) + e) + f) * quarter
                    elif Hk > 1:
                        out[j, c] = (a + e) * half
                    else:
                        out[j, c] = (a + b) * half if Wk > 1 else a * whole


def mip_levels(image: np.ndarray) -> tuple:
    """Levels of a (H, W, C) float32 image: 2x2 box averages (an odd row or column is repeated) down to 1 x 1."""
    return tuple(float_pyramid(image).levels)


def float_pyramid(image: np.ndarray) -> MipTexture:
    """The float32 MipTexture of an (H, W, C) image, built in place."""
    image = np.asarray(image)
    tex = MipTexture.empty(image.shape[0], image.shape[1], image.shape[2], np.float32)
    tex.texels(0)[...] = image
    return tex.build_mips()


def code_pyramid(codes: np.ndarray, colour: int = 0) -> MipTexture:
    """The 8-bit MipTexture of (H, W, C) uint8 codes whose first `colour` channels are sRGB colour, the others data,
    read through decode_tables(C, colour) (offset 0)."""
    codes = np.asarray(codes)
    if codes.dtype != np.uint8 or codes.ndim != 3:
        raise ValueError("code_pyramid: expects (H, W, C) uint8 codes")
    h, w, c = codes.shape
    tex = MipTexture.empty(h, w, c, np.uint8, decode_tables(c, colour))
    tex.texels(0)[...] = codes
    return tex.build_mips(colour)


def decode_tables(channels: int, colour: int = 0, *, offset: float = 0.0, constant=None) -> np.ndarray:
    """(channels, 256) float32 decode tables: the first `colour` channels sRGB after the skin-tone `offset`
    (srgb8_to_linear_lut), or, with `constant` (colour,) linear values, those values whatever the code; the other
    channels code / 255."""
    table = np.empty((channels, 256), np.float32)
    if colour:
        table[:colour] = (srgb8_to_linear_lut(offset) if constant is None
                          else np.asarray(constant, np.float32)[:colour, None])
    table[colour:] = np.arange(256, dtype=np.float32) * np.float32(1 / 255)     # as read_image scales data
    return table


def constant_texture(value) -> MipTexture:
    """A 1 x 1 texture of one value (C,)."""
    return MipTexture([np.asarray(value, np.float32).reshape(1, 1, -1)])


# ------------------------------------------------------------------------------------------------ files


def srgb8_to_linear_lut(offset: float = 0.0) -> np.ndarray:
    """(256,) float32 linear value of each 8-bit sRGB code after adding the skin-tone `offset` to the encoded value
    (the textures stage's convention: textures/color.encode_srgb8), clipped to [0, 1]."""
    return srgb_to_linear(np.clip(np.arange(256, dtype=np.float32) / 255 + np.float32(offset), 0, 1))


def _open(path: Path) -> oiio.ImageBuf:
    from darthand.render.image import read_image_buf  # lazy: it and isal kept off `darthand --help`'s path

    return read_image_buf(path, "texture")


def read_codes(path: str | os.PathLike) -> np.ndarray:
    """(H, W, C) uint8 codes of an 8-bit image file."""
    buf = _open(Path(path))
    codes = buf.get_pixels(oiio.UINT8)
    assert codes is not None, buf.geterror()         # _open read the pixels
    return codes


def is_8bit(path: str | os.PathLike) -> bool:
    """Whether an image file stores 8 bits per channel (reads the header only)."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputError(f"{path}: cannot read image ({oiio.geterror() or 'unknown format'})")
    try:
        return inp.spec().format == oiio.UINT8
    finally:
        inp.close()


def read_image(path: str | os.PathLike, *, srgb: bool, offset: float = 0.0) -> np.ndarray:
    """(H, W, C) float32 pixels of an image file: sRGB images decoded to linear light (after the sRGB `offset`),
    data images (srgb=False) as stored, scaled to [0, 1]."""
    buf = _open(Path(path))
    if buf.spec().format == oiio.UINT8:
        codes = buf.get_pixels(oiio.UINT8)
        assert codes is not None, buf.geterror()     # _open read the pixels
        if srgb:
            return srgb8_to_linear_lut(offset)[codes]
        return codes.astype(np.float32) * np.float32(1 / 255)
    pixels = buf.get_pixels(oiio.FLOAT)
    assert pixels is not None, buf.geterror()
    return srgb_to_linear(np.clip(pixels + np.float32(offset), 0, 1)) if srgb else pixels


def load_texture(path: str | os.PathLike, *, srgb: bool, offset: float = 0.0) -> MipTexture:
    """The mip pyramid of one image file: sRGB colour (cached, see `load_maps`) or raw data."""
    if srgb:
        return load_maps(path, offset=offset)
    if is_8bit(_file_key(path)[0]):
        return code_pyramid(read_codes(path))
    return float_pyramid(read_image(path, srgb=False))


def load_maps(albedo: str | os.PathLike | None, *, offset: float = 0.0, data: str | os.PathLike | None = None,
              channels=(0,), base_color=(0.8, 0.8, 0.8), codes: bool = True) -> MipTexture:
    """One texture for a material's single lookup: channels 0..2 linear albedo (the sRGB image `albedo` after the
    sRGB `offset`, or the constant linear `base_color`), then `channels` of the data image `data` (raw, [0, 1]),
    resized to the albedo's size if they differ.

    8-bit files: the code pyramid is cached by the files (path, modification time) and `channels` only; the offset
    and base colour are decode tables on it (a view, see MipTexture.with_decode). Other files, or codes=False: a
    float32 pyramid of linear values with the offset applied at load (the earlier storage, kept for comparisons:
    benchmarks/textures_load.py), cached by files and arguments."""
    if albedo is None and data is None:
        return constant_texture(base_color)
    keys = [None if p is None else _file_key(p) for p in (albedo, data)]
    channels = tuple(int(c) for c in channels)
    if codes and all(k is None or _is_8bit_file(k) for k in keys):
        pyramid = _code_maps(keys[0], keys[1], channels if keys[1] else ())
        constant = None if albedo is not None else tuple(float(c) for c in base_color)
        return pyramid.with_decode(decode_tables(pyramid.channels, 3, offset=float(offset), constant=constant))
    return _float_maps(keys[0], keys[1], round(float(offset), 6), channels, tuple(float(c) for c in base_color))


def _file_key(path: str | os.PathLike) -> tuple[str, int]:
    """(the file's resolved path, its modification time): what a texture is cached by. The resolution is kept per
    (path as given, device, inode) (_resolved), so a frame pays one stat, not a walk of every component of the path
    (0.1 ms a file, two files a frame); a path that comes to name another file (a symlink moved) has another inode
    and is resolved again."""
    try:
        st = os.stat(path)
    except OSError:
        raise InputError(f"{Path(path)}: texture file not found") from None
    return _resolved(os.fspath(path), st.st_dev, st.st_ino), st.st_mtime_ns


@functools.lru_cache(maxsize=4096)
def _resolved(path: str, device: int, inode: int) -> str:
    """The resolved path of `path`, the file (device, inode) (the cache key only)."""
    return str(Path(path).resolve())


@functools.lru_cache(maxsize=4096)
def _is_8bit_file(key: tuple[str, int]) -> bool:
    """is_8bit of a file by its (path, modification time) key: asked on every load_maps call (every frame), the
    header read once."""
    return is_8bit(key[0])


_PYRAMIDS: OrderedDict = OrderedDict()
_PYRAMIDS_LOCK = threading.Lock()


def _code_maps(albedo_key, data_key, channels: tuple) -> MipTexture:
    """`_build_code_maps`, cached (CACHE_BYTES)."""
    key = (albedo_key, data_key, channels)
    with _PYRAMIDS_LOCK:
        if key in _PYRAMIDS:
            _PYRAMIDS.move_to_end(key)
            return _PYRAMIDS[key]
    tex = _build_code_maps(albedo_key, data_key, channels)
    with _PYRAMIDS_LOCK:
        _PYRAMIDS[key] = tex
        total = sum(t.nbytes for t in _PYRAMIDS.values())
        while len(_PYRAMIDS) > 1 and total > CACHE_BYTES:
            total -= _PYRAMIDS.popitem(last=False)[1].nbytes
    return tex


def clear_cache() -> None:
    """Forget the cached pyramids (benchmarks time cold loads)."""
    with _PYRAMIDS_LOCK:
        _PYRAMIDS.clear()


def _build_code_maps(albedo_key, data_key, channels: tuple) -> MipTexture:
    """The 8-bit pyramid of load_maps: channels 0..2 the albedo's sRGB codes (0 without an albedo: the base colour
    is a constant decode table), then `channels` of the data image. Level 0 is decoded straight into the pyramid
    (render/png.py) where the files allow, else read through OpenImageIO and copied there."""
    rgb = _open_codes(albedo_key[0]) if albedo_key else None
    data = _open_codes(data_key[0]) if data_key else None
    if data is not None:
        _check_channels(data_key[0], _channel_count(data), channels)
    first = rgb if rgb is not None else data
    assert first is not None, "load_maps asks for an albedo, a data image or both"
    h, w = _size(first)
    if data is not None and _size(data) != (h, w):
        data, channels = _resize(_codes(data)[..., list(channels)], w, h), tuple(range(len(channels)))
    tex = MipTexture.empty(h, w, 3 + len(channels), np.uint8, decode_tables(3 + len(channels), 3))
    level0 = tex.texels(0)
    if rgb is None:
        level0[..., :3] = 0
    else:                                                 # grey (+ alpha): repeated
        _write_codes(rgb, level0, 0, (0, 1, 2) if _channel_count(rgb) >= 3 else (0, 0, 0))
    if data is not None:
        _write_codes(data, level0, 3, channels)
    return tex.build_mips(colour=3)


def _open_codes(path: str) -> Png8 | np.ndarray:
    """A file's 8-bit codes for _build_code_maps: a Png8 to decode straight into the pyramid when render/png.py
    reads the file, else its (H, W, C) codes read through OpenImageIO."""
    st = regular_file(path, "texture")
    check_memory(f"reading {path}", st.st_size)
    try:
        png = open_png8(path)
    except OSError as e:
        raise InputError(f"{path}: cannot read texture ({e.strerror or type(e).__name__})") from None
    if png is None:
        return read_codes(path)
    check_memory(f"decoding {path} ({png.width}x{png.height})", 8 * png.width * png.height * png.channels)
    return png


def _write_codes(image: Png8 | np.ndarray, level0: np.ndarray, first: int, take: tuple) -> None:
    """level0[..., first + k] = channel take[k] of the image's codes."""
    if isinstance(image, Png8):
        if image.decode_into(level0, first, take):
            return
        image = read_codes(image.path)                    # damaged scanlines: OpenImageIO reads or reports them
    level0[..., first:first + len(take)] = image[..., list(take)]


def _codes(image: Png8 | np.ndarray) -> np.ndarray:
    """(H, W, C) codes of an opened file (decoded for a Png8)."""
    if isinstance(image, np.ndarray):
        return image
    out = np.empty((image.height, image.width, image.channels), np.uint8)
    _write_codes(image, out, 0, tuple(range(image.channels)))
    return out


def _size(image: Png8 | np.ndarray) -> tuple[int, int]:
    return (image.height, image.width) if isinstance(image, Png8) else image.shape[:2]


def _channel_count(image: Png8 | np.ndarray) -> int:
    return image.channels if isinstance(image, Png8) else image.shape[2]


@functools.lru_cache(maxsize=4)
def _float_maps(albedo_key, data_key, offset: float, channels: tuple, base_color: tuple) -> MipTexture:
    """load_maps for files of more than 8 bits: float32 linear values, the offset applied at load."""
    data = read_image(data_key[0], srgb=False) if data_key else None
    if data is not None:
        _check_channels(data_key[0], data.shape[2], channels)
        data = data[..., list(channels)]
    if albedo_key is not None:
        rgb = read_image(albedo_key[0], srgb=True, offset=offset)
        rgb = rgb[..., :3] if rgb.shape[2] >= 3 else np.repeat(rgb[..., :1], 3, axis=2)
    else:
        shape = data.shape[:2] if data is not None else (1, 1)
        rgb = np.broadcast_to(np.asarray(base_color, np.float32), shape + (3,))
    if data is None:
        return float_pyramid(rgb)
    if data.shape[:2] != rgb.shape[:2]:
        data = _resize(data, rgb.shape[1], rgb.shape[0])
    return float_pyramid(np.concatenate([rgb, data], axis=2))


def _check_channels(path: str, count: int, channels: tuple) -> None:
    if max(channels) >= count:
        raise InputError(f"{path}: has {count} channels, channel {max(channels)} was asked for")


def _resize(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width, C) image resized by OpenImageIO, in its own type (uint8 codes stay codes)."""
    fmt = oiio.UINT8 if image.dtype == np.uint8 else oiio.FLOAT
    buf = oiio.ImageBuf(np.ascontiguousarray(image))
    out = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, width, 0, height, 0, 1, 0, image.shape[2]))
    pixels = out.get_pixels(fmt)
    assert pixels is not None, out.geterror()
    return pixels.reshape(height, width, image.shape[2])


@functools.lru_cache(maxsize=2)
def checker_texture(size: int = 1024, cells: int = 16) -> MipTexture:
    """A UV checker (linear RGB): `cells` x `cells` squares alternating light and dark, tinted by column (hue) and
    row (brightness), so that a misplaced or mirrored island shows as a break in the pattern."""
    idx = (np.arange(size) * cells) // size
    col, row = np.meshgrid(idx, idx[::-1])             # row 0 of the pattern at the bottom (v = 0)
    hue = col / cells * 2 * np.pi
    tint = 0.5 + 0.4 * np.stack([np.cos(hue), np.cos(hue - 2.1), np.cos(hue + 2.1)], -1)
    light = ((col + row) % 2 == 0)[..., None]
    shade = (0.35 + 0.6 * row / cells)[..., None]
    img = np.where(light, 0.85 * tint * shade + 0.1, 0.08 * tint + 0.02)
    return float_pyramid(img.astype(np.float32))
