"""The per-variant working state: pigment changes, paint layers and roughness over the N baked texels.

Skin effects add to the pigment densities (see `color`); things on or in the skin (ink, polish, bandage) are
paint layers composited in order over the skin colour. `finish()` turns it all into linear albedo and roughness.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from darthand.textures import color
from darthand.textures.bake import Bake

SKIN_ROUGHNESS = 0.5  # back of the hand; palms and pads are rougher (see `base_roughness`)


@functools.lru_cache(maxsize=2)   # the same for every variant of a bake: computed once per worker, copied per canvas
def base_roughness(bake: Bake) -> np.ndarray:
    """Skin roughness (N,) float32, read-only: a function of anatomy only (rougher palm side, fine variation from
    the fixed noise bank), so every variant whose overlays leave roughness alone shares one roughness map."""
    r = SKIN_ROUGHNESS + 0.12 * bake.fields["palmar"] + 0.03 * bake.fields["noise_fine0"]
    r = np.clip(r, 0.3, 0.8).astype(np.float32)
    r.setflags(write=False)
    return r


@dataclass
class Paint:
    """One layer on `index` (n,) texels: colour (n, 3) or (3,) linear, coverage alpha (n,), composited 'over'
    the layers below or 'multiply' (ink in the skin), optionally setting roughness (n,) or scalar."""

    index: np.ndarray
    rgb: np.ndarray
    alpha: np.ndarray
    mode: str = "over"
    roughness: np.ndarray | float | None = None


@dataclass
class Canvas:
    """Pigment fields dm, dh, dv (N,) float32, paint layers and roughness (N,) of one variant on one bake."""

    bake: Bake
    tone_rgb: np.ndarray  # linear (3,)
    melanin: float  # the tone's own melanin density m0
    dm: np.ndarray = field(init=False)
    dh: np.ndarray = field(init=False)
    dv: np.ndarray = field(init=False)
    roughness: np.ndarray = field(init=False)
    paints: list = field(default_factory=list)

    def __post_init__(self):
        n = self.bake.num_texels
        self.dm = np.zeros(n, np.float32)
        self.dh = np.zeros(n, np.float32)
        self.dv = np.zeros(n, np.float32)
        self.roughness = base_roughness(self.bake).copy()

    @property
    def n(self) -> int:
        return self.bake.num_texels

    @property
    def pigment_scale(self) -> float:
        """Melanin density that pigment marks (freckles, moles, creases) are scaled by: the tone's melanin, but
        never so little that marks vanish on the lightest skin."""
        return max(self.melanin, 0.45)

    def field(self, name: str) -> np.ndarray:
        """A baked field as float32."""
        return self.bake.fields[name].astype(np.float32, copy=False)

    def paint(self, index, rgb, alpha, mode: str = "over", roughness=None) -> None:
        index = np.asarray(index)
        if len(index):
            self.paints.append(Paint(index, np.asarray(rgb, np.float32), np.asarray(alpha, np.float32), mode,
                                     roughness))

    def finish(self) -> tuple[np.ndarray, np.ndarray]:
        """Linear albedo (N, 3) float32 and roughness (N,) float32."""
        rgb = color.pigment_albedo(self.tone_rgb, self.dm, self.dh, self.dv)
        rough = self.roughness.copy()
        for p in self.paints:
            a = np.clip(p.alpha, 0.0, 1.0)[:, None]
            under = rgb[p.index]
            if p.mode == "multiply":
                rgb[p.index] = under * (1.0 - a + a * p.rgb)
            else:
                rgb[p.index] = under * (1.0 - a) + a * p.rgb
            if p.roughness is not None:
                rough[p.index] = rough[p.index] * (1.0 - a[:, 0]) + a[:, 0] * p.roughness
        return rgb, np.clip(rough, 0.02, 1.0)
