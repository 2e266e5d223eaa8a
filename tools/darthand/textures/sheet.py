"""Contact sheet: every variant as a thumbnail of the textured hand (back and palm views), so a person can see
the catalogue at a glance.

Previews are orthographic renders of the rest-pose mesh with a simple lambert term so the shape reads; the
shading is the preview's only, never part of an albedo. Thumbnails sample a small copy of each albedo.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.textures.raster import rasterize

BACKGROUND = np.array([52, 54, 58], np.uint8)
LABEL_HEIGHT = 14
SUPERSAMPLE = 2


@dataclass(frozen=True)
class PreviewMaps:
    """Per-pixel lookups of one tile (height x width at SUPERSAMPLE x): covered pixel indices, their UVs (M, 2)
    and shading (M,)."""

    width: int
    height: int
    pixel: np.ndarray
    uv: np.ndarray
    shade: np.ndarray


def preview_maps(mesh: dict, tile: int = 160) -> PreviewMaps:
    """Back view (top half) and palm view (bottom half) of the mesh, fingers to the left, in a tile x tile
    square (before the label strip)."""
    w, h = tile * SUPERSAMPLE, (tile // 2) * SUPERSAMPLE
    v, f = mesh["vertices"], mesh["faces"]
    uvs, fuv, vn = mesh["uvs"], mesh["faces_uv"], mesh["vertex_normals"]
    lo, hi = v.min(0), v.max(0)
    scale = 0.94 * min(w / (hi[0] - lo[0]), h / (hi[2] - lo[2]))
    centre = 0.5 * (lo + hi)
    pixels, uv_all, shade_all = [], [], []
    for row, (up_sign, depth_sign) in enumerate(((-1.0, -1.0), (1.0, 1.0))):  # back: looking down -Y; palm: up
        x = (v[:, 0] - centre[0]) * scale + w / 2
        y = -(up_sign * (v[:, 2] - centre[2])) * scale + h / 2
        tri = np.stack([x, y], 1)[f]
        frags = rasterize(tri, w, h, depth=depth_sign * v[f][..., 1])
        bary = frags.bary
        uv = np.einsum("nk,nki->ni", bary, uvs[fuv[frags.face]])
        n = np.einsum("nk,nki->ni", bary, vn[f[frags.face]])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        light = np.array([0.25, -depth_sign, 0.35 * up_sign])
        light /= np.linalg.norm(light)
        shade = 0.3 + 0.7 * np.clip(n @ light, 0.0, 1.0)
        r, c = np.divmod(frags.pixel, w)
        pixels.append((r + row * h) * w + c)
        uv_all.append(uv), shade_all.append(shade)
    return PreviewMaps(w, 2 * h, np.concatenate(pixels), np.concatenate(uv_all), np.concatenate(shade_all))


def small_copy(albedo: np.ndarray, size: int = 256) -> np.ndarray:
    """Block-mean downsample of a square (res, res, 3) uint8 image to (size, size, 3) uint8 (res >= size)."""
    res = albedo.shape[0]
    if res <= size:
        return albedo
    k = res // size
    return albedo[:size * k, :size * k].reshape(size, k, size, k, 3).mean(axis=(1, 3)).round().astype(np.uint8)


def thumbnail(albedo: np.ndarray, maps: PreviewMaps) -> np.ndarray:
    """(tile, tile, 3) uint8 preview of a hand textured with `albedo` (any square size, sRGB uint8)."""
    res = albedo.shape[0]
    img = albedo.astype(np.float32)
    x = np.clip(maps.uv[:, 0] * res - 0.5, 0, res - 1)
    y = np.clip((1.0 - maps.uv[:, 1]) * res - 0.5, 0, res - 1)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    x1, y1 = np.minimum(x0 + 1, res - 1), np.minimum(y0 + 1, res - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    col = ((img[y0, x0] * (1 - fx) + img[y0, x1] * fx) * (1 - fy) + (img[y1, x0] * (1 - fx) + img[y1, x1] * fx) * fy)
    # Shade in linear light, as a renderer would.
    lin = (col / 255.0) ** 2.2 * maps.shade[:, None]
    out = np.tile(BACKGROUND.astype(np.float32), (maps.height * maps.width, 1))
    out[maps.pixel] = np.clip(lin, 0, 1) ** (1 / 2.2) * 255.0
    out = out.reshape(maps.height // SUPERSAMPLE, SUPERSAMPLE, maps.width // SUPERSAMPLE, SUPERSAMPLE, 3)
    return out.mean(axis=(1, 3)).round().astype(np.uint8)


def contact_sheet(tiles: list[tuple[str, np.ndarray]], path: str | Path, columns: int = 18) -> np.ndarray:
    """Lay out (label, tile image) pairs in a grid with a label strip under each; write the PNG atomically and
    return the sheet (H, W, 3) uint8."""
    from darthand.textures.imageio import write_png

    if not tiles:
        raise ValueError("contact sheet needs at least one tile")
    th, tw = tiles[0][1].shape[:2]
    columns = min(columns, len(tiles))
    rows = (len(tiles) + columns - 1) // columns
    cell_h = th + LABEL_HEIGHT
    sheet = np.tile(BACKGROUND, (rows * cell_h, columns * tw, 1))
    for i, (_, img) in enumerate(tiles):
        r, c = divmod(i, columns)
        sheet[r * cell_h:r * cell_h + th, c * tw:(c + 1) * tw] = img
    buf = oiio.ImageBuf(oiio.ImageSpec(sheet.shape[1], sheet.shape[0], 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(sheet))
    for i, (label, _) in enumerate(tiles):
        r, c = divmod(i, columns)
        oiio.ImageBufAlgo.render_text(buf, c * tw + 3, r * cell_h + th + LABEL_HEIGHT - 3, label, 10,
                                      "DroidSans", [0.85, 0.85, 0.85])
    sheet = buf.get_pixels(oiio.UINT8)
    write_png(path, sheet)
    return sheet
