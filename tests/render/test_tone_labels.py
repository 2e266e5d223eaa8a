"""Labels' texture.tone_srgb: the skin tone a frame's albedo shows on the back of the hand, checked against the
texture image itself (the median of its back-of-hand texels, found from the textures stage's bake), not against
the catalogue fields it is made from."""

from __future__ import annotations

import json

import numpy as np
import pytest

from darthand.render.api import Renderer
from darthand.render.assets import HandAssets
from darthand.schemas import check_schema
from darthand.textures.color import luminance, srgb_to_linear
from darthand.textures.loader import TextureSet, load_texture_catalog
from darthand.textures.imageio import read_image


def back_of_hand_median(tex_dir, albedo) -> np.ndarray:
    """(3,) sRGB median of the albedo's texels on the back of the hand (the bake's palmar field < 0.2, no nail)."""
    bake = np.load(next(tex_dir.glob("bake_*.npz")))
    texel = bake["texel"][(bake["field_palmar"] < 0.2) & (bake["field_nail"] < 0.05) & bake["inside"]]
    image = read_image(albedo)[..., :3].reshape(-1, 3) / 255.0
    return np.median(image[texel], axis=0)


@pytest.mark.parametrize("offset", [0.0, 0.06, -0.08])
def test_tone_is_what_the_albedo_shows_on_the_back_of_the_hand(small_build, offset):
    tex_dir = small_build / "tex"
    source = HandAssets.load(small_build / "model" / "right.npz", tex_dir, None)
    renderer = Renderer(source)
    for texture in load_texture_catalog(tex_dir):
        frame = renderer.render("fist", texture=texture.id, skin_tone_offset=offset, width=48, height=48, samples=1,
                                shading={"ao_rays": 0})
        tone = np.asarray(frame.labels["texture"]["tone_srgb"])
        shown = np.clip(back_of_hand_median(tex_dir, texture.albedo) + offset, 0, 1)
        assert np.abs(tone - shown).max() < 0.06, (texture.id, tone, shown)
        check_schema(json.loads(json.dumps(frame.labels)), "labels.schema.json", "labels")


def test_tone_orders_darker_textures_darker(small_build):
    """The two fixture textures (a brown and a light tone): the labels' tone is darker where the image is."""
    tex_dir = small_build / "tex"
    source = HandAssets.load(small_build / "model" / "right.npz", tex_dir, None)
    tones = {t.id: source.skin_tone(t.id) for t in load_texture_catalog(tex_dir)}
    shown = {t.id: back_of_hand_median(tex_dir, t.albedo) for t in load_texture_catalog(tex_dir)}
    lum = lambda srgb: float(luminance(srgb_to_linear(np.asarray(srgb))))
    assert (lum(tones["brown_moles_00"]) < lum(tones["light_tattoos_07"])) == \
        (lum(shown["brown_moles_00"]) < lum(shown["light_tattoos_07"]))


def test_checker_and_sets_without_tones_record_null(small_build):
    tex_dir = small_build / "tex"
    source = HandAssets.load(small_build / "model" / "right.npz", tex_dir, None)
    first = load_texture_catalog(tex_dir)[0]
    source.textures["no_tone"] = TextureSet("no_tone", first.albedo, first.roughness)
    assert source.skin_tone("no_tone") is None
    assert source.skin_tone("checker") is None
    assert source.skin_tone("plain", 2.0) == [1.0, 1.0, 1.0]
    frame = Renderer(source).render("fist", texture="no_tone", width=32, height=32, samples=1, shading={"ao_rays": 0})
    assert frame.labels["texture"]["tone_srgb"] is None
    check_schema(json.loads(json.dumps(frame.labels)), "labels.schema.json", "labels")
