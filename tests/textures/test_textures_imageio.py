"""The image writers: PNG bytes as OpenImageIO's own ImageBuf writer gives them, .tx files that OpenImageIO's
maketx would write (pixels of every MIP level, texture tags), without time stamps."""

import hashlib

import numpy as np
import OpenImageIO as oiio
import pytest
from darthand.textures.imageio import mip_levels, mip_pyramid, read_image, write_png, write_tx


def codes(h, w, c=3, seed=0):
    """Smooth-ish random uint8 pixels (neighbouring texels differ, so block means hit every rounding case)."""
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 256, (h // 4 + 1, w // 4 + 1, c)).repeat(4, 0).repeat(4, 1)[:h, :w]
    return np.clip(base.astype(int) + rng.integers(-9, 10, (h, w, c)), 0, 255).astype(np.uint8)


def digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_png_bytes_match_imagebuf_writer(tmp_path):
    """write_png encodes straight from the array; the bytes are those OpenImageIO's ImageBuf.write gives with the
    same settings (so catalogue PNGs keep their sha256)."""
    for img, srgb in ((codes(64, 32), True), (codes(32, 32, 1)[..., 0], False)):
        pixels = img if img.ndim == 3 else img[..., None]
        buf = oiio.ImageBuf(oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.UINT8))
        buf.set_pixels(oiio.ROI(), pixels)
        buf.specmod().attribute("oiio:ColorSpace", "sRGB" if srgb else "Raw")
        buf.specmod().attribute("png:compressionLevel", 3)
        buf.specmod().attribute("png:filter", 8)
        assert buf.write(str(tmp_path / "ref.png"))
        write_png(tmp_path / "ours.png", img, srgb=srgb)
        assert digest(tmp_path / "ours.png") == digest(tmp_path / "ref.png")
        assert np.array_equal(read_image(tmp_path / "ours.png"), pixels)


def test_mip_pyramid_is_the_rounded_block_mean():
    img = codes(32, 16)
    levels = mip_pyramid(img)
    assert [lv.shape[:2] for lv in levels] == [(32 >> k, max(16 >> k, 1)) for k in range(6)]
    for lv in levels:
        h, w = lv.shape[:2]
        mean = img.astype(float).reshape(h, 32 // h, w, 16 // w, 3).mean(axis=(1, 3))
        assert np.abs(lv - mean).max() <= 0.5 and np.array_equal(lv, np.floor(mean + 0.5))
    with pytest.raises(ValueError, match="power of two"):
        mip_pyramid(codes(24, 16))


def test_tx_matches_maketx_and_carries_no_time_stamp(tmp_path):
    """Against OpenImageIO's make_texture (box filter, clamp): the same level sizes, tiles and texture tags,
    level 0 identical and coarser levels within one code (maketx's float sums round exact halves either way);
    no DateTime at any level, so writing the same pixels twice gives the same bytes."""
    img = codes(128, 128)
    write_tx(tmp_path / "a.tx", img)
    write_tx(tmp_path / "b.tx", img)
    assert digest(tmp_path / "a.tx") == digest(tmp_path / "b.tx")
    config = oiio.ImageSpec()
    config.attribute("maketx:filtername", "box")
    config.attribute("wrapmodes", "clamp,clamp")
    buf = oiio.ImageBuf(oiio.ImageSpec(128, 128, 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(), img)
    assert oiio.ImageBufAlgo.make_texture(oiio.MakeTxTexture, buf, str(tmp_path / "ref.tx"), config)
    assert mip_levels(tmp_path / "a.tx") == mip_levels(tmp_path / "ref.tx") == [(128 >> k,) * 2 for k in range(8)]
    assert np.array_equal(read_image(tmp_path / "a.tx"), img)
    for k in range(8):
        diff = np.abs(read_image(tmp_path / "a.tx", k).astype(int) - read_image(tmp_path / "ref.tx", k))
        assert diff.max() <= 1, k
    inp = oiio.ImageInput.open(str(tmp_path / "a.tx"))
    ref = oiio.ImageInput.open(str(tmp_path / "ref.tx"))
    try:
        for k in range(8):
            assert inp.seek_subimage(0, k) and ref.seek_subimage(0, k)
            s, r = inp.spec(), ref.spec()
            assert (s.tile_width, s.tile_height) == (r.tile_width, r.tile_height) == (64, 64) or s.width < 64
            assert s.getattribute("DateTime") is None and r.getattribute("DateTime") is not None
            for tag in ("textureformat", "wrapmodes", "compression"):
                assert s.getattribute(tag) == r.getattribute(tag), (k, tag)
    finally:
        inp.close()
        ref.close()
