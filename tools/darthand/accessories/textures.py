"""Procedural texture tiles for accessories: metals, stones, leather, fabric, watch dials, knit, engraving.

A tile is a pair (base_color (S, S, 3) linear RGB, metallic_roughness (S, S, 3) with glTF's channel layout: G
roughness, B metallic, R unused), float32 in [0, 1]. Row 0 is the top of the image; in UV terms v = 1 - row/S.
Colours are given in linear light (metal base colours are the usual measured F0 reflectances).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter

from darthand.accessories.mesh import ATLAS_SLOTS

# Linear base colours of the metals and stones the catalogue names.
METALS = {
    "gold": (1.000, 0.766, 0.336), "rose_gold": (0.955, 0.650, 0.540), "silver": (0.972, 0.960, 0.915),
    "platinum": (0.672, 0.637, 0.585), "steel": (0.560, 0.570, 0.580), "titanium": (0.542, 0.497, 0.449),
    "copper": (0.955, 0.637, 0.538), "black_steel": (0.060, 0.060, 0.065),
}
STONES = {
    "diamond": (0.90, 0.92, 0.95), "ruby": (0.55, 0.02, 0.05), "sapphire": (0.03, 0.08, 0.55),
    "emerald": (0.02, 0.40, 0.12), "onyx": (0.015, 0.015, 0.018), "amethyst": (0.30, 0.08, 0.45),
    "topaz": (0.85, 0.45, 0.08),
}


def noise(rng: np.random.Generator, size: int, sigma: float) -> np.ndarray:
    """(size, size) tileable smooth noise, zero mean, unit standard deviation."""
    n = gaussian_filter(rng.standard_normal((size, size)), sigma, mode="wrap")
    return (n - n.mean()) / (n.std() + 1e-12)


def flat(color, roughness: float, metallic: float, size: int) -> tuple[np.ndarray, np.ndarray]:
    base = np.broadcast_to(np.asarray(color, np.float32), (size, size, 3)).copy()
    return base, _mr(np.full((size, size), roughness), np.full((size, size), metallic))


def _mr(roughness: np.ndarray, metallic: np.ndarray) -> np.ndarray:
    out = np.zeros(roughness.shape + (3,), np.float32)
    out[..., 1] = np.clip(roughness, 0.02, 1.0)
    out[..., 2] = np.clip(metallic, 0.0, 1.0)
    return out


def metal(color, rng, size: int, roughness: float = 0.25, brushed: bool = True):
    """A metal: its colour with faint variation; roughness streaked along u (brushed) or mottled (polished)."""
    base, mr = flat(color, roughness, 1.0, size)
    if brushed:
        streak = gaussian_filter(rng.standard_normal((size, size)), (0.6, size / 8), mode="wrap")
        streak /= streak.std() + 1e-12
    else:
        streak = noise(rng, size, size / 16)
    mr[..., 1] = np.clip(roughness + 0.05 * streak, 0.02, 1.0)
    base *= (1.0 + 0.03 * noise(rng, size, size / 12))[..., None]
    return np.clip(base, 0, 1), mr


def stone(color, rng, size: int):
    base, mr = flat(color, 0.05, 0.0, size)
    base *= (1.0 + 0.08 * noise(rng, size, size / 10))[..., None]
    return np.clip(base, 0, 1), mr


def leather(color, rng, size: int, stitch_color=(0.8, 0.75, 0.6)):
    """Grain (fine noise) and, unless `stitch_color` is None, two stitch lines across v (on a strap's outer face,
    v running around its cross-section)."""
    grain = noise(rng, size, 1.2) * 0.5 + noise(rng, size, 4.0) * 0.5
    base = np.asarray(color, np.float32) * (1.0 + 0.12 * grain)[..., None]
    rough = 0.55 + 0.08 * grain
    v = 1.0 - (np.arange(size) + 0.5)[:, None] / size
    u = (np.arange(size) + 0.5)[None, :] / size
    dash = (np.sin(2 * np.pi * 48 * u) > 0.2)
    for line in (0.30, 0.45) if stitch_color is not None else ():
        on = (np.abs(v - line) < 0.012) & dash
        base[on] = stitch_color
    return np.clip(base, 0, 1), _mr(rough, np.zeros_like(rough))


def fabric(color_a, color_b, rng, size: int, stripes: int = 3):
    """A woven strap: a plain weave of two threads and `stripes` coloured stripes across v."""
    u = (np.arange(size) + 0.5)[None, :] / size
    v = 1.0 - (np.arange(size) + 0.5)[:, None] / size
    weave = 0.5 + 0.5 * np.sign(np.sin(2 * np.pi * 64 * u) * np.sin(2 * np.pi * 24 * v))
    stripe = (np.floor(v * (2 * stripes + 1)) % 2 == 1)
    col = np.where(stripe[..., None], np.asarray(color_b, np.float32), np.asarray(color_a, np.float32))
    base = col * (0.82 + 0.18 * weave)[..., None] * (1 + 0.05 * noise(rng, size, 2.0))[..., None]
    base = np.broadcast_to(base, (size, size, 3))
    rough = np.full((size, size), 0.85)
    return np.clip(base, 0, 1).astype(np.float32), _mr(rough, np.zeros_like(rough))


def stripes(colors, size: int, roughness: float = 0.3, metallic: float = 0.0):
    """Horizontal bands, one per colour, top to bottom (bead k of a bracelet maps into band k % len)."""
    rows = np.minimum((np.arange(size) * len(colors)) // size, len(colors) - 1)
    base = np.asarray(colors, np.float32)[rows][:, None, :].repeat(size, 1)
    return base, _mr(np.full((size, size), roughness), np.full((size, size), metallic))


def engraving(color, rng, size: int, roughness: float = 0.3, motif: str = "crest"):
    """A metal face with a darker, rougher engraved motif (rings of a crest, or a monogram-like cross)."""
    base, mr = metal(color, rng, size, roughness, brushed=False)
    y, x = np.mgrid[1:-1:size * 1j, -1:1:size * 1j]
    r = np.hypot(x, y)
    if motif == "crest":
        mask = (np.abs(r - 0.62) < 0.05) | ((r < 0.45) & ((np.abs(x) < 0.07) | (np.abs(y) < 0.07)))
    else:
        mask = (np.abs(r - 0.7) < 0.04) | ((np.abs(np.abs(x) - np.abs(y)) < 0.08) & (r < 0.5))
    base[mask] *= 0.35
    mr[mask, 1] = 0.7
    return base, mr


def dial(face, marker, hands, rng, size: int, style: str = "round"):
    """A watch dial: hour markers, minute track, hour/minute/second hands at a time drawn from `rng`.

    The image spans the case's top cap (12 o'clock up, 3 o'clock right); 2x supersampled for anti-aliasing.
    """
    ss = 2 * size
    y, x = np.mgrid[1:-1:ss * 1j, -1:1:ss * 1j]
    r = np.hypot(x, y)
    ang = np.arctan2(x, y)                       # clockwise from 12 o'clock
    img = np.broadcast_to(np.asarray(face, np.float32), (ss, ss, 3)).copy()
    img *= (1.0 + 0.04 * _upsample(noise(rng, size, size / 10), ss))[..., None]
    hour_sector = np.abs(((ang + np.pi / 12) % (np.pi / 6)) - np.pi / 12) * r
    minute_sector = np.abs(((ang + np.pi / 60) % (np.pi / 30)) - np.pi / 60) * r
    marks = ((r > 0.66) & (r < 0.86) & (hour_sector < 0.035)) | \
            ((r > 0.82) & (r < 0.86) & (minute_sector < 0.008)) | (np.abs(r - 0.9) < 0.006)
    img[marks] = marker
    hour, minute = rng.uniform(0, 12), rng.uniform(0, 60)
    second = rng.uniform(0, 60)
    for frac, length, width, col in ((hour / 12, 0.45, 0.035, hands), (minute / 60, 0.72, 0.025, hands),
                                     (second / 60, 0.80, 0.008, (0.6, 0.02, 0.02))):
        a = 2 * np.pi * frac
        d = np.array([np.sin(a), np.cos(a)])
        t = np.clip(x * d[0] + y * d[1], -0.12, length)
        dist = np.hypot(x - t * d[0], y - t * d[1])
        img[dist < width] = col
    img[r < 0.04] = hands
    base = img.reshape(size, 2, size, 2, 3).mean((1, 3))
    mr = _mr(np.full((size, size), 0.35), np.zeros((size, size)))
    return np.clip(base, 0, 1).astype(np.float32), mr


def knit(color, rng, size: int, rows: int = 90, cols: int = 140):
    """Stocking-stitch knit: rows of V-shaped loops over UV space (wool gloves)."""
    u = (np.arange(size) + 0.5)[None, :] / size
    v = 1.0 - (np.arange(size) + 0.5)[:, None] / size
    fu, fv = (u * cols) % 1.0, (v * rows) % 1.0
    loop = np.abs(np.abs(fu - 0.5) * 2 - fv)        # V shapes
    shade = 0.75 + 0.25 * np.clip(1 - 3 * loop, 0, 1)
    base = np.asarray(color, np.float32) * (shade * (1 + 0.06 * noise(rng, size, 3.0)))[..., None]
    rough = np.full((size, size), 0.95)
    return np.clip(base, 0, 1).astype(np.float32), _mr(rough, np.zeros_like(rough))


def rubber(color, rng, size: int, roughness: float = 0.45):
    """Latex/nitrile: an even colour with a faint sheen variation."""
    base, mr = flat(color, roughness, 0.0, size)
    base *= (1 + 0.03 * noise(rng, size, size / 20))[..., None]
    mr[..., 1] = np.clip(roughness + 0.05 * noise(rng, size, size / 30), 0.02, 1)
    return np.clip(base, 0, 1), mr


def atlas(tiles: dict[int, tuple[np.ndarray, np.ndarray]], size: int) -> dict[str, np.ndarray]:
    """Assemble per-slot tiles (each (size/2)^2) into the accessory's two textures (see mesh.ATLAS_SLOTS).

    Empty slots are filled with the first tile so mip-mapping never blends in black.
    """
    half = size // 2
    first = next(iter(tiles.values()))
    base = np.zeros((size, size, 3), np.float32)
    mr = np.zeros((size, size, 3), np.float32)
    for slot, (u0, _v0, _u1, v1) in ATLAS_SLOTS.items():
        b, m = tiles.get(slot, first)
        r0, c0 = int(round((1 - v1) * size)), int(round(u0 * size))
        base[r0:r0 + half, c0:c0 + half] = b
        mr[r0:r0 + half, c0:c0 + half] = m
    return {"base_color": base, "metallic_roughness": mr}


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def _upsample(img: np.ndarray, size: int) -> np.ndarray:
    k = size // img.shape[0]
    return np.kron(img, np.ones((k, k)))
