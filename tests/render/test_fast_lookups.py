"""The compiled lookups that replaced numpy chains on the frame's hot path, against independent truth: the
environment's prefiltered lookups (environment.lookup_blurred_many) against the numpy definition written here
(trilinear between the mip levels) and closed forms (a constant map, a map that varies only in longitude), the
backdrop's upsampling (environment.upsample) against a separable numpy blend written here and a linear ramp, the
sheen's directional albedo (skin_specular.sheen_directional) against np.interp on its table."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.render import environment as env
from darthand.render import skin_specular


def random_levels(rng: np.random.Generator, height: int = 32) -> list[np.ndarray]:
    """Mip levels of a random positive map (height x 2 height), finest first."""
    return env.pyramid(rng.uniform(0.0, 4.0, (height, 2 * height, 3)).astype(np.float32))


def unit_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def lookup_blurred(levels: list[np.ndarray], d: np.ndarray, angle_deg: np.ndarray) -> np.ndarray:
    """(N, 3) the map along directions d (N, 3) blurred over angle_deg (N,): bilinear in the two mip levels whose
    texels span the angle, blended by the fractional level."""
    lod = env.level_of_detail(levels, np.asarray(angle_deg, np.float64))
    lo = np.floor(lod).astype(np.int64)
    out = np.zeros((len(d), 3))
    for k in np.unique(lo):
        at = np.flatnonzero(lo == k)
        frac = (lod[at] - k)[:, None]
        value = env.bilinear(levels[k], d[at])
        if k + 1 < len(levels):
            value = value * (1 - frac) + env.bilinear(levels[k + 1], d[at]) * frac
        out[at] = value
    return out


def test_blurred_many_matches_the_numpy_definition():
    rng = np.random.default_rng(3)
    levels = random_levels(rng)
    d = unit_directions(rng, 2000)
    angles = np.stack([rng.uniform(0, 120, 2000), np.full(2000, 0.0), np.full(2000, 90.0)])
    got = env.lookup_blurred_many(env.pack_levels(levels), d, angles)
    for k in range(3):
        np.testing.assert_allclose(got[k].T, lookup_blurred(levels, d, angles[k]), rtol=1e-12, atol=1e-12)


def test_blurred_many_of_a_constant_map_is_the_constant():
    levels = env.pyramid(np.full((16, 32, 3), [0.5, 1.0, 2.0], np.float32))
    d = unit_directions(np.random.default_rng(4), 500)
    got = env.lookup_blurred_many(env.pack_levels(levels), d, np.linspace(0, 180, 500)[None])
    np.testing.assert_allclose(got[0].T, np.broadcast_to([0.5, 1.0, 2.0], (500, 3)), rtol=1e-6)


def test_blurred_many_at_the_finest_level_interpolates_longitude_linearly():
    # a map whose value is its column index: at texel centres (u W - 0.5 an integer) the lookup is that index
    h = 8
    levels = env.pyramid(np.broadcast_to(np.arange(2 * h, dtype=np.float32)[None, :, None], (h, 2 * h, 3)).copy())
    columns = np.array([2.0, 5.0, 9.5])                   # between-texel 9.5: the mean of columns 9 and 10
    u = (columns + 0.5) / (2 * h)
    phi = 2 * np.pi * (u - 0.5)                            # direction_uv's inverse on the equator
    d = np.stack([-np.cos(phi), np.sin(phi), np.zeros(3)], axis=1)
    got = env.lookup_blurred_many(env.pack_levels(levels), d, np.zeros((1, 3)))
    np.testing.assert_allclose(got[0, 0], columns, atol=1e-9)


def test_frame_specular_lobes_agree_with_specular_per_row():
    rng = np.random.default_rng(5)
    lighting = env.MapLighting(np.zeros((0, 3)), np.zeros((0, 3)), random_levels(rng), np.zeros((9, 3)), [])
    frame = env.FrameEnvironment([], lighting, env.frame_matrix("camera", np.eye(3), 30.0), np.array([1.0, 0.9, 0.8]))
    d = unit_directions(rng, 300).T
    rough = rng.uniform(0.05, 1.0, (3, 300)).astype(np.float32)
    many = frame.specular_lobes(d, rough)
    for k in range(3):
        np.testing.assert_array_equal(many[k], frame.specular(d, rough[k]))


def test_sky_of_some_rows_and_the_share_it_gives_are_the_whole_lookups():
    """FrameEnvironment.sky(d, rows) is sky(d) on those rows and 0 elsewhere; and _environment_seen, which looks up
    only the rays of vertices neither open nor closed, gives the shares of every ray looked up, bit for bit (an open
    vertex's share is 1 and a closed one's 0 whatever its sky)."""
    from darthand.render.indirect import _sky_share_kernel

    rng = np.random.default_rng(9)
    sh = rng.normal(size=(9, 3))
    lighting = env.MapLighting(np.zeros((0, 3)), np.zeros((0, 3)), random_levels(rng), sh, [])
    frame = env.FrameEnvironment([], lighting, env.frame_matrix("camera", np.eye(3), 30.0), np.array([1.0, 0.9, 0.8]))
    k, n = 16, 400
    d = unit_directions(rng, n * k)
    blocked = rng.random((n, k)) < rng.random((n, 1))
    blocked[: n // 4] = False
    blocked[n // 4: n // 2] = True
    closed = blocked.sum(axis=1)
    rows = np.repeat((closed > 0) & (closed < k), k)
    whole, some = frame.sky(d), frame.sky(d, rows)
    assert some[rows].tobytes() == whole[rows].tobytes() and not some[~rows].any()
    open_sky = frame.irradiance(unit_directions(rng, n).T).T.copy()
    want, got = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32)
    _sky_share_kernel(open_sky, whole, blocked.ravel(), k, want)
    _sky_share_kernel(open_sky, some, blocked.ravel(), k, got)
    assert got.tobytes() == want.tobytes()


def separable_blend(image: np.ndarray, step: int, height: int, width: int) -> np.ndarray:
    """upsample's contract written out in numpy: rows blended, then columns, float32."""
    def axis(n: int, m: int):
        x = np.clip((np.arange(n) - (step - 1) / 2) / step, 0, m - 1)
        lo = np.minimum(x.astype(np.int64), m - 1)
        return lo, np.minimum(lo + 1, m - 1), (x - lo).astype(np.float32)
    r0, r1, fr = axis(height, image.shape[0])
    c0, c1, fc = axis(width, image.shape[1])
    rows = image[r0] * (1 - fr)[:, None, None] + image[r1] * fr[:, None, None]
    return rows[:, c0] * (1 - fc)[None, :, None] + rows[:, c1] * fc[None, :, None]


@pytest.mark.parametrize("step", [2, 3, 8])
def test_upsample_is_the_separable_blend(step):
    rng = np.random.default_rng(step)
    coarse = rng.uniform(0, 5, (-(-100 // step), -(-90 // step), 3)).astype(np.float32)
    np.testing.assert_array_equal(env.upsample(coarse, step, 100, 90), separable_blend(coarse, step, 100, 90))


def test_upsample_reproduces_a_linear_ramp_inside():
    step = 4
    coarse = np.broadcast_to(np.arange(16, dtype=np.float32)[None, :, None], (16, 16, 1)).copy()
    fine = env.upsample(coarse, step, 64, 64)
    x = np.arange(64)
    inside = (x >= (step - 1) / 2) & (x <= 15 * step + (step - 1) / 2)
    np.testing.assert_allclose(fine[0, inside, 0], (x[inside] - (step - 1) / 2) / step, atol=1e-6)


def test_sheen_directional_is_np_interp_on_its_table():
    nv = np.concatenate([np.linspace(0, 1, 20001), [1e-4, 1e-3, 1.0]]).astype(np.float32)
    grid = np.linspace(1e-3, 1, skin_specular.SHEEN_STEPS)
    expected = np.interp(nv, grid, skin_specular.sheen_albedo()).astype(np.float32)
    np.testing.assert_array_equal(skin_specular.sheen_directional(nv), expected)


def numpy_edges(geom: np.ndarray, depth: np.ndarray, normal: np.ndarray, focal: float) -> np.ndarray:
    """aa.edge_pixels' rule written out with array shifts: both pixels of a 4-neighbour pair that differ in what
    they hit or, on the same surface, in depth (over 4 pixel footprints) or in normal (over 40 degrees)."""
    edge = np.zeros(geom.shape, bool)
    cos_tol = np.float32(np.cos(np.deg2rad(40.0)))
    for a, b in (((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
                 ((slice(None), slice(None, -1)), (slice(None), slice(1, None)))):
        differs = geom[a] != geom[b]
        with np.errstate(invalid="ignore"):
            step = np.abs(depth[a] - depth[b]) > 4.0 * np.minimum(depth[a], depth[b]) / np.float32(focal)
            bent = (normal[(slice(None),) + a] * normal[(slice(None),) + b]).sum(axis=0) < cos_tol
        differs |= (geom[a] >= 0) & ~differs & (step | bent)
        edge[a] |= differs
        edge[b] |= differs
    return edge


def test_edge_pixels_follow_the_neighbour_rule():
    from darthand.render import aa

    rng = np.random.default_rng(8)
    geom = rng.integers(-1, 2, (60, 70)).astype(np.int32)
    geom[20:40, 10:50] = 0                                  # a block of one surface: depth and normal decide there
    depth = rng.uniform(0.5, 0.52, (60, 70)).astype(np.float32)
    depth[geom < 0] = np.inf
    depth[20:40, 10:50] = 0.5                               # flat inside the block (random outside it)
    normal = rng.normal(size=(3, 60, 70)).astype(np.float32)
    normal[:, 20:40, 10:50] = np.float32([0, 0, 1])[:, None, None]
    normal[:, 30, 30] = [0, 1, 0]                           # one bent pixel
    depth[25, 20] = 0.4                                     # one step in depth
    got = aa.edge_pixels(geom, depth, normal / np.linalg.norm(normal, axis=0), 500.0)
    np.testing.assert_array_equal(got, numpy_edges(geom, depth, normal / np.linalg.norm(normal, axis=0), 500.0))
    assert got[30, 30] and got[29, 30] and got[25, 20] and got[25, 21] and not got[35, 40]
