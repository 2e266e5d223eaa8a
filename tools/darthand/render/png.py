"""8-bit PNG decoding straight into a caller's array: the fast path of the renderer's texture loads.

A dataset shard loads every catalogue texture once (a 2048^2 RGB albedo and a 2048^2 grey roughness PNG): through
OpenImageIO that is its libpng decode (zlib's inflate, then a copy per row), a copy out of the ImageBuf, and a
copy into the mip pyramid's interleaved level 0: ~75 ms of CPU for the two files. Here the scanlines are
inflated by libdeflate (the `deflate` package: a 2048^2 RGB albedo in 6 ms against zlib's 26 and ISA-L's 15, loaded
2-core machine) and one compiled pass (_unfilter_kernel, ~3 ms) undoes PNG's per-row filters and writes each pixel's
channels where the caller wants them (texture.py: channels 0..2 of level 0 for the albedo, 3 for the roughness).

Only files this module reads exactly as OpenImageIO does take this path: bit depth 8, colour type 0 (grey) or 2
(RGB), not interlaced, no chunk that changes what the pixels read as (tRNS adds alpha, PLTE, sBIT, and any chunk
not listed in PIXEL_NEUTRAL), every chunk's CRC right, the zlib stream whole (its Adler-32 is checked) and of the
exact size. Anything else -- alpha (OpenImageIO associates it on read), palettes, 16 bits, interlacing, damage --
and `open_png8` returns None or `decode_into` False, and the caller reads the file through OpenImageIO, which stays
the reference (tests compare the two) and the one place that reports a corrupt file.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass

import deflate
import numpy as np

from darthand.jit import kernel

SIGNATURE = b"\x89PNG\r\n\x1a\n"
CHANNELS = {0: 1, 2: 3}          # colour type -> channels, of the types read here (no alpha, no palette)
# Chunks that leave the pixels as stored (metadata: colour space, gamma, physical size, offsets, text, time, EXIF).
PIXEL_NEUTRAL = frozenset({b"IHDR", b"IDAT", b"IEND", b"sRGB", b"gAMA", b"cHRM", b"iCCP", b"cICP", b"pHYs",
                           b"oFFs", b"tEXt", b"zTXt", b"iTXt", b"tIME", b"eXIf"})


@dataclass(frozen=True)
class Png8:
    """An 8-bit grey or RGB PNG, parsed but not decoded: its size, channels and compressed scanlines."""

    path: str
    height: int
    width: int
    channels: int
    zdata: bytes          # the IDAT chunks' data, concatenated: one zlib stream

    @property
    def nbytes(self) -> int:
        """Bytes of the filtered scanlines (a filter-type byte per row, then the row's samples)."""
        return self.height * (1 + self.width * self.channels)

    def decode_into(self, out: np.ndarray, first: int, take) -> bool:
        """Write source channel take[k] of every pixel into out[..., first + k]: out (height, width, C) uint8,
        C-contiguous. False (out partly written) when the scanlines turn out corrupt (bad zlib data, a wrong size,
        an unknown filter type): the caller then reads the file through OpenImageIO, which reports it."""
        take = np.asarray(take, np.int64)
        if (out.dtype != np.uint8 or out.shape[:2] != (self.height, self.width) or not out.flags.c_contiguous
                or not 0 <= first <= out.shape[2] - len(take) or take.min() < 0 or take.max() >= self.channels):
            raise ValueError(f"{self.path}: cannot decode {self.channels} channels into {out.shape}")
        try:
            raw = deflate.zlib_decompress(self.zdata, self.nbytes)
        except deflate.DeflateError:
            return False
        if len(raw) != self.nbytes:
            return False
        return bool(_unfilter_kernel(np.frombuffer(raw, np.uint8), self.channels, take, first, out))


def open_png8(path: str | os.PathLike) -> Png8 | None:
    """The file as a Png8 when it is one this module decodes exactly as OpenImageIO (see the module docstring),
    else None (also for a file that is no PNG, is truncated or has a bad CRC: OpenImageIO reports those)."""
    with open(path, "rb") as f:
        data = f.read()
    if not data.startswith(SIGNATURE):
        return None
    view = memoryview(data)
    pos, header, idat, after_idat = len(SIGNATURE), None, [], False
    while True:
        if pos + 12 > len(data):
            return None                                   # truncated before IEND
        length, kind = struct.unpack_from(">I4s", data, pos)
        end = pos + 12 + length
        if end > len(data) or kind not in PIXEL_NEUTRAL:
            return None
        body = view[pos + 8:end - 4]
        if deflate.crc32(body, deflate.crc32(kind)) != struct.unpack_from(">I", data, end - 4)[0]:
            return None
        if header is None and kind != b"IHDR":
            return None
        if kind == b"IHDR":
            if header is not None or length != 13:
                return None
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            if after_idat:
                return None                               # IDAT chunks must be consecutive
            idat.append(body)
        elif kind == b"IEND":
            break
        elif idat:
            after_idat = True
        pos = end
    if header is None:
        return None                                       # no IHDR chunk
    width, height, depth, colour, compression, filtering, interlace = header
    if (depth != 8 or colour not in CHANNELS or compression or filtering or interlace or not idat
            or not 0 < width < 2 ** 31 or not 0 < height < 2 ** 31):
        return None
    return Png8(str(path), height, width, CHANNELS[colour], b"".join(idat))


@kernel
def _unfilter_kernel(raw, channels, take, first, out):
    """Undo PNG's per-row filters (None, Sub, Up, Average, Paeth; ISO/IEC 15948 section 9) of raw: H rows of a
    filter-type byte then W * channels samples, and write sample take[k] of each pixel into out[r, c, first + k]
    (out (H, W, C) uint8). A filtered row is undone into a row buffer (the row above kept for Up, Average and
    Paeth), an unfiltered one read where it lies; the grey and RGB scatters have their own loops (constant
    strides: 3-4x faster than the general one). Returns False at an unknown filter type."""
    H, W, C = out.shape
    stride = W * channels
    n = len(take)
    rgb = channels == 3 and n == 3 and take[0] == 0 and take[1] == 1 and take[2] == 2
    rows = np.zeros((2, stride), np.uint8)
    prev = rows[1]                                      # the row above the first row reads as zeros
    which = 0
    for r in range(H):
        start = r * (stride + 1) + 1
        kind = raw[start - 1]
        if kind == 0:
            line = raw[start:start + stride]
        else:
            line = rows[which]
            for i in range(stride):
                a = int(line[i - channels]) if i >= channels else 0      # left (already undone)
                b = int(prev[i])                                          # above
                if kind == 1:
                    p = a
                elif kind == 2:
                    p = b
                elif kind == 3:
                    p = (a + b) >> 1
                elif kind == 4:
                    c = int(prev[i - channels]) if i >= channels else 0  # above left
                    pa, pb, pc = abs(b - c), abs(a - c), abs(a + b - 2 * c)
                    p = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                else:
                    return False
                line[i] = (int(raw[start + i]) + p) & 255
            which ^= 1
        dst = out[r]
        if rgb:
            for x in range(W):
                dst[x, first] = line[3 * x]
                dst[x, first + 1] = line[3 * x + 1]
                dst[x, first + 2] = line[3 * x + 2]
        elif channels == 1 and n == 1:
            for x in range(W):
                dst[x, first] = line[x]
        elif channels == 1:
            for x in range(W):
                v = line[x]
                for k in range(n):
                    dst[x, first + k] = v
        else:
            for x in range(W):
                for k in range(n):
                    dst[x, first + k] = line[x * channels + take[k]]
        prev = line
    return True
