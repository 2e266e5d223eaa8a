"""Backgrounds for datasets: images from a folder (COCO's, say) or a built-in procedural set that needs no
download, each frame a random crop, zoom and mirror of one image, composited under the hand with its coverage
alpha (in linear light, by the renderer).

Planning (`BackgroundSampler`, in the parent) picks, per frame, a file and two fall-backs (its neighbours in the
folder's sorted listing), a zoom in ZOOM_RANGE, the crop's centre and a horizontal flip. Rendering
(`background_pixels`, in a worker) decodes the first file that decodes; a file that does not (truncated,
corrupt, not an image) is skipped and recorded in the frame's labels (and dataset.json), and when all three fail the
frame takes a built-in background, so one bad file among 100,000 never ends a ten-hour run. Decoded images are
cached per worker (CACHE_BYTES). The frame stays a function of (seed, index) and the folder's contents.

Built-in backgrounds (BUILTIN_COUNT): procedural colour fields (multi-octave value noise), clutter of soft-edged
rectangles, stripes and gradients, generated from their id, so every machine makes the same ones.
"""

from __future__ import annotations

import os
from collections import OrderedDict
from pathlib import Path

import numpy as np

from darthand.errors import InputError
from darthand.jit import kernel
from darthand.processes import native_stderr_captured
from darthand.textures.color import srgb_to_linear

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".exr", ".tif", ".tiff", ".bmp", ".webp", ".hdr")
BUILTIN_COUNT = 24
BUILTIN_SIZE = 768
BUILTIN_SEED = 20221128
ZOOM_RANGE = (1.0, 2.0)
CANDIDATES = 3
CACHE_BYTES = 256 << 20
MAX_DECODE_SIDE = 2048               # larger images are box-downscaled on decode (memory, and cheaper crops)
DEFAULT_MAX_FILES = 10_000_000
UNIFORMS = 5


# ------------------------------------------------------------------------------------------------ planning


def list_images(folder, max_files: int = DEFAULT_MAX_FILES) -> list[str]:
    """Sorted relative paths (posix) of the image files under `folder` (recursively; by suffix, not opened)."""
    root = Path(folder)
    if not root.is_dir():
        raise InputError(f"{folder}: not a folder of background images")
    found = []
    try:
        for dirpath, dirnames, filenames in os.walk(root):
            dirnames.sort()
            for name in filenames:
                if name.lower().endswith(IMAGE_SUFFIXES) and not name.startswith("."):
                    found.append(Path(dirpath, name).relative_to(root).as_posix())
                    if len(found) > max_files:
                        raise InputError(f"{folder}: more than {max_files} images (--max-background-files raises "
                                         "the budget)")
    except OSError as e:
        raise InputError(f"{folder}: cannot list the background folder ({e.strerror})") from None
    if not found:
        raise InputError(f"{folder}: no background images ({', '.join(IMAGE_SUFFIXES)})")
    return sorted(found)


class BackgroundSampler:
    """Per-frame background specs from `backgrounds`: 'builtin' (default), 'none' (transparent frames), a folder of
    images or one image file."""

    def __init__(self, backgrounds="builtin", max_files: int = DEFAULT_MAX_FILES):
        self.kind, self.folder, self.files = "builtin", None, []
        if backgrounds in (None, "none"):
            self.kind = "none"
        elif backgrounds != "builtin":
            path = Path(str(backgrounds))
            if path.is_file():
                self.kind, self.folder, self.files = "folder", str(path.resolve().parent), [path.name]
            elif path.is_dir():
                self.kind, self.folder = "folder", str(path.resolve())
                self.files = list_images(path, max_files)
            else:
                raise InputError(f"backgrounds: {backgrounds!r} is neither 'builtin', 'none', a folder nor an image")
            if len(self.files) == 1:           # its only image: one that does not decode is refused now, as render does
                decode_image(str(Path(self.folder) / self.files[0]))

    def describe(self) -> dict:
        return {"kind": self.kind, "folder": self.folder, "images": len(self.files) or None}

    def sample(self, u: np.ndarray) -> dict | None:
        """The background spec of a frame from UNIFORMS uniforms u, or None (no background)."""
        if self.kind == "none":
            return None
        spec = {"zoom": round(ZOOM_RANGE[0] + (ZOOM_RANGE[1] - ZOOM_RANGE[0]) * float(u[1]), 4),
                "centre": [round(float(u[2]), 4), round(float(u[3]), 4)], "flip": bool(u[4] < 0.5),
                "builtin": min(int(u[0] * BUILTIN_COUNT), BUILTIN_COUNT - 1)}
        if self.kind == "folder":
            n = len(self.files)
            k = min(int(u[0] * n), n - 1)
            spec = {"folder": self.folder, "files": [self.files[(k + j) % n] for j in range(min(CANDIDATES, n))],
                    **spec}
        return spec


# ------------------------------------------------------------------------------------------------ rendering

_CACHE: OrderedDict = OrderedDict()
_CACHE_SIZE = [0]


def background_pixels(spec: dict, width: int, height: int) -> tuple[np.ndarray, dict]:
    """((height, width, 3) float32 linear background, {'used': file or 'builtin:<id>', 'skipped': [files that did
    not decode]}) of a background spec; a spec with 'color' (linear RGB) is that plain colour."""
    if "color" in spec:
        color = np.asarray(spec["color"], np.float32)
        return np.broadcast_to(color, (height, width, 3)).copy(), {"used": "color", "skipped": []}
    skipped = []
    for name in spec.get("files", []):
        path = str(Path(spec["folder"]) / name)
        try:
            image = _cached(("file", path), lambda path=path: decode_image(path))
        except InputError:
            skipped.append(name)
            continue
        return crop(image, spec, width, height), {"used": name, "skipped": skipped}
    k = int(spec["builtin"])
    image = _cached(("builtin", k), lambda: builtin_background(k))
    return crop(image, spec, width, height), {"used": f"builtin:{k}", "skipped": skipped}


def _cached(key, make) -> np.ndarray:
    if key in _CACHE:
        _CACHE.move_to_end(key)
        return _CACHE[key]
    image = make()
    _CACHE[key] = image
    _CACHE_SIZE[0] += image.nbytes
    while len(_CACHE) > 1 and _CACHE_SIZE[0] > CACHE_BYTES:
        _CACHE_SIZE[0] -= _CACHE.popitem(last=False)[1].nbytes
    return image


def decode_image(path: str) -> np.ndarray:
    """(H, W, 3) float32 linear pixels of an image file (8-bit files are sRGB, float files linear), box-downscaled
    so its longer side is at most MAX_DECODE_SIDE; InputError when it cannot be read completely."""
    import OpenImageIO as oiio

    try:
        with native_stderr_captured():         # libpng prints its own line for a damaged file: ours says it
            buf = oiio.ImageBuf(path)
            spec = buf.spec()
            pixels = None if buf.has_error else buf.get_pixels(oiio.FLOAT)
    except Exception as e:                  # OpenImageIO raises plain exceptions for unreadable files
        raise InputError(f"{path}: cannot read background image: {_first_line(str(e))}") from None
    if pixels is None or buf.has_error or pixels.ndim != 3 or not pixels.size:
        raise InputError(f"{path}: cannot read background image: {_first_line(buf.geterror()) or 'no pixels'} "
                         "(truncated or corrupt)")
    if not np.isfinite(pixels).all():
        raise InputError(f"{path}: background image has non-finite pixels")
    channels = pixels.shape[2]
    rgb = np.repeat(pixels[..., :1], 3, axis=2) if channels < 3 else pixels[..., :3]
    if spec.format in (oiio.UINT8, oiio.UINT16):
        rgb = srgb_to_linear(np.clip(rgb, 0, 1))
    factor = -(-max(rgb.shape[:2]) // MAX_DECODE_SIDE)
    if factor > 1:
        rgb = box_downscale(rgb, factor)
    return np.ascontiguousarray(rgb, np.float32)


def _first_line(text: str) -> str:
    """The first line of an OpenImageIO error (its decoders add libpng's own lines after it)."""
    return (text.strip().splitlines() or [""])[0]


def box_downscale(image: np.ndarray, factor: int) -> np.ndarray:
    """(H // f, W // f, C) means of f x f blocks (the remainder rows and columns are dropped)."""
    h, w = image.shape[0] // factor * factor, image.shape[1] // factor * factor
    blocks = image[:h, :w].reshape(h // factor, factor, w // factor, factor, -1)
    return blocks.mean(axis=(1, 3), dtype=np.float32)


def crop(image: np.ndarray, spec: dict, width: int, height: int) -> np.ndarray:
    """The spec's window of `image`, resampled to (height, width, 3): the largest window of the frame's aspect
    ratio, shrunk by 'zoom', placed at 'centre' (fractions of the free room), mirrored with 'flip'; box-filtered
    first when it is more than twice the frame's size, then bilinear (one compiled pass)."""
    sh, sw = image.shape[:2]
    aspect = width / height
    cw, ch = (sh * aspect, sh) if sw / sh > aspect else (sw, sw / aspect)
    zoom = max(1.0, float(spec.get("zoom", 1.0)))
    cw, ch = cw / zoom, ch / zoom
    cx, cy = spec.get("centre", (0.5, 0.5))
    x0, y0 = (sw - cw) * float(cx), (sh - ch) * float(cy)
    factor = int(min(cw / width, ch / height) // 2)
    if factor >= 2:
        r0, c0 = int(y0), int(x0)
        region = image[r0:min(sh, r0 + int(ch) + factor), c0:min(sw, c0 + int(cw) + factor)]
        image, x0, y0, cw, ch = box_downscale(region, factor), (x0 - c0) / factor, (y0 - r0) / factor, \
            cw / factor, ch / factor
        sh, sw = image.shape[:2]
    xs = np.clip(x0 + (np.arange(width) + 0.5) * (cw / width) - 0.5, 0, sw - 1)
    ys = np.clip(y0 + (np.arange(height) + 0.5) * (ch / height) - 0.5, 0, sh - 1)
    if spec.get("flip"):
        xs = xs[::-1]
    x_lo, y_lo = np.floor(xs).astype(np.int64), np.floor(ys).astype(np.int64)
    x_hi, y_hi = np.minimum(x_lo + 1, sw - 1), np.minimum(y_lo + 1, sh - 1)
    fx, fy = (xs - x_lo).astype(np.float32), (ys - y_lo).astype(np.float32)
    out = np.empty((height, width, image.shape[2]), np.float32)
    _bilinear_kernel(np.ascontiguousarray(image), y_lo, y_hi, fy, np.ascontiguousarray(x_lo),
                     np.ascontiguousarray(x_hi), np.ascontiguousarray(fx), out)
    return out


@kernel
def _bilinear_kernel(image, y_lo, y_hi, fy, x_lo, x_hi, fx, out):
    """out (h, w, C) float32: image (H, W, C) (float32, or float64: the built-in stripes) read bilinearly at rows
    y_lo + fy (h,) and columns x_lo + fx (w,), the next row and column being y_hi and x_hi; the rows blended first, then
    the columns (float32, in the order of the separable numpy resampling it replaced; float64 for a float64 image)."""
    for i in range(out.shape[0]):
        a, b, f = y_lo[i], y_hi[i], fy[i]
        for j in range(out.shape[1]):
            left, right, g = x_lo[j], x_hi[j], fx[j]
            for k in range(out.shape[2]):
                lo = image[a, left, k]
                lo = lo + (image[b, left, k] - lo) * f
                hi = image[a, right, k]
                hi = hi + (image[b, right, k] - hi) * f
                out[i, j, k] = lo + (hi - lo) * g


# ------------------------------------------------------------------------------------------------ built-in set


def builtin_background(k: int, size: int = BUILTIN_SIZE) -> np.ndarray:
    """(size, size, 3) float32 linear built-in background number k: by k mod 4 a smooth colour field, a clutter of
    soft-edged rectangles, stripes, or a gradient with blobs, with a little grain. The smooth kinds are made at a
    quarter of the size and upsampled (they have no detail to lose), so one costs tens of milliseconds."""
    rng = np.random.default_rng([BUILTIN_SEED, int(k)])
    palette = _muted_colours(rng, 5)
    kind = int(k) % 4
    if kind == 1:
        image = _clutter(rng, size, palette)
    else:
        small = size // 4
        make = {0: _colour_field, 2: _stripes, 3: _gradient_blobs}[kind]
        image = crop(make(rng, small, palette), {}, size, size)
    image *= 1 + 0.04 * rng.standard_normal((size, size, 1), dtype=np.float32)
    return np.ascontiguousarray(np.clip(image, 0, 1), np.float32)


def _muted_colours(rng, n: int) -> np.ndarray:
    """(n, 3) linear colours: hue anywhere, moderate saturation and value (rooms, walls, fabric, foliage)."""
    import colorsys

    out = []
    for _ in range(n):
        h, s, v = rng.random(), rng.uniform(0.1, 0.6), rng.uniform(0.2, 0.9)
        out.append([c ** 2.2 for c in colorsys.hsv_to_rgb(h, s, v)])
    return np.array(out, np.float32)


def _value_noise(rng, size: int, cells: int) -> np.ndarray:
    """(size, size) smooth noise in [-1, 1]: a cells x cells random grid, bilinearly upsampled."""
    grid = rng.uniform(-1, 1, (cells + 1, cells + 1, 1)).astype(np.float32)
    return crop(grid, {}, size, size)[..., 0]


def _colour_field(rng, size, palette) -> np.ndarray:
    weights = np.stack([sum(_value_noise(rng, size, c) / c ** 0.5 for c in (2, 5, 11)) for _ in palette], -1)
    weights = np.exp(3 * weights)
    return (weights / weights.sum(-1, keepdims=True)) @ palette


def _clutter(rng, size, palette) -> np.ndarray:
    image = np.empty((size, size, 3), np.float32)
    image[:] = palette[0]
    for _ in range(int(rng.integers(12, 30))):
        x0, y0 = rng.random(2) * size
        w, h = rng.uniform(0.05, 0.5, 2) * size
        soft = rng.uniform(0.002, 0.02) * size
        c0, c1 = int(max(0, x0)), int(min(size, x0 + w + 1))
        r0, r1 = int(max(0, y0)), int(min(size, y0 + h + 1))
        if c1 <= c0 or r1 <= r0:
            continue
        x = np.arange(c0, c1, dtype=np.float32)[None, :]
        y = np.arange(r0, r1, dtype=np.float32)[:, None]
        inside = (_ramp((x - x0) / soft) * _ramp((x0 + w - x) / soft) * _ramp((y - y0) / soft)
                  * _ramp((y0 + h - y) / soft))[..., None]
        shade = 1 + 0.3 * ((y - y0) / size)[..., None] * rng.uniform(-1, 1)
        region = image[r0:r1, c0:c1]
        region *= 1 - inside
        region += inside * palette[rng.integers(len(palette))] * shade
    return image


def _stripes(rng, size, palette) -> np.ndarray:
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    angle = rng.uniform(0, np.pi)
    t = x * np.cos(angle) + y * np.sin(angle) + 0.05 * _value_noise(rng, size, 6)
    k = rng.uniform(4, 30)
    mix = (0.5 + 0.5 * np.sin(2 * np.pi * k * t))[..., None]
    return palette[0] * mix + palette[1] * (1 - mix)


def _gradient_blobs(rng, size, palette) -> np.ndarray:
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    image = palette[0] * (1 - y[..., None]) + palette[1] * y[..., None]
    for _ in range(int(rng.integers(3, 9))):
        cx, cy, r = rng.random(), rng.random(), rng.uniform(0.05, 0.3)
        blob = np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * r * r))[..., None]
        image = image * (1 - blob) + palette[rng.integers(2, len(palette))] * blob
    return image


def _ramp(x: np.ndarray) -> np.ndarray:
    return np.clip(x, 0, 1)
