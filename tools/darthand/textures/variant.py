"""One catalogue variant: a pure function of (baked maps, catalogue entry) -> sRGB albedo and roughness images.

Maths in linear light on the N baked texels; the sRGB offset and 8-bit quantisation come last, then the padding
(push-pull through the bake's shared block layout).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from darthand.textures import color
from darthand.textures.bake import Bake
from darthand.textures.canvas import Canvas
from darthand.textures.catalog import Entry
from darthand.textures.overlays import OVERLAYS
from darthand.textures.skin import BASE_VARIATIONS, apply_base
from darthand.textures.surface import Surface


@dataclass(frozen=True)
class Variant:
    """Images of one entry: albedo (res, res, 3) uint8 sRGB, roughness (res, res) uint8 (linear 0..255)."""

    entry: Entry
    albedo: np.ndarray
    roughness: np.ndarray


def render_texels(bake: Bake, entry: Entry, overlay: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Linear albedo (N, 3) float32 and roughness (N,) float32 of `entry` at the bake's texels (no offset);
    with `overlay=False` only the entry's base skin (its category's overlay or variation left out)."""
    tone = color.srgb_to_linear(np.asarray(entry.tone_srgb, np.float32))
    canvas = Canvas(bake, tone, color.tone_melanin(tone))
    surface = Surface(bake)
    # Separate streams for the base and the category: a category's draws never shift the base's noise.
    apply_base(canvas, surface, entry.params["skin"], np.random.default_rng([entry.seed, 1]))
    if overlay:
        apply = (OVERLAYS.get(entry.category) or BASE_VARIATIONS[entry.category])[1]
        apply(canvas, surface, entry.params[entry.category], np.random.default_rng([entry.seed, 2]))
    return canvas.finish()


def render_variant(bake: Bake, entry: Entry) -> Variant:
    """The padded images of `entry` at the bake's resolution."""
    rgb, rough = render_texels(bake, entry)
    albedo = color.encode_srgb8(rgb, entry.offset)
    rough8 = (rough * np.float32(255.0) + np.float32(0.5)).astype(np.uint8)
    return Variant(entry, bake.image(albedo), bake.image(rough8))
