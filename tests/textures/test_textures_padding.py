"""Push-pull padding (textures.padding) against closed-form cases and a brute-force reading of its rule."""

import numpy as np
import pytest

from darthand.textures.padding import Layout, pad


def test_two_stored_texels_fill_their_quadrants_and_share_the_rest():
    """8 x 8 image, one stored texel in the top-left quadrant (10) and one in the bottom-right (21): each of those
    quadrants is its texel's colour, the other two quadrants the mean of both, 15.5, rounded half to even: 16."""
    texel = np.array([0 * 8 + 0, 7 * 8 + 7])
    img = pad(Layout.of(texel, 8), np.array([[10], [21]], np.uint8))[..., 0]
    expected = np.full((8, 8), 16, np.uint8)
    expected[:4, :4], expected[4:, 4:] = 10, 21
    assert np.array_equal(img, expected)


def test_one_stored_texel_fills_everything_and_an_odd_side_pads_with_empty_texels():
    img = pad(Layout.of(np.array([5 * 7 + 6]), 7), np.array([[200, 3, 77]], np.uint8))
    assert img.shape == (7, 7, 3) and (img == [200, 3, 77]).all()


@pytest.mark.parametrize("res", [32, 37])
def test_every_empty_texel_takes_the_mean_of_the_smallest_aligned_block_holding_stored_texels(res):
    """Brute force, per texel, in exact arithmetic: stored texels keep their value; any other takes the mean of
    the stored texels in the smallest aligned 2^L x 2^L block around it, rounded to the nearest code."""
    rng = np.random.default_rng(res)
    for count in (1, 3, 40, res * res // 2):
        texel = np.sort(rng.choice(res * res, count, replace=False))
        values = rng.integers(0, 256, (count, 3), dtype=np.uint8)
        img = pad(Layout.of(texel, res), values)
        stored = np.zeros((res, res), bool)
        stored.flat[texel] = True
        full = np.zeros((res, res, 3), np.int64)
        full.reshape(-1, 3)[texel] = values
        for r in range(res):
            for c in range(res):
                L = next(L for L in range(8) if stored[(r >> L) << L:((r >> L) + 1) << L,
                                                       (c >> L) << L:((c >> L) + 1) << L].any())
                block = (slice((r >> L) << L, ((r >> L) + 1) << L), slice((c >> L) << L, ((c >> L) + 1) << L))
                mean = full[block].sum((0, 1)) / stored[block].sum()
                assert np.array_equal(img[r, c], np.rint(mean)), (count, r, c)


def test_pad_refuses_anything_but_8_bit_codes():
    with pytest.raises(TypeError, match="uint8"):
        pad(Layout.of(np.array([0]), 4), np.array([[0.5]]))
