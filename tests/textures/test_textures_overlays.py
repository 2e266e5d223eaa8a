"""Overlays at the sizes and contrast the catalogue asks for: a tattoo's ink covers its motif's region at the
drawn size, dark enough to read on every tone; sizes are drawn per site from the catalogue; scars and palm creases
change the skin by more than a render's noise."""

import dataclasses

import numpy as np
import pytest

from darthand.textures import color
from darthand.textures.motifs import star_points
from darthand.textures.overlays import TATTOO_STROKE, sample_tattoos
from darthand.textures.surface import Surface
from darthand.textures.variant import render_texels
from texture_hand import entries, entry, fixture_bake, spec

RES = 256


def winding_inside(points, polygon):
    """(M,) bool: winding number of the closed polygon (K, 2) about each point is non-zero (sum of the signed
    angles its edges subtend)."""
    a = polygon[None, :, :] - points[:, None, :]
    b = np.roll(a, -1, axis=1)
    angles = np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], (a * b).sum(-1))
    return np.abs(angles.sum(1)) > np.pi


def with_params(e, category, **changes):
    params = {**e.params, category: {**e.params[category], **changes}}
    return dataclasses.replace(e, params=params)


@pytest.mark.parametrize("tone", ["light", "dark"])
def test_tattoo_covers_its_motif_at_the_drawn_size(tone):
    """A 40 mm star on the back of the hand: the inked texels are those whose position on the surface (decal
    coordinates: metres along the site's forward and side directions) falls inside the star polygon at that size
    grown by the stroke (winding numbers about the polygon's vertices, not the motif's distance function); its
    tips reach 0.95 x 20 mm from the centre; the ink takes at least 60 % of the luminance away, on the lightest
    and the darkest tone."""
    b = fixture_bake(RES)
    half = 0.020
    place = {"site": "dorsum", "along": 0.5, "across": 0.0}
    e = with_params(entry(f"{tone}_tattoos_01"), "tattoos", motif="star", size_mm=2000 * half, angle=0.0, age=0.0,
                    outline=False, ink="black", ink_srgb=[0.1, 0.1, 0.13], place=place)
    inked, _ = render_texels(b, e)
    skin, _ = render_texels(b, e, overlay=False)
    ratio = color.luminance(inked) / np.maximum(color.luminance(skin), 1e-6)
    surface = Surface(b)
    idx, uv = surface.decal(surface.site("dorsum", along=0.5, across=0.0), 1.5 * half, facing=0.35)
    star = star_points(5, 0.95, 0.4) * half
    grown = star * (1 + TATTOO_STROKE / np.linalg.norm(star, axis=1, keepdims=True))   # about the stroke, outward
    truth = np.zeros(len(ratio), bool)
    truth[idx] = winding_inside(uv, grown)
    ink = ratio < 0.5
    assert (ink & truth).sum() / (ink | truth).sum() > 0.85
    assert not ink[np.setdiff1d(np.arange(len(ink)), idx)].any()
    reach = np.linalg.norm(uv[ratio[idx] < 0.9], axis=1).max()      # visible ink; the tips are under a texel
    texel = surface.texel_size
    assert 0.95 * half - 2 * texel <= reach <= 0.95 * half + TATTOO_STROKE + 2 * texel
    assert np.median(ratio[truth]) < 0.4


def test_tattoo_sizes_come_from_their_site():
    """Each site draws its size from the catalogue's range for it: fingers small, the forearm large."""
    s = spec()["overlays"]["tattoos"]
    rng = np.random.default_rng(0)
    seen = {}
    for i in range(400):
        p = sample_tattoos(rng, s, i)
        lo, hi = s["site_size_mm"].get(p["place"]["site"], s["size_mm"])
        assert lo <= p["size_mm"] <= hi
        seen.setdefault(p["place"]["site"], []).append(p["size_mm"])
    assert min(seen["wrist_dorsal"]) > max(seen["finger"])
    assert np.median(seen["dorsum"]) >= 30


def test_catalogue_tattoos_and_scars_are_centimetres_long():
    """Realistic sizes: tattoos on the back of the hand or the forearm are a few centimetres, scars too."""
    for e in entries():
        if e.category == "tattoos" and e.params["tattoos"]["place"]["site"] in ("dorsum", "wrist_dorsal",
                                                                                 "wrist_inner"):
            assert e.params["tattoos"]["size_mm"] >= 25, e.id
        if e.category == "scars" and e.params["scars"]["place"]["site"] != "finger":
            assert e.params["scars"]["length_mm"] >= 25 and e.params["scars"]["width_mm"] >= 2.5, e.id


@pytest.mark.parametrize("entry_id", ["light_scars_00", "brown_scars_00", "dark_scars_00", "light_palm_prints_00",
                                      "dark_palm_prints_00"])
def test_scars_and_creases_stand_out(entry_id):
    """The mark changes the albedo of its texels by a visible amount: a luminance or redness change of 15 % at
    the core of the mark (a 512^2 render resolves about 0.5 mm, and a few percent disappears in shading)."""
    b = fixture_bake(RES)
    e = entry(entry_id)
    marked, _ = render_texels(b, e)
    skin, _ = render_texels(b, e, overlay=False)
    change = np.abs(marked - skin).max(1) / np.maximum(skin.max(1), 1e-6)
    assert (change > 1e-3).any(), entry_id
    assert np.percentile(change[change > 1e-3], 90) > 0.15, entry_id
