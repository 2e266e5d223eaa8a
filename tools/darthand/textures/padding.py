"""Push-pull padding: per-texel values at a bake's stored texels -> a full image whose empty texels hold block means.

Every texel that is not stored takes the mean of the stored texels in the smallest aligned 2^L x 2^L block around
it (the blocks of the image's own box mipmap). A box mipmap of the padded image (what Blender's EEVEE, three.js and
game engines build from a PNG) therefore mixes, in each block, only that block's stored colours, never the colours
of a neighbouring island, so UV seams do not bleed.

The layout (which texels are stored) is the same for every image of a bake, so what depends on it only -- the
stored-texel counts of every block and the masks of the blocks that hold none -- is built once (`Layout`); each
image is then one scatter, one pyramid of exact integer block sums, and one top-down pass that gives every empty
block its parent's value:

    padded_L = mean_L where block L holds stored texels, else upsample(padded_{L+1})   (L = top ... 0)

which is the smallest-block rule above, level by level. Means are float32 quotients of the exact sums, rounded to
the nearest code (half to even).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Layout:
    """The block structure of the stored texels of a res x res image (levels 0 = texels, 1 = 2 x 2 blocks, ...,
    up to one block; odd sides padded with empty texels).

    shape    (res, res)
    texel    (N,) flat indices (row * res + col) of the stored texels
    empty    per level, (h_L, w_L, 1) bool: the block holds no stored texel
    count    per level >= 1, (h_L, w_L, 1) float32: stored texels in the block, at least 1 (a divisor)
    """

    shape: tuple[int, int]
    texel: np.ndarray
    empty: list
    count: list
    _masks: dict = field(default_factory=dict, repr=False)

    @classmethod
    def of(cls, texel: np.ndarray, res: int) -> "Layout":
        stored = np.zeros(res * res, np.int32)
        stored[texel] = 1
        counts = [stored.reshape(res, res, 1)]
        while max(counts[-1].shape[:2]) > 1:
            counts.append(halve(counts[-1]))
        return cls(shape=(res, res), texel=np.asarray(texel), empty=[c == 0 for c in counts],
                   count=[None] + [np.maximum(c, 1).astype(np.float32) for c in counts[1:]])

    def fill_mask(self, level: int, channels: int) -> np.ndarray:
        """(h_L, w_L, channels) uint8: 255 in the blocks of `level` that hold no stored texel, else 0 (made once per
        level and channel count: a full-size mask, not a broadcast one, keeps the per-image pass a plain AND)."""
        key = (level, channels)
        if key not in self._masks:
            empty = self.empty[level]
            self._masks[key] = np.where(np.broadcast_to(empty, empty.shape[:2] + (channels,)), np.uint8(255),
                                        np.uint8(0))
        return self._masks[key]


def pad(layout: Layout, values: np.ndarray) -> np.ndarray:
    """(N, C) uint8 values at `layout.texel` -> (res, res, C) uint8 image: the stored texels exact, every other
    texel the rounded mean of the stored texels in the smallest aligned 2^L block around it."""
    values = np.asarray(values)
    if values.dtype != np.uint8 or values.ndim != 2:
        raise TypeError(f"pad: expected (N, C) uint8 values, got {values.shape} {values.dtype}")
    h, w = layout.shape
    img = np.zeros((h * w, values.shape[1]), np.uint8)
    img[layout.texel] = values
    img = img.reshape(h, w, -1)
    means = [img]
    total = halve(img, np.uint16)               # 4 x 255 fits; the first level is the only full-size sum
    for level in range(1, len(layout.empty)):
        if level > 1:
            total = halve(total, np.uint64)
        mean = total.astype(np.float32)
        mean /= layout.count[level]
        means.append(np.rint(mean, out=mean).astype(np.uint8))   # 0 in empty blocks (0 / 1)
    padded = means[-1]
    for level in range(len(means) - 2, -1, -1):      # means[level] is 0 where the parent's value goes, so:
        up = upsample(padded, means[level].shape)
        np.bitwise_and(up, layout.fill_mask(level, values.shape[1]), out=up)
        padded = np.bitwise_or(up, means[level], out=up)
    return padded


def halve(a: np.ndarray, dtype=None) -> np.ndarray:
    """(H, W, C) -> (ceil(H/2), ceil(W/2), C): sums of 2 x 2 blocks (zeros past an odd edge), in `dtype` (default:
    a's)."""
    if a.shape[0] % 2 or a.shape[1] % 2:
        a = np.pad(a, ((0, a.shape[0] % 2), (0, a.shape[1] % 2), (0, 0)))
    rows = np.add(a[0::2], a[1::2], dtype=dtype or a.dtype)
    return rows[:, 0::2] + rows[:, 1::2]


def upsample(a: np.ndarray, shape: tuple) -> np.ndarray:
    """Every texel of (h, w, C) `a` repeated over its 2 x 2 block, cropped to `shape`'s first two sides."""
    return np.repeat(np.repeat(a, 2, axis=0), 2, axis=1)[:shape[0], :shape[1]]
