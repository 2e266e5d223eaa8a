"""Textures for shading: a mip pyramid in linear light, trilinear lookups, the mip level from a pixel's UV footprint.

UV convention (verified against the textures stage's baker, textures/bake.py, which rasterises a UV triangle at
pixel coordinates (u * res, (1 - v) * res) with texel centres at integer + 0.5): OpenGL-style st, u to the right,
v UP, v = 0 at the BOTTOM row of the image. Texel (row r, column c) of an H x W level has its centre at
u = (c + 0.5) / W, v = 1 - (r + 0.5) / H. Lookups clamp to the edge (the textures carry padded gutters).

Written here rather than through OpenImageIO's TextureSystem because its Python binding samples one point per call;
these lookups are numpy gathers over every shaded sample at once.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.errors import InputError
from darthand.textures.color import srgb_to_linear

BLEND = 0.25     # half-width of the band of fractional mip levels (around .5) in which two levels are blended


class MipTexture:
    """A mip pyramid: levels[k] (H_k, W_k, C) float32, level 0 the full image, each next level half the size (2x2
    box filter in linear light), down to 1 x 1. All levels are also kept in one flat (texels, C) array so that a
    lookup at per-sample levels is one gather, whatever the levels."""

    def __init__(self, levels):
        self.levels = tuple(np.ascontiguousarray(a, np.float32) for a in levels)
        sizes = np.array([a.shape[0] * a.shape[1] for a in self.levels], np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        self.widths = np.array([a.shape[1] for a in self.levels], np.int64)
        self.heights = np.array([a.shape[0] for a in self.levels], np.int64)
        self.flat = np.concatenate([a.reshape(-1, a.shape[2]) for a in self.levels])

    @property
    def width(self) -> int:
        return int(self.widths[0])

    @property
    def height(self) -> int:
        return int(self.heights[0])

    @property
    def channels(self) -> int:
        return int(self.flat.shape[1])

    def bilinear(self, uv: np.ndarray, level=0) -> np.ndarray:
        """(C, N) float32 bilinear lookup at uv (2, N) in mip level `level` (an int or (N,) ints)."""
        n = uv.shape[1]
        level = np.broadcast_to(np.asarray(level, np.int64), (n,))
        w, h = self.widths[level], self.heights[level]
        x = uv[0] * w.astype(np.float32) - np.float32(0.5)
        y = (np.float32(1.0) - uv[1]) * h.astype(np.float32) - np.float32(0.5)
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
        xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
        row_a = self.offsets[level] + np.clip(y0, 0, h - 1) * w
        row_b = self.offsets[level] + np.clip(y0 + 1, 0, h - 1) * w
        flat = self.flat
        top = np.take(flat, row_a + xa, axis=0)
        top += (np.take(flat, row_a + xb, axis=0) - top) * fx
        bottom = np.take(flat, row_b + xa, axis=0)
        bottom += (np.take(flat, row_b + xb, axis=0) - bottom) * fx
        top += (bottom - top) * fy
        return np.ascontiguousarray(top.T)

    def sample(self, uv: np.ndarray, lod: np.ndarray | float = 0.0) -> np.ndarray:
        """(C, N) float32 lookup at uv (2, N), mip level `lod` (N,): bilinear in the nearer level, blended with the
        other level around the middle between two levels (where frac(lod) is within BLEND of 0.5) -- trilinear
        filtering with a narrowed blend band ("brilinear"), half the texel reads of full trilinear."""
        n = uv.shape[1]
        last = len(self.levels) - 1
        lod = np.clip(np.broadcast_to(np.asarray(lod, np.float32), (n,)), 0, last)
        base = np.floor(lod).astype(np.int64)
        frac = lod - base
        near = np.where(frac < 0.5, base, np.minimum(base + 1, last))
        out = self.bilinear(uv, near)
        w = np.clip((frac - (0.5 - BLEND)) / (2 * BLEND), 0, 1)          # weight of level base + 1
        blend = np.flatnonzero((w > 0) & (w < 1) & (base < last))
        if len(blend):
            other = np.where(frac[blend] < 0.5, base[blend] + 1, base[blend])
            t = np.where(frac[blend] < 0.5, w[blend], 1 - w[blend]).astype(np.float32)
            out[:, blend] += (self.bilinear(uv[:, blend], other) - out[:, blend]) * t
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


def pack_textures(*textures: MipTexture) -> MipTexture:
    """One texture whose channels are those of `textures` (same size) side by side, for a single lookup."""
    if len({(t.width, t.height) for t in textures}) != 1:
        raise ValueError("pack_textures: the textures differ in size")
    return MipTexture([np.concatenate(lv, axis=2) for lv in zip(*(t.levels for t in textures))])


def mip_levels(image: np.ndarray) -> tuple:
    """Levels of a (H, W, C) float32 image: 2x2 box averages (an odd row or column is repeated) down to 1 x 1."""
    levels = [np.ascontiguousarray(image, dtype=np.float32)]
    while levels[-1].shape[0] > 1 or levels[-1].shape[1] > 1:
        img = levels[-1]
        if img.shape[0] % 2 and img.shape[0] > 1:
            img = np.concatenate([img, img[-1:]], 0)
        if img.shape[1] % 2 and img.shape[1] > 1:
            img = np.concatenate([img, img[:, -1:]], 1)
        h, w = max(1, img.shape[0] // 2), max(1, img.shape[1] // 2)
        fy, fx = img.shape[0] // h, img.shape[1] // w
        levels.append(np.ascontiguousarray(img.reshape(h, fy, w, fx, -1).mean(axis=(1, 3), dtype=np.float32)))
    return tuple(levels)


def constant_texture(value) -> MipTexture:
    """A 1 x 1 texture of one value (C,)."""
    return MipTexture([np.asarray(value, np.float32).reshape(1, 1, -1)])


def srgb8_to_linear_lut(offset: float = 0.0) -> np.ndarray:
    """(256,) float32 linear value of each 8-bit sRGB code after adding the skin-tone `offset` to the encoded value
    (the textures stage's convention: textures/color.encode_srgb8), clipped to [0, 1]."""
    return srgb_to_linear(np.clip(np.arange(256, dtype=np.float32) / 255 + np.float32(offset), 0, 1))


def read_image(path: str | os.PathLike, *, srgb: bool, offset: float = 0.0) -> np.ndarray:
    """(H, W, C) float32 pixels of an image file: sRGB images decoded to linear light (after the sRGB `offset`),
    data images (srgb=False) as stored, scaled to [0, 1]."""
    path = Path(path)
    buf = oiio.ImageBuf(str(path))
    if buf.has_error or not path.is_file():
        raise InputError(f"{path}: cannot read image ({buf.geterror() or 'no such file'})")
    if buf.spec().format == oiio.UINT8:
        codes = buf.get_pixels(oiio.UINT8)
        if srgb:
            return srgb8_to_linear_lut(offset)[codes]
        return codes.astype(np.float32) * np.float32(1 / 255)
    pixels = buf.get_pixels(oiio.FLOAT)
    return srgb_to_linear(np.clip(pixels + np.float32(offset), 0, 1)) if srgb else pixels


def load_texture(path: str | os.PathLike, *, srgb: bool, offset: float = 0.0) -> MipTexture:
    """The mip pyramid of one image file: sRGB colour (cached, see `load_maps`) or raw data."""
    if srgb:
        return load_maps(path, offset=offset)
    return MipTexture(mip_levels(read_image(path, srgb=False)))


def load_maps(albedo: str | os.PathLike | None, *, offset: float = 0.0, data: str | os.PathLike | None = None,
              channels=(0,), base_color=(0.8, 0.8, 0.8)) -> MipTexture:
    """One texture for a material's single lookup: channels 0..2 linear albedo (the sRGB image `albedo` after the
    sRGB `offset`, or the constant linear `base_color`), then `channels` of the data image `data` (raw, [0, 1]),
    resized to the albedo's size if they differ. Cached by the files (path, modification time) and arguments."""
    keys = []
    for path in (albedo, data):
        if path is None:
            keys.append(None)
            continue
        path = Path(path)
        try:
            keys.append((str(path.resolve()), path.stat().st_mtime_ns))
        except OSError:
            raise InputError(f"{path}: texture file not found") from None
    return _load_maps(keys[0], keys[1], round(float(offset), 6), tuple(int(c) for c in channels),
                      tuple(float(c) for c in base_color))


@functools.lru_cache(maxsize=8)
def _load_maps(albedo_key, data_key, offset: float, channels: tuple, base_color: tuple) -> MipTexture:
    data = read_image(data_key[0], srgb=False) if data_key else None
    if data is not None:
        if max(channels) >= data.shape[2]:
            raise InputError(f"{data_key[0]}: has {data.shape[2]} channels, channel {max(channels)} was asked for")
        data = data[..., list(channels)]
    if albedo_key is not None:
        rgb = read_image(albedo_key[0], srgb=True, offset=offset)[..., :3]
        if rgb.shape[2] == 1:
            rgb = np.repeat(rgb, 3, axis=2)
    else:
        shape = data.shape[:2] if data is not None else (1, 1)
        rgb = np.broadcast_to(np.asarray(base_color, np.float32), shape + (3,))
    if data is None:
        return MipTexture(mip_levels(rgb))
    if data.shape[:2] != rgb.shape[:2]:
        data = _resize(data, rgb.shape[1], rgb.shape[0])
    return MipTexture(mip_levels(np.concatenate([rgb, data], axis=2)))


def _resize(image: np.ndarray, width: int, height: int) -> np.ndarray:
    buf = oiio.ImageBuf(np.ascontiguousarray(image, np.float32))
    out = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, width, 0, height, 0, 1, 0, image.shape[2]))
    return out.get_pixels(oiio.FLOAT).reshape(height, width, image.shape[2])


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
    return MipTexture(mip_levels(img.astype(np.float32)))
