"""Compositing and 8-bit encoding of a frame (render/image.compose, a compiled pass) against the formulas in float64:
over a background, premult + (1 - alpha) B and its sRGB codes; transparent, the straight colour's codes and the
8-bit coverage; the frame outside the rendered region is the background (or empty)."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.render.image import compose
from darthand.textures.color import encode_srgb8


def srgb_codes64(linear):
    c = np.clip(np.asarray(linear, np.float64), 0, 1)
    return 255 * np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)


def frame_parts(seed=0, H=40, W=56, region=(7, 11), size=(20, 30)):
    rng = np.random.default_rng(seed)
    h, w = size
    alpha = rng.choice([0.0, 1.0, 0.25, 0.6], (h, w)).astype(np.float32)
    premult = (rng.uniform(0, 1.2, (3, h, w)) * alpha).astype(np.float32)     # some colours above 1: clipped
    background = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    return premult, alpha, background, region, (H, W)


# Worst distance from the exact code: half a code of rounding, plus the 65536-step table on the linear value (half a
# step times the steepest slope of the curve, 12.92, times 255 codes), plus float32 rounding of the blend.
CODE_BOUND = 0.5 + 255 * 12.92 * 0.5 / 65535 + 1e-3


def test_compose_over_a_background_is_premult_plus_the_uncovered_background():
    premult, alpha, bg, (r0, c0), (H, W) = frame_parts()
    colour, rgba = compose(premult, alpha, (r0, c0), bg, (H, W))
    h, w = alpha.shape
    want = bg.astype(np.float64)
    want[r0:r0 + h, c0:c0 + w] = (premult.transpose(1, 2, 0).astype(np.float64)
                                  + (1 - alpha[..., None].astype(np.float64)) * bg[r0:r0 + h, c0:c0 + w])
    assert colour.dtype == np.float32 and np.allclose(colour, want, atol=2e-7 * 4)
    assert np.array_equal(colour[:r0], bg[:r0]) and np.array_equal(colour[:, c0 + w:], bg[:, c0 + w:])
    assert np.abs(rgba[..., :3] - srgb_codes64(want)).max() <= CODE_BOUND
    assert (rgba[..., 3] == 255).all()
    assert np.array_equal(rgba[..., :3], encode_srgb8(colour))     # the same encoder as every other 8-bit output


def test_compose_without_background_stores_straight_colour_and_coverage():
    premult, alpha, _, (r0, c0), (H, W) = frame_parts(seed=1)
    colour, rgba = compose(premult, alpha, (r0, c0), None, (H, W))
    h, w = alpha.shape
    inner = (slice(r0, r0 + h), slice(c0, c0 + w))
    assert np.array_equal(colour[inner], premult.transpose(1, 2, 0))
    assert not colour[:r0].any() and not rgba[:r0].any() and not rgba[:, :c0].any()
    covered = alpha > 0
    straight = np.zeros((h, w, 3))
    straight[covered] = premult.transpose(1, 2, 0)[covered] / alpha[covered, None]
    assert np.abs(rgba[inner][..., :3] - srgb_codes64(straight)).max() <= CODE_BOUND
    assert np.array_equal(rgba[inner][..., 3], np.rint(alpha.astype(np.float64) * 255).astype(np.uint8))


@pytest.mark.parametrize("value,code", [(np.nan, 0), (-1.0, 0), (2.0, 255)])
def test_out_of_range_colour_and_coverage_clip(value, code):
    premult = np.full((3, 2, 2), value, np.float32)
    alpha = np.full((2, 2), value, np.float32)
    _, rgba = compose(premult, alpha, (0, 0), np.zeros((2, 2, 3), np.float32), (2, 2))
    assert (rgba[..., :3] == code).all()
    _, clear = compose(premult, alpha, (0, 0), None, (2, 2))
    assert (clear[..., 3] == (255 if value > 1 else 0)).all()
