"""Contact sheet: every variant as a thumbnail of the textured hand (back and palm views), grouped by category
under a header, each labelled with its tone, number and what it shows, so a person can see the catalogue at a
glance.

Previews are orthographic renders of the rest-pose mesh with a simple lambert term so the shape reads; the
shading is the preview's only, never part of an albedo. Thumbnails sample a small copy of each albedo.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from darthand.textures.imageio import write_png
from darthand.textures.raster import rasterize

BACKGROUND = np.array([52, 54, 58], np.uint8)
HEADER = np.array([30, 31, 34], np.uint8)
LABEL_HEIGHT = 20
HEADER_HEIGHT = 34
TILE = 240
COLUMNS = 12
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


def preview_maps(mesh: dict, tile: int = TILE) -> PreviewMaps:
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
        uv_all.append(uv)
        shade_all.append(shade)
    return PreviewMaps(w, 2 * h, np.concatenate(pixels), np.concatenate(uv_all), np.concatenate(shade_all))


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


def describe(record: dict) -> str:
    """A tile's label: tone and number, and what the variant shows (a tattoo's motif, a scar's kind, ...)."""
    p = record.get("params", {}).get(record["category"], {})
    what = p.get("motif") or p.get("kind") or p.get("style") or p.get("polish") or ""
    if record.get("kind") == "base_variation":
        what = record["category"].replace("_", " ")
    if isinstance(what, str) and what:
        what = " " + what.replace("_", " ")
    return f"{record['tone']} {record['index']:02d}{what}"


def group_name(record: dict) -> str:
    """The sheet section of a catalogue record: its overlay category, or 'base variations'."""
    return "base variations" if record.get("kind") == "base_variation" else record["category"].replace("_", " ")


def contact_sheet(tiles: list[tuple[str, str, np.ndarray]], path: str | Path, columns: int = COLUMNS) -> np.ndarray:
    """Lay out (group, label, tile image) triples in catalogue order: each group starts a new row under a header
    with its name and size, each tile has its label below. Writes the PNG atomically and returns the sheet
    (H, W, 3) uint8."""
    if not tiles:
        raise ValueError("contact sheet needs at least one tile")
    th, tw = tiles[0][2].shape[:2]
    groups: dict[str, list] = {}
    for group, label, img in tiles:
        groups.setdefault(group, []).append((label, img))
    columns = min(columns, max(len(g) for g in groups.values()))
    cell_h = th + LABEL_HEIGHT
    height = sum(HEADER_HEIGHT + -(-len(g) // columns) * cell_h for g in groups.values())
    sheet = np.tile(BACKGROUND, (height, columns * tw, 1))
    texts, y = [], 0
    for group, members in groups.items():
        sheet[y:y + HEADER_HEIGHT] = HEADER
        texts.append((8, y + HEADER_HEIGHT - 9, f"{group} ({len(members)})", 22, [1.0, 1.0, 1.0]))
        y += HEADER_HEIGHT
        for i, (label, img) in enumerate(members):
            r, c = divmod(i, columns)
            top = y + r * cell_h
            sheet[top:top + th, c * tw:(c + 1) * tw] = img
            texts.append((c * tw + 4, top + th + LABEL_HEIGHT - 5, label, 14, [0.85, 0.85, 0.85]))
        y += -(-len(members) // columns) * cell_h
    buf = oiio.ImageBuf(oiio.ImageSpec(sheet.shape[1], sheet.shape[0], 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(sheet))
    for x, y, text, size, colour in texts:
        oiio.ImageBufAlgo.render_text(buf, x, y, text, size, "DroidSans", colour)
    sheet = buf.get_pixels(oiio.UINT8)
    if sheet is None:
        raise RuntimeError(f"OpenImageIO could not draw the contact sheet's labels: {buf.geterror()}")
    write_png(path, sheet)
    return sheet
