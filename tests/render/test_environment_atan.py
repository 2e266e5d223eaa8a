"""The environment lookups' arctangent (render/environment.fast_atan2) against np.arctan2 (the independent truth): its
error bound around the whole circle, the signed zeros and axes it must hit exactly (the seam, the poles), and map
lookups through it (bilinear, and blurred between mip levels) against numpy lookups by the contract's own formula
(direction_uv, np.arctan2), on a map whose texels hold their own coordinates; NaN inputs read inside the map."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.render import environment as env

SPECIAL = np.array([0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 5e-324, -5e-324, 1e300, -1e300])
HEIGHT = 16


def test_error_bound_over_the_circle():
    angle = np.linspace(-np.pi, np.pi, 400_001)
    for radius in (1e-6, 1e-2, 1.0, 3.0, 1e4):
        y, x = radius * np.sin(angle), radius * np.cos(angle)
        error = np.abs(env.atan2_many(y, x) - np.arctan2(y, x))
        assert error.max() <= env.ATAN_ERROR


def test_error_bound_on_random_points_of_every_scale():
    rng = np.random.default_rng(3)
    y, x = rng.standard_normal((2, 200_000)) * np.exp(rng.uniform(-30, 30, (2, 200_000)))
    assert np.abs(env.atan2_many(y, x) - np.arctan2(y, x)).max() <= env.ATAN_ERROR


def test_axes_and_signed_zeros_are_exact():
    # on an axis np.arctan2 is 0, +-pi/2 or +-pi (signed by y's zero): the seam and the poles land where they did
    y, x = (a.ravel() for a in np.meshgrid(SPECIAL, SPECIAL))
    fast, truth = env.atan2_many(y, x), np.arctan2(y, x)
    on_axis = (y == 0) | (x == 0)
    assert np.array_equal(fast[on_axis], truth[on_axis])
    assert np.array_equal(np.signbit(fast), np.signbit(truth))
    assert np.abs(fast - truth).max() <= env.ATAN_ERROR
    assert env.fast_atan2(0.0, -1.0) == np.pi and env.fast_atan2(-0.0, -1.0) == -np.pi    # plain Python too
    assert env.fast_atan2(0.0, -0.0) == np.pi and env.fast_atan2(-0.0, 0.0) == 0.0


def coordinate_map(height: int = HEIGHT) -> np.ndarray:
    """(H, 2H, 3) float32: each texel holds (column, row, column x row)."""
    rows, cols = np.mgrid[0:height, 0:2 * height].astype(np.float32)
    return np.stack([cols, rows, cols * rows], axis=-1)


def contract_bilinear(level: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N, 3) the bilinear lookup by the contract's formula in numpy (direction_uv: np.arctan2 and np.hypot), x
    wrapping, y clamped."""
    h, w = level.shape[:2]
    u, v = env.direction_uv(d)
    x, y = u * w - 0.5, (1 - v) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    c0, c1 = x0.astype(int) % w, (x0.astype(int) + 1) % w
    r0, r1 = np.clip(y0.astype(int), 0, h - 1), np.clip(y0.astype(int) + 1, 0, h - 1)
    top = level[r0, c0] * (1 - fx) + level[r0, c1] * fx
    bottom = level[r1, c0] * (1 - fx) + level[r1, c1] * fx
    return top * (1 - fy) + bottom * fy


def lookup_directions() -> np.ndarray:
    """(N, 3): random directions, every texel centre, the seam (both signed zeros), the poles (all signed zeros)."""
    rng = np.random.default_rng(5)
    random = rng.standard_normal((5000, 3))
    centres = env.texel_directions(HEIGHT).reshape(-1, 3)
    seam = np.array([[1.0, 0.0, 0.0], [1.0, -0.0, 0.0], [1.0, 0.0, 0.3], [2.0, -0.0, -0.7]])
    zeros = (0.0, -0.0)
    poles = np.array([[a, b, z] for a in zeros for b in zeros for z in (1.0, -1.0)])
    return np.concatenate([random, centres, seam, poles])


def test_bilinear_lookup_matches_the_contract_formula():
    level = coordinate_map()
    d = lookup_directions()
    got, want = env.bilinear(level, d), contract_bilinear(level, d)
    assert np.abs(got - want).max() <= 1e-5 * np.abs(level).max()


def test_texel_centres_look_up_their_own_texel():
    level = coordinate_map()
    got = env.bilinear(level, env.texel_directions(HEIGHT).reshape(-1, 3))
    assert np.abs(got - level.reshape(-1, 3)).max() < 1e-4


@pytest.mark.parametrize("d", [(1.0, 0.0, 0.0), (1.0, -0.0, 0.0)])
def test_the_seam_wraps(d):
    # u = 1 (+0) or 0 (-0): either way half of the last column and half of the first
    level = coordinate_map()
    got = env.bilinear(level, np.array([d]))[0]
    assert got[0] == pytest.approx((2 * HEIGHT - 1) / 2, abs=1e-6)
    blurred = env.lookup_blurred_many(env.pack_levels([level]), np.array([d]), np.zeros((1, 1)))[0, :, 0]
    assert blurred[0] == pytest.approx((2 * HEIGHT - 1) / 2, abs=1e-6)


def test_blurred_lookup_at_the_finest_level_matches_the_contract_formula():
    level = coordinate_map()
    levels = env.pyramid(level)
    d = lookup_directions()
    got = env.lookup_blurred_many(env.pack_levels(levels), d, np.zeros((1, len(d))))[0].T
    assert np.abs(got - contract_bilinear(level, d)).max() <= 1e-5 * np.abs(level).max()


ZERO_VECTORS = np.array([[a, b, c] for a in (0.0, -0.0) for b in (0.0, -0.0) for c in (0.0, -0.0)])


def contract_blurred(levels: list[np.ndarray], d: np.ndarray, lod: np.ndarray) -> np.ndarray:
    """(N, 3) trilinear by the contract's formula: contract_bilinear in the levels floor(lod) and the next one,
    blended by lod's fraction (N,)."""
    lo = np.minimum(np.floor(lod).astype(int), len(levels) - 1)
    out = np.zeros((len(d), 3))
    for k in np.unique(lo):
        at = lo == k
        frac = (lod[at] - k)[:, None]
        out[at] = contract_bilinear(levels[k], d[at]) * (1 - frac)
        if k + 1 < len(levels):
            out[at] += contract_bilinear(levels[k + 1], d[at]) * frac
    return out


def test_blurred_lookup_between_levels_matches_the_contract_formula():
    # directions at the seam, the poles, zero vectors and at random, each at two random blurs, whole levels and the
    # coarsest among them; a count that is not a multiple of the kernel's batch of 256
    levels = env.pyramid(coordinate_map(64))
    d = np.concatenate([lookup_directions(), ZERO_VECTORS])
    rng = np.random.default_rng(8)
    lod = rng.uniform(0, len(levels) - 1, (2, len(d)))
    lod[:, :40] = np.arange(40) % len(levels)
    finest = 360.0 / levels[0].shape[1]
    angles = finest * 2.0 ** lod
    packed = env.pack_levels(levels)
    got = env.lookup_blurred_many(packed, d, angles, (1.0, 2.0, 0.5))
    for k in range(2):
        want = contract_blurred(levels, d, env.level_of_detail(levels, angles[k])) * [1.0, 2.0, 0.5]
        assert np.abs(got[k].T - want).max() <= 1e-5 * np.abs(levels[0]).max()


def test_bilinear_lookup_of_zero_vectors_matches_the_contract_formula():
    level = coordinate_map()
    assert np.abs(env.bilinear(level, ZERO_VECTORS) - contract_bilinear(level, ZERO_VECTORS)).max() < 1e-4


def test_nan_directions_and_blurs_read_inside_the_map_and_leave_the_others_alone():
    levels = env.pyramid(coordinate_map(64))
    d = np.concatenate([lookup_directions()[:600], [[np.nan, 0.0, 1.0], [1.0, np.nan, np.nan], [np.nan] * 3]])
    angles = np.random.default_rng(9).uniform(0, 90, (1, len(d)))
    angles[0, :3] = np.nan
    finite = np.isfinite(d).all(axis=1) & np.isfinite(angles[0])
    got = env.lookup_blurred_many(env.pack_levels(levels), d, angles)[0]
    alone = env.lookup_blurred_many(env.pack_levels(levels), d[finite], angles[:, finite])[0]
    assert np.array_equal(got[:, finite], alone)
    assert (np.isnan(got[:, ~finite]) | (np.abs(got[:, ~finite]) <= np.abs(levels[0]).max())).all()
    sky = env.bilinear(coordinate_map(), d)
    assert np.array_equal(sky[:600], env.bilinear(coordinate_map(), d[:600]))
    assert (np.isnan(sky[600:]) | (np.abs(sky[600:]) <= np.abs(coordinate_map()).max())).all()
