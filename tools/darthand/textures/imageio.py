"""Image files through OpenImageIO: sRGB albedo and raw data PNGs, tiled mip-mapped .tx textures, reading.

All writes are atomic (fileio.atomic_path). PNG output is deterministic: no timestamps, fixed compression.
.tx files are not byte-for-byte reproducible: make_texture stamps the current time on each MIP level.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.errors import InputError
from darthand.fileio import atomic_path

PNG_COMPRESSION = 3  # zlib level
# libpng's 'Up' filter only: on 2048^2 skin albedo about 2x faster than the adaptive choice for files ~20% larger
# (0.13 s and 2.1 MB against 0.25 s and 1.7 MB, measured).
PNG_FILTER = 8


def image_buffer(img, srgb: bool = True) -> oiio.ImageBuf:
    """An OpenImageIO buffer of a (H, W, C) / (H, W) array tagged sRGB or raw; buffers pass through."""
    if isinstance(img, oiio.ImageBuf):
        return img
    return _buffer(np.asarray(img), "sRGB" if srgb else "Raw")


def _buffer(img: np.ndarray, colorspace: str) -> oiio.ImageBuf:
    img = np.ascontiguousarray(img)
    if img.ndim == 2:
        img = img[..., None]
    fmt = {np.dtype(np.uint8): oiio.UINT8, np.dtype(np.uint16): oiio.UINT16,
           np.dtype(np.float32): oiio.FLOAT}[img.dtype]
    buf = oiio.ImageBuf(oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], fmt))
    buf.set_pixels(oiio.ROI(), img)
    buf.specmod().attribute("oiio:ColorSpace", colorspace)
    return buf


def write_png(path: str | os.PathLike, img, srgb: bool = True) -> None:
    """Write a (H, W, C) or (H, W) uint8 image (or an `image_buffer`) as PNG: tagged sRGB (albedo) or untagged
    raw data (`srgb=False`)."""
    buf = image_buffer(img, srgb)
    buf.specmod().attribute("png:compressionLevel", PNG_COMPRESSION)
    buf.specmod().attribute("png:filter", PNG_FILTER)
    with atomic_path(path) as tmp:
        if not buf.write(str(tmp)):
            raise OSError(f"{path}: cannot write PNG ({buf.geterror()})")


def write_tx(path: str | os.PathLike, img, srgb: bool = True) -> None:
    """Write a tiled, mip-mapped, zip-compressed .tx texture via OpenImageIO's make_texture."""
    buf = image_buffer(img, srgb)
    config = oiio.ImageSpec()
    config.attribute("maketx:hash", 0)  # the sha-1 metadata and the average colour cost ~30% and are unused
    config.attribute("maketx:compute_average", 0)
    config.attribute("maketx:filtername", "box")
    config.attribute("compression", "zip")
    config.attribute("wrapmodes", "clamp,clamp")  # an atlas does not tile; its padding reaches the borders
    with atomic_path(path) as tmp:
        if not oiio.ImageBufAlgo.make_texture(oiio.MakeTxTexture, buf, str(tmp), config):
            raise OSError(f"{path}: cannot write .tx ({oiio.geterror()})")


def read_image(path: str | os.PathLike, miplevel: int = 0) -> np.ndarray:
    """(H, W, C) uint8 pixels of an image file (a given MIP level of a .tx)."""
    buf = oiio.ImageBuf(str(path), 0, miplevel)
    if buf.has_error:
        raise InputError(f"{path}: cannot read image ({buf.geterror()})")
    return buf.get_pixels(oiio.UINT8)


def mip_levels(path: str | os.PathLike) -> list[tuple[int, int]]:
    """(width, height) of every MIP level of a texture file, finest first."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise InputError(f"{path}: cannot open texture ({oiio.geterror()})")
    sizes = []
    try:
        level = 0
        while inp.seek_subimage(0, level):
            spec = inp.spec()
            sizes.append((spec.width, spec.height))
            level += 1
    finally:
        inp.close()
    return sizes


def read_small(path: str | os.PathLike, size: int = 256) -> np.ndarray:
    """A copy of a square image about `size` pixels wide: the matching MIP level of a .tx, else the PNG
    resized by OpenImageIO."""
    path = Path(path)
    if path.suffix == ".tx":
        levels = mip_levels(path)
        level = max((i for i, (w, _) in enumerate(levels) if w >= size), default=0)
        return read_image(path, level)
    buf = oiio.ImageBuf(str(path))
    if buf.spec().width <= size:
        return buf.get_pixels(oiio.UINT8)
    small = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, size, 0, size, 0, 1, 0, buf.nchannels))
    return small.get_pixels(oiio.UINT8)
