"""Colour: sRGB transfer functions, the skin-tone scale, and a two-pigment skin model in linear light.

Skin albedo is modelled as a tone colour filtered by changes in two pigments, Beer-Lambert style:

    albedo = tone_rgb * exp(-(dm * SIGMA_MELANIN + dh * SIGMA_BLOOD + dv * SIGMA_VEIN))

dm, dh, dv are per-texel changes in melanin, blood and deep-vein density (dimensionless optical depths); the
tone's own melanin `m0` (fitted from its colour against melanin-free skin) sets how far a palm can lighten.
Albedo is never lit: no shading, no occlusion, no highlights.
"""

from __future__ import annotations

import functools

import numpy as np

from darthand.jit import kernel

# Relative absorbance per unit density in linear R, G, B (melanin: fitted to the ramp of the tone scale itself,
# so removing melanin walks back along the scale; haemoglobin mostly
# green; deep veins show through as a loss of red).
SIGMA_MELANIN = np.array([0.7, 0.9, 1.1], np.float32)
SIGMA_BLOOD = np.array([0.12, 1.0, 0.70], np.float32)
SIGMA_VEIN = np.array([0.75, 0.35, 0.05], np.float32)
# Skin without melanin (linear): the reference the tone's melanin is measured against.
MELANIN_FREE = np.array([0.93, 0.75, 0.66], np.float32)


def srgb_to_linear(c):
    """sRGB-encoded values in [0, 1] -> linear light (IEC 61966-2-1)."""
    c = np.asarray(c, np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(c):
    """Linear light -> sRGB-encoded values (inputs clipped to [0, 1])."""
    c = np.clip(np.asarray(c, np.float32), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055).astype(np.float32)


def hex_to_srgb(h: str) -> np.ndarray:
    """'#rrggbb' -> (3,) float32 sRGB in [0, 1]."""
    h = h.lstrip("#")
    return np.array([int(h[i:i + 2], 16) / 255.0 for i in (0, 2, 4)], np.float32)


def luminance(linear_rgb) -> np.ndarray:
    """Relative luminance (Rec. 709 primaries) of linear RGB (..., 3)."""
    return np.asarray(linear_rgb, np.float32) @ np.array([0.2126, 0.7152, 0.0722], np.float32)


def tone_color(mst: float, anchors_srgb) -> np.ndarray:
    """Linear RGB (3,) of the skin tone at `mst` on a 10-step scale (1 lightest .. 10 darkest), interpolated in
    linear light between the scale's sRGB anchors (10, 3); values outside 1..10 are clamped."""
    anchors = srgb_to_linear(np.asarray(anchors_srgb, np.float32))
    x = float(np.clip(mst, 1.0, float(len(anchors)))) - 1.0
    i = min(int(np.floor(x)), len(anchors) - 2)
    t = x - i
    return ((1 - t) * anchors[i] + t * anchors[i + 1]).astype(np.float32)


def tone_melanin(tone_rgb) -> float:
    """Melanin density m0 of a tone: least squares of -log(tone / MELANIN_FREE) = m0 SIGMA_M + h0 SIGMA_B."""
    y = -np.log(np.maximum(np.asarray(tone_rgb, np.float64), 1e-4) / MELANIN_FREE)
    a = np.stack([SIGMA_MELANIN, SIGMA_BLOOD], 1).astype(np.float64)
    (m0, _), *_ = np.linalg.lstsq(a, y, rcond=None)
    return float(max(m0, 0.0))


def pigment_albedo(tone_rgb, dm, dh, dv) -> np.ndarray:
    """(N, 3) float32 linear albedo of a tone under per-texel pigment changes dm, dh, dv (N,)."""
    tone = np.asarray(tone_rgb, np.float32)
    out = np.empty((len(dm), 3), np.float32)
    for c in range(3):  # one channel at a time: three passes over (N,) instead of (N, 3) temporaries
        depth = np.float32(SIGMA_MELANIN[c]) * dm
        depth += np.float32(SIGMA_BLOOD[c]) * dh
        depth += np.float32(SIGMA_VEIN[c]) * dv
        np.exp(-depth, out=depth)
        depth *= tone[c]
        out[:, c] = np.minimum(depth, np.float32(0.95))
    return out


_LUT_BITS = 16


def encode_srgb8(linear_rgb, offset: float = 0.0) -> np.ndarray:
    """Linear RGB -> 8-bit sRGB, after adding the global skin-tone `offset` to the sRGB-encoded values.

    Through a 65536-entry lookup table on the linear value (one step is far below an 8-bit sRGB step), so the
    transfer function is evaluated 65536 times (once per offset) rather than per texel; one compiled pass."""
    values = np.asarray(linear_rgb, np.float32, order="C")
    out = np.empty(values.shape, np.uint8)
    encode_srgb8_into(values.reshape(-1), srgb8_table(float(offset)), out.reshape(-1))
    return out


@kernel
def encode_srgb8_into(values, table, out):
    """out (N,) uint8 = table[index of values (N,) float32 clipped to [0, 1] on the table's 65536 steps] (rounded to
    the nearest step; NaN reads step 0): the sRGB codes of linear values through srgb8_table."""
    top, half = np.float32(len(table) - 1), np.float32(0.5)
    for i in range(values.size):
        v = values[i]
        if v > 1:
            v = np.float32(1.0)
        elif not v > 0:
            v = np.float32(0.0)
        out[i] = table[int(v * top + half)]


@functools.lru_cache(maxsize=16)
def srgb8_table(offset: float = 0.0) -> np.ndarray:
    """(65536,) uint8 sRGB code of each linear value step k / 65535, after the sRGB offset (encode_srgb8_into reads
    it)."""
    lin = np.linspace(0.0, 1.0, 1 << _LUT_BITS, dtype=np.float64)
    srgb = np.where(lin <= 0.0031308, lin * 12.92, 1.055 * lin ** (1 / 2.4) - 0.055) + offset
    return np.rint(np.clip(srgb, 0.0, 1.0) * 255.0).astype(np.uint8)
