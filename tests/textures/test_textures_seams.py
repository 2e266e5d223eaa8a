"""Seams and padding: both sides of every UV seam agree after padding, and no background colour reaches any
island at any MIP level."""

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from darthand.model.layout import FACE_LABEL_IDS
from darthand.model.atlas import ensure_uvs, seam_edges
from darthand.textures.build import build_textures
from darthand.textures.imageio import mip_levels, read_image
from darthand.textures.variant import render_variant
from texture_hand import entry, fixture_bake, fixture_model, spec

RES = 256


def bilinear(img, uv):
    """Bilinear lookup of an (R, R, C) image at UVs (M, 2) (bottom-left origin, texel centres at +0.5)."""
    res = img.shape[0]
    x, y = uv[:, 0] * res - 0.5, (1 - uv[:, 1]) * res - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]

    def at(r, c):
        return img[np.clip(r, 0, res - 1), np.clip(c, 0, res - 1)].astype(float)

    top = at(y0, x0) * (1 - fx) + at(y0, x0 + 1) * fx
    bottom = at(y0 + 1, x0) * (1 - fx) + at(y0 + 1, x0 + 1) * fx
    return top * (1 - fy) + bottom * fy


def seam_differences(img, model, b, skip_near_nails=0.003):
    """Largest channel difference (8-bit levels) between the two sides of every seam edge, sampled at five
    points along each edge; edges within `skip_near_nails` metres of a nail are left out (the nail's hard edge
    is real texture detail at texel scale, not a seam artefact)."""
    s = seam_edges(model.faces, model.faces_uv, model.uvs)
    mid = model.v_template[s["vertices"]].mean(1)
    nails = b.position[b.label == FACE_LABEL_IDS["nail"]]
    far = cKDTree(nails).query(mid)[0] > skip_near_nails
    t = np.array([0.2, 0.35, 0.5, 0.65, 0.8])[None, :, None]
    uv = s["uv"][far]
    side_a = (uv[:, 0, 0][:, None] * (1 - t) + uv[:, 0, 1][:, None] * t).reshape(-1, 2)
    side_b = (uv[:, 1, 0][:, None] * (1 - t) + uv[:, 1, 1][:, None] * t).reshape(-1, 2)
    return np.abs(bilinear(img, side_a) - bilinear(img, side_b)).max(1)


@pytest.mark.parametrize("atlas", [False, True], ids=["template_uvs", "xatlas"])
@pytest.mark.parametrize("entry_id", ["light_moles_00", "dark_scars_00"])
def test_both_sides_of_every_seam_agree(atlas, entry_id):
    b = fixture_bake(RES, atlas)
    model = ensure_uvs(fixture_model(with_uvs=False), RES) if atlas else fixture_model()
    img = render_variant(b, entry(entry_id).with_offset(0.0)).albedo
    d = seam_differences(img, model, b)
    assert len(d) > 100
    assert d.mean() < 3.0 and np.percentile(d, 95) < 10.0, (d.mean(), np.percentile(d, 95))
    # The same measure on the unpadded image (background black) is far off: it detects bleeding.
    raw = img.copy()
    raw[~b.coverage()] = 0
    assert seam_differences(raw, model, b).mean() > 5 * d.mean()


def test_no_background_near_islands_at_any_mip_level(tmp_path):
    catalog = build_textures(fixture_model(), spec(), tmp_path, res=RES, ids=["light_tattoos_00"], workers=1,
                             progress=False, sheet=False)
    e = catalog["entries"][0]
    cover = read_image(tmp_path / catalog["bake"]["coverage"])[..., 0] > 0
    tx = tmp_path / e["files"]["tx"]
    levels = mip_levels(tx)
    assert len(levels) == RES.bit_length()
    for level, (w, _) in enumerate(levels):
        img = read_image(tx, level).astype(float)
        k = RES // w
        cov = cover.reshape(w, k, w, k).any(axis=(1, 3))
        if not cov.any():
            continue
        lum = img @ [0.2126, 0.7152, 0.0722]
        band = ndimage.binary_dilation(cov, iterations=2) if w > 4 else np.ones_like(cov)
        # Bilinear lookups near an island at this level read texels within two texels of it: none of them
        # may be (or be darkened toward) the black background.
        assert lum[band].min() > 0.6 * lum[cov].min(), level
