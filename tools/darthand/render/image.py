"""Image output: compositing over a background in linear light, sRGB encoding, PNG / EXR writing.

The renderer keeps colour premultiplied by coverage alpha. Over a background image B (linear):
out = C_premult + (1 - alpha) B, which for an edge pixel is alpha * fg + (1 - alpha) * bg with fg the mean colour
of the sub-samples that hit: no halo. Without a background, image.png stores straight (unpremultiplied) colour,
sRGB-encoded, and alpha, as PNG defines, so compositing it with any "over" operator in linear light gives the same.
"""

from __future__ import annotations

import functools
import os
import struct
import zlib
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
from isal import isal_zlib

from darthand.budget import check_memory
from darthand.errors import InputError
from darthand.fileio import atomic_path, regular_file
from darthand.jit import kernel
from darthand.processes import native_stderr_captured
from darthand.textures.color import linear_to_srgb, srgb8_table, srgb_to_linear

# Deflate by Intel's ISA-L (the `isal` package): the same format as zlib's, 4-6x faster at its level 1 than zlib at
# level 1 with the run-length strategy used before, and files as small or smaller. A 512^2 frame over a built-in
# background: 3.6 ms, 303 kB against 15.2 ms, 324 kB; a transparent frame: 0.7 ms, 56 kB against 4.6 ms, 51 kB
# (loaded 2-core machine). Dataset frames spend their write time here.
PNG_COMPRESSION = 1


def encode_mask8(alpha: np.ndarray) -> np.ndarray:
    """(H, W) uint8 coverage, 0..255: rint(clip(alpha, 0, 1) x 255) in float32 (NaN as 0), in one compiled pass."""
    alpha = np.asarray(alpha)
    out = np.empty(alpha.shape, np.uint8)
    _mask8_kernel(np.ascontiguousarray(alpha, np.float32).reshape(-1), out.reshape(-1))
    return out


@kernel
def _mask8_kernel(alpha, out):
    """out[i] = rint(alpha[i] clipped to [0, 1] x 255) (float32, NaN as 0): numpy's clip, product and rint, a
    third of their time."""
    one, zero, scale = np.float32(1.0), np.float32(0.0), np.float32(255)
    for i in range(alpha.shape[0]):
        v = alpha[i]
        v = v if v > zero else zero
        v = v if v < one else one
        out[i] = np.uint8(np.rint(v * scale))


def compose(premult: np.ndarray, alpha: np.ndarray, region: tuple[int, int], background: np.ndarray | None,
            size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(colour (H, W, 3) float32 linear, rgba (H, W, 4) uint8) of a frame of `size` (H, W) whose pixels from
    `region` (r0, c0) on were rendered: premult (3, h, w) linear colour premultiplied by coverage alpha (h, w).
    Over a background (H, W, 3) linear: colour = premult + (1 - alpha) background (the background outside the
    region), rgba its sRGB codes (encode_srgb8), opaque. Without one: colour the premultiplied colour (0 outside),
    rgba the sRGB codes of the straight colour premult / alpha (0 where alpha is 0) and the 8-bit alpha
    (encode_mask8). One compiled pass over the frame."""
    H, W = size
    colour = np.empty((H, W, 3), np.float32)
    rgba = np.empty((H, W, 4), np.uint8)
    premult = np.ascontiguousarray(premult, np.float32)
    alpha = np.ascontiguousarray(alpha, np.float32)
    if background is None:
        background = np.zeros((0, 0, 3), np.float32)
        over = False
    else:
        background, over = np.ascontiguousarray(background, np.float32), True
    _compose_kernel(premult, alpha, int(region[0]), int(region[1]), background, over, srgb8_table(0.0), colour, rgba)
    return colour, rgba


@kernel
def _compose_kernel(premult, alpha, r0, c0, background, over, table, colour, rgba):
    """colour, rgba of `compose`, pixel by pixel, with numpy's float32 arithmetic in the same order (composite:
    premult + (1 - alpha) background; straight colour: premult / alpha where alpha > 0) and encode_srgb8's and
    encode_mask8's rounding (textures/color.encode_srgb8_into: the value clipped to [0, 1], NaN as 0, rounded to
    the nearest of the table's 65536 steps; the mask: rint of alpha x 255), so the codes are the same. Over a
    background, a pixel outside the region (the background alone) and one inside (the composite) take separate
    branches with their three channels each: a third faster than choosing per channel, the same numbers."""
    H, W = colour.shape[0], colour.shape[1]
    h, w = alpha.shape
    top, half, one, zero = np.float32(len(table) - 1), np.float32(0.5), np.float32(1.0), np.float32(0.0)
    if over:
        for r in range(H):
            inside_row = r0 <= r < r0 + h
            for c in range(W):
                if inside_row and c0 <= c < c0 + w:
                    a = alpha[r - r0, c - c0]
                    for k in range(3):
                        v = premult[k, r - r0, c - c0] + (one - a) * background[r, c, k]
                        colour[r, c, k] = v
                        code = one if v > 1 else (v if v > 0 else zero)
                        rgba[r, c, k] = table[int(code * top + half)]
                else:
                    for k in range(3):
                        v = background[r, c, k]
                        colour[r, c, k] = v
                        code = one if v > 1 else (v if v > 0 else zero)
                        rgba[r, c, k] = table[int(code * top + half)]
                rgba[r, c, 3] = 255
        return
    for r in range(H):
        for c in range(W):
            inside = r0 <= r < r0 + h and c0 <= c < c0 + w
            a = alpha[r - r0, c - c0] if inside else zero
            for k in range(3):
                p = premult[k, r - r0, c - c0] if inside else zero
                colour[r, c, k] = p
                code = p / a if a > 0 else zero
                code = one if code > 1 else (code if code > 0 else zero)
                rgba[r, c, k] = table[int(code * top + half)]
            m = zero if not a > zero else (a if a < one else one)          # clipped; NaN as 0
            rgba[r, c, 3] = int(np.rint(m * np.float32(255)))


def compose_over_grid(premult: np.ndarray, alpha: np.ndarray, region: tuple[int, int], grid: np.ndarray,
                      axes: tuple, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """`compose` over the background given as a grid (h, w, 3) float32 linear and its bilinear upsampling `axes`
    ((r0, r1, fr), (c0, c1, fc): frame row i is grid rows r0[i], r1[i] blended by fr[i], then column j grid columns
    c0[j], c1[j] blended by fc[j]; environment.Backdrop.axes): the same colour and rgba as `compose` over the
    upsampled background (environment.upsample's float32 numbers), without making it. One compiled pass."""
    (r0, r1, fr), (c0, c1, fc) = axes
    H, W = size
    colour = np.empty((H, W, 3), np.float32)
    rgba = np.empty((H, W, 4), np.uint8)
    index = lambda a: np.ascontiguousarray(a, np.int64)
    weight = lambda a: np.ascontiguousarray(a, np.float32)
    _compose_grid_kernel(weight(premult), weight(alpha), int(region[0]), int(region[1]), weight(grid), index(r0),
                         index(r1), weight(fr), index(c0), index(c1), weight(fc), srgb8_table(0.0), colour, rgba)
    return colour, rgba


@kernel
def _compose_grid_kernel(premult, alpha, r0, c0, grid, gr0, gr1, gfr, gc0, gc1, gfc, table, colour, rgba):
    """colour, rgba of `compose_over_grid`, a frame row at a time: the grid's two rows blended (_upsample_kernel's
    numbers), the row's background blended from it into colour, the region's columns composited over it, then the
    row encoded, each as _compose_kernel does (the same float32 operations in the same order). Three plain loops
    per row rather than one with per-pixel branches: a third less time."""
    H, W = colour.shape[0], colour.shape[1]
    h, w = alpha.shape
    top, half, one, zero = np.float32(len(table) - 1), np.float32(0.5), np.float32(1.0), np.float32(0.0)
    row = np.empty((grid.shape[1], 3), np.float32)
    lo, hi = min(max(c0, 0), W), min(max(c0 + w, 0), W)
    for r in range(H):
        a, b, f = gr0[r], gr1[r], gfr[r]
        g = one - f
        for q in range(grid.shape[1]):
            for k in range(3):
                row[q, k] = grid[a, q, k] * g + grid[b, q, k] * f
        out = colour[r]
        for c in range(W):
            p, q, e = gc0[c], gc1[c], gfc[c]
            d = one - e
            for k in range(3):
                out[c, k] = row[p, k] * d + row[q, k] * e
        if r0 <= r < r0 + h:
            for c in range(lo, hi):
                m = one - alpha[r - r0, c - c0]
                for k in range(3):
                    out[c, k] = premult[k, r - r0, c - c0] + m * out[c, k]
        codes = rgba[r]
        for c in range(W):
            for k in range(3):
                v = out[c, k]
                v = one if v > 1 else (v if v > 0 else zero)        # clipped to [0, 1], NaN as 0
                codes[c, k] = table[np.uint32(v * top + half)]
            codes[c, 3] = 255


def read_image_buf(path: str | os.PathLike, what: str = "image") -> oiio.ImageBuf:
    """An image file decoded whole into an ImageBuf, after checking that it is a regular file and that its declared
    size fits the memory budget; InputError naming the file when it is truncated or corrupt (OpenImageIO reads
    lazily and would otherwise hand back the pixels decoded before the damage)."""
    regular_file(path, what)
    with native_stderr_captured():             # libpng prints its own line for a damaged file: ours says it
        inp = oiio.ImageInput.open(str(path))
    if inp is None:                            # OpenImageIO's reason can run to several lines: its first says it
        raise InputError(f"{path}: cannot read {what}: {first_line(oiio.geterror()) or 'unknown format'}")
    spec = inp.spec()
    inp.close()
    check_memory(f"decoding {path} ({spec.width}x{spec.height})", 8 * spec.width * spec.height * spec.nchannels)
    buf = oiio.ImageBuf(str(path))
    with native_stderr_captured():
        read = buf.read(force=True)
    if not read or buf.has_error:
        raise InputError(f"{path}: cannot read {what}: {first_line(buf.geterror()) or 'read failed'} (truncated or "
                         "corrupt)")
    return buf


def first_line(text: str | None) -> str:
    """The first line of an OpenImageIO error (its decoders add lines of their own, e.g. libpng's, after it)."""
    return (str(text or "").strip().splitlines() or [""])[0]


@functools.lru_cache(maxsize=4)
def _background(path: str, mtime: int, width: int, height: int) -> np.ndarray:
    buf = read_image_buf(path, "background image")
    spec = buf.spec()
    # Scale to cover the frame, keeping the aspect ratio, then crop the centre.
    scale = max(width / spec.width, height / spec.height)
    w, h = max(width, round(spec.width * scale)), max(height, round(spec.height * scale))
    linear = buf.get_pixels(oiio.FLOAT)
    assert linear is not None, buf.geterror()         # read_image_buf read the pixels
    if spec.format == oiio.UINT8:
        linear = srgb_to_linear(linear)
    if linear.shape[2] == 1:
        linear = np.repeat(linear, 3, axis=2)
    lin = oiio.ImageBuf(np.ascontiguousarray(linear[..., :3], np.float32))
    resized = oiio.ImageBufAlgo.resize(lin, roi=oiio.ROI(0, w, 0, h, 0, 1, 0, 3))
    x0, y0 = (w - width) // 2, (h - height) // 2
    pixels = resized.get_pixels(oiio.FLOAT)
    assert pixels is not None, resized.geterror()
    pixels = pixels.reshape(h, w, 3)
    return np.ascontiguousarray(pixels[y0:y0 + height, x0:x0 + width], np.float32)


def load_background(path: str | os.PathLike, width: int, height: int) -> np.ndarray:
    """(height, width, 3) float32 linear background: the image (8-bit files are sRGB, float files linear) scaled to
    cover the frame and centre-cropped."""
    path = Path(path)
    st = regular_file(path, "background image")
    return _background(str(path.resolve()), st.st_mtime_ns, int(width), int(height))


def write_png(path: str | os.PathLike, pixels: np.ndarray, srgb: bool = True) -> None:
    """Write (H, W, C) or (H, W) uint8 pixels (C = 1 gray, 2 gray + alpha, 3 RGB, 4 RGBA, straight alpha) as an
    8-bit PNG, atomically; deterministic bytes for the same pixels. srgb: tag the file with an sRGB chunk. uint16
    pixels are written as a 16-bit PNG (samples big-endian, as PNG stores them; data maps: pass srgb=False).

    Encoded here (deflate by ISA-L, see PNG_COMPRESSION) rather than through OpenImageIO because OpenImageIO's
    Python write holds the GIL for most of its run, which stalls the renderer while a FrameWriter thread writes;
    the compressor releases it. Every
    row uses PNG's 'Up' filter (the difference to the row above: one vectorised subtraction).
    """
    bits = 16 if np.asarray(pixels).dtype == np.uint16 else 8
    img = np.ascontiguousarray(pixels, ">u2" if bits == 16 else np.uint8)
    if img.ndim == 2:
        img = img[..., None]
    h, w, c = img.shape
    if c not in _PNG_COLOUR_TYPES:
        raise ValueError(f"{path}: cannot write {c} channels as PNG")
    rows = img.view(np.uint8).reshape(h, w * c * bits // 8)     # 'Up' works on bytes whatever the bit depth
    filtered = np.empty((h, rows.shape[1] + 1), np.uint8)
    filtered[:, 0] = 2                                   # filter type 'Up'
    filtered[0, 0] = 0                                   # the first row has no row above: 'None'
    filtered[0, 1:] = rows[0]
    np.subtract(rows[1:], rows[:-1], out=filtered[1:, 1:])  # uint8 arithmetic wraps modulo 256, as PNG specifies
    header = struct.pack(">IIBBBBB", w, h, bits, _PNG_COLOUR_TYPES[c], 0, 0, 0)
    chunks = [_png_chunk(b"IHDR", header)]
    if srgb:
        chunks.append(_png_chunk(b"sRGB", b"\x00"))      # perceptual rendering intent
    deflate = isal_zlib.compressobj(PNG_COMPRESSION)
    chunks += [_png_chunk(b"IDAT", deflate.compress(filtered.data) + deflate.flush()), _png_chunk(b"IEND", b"")]
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(b"\x89PNG\r\n\x1a\n")
            f.writelines(chunks)


_PNG_COLOUR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def write_exr(path: str | os.PathLike, values: np.ndarray, channel: str = "Z") -> None:
    """Write a (H, W) float32 map as a single-channel EXR, atomically."""
    img = np.ascontiguousarray(values, np.float32)[..., None]
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], 1, oiio.FLOAT)
    spec.channelnames = (channel,)
    spec.attribute("compression", "zip")
    spec.attribute("DateTime", "")  # else OpenImageIO stamps the write time (EXR capDate): same frame, other bytes
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), img)
    with atomic_path(path) as tmp:
        if not buf.write(str(tmp), fileformat="exr"):
            raise OSError(f"{path}: cannot write EXR ({buf.geterror()})")


def read_png(path: str | os.PathLike) -> np.ndarray:
    """(H, W, C) uint8 pixels of a PNG (for checks and tests)."""
    buf = oiio.ImageBuf(str(path))
    pixels = None if buf.has_error else buf.get_pixels(oiio.UINT8)
    if pixels is None:                               # the pixels are read here: a truncated file fails now
        raise InputError(f"{path}: cannot read image ({buf.geterror()})")
    return pixels


def read_straight_png(path: str | os.PathLike) -> np.ndarray:
    """(H, W, C) uint8 pixels of an image as stored: alpha not associated (read_png's OpenImageIO multiplies colour
    by alpha on read)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    buf = oiio.ImageBuf()
    buf.reset(str(path), 0, 0, config)
    pixels = None if buf.has_error else buf.get_pixels(oiio.UINT8)
    if pixels is None:
        raise InputError(f"{path}: cannot read image ({buf.geterror()})")
    return pixels


def over_black(rgba: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 sRGB of 8-bit straight-alpha pixels (H, W[, C]) composited over black in linear light (grey
    repeated, an opaque image as it is): what a layout that reads 3 channels shows of a transparent frame."""
    if rgba.ndim == 2:
        rgba = rgba[..., None]
    if rgba.shape[2] in (1, 2):
        rgba = np.concatenate([np.repeat(rgba[..., :1], 3, axis=2), rgba[..., 1:]], axis=2)
    if rgba.shape[2] == 3 or (rgba[..., 3] == 255).all():
        return np.ascontiguousarray(rgba[..., :3])
    index = rgba[..., :3].astype(np.intp) * 256 + rgba[..., 3:]
    return np.take(_over_black_table().ravel(), index)


@functools.cache
def _over_black_table() -> np.ndarray:
    """(256, 256) uint8: [sRGB code, alpha code] -> the sRGB code of that straight colour over black in linear
    light."""
    codes = np.arange(256) / 255
    over = srgb_to_linear(codes)[:, None] * codes[None, :]
    return np.rint(linear_to_srgb(over).astype(np.float64) * 255).astype(np.uint8)
