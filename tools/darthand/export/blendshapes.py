"""Blend shapes every importer takes as they are: signed channels encoded as shapes whose weights stay in [0, 1].

A rig drives a blend-shape channel c (a pose-feature entry (R_i - I)_rc, a PCA coefficient of the correctives, and
later a shape coefficient beta) with a signed value x_c in a known range [lo_c, hi_c], and adds x_c d_c to the rest
points (d_c (V, 3) its offsets). Many importers clamp blend-shape weights to [0, 1] (Blender's shape keys, from
USD and glTF alike), so x_c is not exported as a weight. Each channel becomes one shape per side of zero its range
reaches, with scaled offsets:

    positive shape (hi_c > 0):  offsets  hi_c d_c,   weight  max(x_c, 0) / hi_c
    negative shape (lo_c < 0):  offsets  lo_c d_c,   weight  max(-x_c, 0) / -lo_c

Both weights lie in [0, 1] for every x_c in the range, at most one is non-zero, and the shapes add up to exactly
x_c d_c. A channel whose range has one sign gets one shape (the diagonal of R_i - I is never positive). The
encoding is a table per exported shape: the channel it encodes and its signed scale a_s (hi_c or lo_c), so that
offsets_s = a_s d_c and weight_s = clip(x_c / a_s, 0, 1). `asset.json` (USD) and the glTF asset's extras record that
table, so a consumer can decode the weights back to channel values: x_c = sum over its shapes of a_s weight_s.

A future shape space (betas) adds its channels with their own range next to the correctives, through the same
functions (`encode_channels` takes any names and ranges).

Shapes: V points, C channels, S exported shapes, B samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ShapeEncoding:
    """Exported shapes of C signed channels. names (S,) shape names; channel (S,) int the channel index each encodes;
    scale (S,) float its signed scale a_s (offsets a_s d_c, weight clip(x_c / a_s, 0, 1)); channels (C,) names."""

    names: tuple[str, ...]
    channel: np.ndarray
    scale: np.ndarray
    channels: tuple[str, ...]

    @property
    def count(self) -> int:
        return len(self.names)

    def weights(self, values: np.ndarray) -> np.ndarray:
        """(B, S) shape weights in [0, 1] of channel values (B, C) (values outside a channel's range are clipped)."""
        x = np.asarray(values, dtype=np.float64)[..., self.channel]
        return np.clip(x / self.scale, 0.0, 1.0)

    def offsets(self, channel_offsets: np.ndarray) -> np.ndarray:
        """(V, 3, S) shape offsets of channel offsets (V, 3, C)."""
        return np.asarray(channel_offsets)[:, :, self.channel] * self.scale

    def decode(self, weights: np.ndarray) -> np.ndarray:
        """(B, C) channel values of shape weights (B, S): the inverse of `weights` within the ranges."""
        onehot = np.zeros((self.count, len(self.channels)))
        onehot[np.arange(self.count), self.channel] = 1.0
        return (np.asarray(weights, dtype=np.float64) * self.scale) @ onehot

    def as_dict(self) -> dict:
        """The table for asset metadata: per shape its name, channel name and scale."""
        return {"weight_range": [0.0, 1.0],
                "rule": "shape offsets = scale * channel offsets; weight = clip(value / scale, 0, 1); "
                        "value = sum over the channel's shapes of scale * weight",
                "shapes": [{"name": n, "channel": self.channels[c], "scale": float(a)}
                           for n, c, a in zip(self.names, self.channel, self.scale)]}


def encode_channels(names, lo, hi) -> ShapeEncoding:
    """The encoding of channels `names` (C,) with value ranges [lo, hi] (C,) each (lo <= 0 <= hi): a `_pos` shape
    where hi > 0, a `_neg` shape where lo < 0, in channel order (positive first)."""
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    if (lo > 0).any() or (hi < 0).any():
        raise ValueError("blend-shape channel ranges must contain 0")
    shape_names, channel, scale = [], [], []
    for c, name in enumerate(names):
        for bound, suffix in ((hi[c], "pos"), (lo[c], "neg")):
            if bound != 0:
                shape_names.append(f"{name}_{suffix}")
                channel.append(c)
                scale.append(bound)
    return ShapeEncoding(tuple(shape_names), np.asarray(channel, dtype=np.int64), np.asarray(scale), tuple(names))


def linear_ranges(matrix: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranges (K,), (K,) of y = matrix @ x (K, N) over the box lo <= x <= hi (N,): interval arithmetic, attained."""
    m = np.asarray(matrix, dtype=np.float64)
    pos, neg = np.maximum(m, 0), np.minimum(m, 0)
    return pos @ lo + neg @ hi, pos @ hi + neg @ lo
