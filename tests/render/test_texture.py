"""Texture lookups against closed form: texel centres, bilinear weights, the v-up convention, box mips, the mip
level of a tilted plane's footprint, the sRGB offset."""

from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest
from render_scenes import flat_material, one_light, quad, render, subject, top_camera

from darthand.render.camera import look_at
from darthand.render.scene import Scene
from darthand.render.shade import surface_hits
from darthand.render.texture import (MipTexture, load_maps, load_texture, mip_levels, srgb8_to_linear_lut)
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
