"""Rendered variants: tone order, offset, palm vs back, overlays where they belong, roughness, determinism."""

import numpy as np
import pytest

from darthand.model.layout import FACE_LABEL_IDS
from darthand.textures import color
from darthand.textures.variant import render_texels, render_variant
from texture_hand import entries, entry, fixture_bake, fixture_model

RES = 128


def _lum(rgb):
    return color.luminance(rgb)


def _changed(b, e, tol=1e-4):
    """Texels whose albedo the entry's overlay changed (against its base skin alone)."""
    with_overlay, _ = render_texels(b, e)
    base, _ = render_texels(b, e, overlay=False)
    return np.abs(with_overlay - base).max(1) > tol


def test_tone_order_dark_brown_light_at_zero_offset():
    b = fixture_bake(RES)
    means = {}
    for tone in ("dark", "brown", "light"):
        e = entry(f"{tone}_moles_00").with_offset(0.0)
        rgb, _ = render_texels(b, e, overlay=False)
        means[tone] = float(_lum(rgb[b.inside]).mean())
    assert means["dark"] < means["brown"] < means["light"]


def test_offset_moves_luminance_monotonically():
    b = fixture_bake(RES)
    e = entry("brown_tattoos_03")
    lum = []
    for o in (-0.15, -0.05, 0.0, 0.05, 0.15):
        v = render_variant(b, e.with_offset(o))
        lum.append(float(_lum(color.srgb_to_linear(v.albedo.reshape(-1, 3) / 255.0)).mean()))
    assert all(a < b_ for a, b_ in zip(lum, lum[1:]))


def test_the_lightest_variants_do_not_clip():
    """Skin albedo stays below 1: in the catalogue's lightest variants (with their own offsets) almost no skin texel
    reaches sRGB 255 in any channel (before the offset cap, 53 of 325 variants had over 20 % of texels at red 255)."""
    b = fixture_bake(RES)
    lightest = sorted((e for e in entries() if e.category in ("moles", "freckles", "tan", "veins")),
                      key=lambda e: min(e.tone_srgb) + e.offset, reverse=True)[:4]
    for e in lightest:
        albedo = render_variant(b, e).albedo[b.coverage()]
        assert (albedo == 255).any(axis=1).mean() < 0.01, e.id


@pytest.mark.parametrize("tone", ["dark", "brown", "light"])
def test_palm_is_lighter_than_the_back(tone):
    b = fixture_bake(RES)
    rgb, _ = render_texels(b, entry(f"{tone}_moles_01").with_offset(0.0), overlay=False)
    lum = _lum(rgb)
    palm = b.inside & (b.label == FACE_LABEL_IDS["palm"]) & (b.fields["wrist"] < 0.05)
    back = b.inside & (b.label == FACE_LABEL_IDS["dorsum"]) & (b.fields["wrist"] < 0.05)
    assert np.median(lum[palm]) > 1.1 * np.median(lum[back])


def test_knuckles_and_fingertips_are_redder_than_the_back():
    b = fixture_bake(RES)
    rgb, _ = render_texels(b, entry("light_moles_02").with_offset(0.0), overlay=False)
    redness = rgb[:, 0] / rgb[:, 1]
    f = b.fields
    back = (f["knuckle"] < 0.05) & (f["tip"] < 0.05) & (f["palmar"] < 0.1) & (f["veins0"] < 0.1)
    assert np.median(redness[b.fields["knuckle"] > 0.7]) > np.median(redness[back])
    assert np.median(redness[b.fields["tip"] > 0.7]) > np.median(redness[back])


@pytest.mark.parametrize("entry_id", ["dark_moles_03", "light_moles_03"])
def test_nail_beds_are_lighter_and_have_a_pale_lunula(entry_id):
    b = fixture_bake(256)
    rgb, rough = render_texels(b, entry(entry_id).with_offset(0.0), overlay=False)
    lum = _lum(rgb)
    nail = b.label == FACE_LABEL_IDS["nail"]
    skin_near = (b.fields["cuticle"] > 0.2) & ~nail
    assert np.median(lum[nail]) > 1.2 * np.median(lum[skin_near])
    u, v = b.fields["nail_u"], np.abs(b.fields["nail_v"])
    lunula = nail & (u > 0.06) & (u < 0.14) & (v < 0.3)
    middle = nail & (u > 0.4) & (u < 0.7) & (v < 0.5)
    assert lunula.sum() >= 3 and middle.sum() >= 3
    assert np.median(lum[lunula]) > np.median(lum[middle])
    assert np.median(rough[nail]) < np.median(rough[~nail])


def test_nail_colours_only_on_nails_with_glossy_roughness():
    b = fixture_bake(RES)
    nail = b.label == FACE_LABEL_IDS["nail"]
    for e in [x for x in entries() if x.category == "nail_colors"][::7]:
        changed = _changed(b, e)
        assert changed.any(), e.id
        assert not (changed & ~nail).any(), e.id
        _, rough = render_texels(b, e)
        _, base_rough = render_texels(b, e, overlay=False)
        finish = e.params["nail_colors"]["finish"]
        glossier = np.median(rough[changed]) < np.median(base_rough[changed])
        assert glossier == (finish != "matte"), (e.id, finish)


def test_every_category_changes_its_region_only():
    b = fixture_bake(RES)
    bone, palmar = b.fields["bone"], b.fields["palmar"]
    for e in entries():
        if e.index not in (0, 1) or e.tone not in ("light", "base"):
            continue
        changed = _changed(b, e)
        assert changed.any(), e.id
        if e.category == "palm_prints":
            assert (palmar[changed] > 0.2).mean() > 0.95, e.id
        if e.category == "bandage" and e.params["bandage"]["style"] == "gauze_finger":
            finger = ("thumb", "index", "middle", "ring", "pinky").index(e.params["bandage"]["finger"])
            assert (bone[changed] // 3 == finger).all(), e.id
        if e.category in ("tattoos", "scars", "moles"):
            # Local marks: a small part of the surface.
            assert changed.mean() < 0.2, e.id


def test_render_is_deterministic_and_resolution_consistent():
    e = entry("light_tattoos_07")
    b = fixture_bake(RES)
    v1, v2 = render_variant(b, e), render_variant(b, e)
    assert np.array_equal(v1.albedo, v2.albedo) and np.array_equal(v1.roughness, v2.roughness)
    assert v1.albedo.shape == (RES, RES, 3) and v1.albedo.dtype == np.uint8
    # Defined on the surface: the same entry at twice the resolution, averaged down, matches closely.
    hi = render_variant(fixture_bake(2 * RES), e).albedo.astype(float)
    down = hi.reshape(RES, 2, RES, 2, 3).mean(axis=(1, 3))
    inside = fixture_bake(RES).coverage() & _interior(fixture_bake(RES))
    diff = np.abs(down - v1.albedo)[inside]
    assert np.median(diff) < 4.0


def _interior(b):
    from scipy import ndimage

    return ndimage.binary_erosion(b.coverage(), iterations=2)


def test_left_hand_gets_the_right_hands_textures_on_its_own_uvs():
    from darthand.model.mirror import mirror_model
    from darthand.textures.bake import bake

    right = fixture_model()
    left = mirror_model(right)
    assert left.side == "left" and np.array_equal(left.uvs, right.uvs)
    e = entry("light_tattoos_07")
    a = render_variant(bake(left, 64), e).albedo
    assert np.array_equal(a, render_variant(fixture_bake(64), e).albedo)


def test_tone_scale_is_continuous_and_monotone():
    from darthand.textures.catalog import tone_rgb
    from texture_hand import spec

    mst = np.linspace(1.0, 10.0, 91)
    rgb = np.array([tone_rgb(spec(), m) for m in mst])
    lum = _lum(rgb)
    assert (np.diff(lum) < 0).all()
    assert np.abs(np.diff(rgb, axis=0)).max() < 0.05  # no jumps between neighbouring steps
    melanin = [color.tone_melanin(c) for c in rgb]
    assert (np.diff(melanin) >= -1e-9).all() and melanin[-1] > 5 * max(melanin[0], 0.1)
    # Anchors are reproduced at integer steps.
    anchors = [color.srgb_to_linear(color.hex_to_srgb(h)) for h in spec()["tone_scale"]["anchors_srgb"]]
    assert np.allclose(rgb[::10], anchors, atol=1e-6)
