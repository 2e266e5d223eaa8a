"""Texture lookups against closed form: texel centres, bilinear weights, the v-up convention, box mips, the mip
level of a tilted plane's footprint, the sRGB offset; 8-bit (SRGB8-style) pyramids: decode tables at fetch, mips
within 8-bit quantisation of the linear-light box filter, one decode of a file for every skin-tone offset."""

from __future__ import annotations

import os

import numpy as np
import OpenImageIO as oiio
import pytest
from render_scenes import flat_material, one_light, quad, render, subject, top_camera

from darthand.errors import InputError
from darthand.render.camera import look_at
from darthand.render.scene import Scene
from darthand.render.shade import surface_hits
from darthand.render import texture as texture_module
from darthand.render.texture import (MipTexture, checker_texture, code_pyramid, constant_texture, decode_tables,
                                     load_maps, load_texture, mip_levels, srgb8_to_linear_lut)
from darthand.render.trace import Context
from darthand.textures.color import srgb_to_linear


def grid_texture(h=4, w=8) -> tuple[np.ndarray, MipTexture]:
    img = np.arange(h * w * 2, dtype=np.float32).reshape(h, w, 2)
    return img, MipTexture(mip_levels(img))


def uv_of(row, col, h, w):
    """UV of the centre of texel (row, col): u = (c + 0.5) / W, v = 1 - (r + 0.5) / H (v up, row 0 at the top)."""
    return np.array([(col + 0.5) / w, 1 - (row + 0.5) / h], np.float32)


def test_texel_centres_give_the_texel():
    img, tex = grid_texture()
    rows, cols = np.mgrid[0:4, 0:8]
    uv = np.stack([uv_of(r, c, 4, 8) for r, c in zip(rows.ravel(), cols.ravel())], 1)
    assert np.allclose(tex.bilinear(uv, 0).T, img.reshape(-1, 2))
    # v = 0 is the bottom row: uv (just above 0) reads the last row.
    assert np.allclose(tex.bilinear(np.array([[0.5 / 8], [0.01]], np.float32), 0).T, img[3, 0])


def test_bilinear_closed_form():
    img, tex = grid_texture()
    # A point 30% of the way from texel (1, 2) to (1, 3) and 75% from row 1 to row 2.
    u = (2 + 0.5 + 0.3) / 8
    v = 1 - (1 + 0.5 + 0.75) / 4
    want = ((1 - 0.75) * ((1 - 0.3) * img[1, 2] + 0.3 * img[1, 3])
            + 0.75 * ((1 - 0.3) * img[2, 2] + 0.3 * img[2, 3]))
    assert np.allclose(tex.bilinear(np.array([[u], [v]], np.float32), 0)[:, 0], want, atol=1e-4)
    # Outside the image the lookup clamps to the edge texel.
    assert np.allclose(tex.bilinear(np.array([[-0.2], [1.3]], np.float32), 0)[:, 0], img[0, 0])


def test_mip_levels_are_box_averages_and_trilinear_blends_them():
    img = np.random.default_rng(0).random((8, 8, 3)).astype(np.float32)
    levels = mip_levels(img)
    assert [lv.shape[:2] for lv in levels] == [(8, 8), (4, 4), (2, 2), (1, 1)]
    assert np.allclose(levels[1][1, 2], img[2:4, 4:6].reshape(-1, 3).mean(0), atol=1e-6)
    assert np.allclose(levels[-1][0, 0], img.reshape(-1, 3).mean(0), atol=1e-6)
    tex = MipTexture(levels)
    uv = np.array([[0.3], [0.6]], np.float32)
    a, b = tex.bilinear(uv, 1), tex.bilinear(uv, 2)
    # Levels blend linearly across the band frac in [0.25, 0.75] and are pure outside it.
    assert np.allclose(tex.sample(uv, 1.5), a + 0.5 * (b - a), atol=1e-6)
    assert np.allclose(tex.sample(uv, 1.6), a + 0.7 * (b - a), atol=1e-6)
    assert np.allclose(tex.sample(uv, 1.1), a, atol=1e-6) and np.allclose(tex.sample(uv, 1.9), b, atol=1e-6)
    lods = np.linspace(0, 3, 200, dtype=np.float32)
    steps = np.diff(tex.sample(np.repeat(uv, 200, 1), lods), axis=1)
    assert np.abs(steps).max() < 0.1 * np.abs(levels[0] - levels[-1]).max()     # continuous in the level
    assert np.allclose(tex.sample(uv, 99.0)[:, 0], img.reshape(-1, 3).mean(0), atol=1e-6)


def test_odd_sizes_reduce_to_one_texel():
    levels = mip_levels(np.ones((5, 3, 1), np.float32))
    assert levels[-1].shape == (1, 1, 1) and np.allclose(levels[-1], 1)


def test_lod_is_log2_of_the_footprint_in_texels():
    tex = MipTexture(mip_levels(np.zeros((256, 128, 1), np.float32)))
    dx = np.array([[2 / 128], [0]], np.float32)      # 2 texels across u
    dy = np.array([[0], [8 / 256]], np.float32)      # 8 texels along v
    assert np.allclose(tex.lod(dx, dy), 3.0)
    assert np.allclose(tex.lod(dx * 0.1, dy * 0.1), 0.0)   # magnification clamps to level 0


@pytest.mark.parametrize("tilt_deg", [0.0, 40.0, 70.0])
def test_mip_level_of_a_tilted_plane(tilt_deg):
    """A 1 m square with UVs [0, 1]^2 seen from 10 m with a 2000 px focal length: a pixel covers 5 mm, the texture
    of 1024 texels has 1024 texels per metre, so 5.12 texels per pixel facing the camera and 5.12 / cos(tilt)
    along the tilt: lod = log2(5.12 / cos(tilt)) at the plane's centre."""
    t = np.deg2rad(tilt_deg)
    plane = quad(size=1.0, normal_axis=2)
    R = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    plane = type(plane)(plane.name, (plane.vertices @ R.T).astype(np.float32), plane.faces,
                        (plane.normals @ R.T).astype(np.float32), plane.material, plane.uvs, plane.faces_uv)
    subj = subject(plane)
    scene = Scene(subj)
    cam = look_at((0, 0, 10), (0, 0, 0), (0, 1, 0), width=64, height=64, focal_px=2000)
    ctx = Context(scene, cam, [], np.zeros(3, np.float32))
    uv = np.array([[32.0, 32.0]])
    d = ctx.directions(uv)
    hit = scene.intersect(np.repeat(cam.centre[None].astype(np.float32), 1, 0), np.ascontiguousarray(d.T))
    hits = surface_hits(scene.faces[0], hit["primID"], hit["u"], hit["v"], d, hit["tfar"], 1 / 2000)
    tex = MipTexture(mip_levels(np.zeros((1024, 1024, 1), np.float32)))
    # Perspective adds a little at the centre pixel; 2% of a level at most here.
    assert np.isclose(tex.lod_of_footprint(hits.footprint)[0], np.log2(5.12 / np.cos(t)), atol=0.02)
    assert np.allclose(hits.uv[:, 0], [0.5, 0.5], atol=1e-4)


def write_png(path, img):
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], oiio.UINT8)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(img))
    assert buf.write(str(path))
    return path


def test_srgb_files_decode_to_linear_with_the_offset(tmp_path):
    img = np.arange(4 * 4 * 3, dtype=np.uint8).reshape(4, 4, 3) * 5
    path = write_png(tmp_path / "a.png", img)
    tex = load_texture(path, srgb=True)
    assert np.allclose(tex.levels[0], srgb_to_linear(img / 255.0), atol=1e-6)
    shifted = load_texture(path, srgb=True, offset=0.1)
    assert np.allclose(shifted.levels[0], srgb_to_linear(np.clip(img / 255.0 + 0.1, 0, 1)), atol=1e-6)
    assert np.allclose(srgb8_to_linear_lut(-1.0), 0)
    data = load_texture(path, srgb=False)
    assert np.allclose(data.levels[0], img / 255.0, atol=1e-6)


def test_maps_pack_albedo_and_data_channels(tmp_path):
    albedo = write_png(tmp_path / "albedo.png", np.full((8, 8, 3), 200, np.uint8))
    mr = np.zeros((4, 4, 3), np.uint8)
    mr[..., 1], mr[..., 2] = 51, 255                      # glTF layout: G roughness 0.2, B metallic 1
    mr_path = write_png(tmp_path / "mr.png", mr)
    maps = load_maps(albedo, data=mr_path, channels=(1, 2))
    assert maps.channels == 5 and maps.width == 8          # data resized to the albedo's size
    assert np.allclose(maps.levels[0][..., 3], 0.2, atol=1e-3) and np.allclose(maps.levels[0][..., 4], 1.0)
    assert np.allclose(maps.levels[0][..., :3], srgb_to_linear(np.float32(200 / 255)), atol=1e-6)


def test_rendered_texture_reads_the_right_texel():
    """A plane filling the view with a texture of one colour per quadrant renders each quadrant's colour in the
    matching image quadrant: u to the right, v up (image row 0 at the top)."""
    img = np.zeros((64, 64, 3), np.float32)
    img[:32, :32], img[:32, 32:], img[32:, :32], img[32:, 32:] = [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0]
    material = flat_material()
    material = type(material)("pbr", MipTexture([img]), None, 0.5, None, 0.0, (0, 0, 0), 0.0, "quadrants")
    plane = quad(size=2.0, material=material)
    frame = render(subject(plane), top_camera(height=1.0, size=64, fov_deg=60), one_light((0, 0, -1), shadows=False),
                   samples=1, labels=False)
    c = frame.colour
    assert np.allclose(c[16, 16], [1, 0, 0], atol=1e-5) and np.allclose(c[16, 48], [0, 1, 0], atol=1e-5)
    assert np.allclose(c[48, 16], [0, 0, 1], atol=1e-5) and np.allclose(c[48, 48], [1, 1, 0], atol=1e-5)


# ------------------------------------------------------------------------------------------------ 8-bit storage


def srgb_decode64(codes, offset=0.0):
    """IEC 61966-2-1 sRGB -> linear in float64, after adding `offset` to the encoded value (clipped to [0, 1])."""
    c = np.clip(np.asarray(codes, np.float64) / 255 + offset, 0, 1)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def srgb_encode64(linear):
    c = np.clip(np.asarray(linear, np.float64), 0, 1)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)


def random_codes(h, w, c, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (h, w, c), dtype=np.uint8)


def centres(h, w):
    """(2, H*W) uv of every texel centre of an H x W level, row-major."""
    rows, cols = np.mgrid[0:h, 0:w]
    return np.stack([(cols.ravel() + 0.5) / w, 1 - (rows.ravel() + 0.5) / h]).astype(np.float32)


def test_code_texel_centres_return_their_texel_through_the_decode_table():
    codes = random_codes(16, 32, 4)
    tex = code_pyramid(codes, colour=3).with_decode(decode_tables(4, 3, offset=0.05))
    table = tex.decode
    assert tex.flat.dtype == np.uint8 and tex.channels == 4
    for k in range(len(tex.levels)):
        stored = tex.texels(k)
        h, w = stored.shape[:2]
        got = tex.bilinear(centres(h, w), k)                       # (C, H*W)
        want = np.stack([table[c][stored[..., c].ravel()] for c in range(4)])
        assert np.array_equal(got, want)
        assert np.array_equal(tex.levels[k], want.T.reshape(h, w, 4))


def test_code_bilinear_interpolates_decoded_values():
    """Between texels the lookup blends the decoded (linear) values, not the codes."""
    codes = np.zeros((2, 2, 3), np.uint8)
    codes[:, 1] = 255                                    # left column black, right column white
    tex = code_pyramid(codes, colour=3)
    mid = tex.bilinear(np.array([[0.5], [0.5]], np.float32), 0)[:, 0]
    assert np.allclose(mid, 0.5, atol=1e-6)              # half of linear 1, not the decode of code 127.5


def test_offset_at_fetch_equals_the_per_texel_decode_at_level_0(tmp_path):
    codes = random_codes(8, 16, 3, seed=1)
    path = write_png(tmp_path / "skin.png", codes)
    for offset in (0.0, -0.1, 0.07, -1.0):
        tex = load_maps(path, offset=offset)
        assert tex.flat.dtype == np.uint8
        got = tex.bilinear(centres(8, 16), 0).T.reshape(8, 16, 3)
        assert np.array_equal(got, srgb8_to_linear_lut(offset)[codes])        # the earlier load-time decode
        assert np.allclose(got, srgb_decode64(codes, offset), atol=1e-6)      # and the sRGB formula


# Worst error, in 8-bit codes, of re-encoding a linear value: half a code from rounding, plus the encoder's
# 65536-entry table on the linear value (index rounded by half a step of 1 / 65535, times the steepest slope of
# the sRGB curve, 12.92, times 255 codes), plus a margin for float32 sums.
ENCODE_BOUND = 0.5 + 255 * 12.92 * 0.5 / 65535 + 1e-3


@pytest.mark.parametrize("shape", [(16, 16), (32, 8), (8, 2), (1, 8), (8, 1)])
def test_mip_texels_are_linear_light_box_averages_within_8bit_quantisation(shape):
    h, w = shape
    codes = random_codes(h, w, 4, seed=2)
    codes[: h // 2, : w // 2, :3] = 3                    # a dark block: the linear segment of the sRGB curve
    tex = code_pyramid(codes, colour=3)
    linear = srgb_decode64(codes[..., :3])
    for k in range(1, len(tex.levels)):
        stored = tex.texels(k).astype(np.float64)
        bh, bw = h // stored.shape[0], w // stored.shape[1]           # level-0 texels under one level-k texel
        blocks = lambda a, s=stored.shape, bh=bh, bw=bw: a.reshape(s[0], bh, s[1], bw, -1).mean(axis=(1, 3))
        colour_err = np.abs(stored[..., :3] - 255 * srgb_encode64(blocks(linear)))
        data_err = np.abs(stored[..., 3:] - blocks(codes[..., 3:].astype(np.float64)))
        assert colour_err.max() <= ENCODE_BOUND, (k, colour_err.max())
        assert data_err.max() <= 0.5 + 1e-3, (k, data_err.max())
    assert tex.texels(-1).shape == (1, 1, 4)


def test_odd_sizes_repeat_the_last_row_and_column_in_level_1():
    codes = random_codes(5, 7, 2, seed=3)
    tex = code_pyramid(codes, colour=1)
    assert [lv.shape[:2] for lv in tex.levels] == [(5, 7), (3, 4), (2, 2), (1, 1)]
    linear = srgb_decode64(codes[..., 0])
    stored = tex.texels(1).astype(np.float64)
    for r in range(3):
        for c in range(4):
            rows, cols = [2 * r, min(2 * r + 1, 4)], [2 * c, min(2 * c + 1, 6)]
            block = np.ix_(rows, cols)
            assert abs(stored[r, c, 0] - 255 * srgb_encode64(linear[block].mean())) <= ENCODE_BOUND
            assert abs(stored[r, c, 1] - codes[..., 1][block].astype(float).mean()) <= 0.5 + 1e-3


def test_two_offsets_decode_the_file_once(tmp_path, monkeypatch):
    codes = random_codes(16, 16, 3, seed=4)
    albedo = write_png(tmp_path / "albedo.png", codes)
    rough = write_png(tmp_path / "rough.png", random_codes(16, 16, 1, seed=5))
    reads = []
    real = texture_module._open_codes
    monkeypatch.setattr(texture_module, "_open_codes", lambda path: reads.append(str(path)) or real(path))
    a = load_maps(albedo, offset=0.0, data=rough)
    b = load_maps(albedo, offset=-0.1, data=rough)
    assert sorted(reads) == sorted([str(albedo.resolve()), str(rough.resolve())])      # each file decoded once
    assert a.flat is b.flat                                                           # one pyramid, two tables
    assert np.array_equal(b.levels[0][..., :3], srgb8_to_linear_lut(-0.1)[codes])
    assert np.array_equal(a.levels[0][..., 3], b.levels[0][..., 3])                  # data ignores the offset
    # A changed file (new modification time) is decoded again (with the map packed beside it).
    write_png(albedo, codes[::-1].copy())
    os.utime(albedo, ns=(os.stat(albedo).st_atime_ns, os.stat(albedo).st_mtime_ns + 10**9))
    c = load_maps(albedo, offset=-0.1, data=rough)
    assert len(reads) == 4 and np.array_equal(c.levels[0][..., :3], srgb8_to_linear_lut(-0.1)[codes[::-1]])


def test_the_cache_keeps_many_small_maps_within_its_memory_budget(tmp_path, monkeypatch):
    """Sixty small maps (an accessory catalogue's worth) stay cached together; past the byte budget the least
    recently used pyramid is dropped and decoded again when asked for."""
    paths = [write_png(tmp_path / f"m{i}.png", random_codes(8, 8, 3, seed=i)) for i in range(60)]
    texture_module.clear_cache()
    reads = []
    real = texture_module._open_codes
    monkeypatch.setattr(texture_module, "_open_codes", lambda path: reads.append(str(path)) or real(path))
    for _ in range(2):
        for p in paths:
            load_maps(p)
    assert len(reads) == 60
    size = load_maps(paths[0]).nbytes
    monkeypatch.setattr(texture_module, "CACHE_BYTES", 10 * size)
    load_maps(write_png(tmp_path / "new.png", random_codes(8, 8, 3, seed=99)))   # over budget: keeps the last 10
    load_maps(paths[-1])
    assert len(reads) == 61
    load_maps(paths[1])
    assert len(reads) == 62
    texture_module.clear_cache()


def test_data_maps_without_albedo_use_the_constant_base_colour(tmp_path):
    mr = random_codes(8, 8, 3, seed=6)
    path = write_png(tmp_path / "mr.png", mr)
    base = (0.9, 0.5, 0.1)
    tex = load_maps(None, data=path, channels=(1, 2), base_color=base)
    for k in range(len(tex.levels)):
        level = tex.levels[k]
        assert np.array_equal(level[..., :3], np.broadcast_to(np.float32(base), level.shape[:2] + (3,)))
    assert np.array_equal(tex.levels[0][..., 3:], mr[..., 1:].astype(np.float32) * np.float32(1 / 255))


def test_float_textures_keep_float_storage(tmp_path):
    # Values that are not 8-bit codes (positions in metres, say) are stored and returned as given.
    img = np.array([[[-3.5, 1e3], [0.25, 7.0]], [[2.0, -1.0], [0.0, 1.5]]], np.float32)
    tex = MipTexture(mip_levels(img))
    assert tex.flat.dtype == np.float32 and tex.decode is None
    assert np.array_equal(tex.bilinear(centres(2, 2), 0).T, img.reshape(-1, 2))
    assert np.allclose(tex.sample(np.array([[0.5], [0.5]], np.float32), 5.0)[:, 0], img.reshape(-1, 2).mean(0))
    assert np.array_equal(constant_texture((0.1, 0.2, 0.3)).levels[-1].ravel(), np.float32([0.1, 0.2, 0.3]))
    assert checker_texture(64, 4).flat.dtype == np.float32
    # A 16-bit sRGB file keeps its precision: float storage, the offset applied at load.
    values = (np.arange(4 * 4 * 3, dtype=np.uint16).reshape(4, 4, 3) * 1300)
    spec = oiio.ImageSpec(4, 4, 3, oiio.UINT16)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), values)
    assert buf.write(str(tmp_path / "deep.png"))
    tex16 = load_maps(tmp_path / "deep.png", offset=-0.05)
    assert tex16.flat.dtype == np.float32
    want = srgb_decode64(values / 65535 * 255, -0.05)
    assert np.allclose(tex16.levels[0], want, atol=1e-5)


# ------------------------------------------------------------------------------------------------ the compiled lookup


def reference_sample(tex: MipTexture, u: float, v: float, lod: float) -> np.ndarray:
    """(C,) float64 lookup of one sample written from the definition (module docstring, MipTexture.sample): the
    level clamped to the pyramid, the nearer level read bilinearly at texel centres with the edge clamped, the other
    level blended in across the band frac(lod) in [0.5 - BLEND, 0.5 + BLEND]."""
    levels = [lv.astype(np.float64) for lv in tex.levels]
    last = len(levels) - 1
    lod = min(max(lod, 0.0), last)

    def bilinear(k):
        img = levels[k]
        h, w = img.shape[:2]
        x, y = u * w - 0.5, (1 - v) * h - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = x - x0, y - y0
        at = lambda r, c: img[int(np.clip(r, 0, h - 1)), int(np.clip(c, 0, w - 1))]
        return ((1 - fy) * ((1 - fx) * at(y0, x0) + fx * at(y0, x0 + 1))
                + fy * ((1 - fx) * at(y0 + 1, x0) + fx * at(y0 + 1, x0 + 1)))

    base = int(np.floor(lod))
    frac = lod - base
    if base == last:
        return bilinear(last)
    w = np.clip((frac - (0.5 - texture_module.BLEND)) / (2 * texture_module.BLEND), 0, 1)
    return (1 - w) * bilinear(base) + w * bilinear(base + 1)


@pytest.mark.parametrize("shape,coded", [((37, 64, 4), True), ((64, 37, 4), False), ((1, 1, 3), True),
                                          ((1, 9, 2), False), ((16, 16, 5), True)])
def test_lookups_match_the_definition_on_random_uvs_and_levels(shape, coded):
    """(MipTexture's lookup is a compiled loop, render/texture._lookup_kernel.) Random uv (outside [0, 1] too: edge
    clamping), random levels (below 0, past the last level, on and around the blend band's edges) on non-square,
    1-texel-high and 1 x 1 pyramids, 8-bit (with a skin-tone offset's table) and float: the compiled lookup equals the
    per-sample float64 definition within float32 rounding."""
    rng = np.random.default_rng(sum(shape))
    h, w, c = shape
    if coded:
        tex = code_pyramid(random_codes(h, w, c, seed=7), colour=min(3, c))
        tex = tex.with_decode(decode_tables(c, min(3, c), offset=-0.07))
    else:
        tex = MipTexture(mip_levels(rng.standard_normal((h, w, c)).astype(np.float32)))
    n = 3000
    uv = rng.uniform(-0.3, 1.3, (2, n)).astype(np.float32)
    uv[:, :600] = (np.round(uv[:, :600] * 2 * max(h, w)) / (2 * max(h, w))).astype(np.float32)  # centres, edges
    last = len(tex.levels) - 1
    lod = rng.uniform(-1, last + 1, n).astype(np.float32)
    lod[:400] = np.round(lod[:400] * 8) / 8                        # 0.25 and 0.75: the band's edges
    got = tex.sample(uv, lod)
    assert got.shape == (c, n) and got.dtype == np.float32
    want = np.stack([reference_sample(tex, float(uv[0, i]), float(uv[1, i]), float(lod[i])) for i in range(n)], 1)
    # float32 rounding: of the texel coordinate u * W - 0.5 (half an ulp of W moves a weight by that much, times the
    # largest difference between texels) and of the blends
    scale = max(1.0, np.abs(want).max())
    assert np.abs(got - want).max() <= (2 * 2.0 ** -24 * max(h, w) * 2 + 4e-7) * 2 * scale
    # bilinear at whole levels is sample without the blend
    levels = rng.integers(0, last + 1, n)
    assert np.array_equal(tex.bilinear(uv, levels), tex.sample(uv, levels.astype(np.float32)))
    # NaN levels read level 0 rather than failing
    assert np.isfinite(tex.sample(uv[:, :4], np.full(4, np.nan, np.float32))).all()


def numpy_lookup(tex: MipTexture, uv: np.ndarray, lod: np.ndarray, band: float) -> np.ndarray:
    """(C, N) float32 lookups written in numpy from the definition, float32 arithmetic in the documented order
    (MipTexture.sample; texture._lookup_kernel): x = u W - 1/2, y = (1 - v) H - 1/2, fx = x - floor(x), the four
    texels clamped to the edge (8-bit codes decoded through the table first), top = (b - a) fx + a, bottom likewise,
    value = (bottom - top) fy + top; the other level blended in as value + (other - value) t. The level: NaN and
    negative read 0, clamped to the last; frac = lod - floor(lod) (float64), the nearer level rounding half up,
    w = clip((frac - (1/2 - band)) / (2 band), 0, 1) (float64), blended where 0 < w < 1 below the last level."""
    last = len(tex.levels) - 1
    level = np.minimum(np.where(lod > 0, lod, np.float32(0)), np.float32(last))
    base = np.floor(level).astype(np.int64)
    frac = level.astype(np.float64) - base
    near = np.where(frac < 0.5, base, np.minimum(base + 1, last))
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.clip((frac - (0.5 - np.float64(band))) / (2 * np.float64(band)), 0.0, 1.0)
    blend = (band > 0) & (base < last) & (w > 0) & (w < 1)
    other = np.where(frac < 0.5, base + 1, base)
    t = np.where(frac < 0.5, w, 1 - w).astype(np.float32)

    def bilinear(k: np.ndarray) -> np.ndarray:
        out = np.zeros((tex.channels, len(k)), np.float32)
        for level_k in np.unique(k):
            at = k == level_k
            stored = tex.texels(int(level_k))
            h, wd = stored.shape[:2]
            x = uv[0, at] * np.float32(wd) - np.float32(0.5)
            y = (np.float32(1) - uv[1, at]) * np.float32(h) - np.float32(0.5)
            x0, y0 = np.floor(x), np.floor(y)
            fx, fy = x - x0, y - y0
            xi = np.clip(x0, -1, wd).astype(np.int64)
            yi = np.clip(y0, -1, h).astype(np.int64)
            xa, xb = np.clip(xi, 0, wd - 1), np.clip(xi + 1, 0, wd - 1)
            ya, yb = np.clip(yi, 0, h - 1), np.clip(yi + 1, 0, h - 1)
            for c in range(tex.channels):
                texel = stored[..., c] if tex.decode is None else tex.decode[c][stored[..., c]]
                a, b, cc, d = texel[ya, xa], texel[ya, xb], texel[yb, xa], texel[yb, xb]
                top = (b - a) * fx + a
                bottom = (d - cc) * fx + cc
                out[c, at] = (bottom - top) * fy + top
        return out

    value = bilinear(near)
    second = bilinear(np.where(blend, other, near))
    return np.where(blend, value + (second - value) * t, value)


@pytest.mark.parametrize("shape,coded", [((37, 64, 4), True), ((64, 37, 4), False), ((1, 1, 3), True),
                                          ((1, 9, 2), False), ((16, 16, 5), True), ((33, 20, 4), True)])
def test_lookups_are_the_numpy_definition_to_the_bit(shape, coded):
    """The compiled lookup (sample and bilinear) gives the float32 numpy definition's bits: one level and two,
    uv far outside [0, 1] and on texel centres and edges (the edge clamp, coordinates past the int range), levels
    below 0, past the last, NaN and on the blend band's edges, 8-bit and float storage, 2 to 5 channels."""
    rng = np.random.default_rng(sum(shape) + coded)
    h, w, c = shape
    if coded:
        tex = code_pyramid(random_codes(h, w, c, seed=3), colour=min(3, c))
        tex = tex.with_decode(decode_tables(c, min(3, c), offset=0.04))
    else:
        tex = MipTexture(mip_levels(rng.standard_normal((h, w, c)).astype(np.float32)))
    n = 4000
    uv = rng.uniform(-0.3, 1.3, (2, n)).astype(np.float32)
    uv[:, :800] = (np.round(uv[:, :800] * 4 * max(h, w)) / (4 * max(h, w))).astype(np.float32)
    uv[:, 800:840] = rng.choice(np.float32([-1e20, -1e12, 1e12, 1e20]), (2, 40))
    last = len(tex.levels) - 1
    lod = rng.uniform(-1, last + 1, n).astype(np.float32)
    lod[:1000] = np.round(lod[:1000] * 8) / 8
    lod[1000:1010] = np.nan
    for band in (texture_module.BLEND, 0.0):
        got = tex.sample(uv, lod) if band else tex.bilinear(uv, np.floor(np.where(lod > 0, lod, 0) + 0.5))
        want = numpy_lookup(tex, uv, lod if band else np.floor(np.where(lod > 0, lod, 0) + 0.5), band)
        assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


def test_file_key_is_the_resolved_path_and_follows_a_moved_symlink(tmp_path, monkeypatch):
    """_file_key keeps each path's resolution (one stat a frame) and gives what Path.resolve and stat give, also
    for a relative path and for a symlink moved to another file."""
    for name in ("a.png", "b.png"):
        (tmp_path / name).write_bytes(name.encode())
    os.utime(tmp_path / "b.png", ns=(1, 2_000_000_000))
    link = tmp_path / "skin.png"
    link.symlink_to(tmp_path / "a.png")
    monkeypatch.chdir(tmp_path)
    truth = lambda p: (str(p.resolve()), p.stat().st_mtime_ns)
    for _ in range(2):
        assert texture_module._file_key("skin.png") == truth(link)
        assert texture_module._file_key(link) == truth(link)
    link.unlink()
    link.symlink_to(tmp_path / "b.png")
    assert texture_module._file_key("skin.png") == truth(link) == (str(tmp_path.resolve() / "b.png"), 2_000_000_000)
    with pytest.raises(InputError, match="nothing.png: texture file not found"):
        texture_module._file_key(tmp_path / "nothing.png")
