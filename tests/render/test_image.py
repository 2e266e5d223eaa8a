"""Compositing and 8-bit encoding of a frame (render/image.compose, a compiled pass) against the formulas in float64:
over a background, premult + (1 - alpha) B and its sRGB codes; transparent, the straight colour's codes and the
8-bit coverage; the frame outside the rendered region is the background (or empty). compose_over_grid against
compose over the grid upsampled by a numpy blend written here; encode_mask8 against numpy's float32 rint of the
clipped coverage."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.render.image import compose, compose_over_grid, encode_mask8
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


def grid_axis(step: int, n: int, m: int):
    """A fine axis of n pixels over m grid samples, sample i at fine position step i + (step - 1) / 2: each pixel's
    two samples and its float32 fraction between them (clamped at the ends)."""
    x = np.clip((np.arange(n) - (step - 1) / 2) / step, 0, m - 1)
    lo = np.floor(x).astype(np.int64)
    return lo, np.minimum(lo + 1, m - 1), (x - lo).astype(np.float32)


def blend_grid(grid: np.ndarray, rows, cols) -> np.ndarray:
    """The grid (h, w, 3) blended bilinearly to the fine frame in numpy, float32: rows first, then columns."""
    (r0, r1, fr), (c0, c1, fc) = rows, cols
    one = np.float32(1)
    tall = grid[r0] * (one - fr)[:, None, None] + grid[r1] * fr[:, None, None]
    return tall[:, c0] * (one - fc)[None, :, None] + tall[:, c1] * fc[None, :, None]


@pytest.mark.parametrize("step,region,size", [(2, (7, 11), (20, 30)), (3, (0, 0), (40, 56)), (8, (25, 40), (15, 16)),
                                              (5, (39, 0), (1, 56))])
def test_compose_over_grid_is_compose_over_the_blended_grid(step, region, size):
    premult, alpha, _, _, (H, W) = frame_parts(seed=step, region=region, size=size)
    premult[0, 0, 0], premult[1, -1, -1] = np.nan, -0.5                   # clipping as compose's
    grid = np.random.default_rng(step).uniform(0, 1.3, (-(-H // step), -(-W // step), 3)).astype(np.float32)
    axes = (grid_axis(step, H, grid.shape[0]), grid_axis(step, W, grid.shape[1]))
    colour, rgba = compose_over_grid(premult, alpha, region, grid, axes, (H, W))
    want_colour, want_rgba = compose(premult, alpha, region, blend_grid(grid, *axes), (H, W))
    assert colour.tobytes() == want_colour.tobytes() and rgba.tobytes() == want_rgba.tobytes()


def test_encode_mask8_is_the_rounded_clipped_coverage():
    rng = np.random.default_rng(2)
    alpha = np.concatenate([rng.uniform(-0.5, 1.5, 5000), np.arange(256) / 255, (np.arange(510) + 0.5) / 510,
                            [-0.0, np.inf, -np.inf, 1.0, 0.0]]).astype(np.float32)
    want = np.rint(np.clip(alpha, 0, 1) * np.float32(255))                   # numpy's float32 arithmetic
    got = encode_mask8(alpha.reshape(1, -1, 1)[..., 0])
    assert got.dtype == np.uint8 and got.shape == (1, alpha.size) and np.array_equal(got[0], want)
    assert encode_mask8(np.array([[np.nan]], np.float32))[0, 0] == 0
