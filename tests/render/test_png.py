"""The texture loads' PNG fast path (render/png.py) and streaming mip pass against independent truth: every file is
decoded by OpenImageIO (libpng) too, and the pyramids load_maps builds are compared with the ones made the earlier
way (OpenImageIO's codes copied into level 0; levels >= 1 by numpy's float32 box averages and encode_srgb8), to the
byte.
Files are written by libpng itself (OpenImageIO's writer, one PNG filter selection at a time) and by this test's own
encoder (every filter type on every row, the chunk layouts a fast path must refuse). Damaged files give one
InputError line naming the file."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import OpenImageIO as oiio
import pytest

from darthand.errors import InputError
from darthand.render import png
from darthand.render import texture as texture_module
from darthand.render.texture import MipTexture, code_pyramid, decode_tables, load_maps
from darthand.textures.color import encode_srgb8

COLOUR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}          # channels -> PNG colour type
LIBPNG_FILTERS = {"none": 0x08, "sub": 0x10, "up": 0x20, "average": 0x40, "paeth": 0x80, "adaptive": 0xF8}


def pattern(h, w, c, seed=0):
    """Codes with both smooth gradients (which Sub/Up/Paeth predict) and noise (which they do not)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    smooth = (x[..., None] * 7 + y[..., None] * 3 + np.arange(c) * 50) % 256
    noisy = rng.integers(0, 256, (h, w, c))
    return np.where(rng.random((h, w, 1)) < 0.3, noisy, smooth).astype(np.uint8)


def oiio_codes(path, unassociated=False) -> np.ndarray:
    config = oiio.ImageSpec()
    if unassociated:
        config.attribute("oiio:UnassociatedAlpha", 1)
    buf = oiio.ImageBuf(str(path), 0, 0, config)
    return buf.get_pixels(oiio.UINT8)


def write_libpng(path, img, flags):
    spec = oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], oiio.UINT8)
    spec.attribute("png:filter", flags)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(img))
    assert buf.write(str(path))
    return path


def chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def filtered(img: np.ndarray, kinds) -> bytes:
    """The scanlines of img (H, W, C) uint8 with row r filtered by kinds[r] (0..4), as ISO/IEC 15948 defines."""
    h, w, c = img.shape
    rows = img.reshape(h, w * c).astype(np.int64)
    out = bytearray()
    for r in range(h):
        cur = rows[r]
        up = rows[r - 1] if r else np.zeros_like(cur)
        left = np.concatenate([np.zeros(c, np.int64), cur[:-c]])
        up_left = np.concatenate([np.zeros(c, np.int64), up[:-c]])
        kind = kinds[r % len(kinds)]
        if kind == 4:
            p = left + up - up_left
            pa, pb, pc = np.abs(p - left), np.abs(p - up), np.abs(p - up_left)
            pred = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, up, up_left))
        else:
            pred = [np.zeros_like(cur), left, up, (left + up) // 2][kind]
        out.append(kind)
        out += ((cur - pred) % 256).astype(np.uint8).tobytes()
    return bytes(out)


def write_own(path, img, kinds=(0, 1, 2, 3, 4), extra=(), depth=8, interlace=0, idat=None, split=3):
    """A PNG of img by this test's encoder: rows filtered by `kinds` in turn, the zlib stream split over `split`
    IDAT chunks, `extra` chunks (kind, data) placed after IHDR."""
    h, w, c = img.shape
    data = zlib.compress(filtered(img, kinds), 6) if idat is None else idat
    parts = [data[i * len(data) // split:(i + 1) * len(data) // split] for i in range(split)]
    body = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, COLOUR_TYPES[c], 0, 0,
                                                            interlace))
    body += b"".join(chunk(k, d) for k, d in extra) + b"".join(chunk(b"IDAT", p) for p in parts)
    path.write_bytes(body + chunk(b"IEND", b""))
    return path


def fast_decode(path) -> np.ndarray:
    f = png.open_png8(path)
    assert f is not None, path
    out = np.zeros((f.height, f.width, f.channels), np.uint8)
    assert f.decode_into(out, 0, range(f.channels))
    return out


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("size", [(37, 53), (1, 1), (2, 7), (64, 64)])
def test_decode_equals_openimageio_for_every_libpng_filter(tmp_path, channels, size):
    img = pattern(*size, channels)
    for name, flags in LIBPNG_FILTERS.items():
        path = write_libpng(tmp_path / f"{name}.png", img, flags)
        got = fast_decode(path)
        assert np.array_equal(got, oiio_codes(path)) and np.array_equal(got, img), name


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
def test_every_filter_type_on_every_row_and_channel_count(tmp_path, channels):
    """All five filter types in turn, row by row; grey and RGB through open_png8, and the unfilter of 2 and 4
    channels (alpha files, which the loads leave to OpenImageIO) against OpenImageIO's unassociated read."""
    img = pattern(23, 19, channels, seed=channels)
    path = write_own(tmp_path / "mixed.png", img)
    assert np.array_equal(oiio_codes(path, unassociated=True), img)
    if channels in (1, 3):
        assert np.array_equal(fast_decode(path), img)
        return
    assert png.open_png8(path) is None                    # alpha: OpenImageIO associates it; the loads use that
    raw = np.frombuffer(zlib.decompress(zlib.compress(filtered(img, (0, 1, 2, 3, 4)))), np.uint8)
    out = np.zeros(img.shape, np.uint8)
    assert png._unfilter_kernel(raw, channels, np.arange(channels), 0, out)
    assert np.array_equal(out, img)


def test_decode_into_scatters_channels_into_a_wider_array(tmp_path):
    img = pattern(9, 11, 3)
    f = png.open_png8(write_own(tmp_path / "rgb.png", img))
    out = np.zeros((9, 11, 5), np.uint8)
    assert f.decode_into(out, 2, (2, 0, 1))
    assert np.array_equal(out[..., 2:], img[..., [2, 0, 1]]) and not out[..., :2].any()
    grey = png.open_png8(write_own(tmp_path / "grey.png", img[..., :1]))
    assert grey.decode_into(out, 0, (0, 0, 0)) and np.array_equal(out[..., :3], np.repeat(img[..., :1], 3, 2))


def test_files_the_fast_path_must_leave_to_openimageio(tmp_path):
    img = pattern(8, 8, 3)
    refused = {
        "palette_transparency": write_own(tmp_path / "trns.png", img, extra=[(b"tRNS", b"\x00\x01\x00\x02\x00\x03")]),
        "significant_bits": write_own(tmp_path / "sbit.png", img, extra=[(b"sBIT", b"\x05\x06\x05")]),
        "interlaced": write_own(tmp_path / "adam7.png", img, interlace=1),
        "sixteen_bit": write_own(tmp_path / "deep.png", img, depth=16),
        "rgba": write_libpng(tmp_path / "rgba.png", pattern(8, 8, 4), 0x08),
        "not_png": tmp_path / "x.png",
    }
    (tmp_path / "x.png").write_bytes(b"GIF89a" + bytes(40))
    for name, path in refused.items():
        assert png.open_png8(path) is None, name
    # Metadata chunks leave the pixels alone: read on the fast path.
    tagged = write_own(tmp_path / "tagged.png", img, extra=[(b"gAMA", struct.pack(">I", 45455)), (b"sRGB", b"\x00"),
                                                           (b"tEXt", b"Software\x00test")])
    assert np.array_equal(fast_decode(tagged), oiio_codes(tagged))


def box_numpy(level: np.ndarray, pairs: bool) -> np.ndarray:
    """The next level of (H, W, C) float32 values by numpy, in the float32 order the pyramids have always been
    summed in: (a + b) + (c + d) of horizontal pairs (8-bit level 0 of an even width), else ((a + b) + c) + d; an
    odd last row or column repeated, a side of 1 averaged along the other only."""
    H, W = level.shape[:2]
    rows, cols = np.minimum(np.arange(0, H, 2) + 1, H - 1), np.minimum(np.arange(0, W, 2) + 1, W - 1)
    a, b = level[0::2][:, 0::2], level[0::2][:, cols]
    c, d = level[rows][:, 0::2], level[rows][:, cols]
    quarter, half = np.float32(0.25), np.float32(0.5)
    if pairs:
        return ((a + b) + (c + d)) * quarter if H > 1 else (a + b) * half
    if H > 1 and W > 1:
        return (((a + b) + c) + d) * quarter
    return (a + c) * half if H > 1 else (a + b) * half if W > 1 else a * np.float32(1)


def old_pyramid(level0: np.ndarray, colour: int) -> MipTexture:
    """The 8-bit pyramid as load_maps made it before its streaming pass, by numpy: level 0's codes decoded to float32
    (decode_tables), box averages level by level in float32, then encode_srgb8 of the colour channels and
    rint(x 255) of the others."""
    h, w, c = level0.shape
    tex = MipTexture.empty(h, w, c, np.uint8, decode_tables(c, colour))
    tex.texels(0)[...] = level0
    table = decode_tables(c, colour)
    values = np.stack([table[k][level0[..., k]] for k in range(c)], axis=-1)
    for k in range(1, len(tex.offsets)):
        values = box_numpy(values, pairs=k == 1 and w % 2 == 0)
        tex.texels(k)[..., :colour] = encode_srgb8(values[..., :colour])
        tex.texels(k)[..., colour:] = np.rint(values[..., colour:] * np.float32(255))
    return tex


@pytest.mark.parametrize("shape", [(1, 1), (1, 6), (7, 1), (5, 7), (6, 3), (2, 2), (33, 64), (64, 17), (48, 48)])
@pytest.mark.parametrize("channels,colour", [(4, 3), (3, 3), (5, 3), (1, 0), (2, 1)])
def test_streaming_mips_equal_numpys_float_chain_to_the_byte(shape, channels, colour):
    codes = pattern(*shape, channels, seed=sum(shape))
    codes[: shape[0] // 2, : shape[1] // 2, :colour] = 2                 # dark: the sRGB curve's linear segment
    assert np.array_equal(code_pyramid(codes, colour).flat, old_pyramid(codes, colour).flat)


@pytest.mark.parametrize("albedo_channels", [1, 2, 3, 4])
def test_load_maps_equals_the_openimageio_pyramid(tmp_path, albedo_channels):
    """load_maps of an albedo (grey, grey + alpha, RGB, RGBA) and a grey or RGB data map: the pyramid made from
    OpenImageIO's codes, as load_maps made it before (alpha files take OpenImageIO's path, associated alpha)."""
    albedo = write_libpng(tmp_path / "albedo.png", pattern(40, 24, albedo_channels, seed=1), 0xF8)
    for data_channels, channels in ((1, (0,)), (3, (1, 2))):
        data = write_own(tmp_path / f"data{data_channels}.png", pattern(40, 24, data_channels, seed=2))
        texture_module.clear_cache()
        got = load_maps(albedo, data=data, channels=channels)
        rgb, values = oiio_codes(albedo), oiio_codes(data)
        level0 = np.concatenate([rgb[..., :3] if albedo_channels >= 3 else np.repeat(rgb[..., :1], 3, 2),
                                 values[..., list(channels)]], axis=2)
        assert np.array_equal(got.flat, old_pyramid(level0, 3).flat), (albedo_channels, data_channels)
    texture_module.clear_cache()


def damaged_files(tmp_path) -> dict:
    img = pattern(32, 32, 3)
    good = write_own(tmp_path / "good.png", img).read_bytes()
    start = good.index(b"IDAT") - 4
    n = struct.unpack(">I", good[start:start + 4])[0]
    payload = bytearray(good[start + 8:start + 8 + n])
    payload[len(payload) // 2:] = bytes(len(payload) - len(payload) // 2)           # zeros: not a deflate stream
    broken_zlib = good[:start] + chunk(b"IDAT", bytes(payload)) + good[start + 12 + n:]
    bad_crc = bytearray(good)
    bad_crc[start + 10] ^= 0xFF
    rows = bytearray(filtered(img, (0,)))
    rows[5 * (1 + 32 * 3)] = 7                                                     # row 5: filter type 7
    files = {"truncated": good[: len(good) // 2], "broken_zlib": broken_zlib, "bad_crc": bytes(bad_crc),
             "empty": b"", "short_scanlines": None, "bad_filter": None}
    paths = {}
    for name, data in files.items():
        paths[name] = tmp_path / f"{name}.png"
        if data is not None:
            paths[name].write_bytes(data)
    write_own(paths["short_scanlines"], img, idat=zlib.compress(filtered(img, (0,))[:-50]))
    write_own(paths["bad_filter"], img, idat=zlib.compress(bytes(rows)))
    return paths


def test_damaged_files_give_one_line_naming_the_file(tmp_path):
    paths = damaged_files(tmp_path)
    # Damage found only while decoding (the chunks and CRCs are sound): the fast path gives up, OpenImageIO reports.
    assert all(png.open_png8(paths[name]) is not None for name in ("broken_zlib", "short_scanlines", "bad_filter"))
    for name, path in paths.items():
        texture_module.clear_cache()
        with pytest.raises(InputError) as err:
            load_maps(path, data=path, channels=(0,))
        message = str(err.value)
        assert str(path) in message and "\n" not in message, (name, message)
