"""Skin's dual-lobe specular and sheen (render/skin_specular.py) and its relief (render/skin_detail.py): energy by a
white-furnace integral written here, the sheen's growth toward grazing angles, the bump map's tangent frame on a
flat quad against the known tilt of a known slope, the relief's determinism and its continuity across UV seams, and
on the hand: options off by default, labels, mask, edges and normals unchanged with both on."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from render_scenes import assert_only_shading_differs

from darthand.errors import InputError
from darthand.render import skin_detail, skin_specular
from darthand.render.api import Renderer
from darthand.render.scene import FaceData
from darthand.render.shade import Hits, ShadingOptions
from darthand.render.texture import float_pyramid
from darthand.render.subject import PLAIN_SKIN, SKIN_F0, Surface, skin_material
from darthand.textures.bake import bake

# ------------------------------------------------------------------------------------------------ energy


def hemisphere(n_theta: int = 384, n_phi: int = 192):
    """Midpoint quadrature over the upper hemisphere (z up): directions (3, T, P), solid-angle weights (T, P)."""
    theta = (np.arange(n_theta) + 0.5) * (np.pi / 2) / n_theta
    phi = (np.arange(n_phi) + 0.5) * (2 * np.pi) / n_phi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])
    return d, np.sin(t) * (np.pi / 2 / n_theta) * (2 * np.pi / n_phi)


def directional_albedo(response, nv: float) -> float:
    """integral over the hemisphere of f(l, v) n.l dl, where response(nl, nv, nh, vh) = pi f n.l (the module's
    convention: intensities have pi folded in)."""
    light, weight = hemisphere()
    view = np.array([np.sqrt(1 - nv * nv), 0.0, nv])
    h = light + view[:, None, None]
    h /= np.linalg.norm(h, axis=0)
    nl, nh, vh = light[2], h[2], np.einsum("i,ijk->jk", view, h)
    return float((response(nl, np.full_like(nl, nv), nh, vh) / np.pi * weight).sum())


@pytest.mark.parametrize("roughness", [0.3, 0.5, 0.7])
def test_white_furnace_dual_lobes_and_sheen_reflect_at_most_what_arrives(roughness):
    """A uniform white environment: the dual lobes (with F = 1, the most they can reflect) under the sheen's layer
    (scaled by 1 - weight x the sheen's albedo) plus the weighted sheen return at most the light that arrives, at
    every view angle; with skin's F0 the specular is a few per cent (a quarter at grazing view), and with the plain
    skin's Lambert diffuse (the diffuse is not reduced by the specular's share, as with the single lobe: a light skin
    of albedo 0.8 would pass 1 at grazing view) the total stays under 1."""
    rough_a, rough_b = skin_specular.lobe_roughness(np.float32(roughness), np.float32(1.0))
    for nv in (1.0, 0.7, 0.4, 0.15, 0.05):
        full = directional_albedo(lambda nl, v, nh, vh: skin_specular.dual_specular(nl, v, nh, vh, rough_a, rough_b,
                                                                                    1.0), nv)
        sheen = directional_albedo(lambda nl, v, nh, vh: skin_specular.charlie_sheen(nl, v, nh, 0.6), nv)
        skin = directional_albedo(lambda nl, v, nh, vh: skin_specular.dual_specular(nl, v, nh, vh, rough_a, rough_b,
                                                                                    SKIN_F0), nv)
        layer = 1 - skin_specular.SHEEN_WEIGHT * skin_specular.sheen_directional(np.float32(nv))
        assert full * layer + skin_specular.SHEEN_WEIGHT * sheen <= 1.0
        assert max(PLAIN_SKIN) + skin * layer + skin_specular.SHEEN_WEIGHT * sheen <= 1.0
        assert full > 0.6 or nv < 0.4        # F = 1 loses little but multiple scattering (most at grazing view)
        assert 0.02 < skin < 0.3


def test_a_smooth_lobe_with_full_fresnel_reflects_almost_everything():
    """GGX is normalised (integral of D (n.h) = 1) and Smith's masking is near 1 for a smooth surface: at normal
    incidence a lobe of roughness 0.2 with F = 1 reflects more than 98 % of a white environment."""
    r = np.float32(0.2)
    albedo = directional_albedo(lambda nl, v, nh, vh: skin_specular.ggx_lobe(nl, v, nh, vh, r, 1.0), 1.0)
    assert 0.98 < albedo <= 1.0


def test_ambient_terms_match_the_integrals():
    """The ambient specular (Karis' fit per lobe; the sheen's tabulated albedo) is the directional albedo that the
    quadrature here gives, within the fit's accuracy."""
    for nv in (0.9, 0.5, 0.2):
        sheen = directional_albedo(lambda nl, v, nh, vh: skin_specular.charlie_sheen(nl, v, nh, 0.6), nv)
        table = np.interp(nv, np.linspace(1e-3, 1, skin_specular.SHEEN_STEPS), skin_specular.sheen_albedo(0.6))
        assert abs(table - sheen) < 0.01 * max(sheen, 0.1)
        for r in (0.35, 0.6):
            lobe = directional_albedo(lambda nl, v, nh, vh, r=r: skin_specular.ggx_lobe(nl, v, nh, vh, np.float32(r),
                                                                                       SKIN_F0), nv)
            fit = skin_specular.environment_lobe(SKIN_F0, np.float32(r), np.float32(nv))
            assert abs(fit - lobe) < 0.02


def test_the_sheen_grows_toward_grazing_angles():
    """Charlie's distribution is 0 with the half vector on the normal and largest with it in the tangent plane:
    looking back along the light (l = v), the sheen rises monotonically as the angle grows toward grazing, and its
    albedo is largest at grazing view."""
    cos = np.array([1.0, 0.8, 0.6, 0.4, 0.2, 0.1])
    assert skin_specular.charlie_sheen(np.ones(1), np.ones(1), np.ones(1), 0.6)[0] == 0
    # l = v in the same direction: h = l, n.h = cos; per unit n.l, the sheen rises as cos falls
    per_cos = skin_specular.charlie_sheen(cos, cos, cos, 0.6) / cos
    assert np.all(np.diff(per_cos) > 0)
    albedo = skin_specular.sheen_albedo(0.6)
    assert albedo[0] > albedo[-1] and np.all(np.diff(albedo) <= 1e-6)


def test_nails_are_glossier_than_skin_and_palms_less_specular():
    labels = np.array([0, 1, 2, -1])                       # nail, palm, dorsum, unlabelled
    rough, spec = skin_specular.region_factors(labels, 4)
    assert rough[0] < rough[2] and spec[0] > spec[2] and spec[1] < spec[2]
    assert rough[3] == 1 and spec[3] == 1


def test_the_compiled_lights_pass_is_the_numpy_definition():
    """skin_specular_radiance's per-light kernel against lights_radiance (numpy, float64), on random hits under a
    directional and a point light, some hits not reached."""
    rng = np.random.default_rng(3)
    m = 500
    n = rng.normal(size=(3, m))
    n /= np.linalg.norm(n, axis=0)
    v = n + rng.normal(scale=0.6, size=(3, m))
    v /= np.linalg.norm(v, axis=0)
    hits = Hits(rng.uniform(-0.05, 0.05, (3, m)).astype(np.float32), n.astype(np.float32), v.astype(np.float32),
                None, None, region=rng.integers(-1, 6, m))
    lights = np.array([[0, 0.0, 0.6, 0.8, 2.0, 1.8, 1.5, 1], [1, 0.1, 0.3, 0.2, 0.05, 0.04, 0.03, 0]], np.float32)
    reached = rng.random((2, m)) < 0.8
    roughness = rng.uniform(0.3, 0.8, m).astype(np.float32)
    got = skin_specular.skin_specular_radiance(hits, roughness, np.float32(SKIN_F0), 1.0, lights, reached,
                                               np.zeros(3, np.float32))
    rough_f, spec_f = skin_specular.region_factors(hits.region, m)
    rough_a, rough_b = skin_specular.lobe_roughness(roughness, rough_f)
    nv = np.clip((hits.normal * hits.view).sum(0), 1e-4, 1)
    layer = 1 - skin_specular.SHEEN_WEIGHT * skin_specular.sheen_directional(nv)
    want = skin_specular.lights_radiance(hits, nv, rough_a, rough_b, np.full((3, m), SKIN_F0), spec_f * layer,
                                         spec_f, lights, reached)
    assert np.allclose(got, want, rtol=1e-4, atol=1e-6)
    assert (want > 0).any()


def test_a_roughness_map_decides_the_nails_gloss_and_the_region_only_their_strength():
    """With a textured roughness (textured=True) a nail hit differs from an unlabelled one by the nail's specular
    factor alone; without, its lobes are also sharper (a higher peak toward the mirror direction)."""
    m = 2
    n = np.tile([[0.0], [0.0], [1.0]], m).astype(np.float32)
    v = np.tile([[0.3], [0.0], [np.sqrt(1 - 0.09)]], m).astype(np.float32)
    hits = Hits(np.zeros((3, m), np.float32), n, v, None, None, region=np.array([0, -1]))
    light = np.array([[0, -0.3, 0.0, np.sqrt(1 - 0.09), 1, 1, 1, 0]], np.float32)        # the mirror direction
    args = (np.full(m, 0.5, np.float32), np.float32(SKIN_F0), 1.0, light, np.ones((1, m), bool),
            np.zeros(3, np.float32))
    textured = skin_specular.skin_specular_radiance(hits, *args, textured=True)
    nail_spec = skin_specular.REGION_SCALE["nail"][1]
    assert np.allclose(textured[:, 0], nail_spec * textured[:, 1], rtol=1e-5)
    plain = skin_specular.skin_specular_radiance(hits, *args, textured=False)
    assert plain[0, 0] > 1.5 * nail_spec * plain[0, 1]


# ------------------------------------------------------------------------------------------------ tangent frame


def quad(uv_of) -> Surface:
    """A 1 cm square in the z = 0 plane (normal +z), two faces, uvs uv_of(x, y)."""
    v = np.array([[0, 0, 0], [0.01, 0, 0], [0.01, 0.01, 0], [0, 0.01, 0]], np.float32)
    faces = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uvs = np.array([uv_of(x, y) for x, y, _ in v], np.float32)
    return Surface("quad", v, faces, np.tile([0, 0, 1], (4, 1)).astype(np.float32), skin_material(), uvs, faces)


@pytest.mark.parametrize("uv_of", [lambda x, y: (10 * x + 0.2, 10 * y + 0.3),       # 10 uv units per metre
                                   lambda x, y: (0.5 - 20 * x, 5 * y),               # mirrored, stretched
                                   lambda x, y: (7 * (x + y), 7 * (y - x) + 0.5)])   # rotated
def test_a_bump_of_known_slope_tilts_the_normal_by_its_angle(uv_of):
    """h = s x on a flat quad: whatever the UV layout (scaled, mirrored, rotated), the bumped normal is the
    normal of the plane z = s x, (-s, 0, 1) / sqrt(1 + s^2), tilted by atan(s)."""
    surface = quad(uv_of)
    table = FaceData(surface).table
    prim = np.array([0, 1, 1])
    pu, pv = skin_detail.face_tangents(table, prim)
    # dh/du, dh/dv of h = s x: x as a function of (u, v) is linear, its gradient from the UV map's inverse
    s = 0.3
    uvs = np.array([uv_of(x, y) for x, y in ((0, 0), (1, 0), (0, 1))], np.float64)
    J = np.stack([uvs[1] - uvs[0], uvs[2] - uvs[0]], 1)         # d(u, v) / d(x, y)
    dx_duv = np.linalg.inv(J)[0]                                # (dx/du, dx/dv)
    slopes = np.repeat((s * dx_duv)[:, None], 3, axis=1)
    n = np.tile([[0.0], [0.0], [1.0]], 3).astype(np.float32)
    got = skin_detail.bumped_normals(n, pu, pv, slopes, n, 1.0)
    want = np.array([-s, 0, 1]) / np.hypot(1, s)
    assert np.allclose(got, want[:, None], atol=1e-5)
    assert np.isclose(np.degrees(np.arccos(got[2, 0])), np.degrees(np.arctan(s)), atol=1e-3)
    half = skin_detail.bumped_normals(n, pu, pv, slopes, n, 0.5)
    assert np.isclose(np.arccos(half[2, 0]), np.arctan(s / 2), atol=1e-5)


def test_a_bump_never_turns_the_normal_away_from_the_viewer():
    surface = quad(lambda x, y: (10 * x, 10 * y))
    pu, pv = skin_detail.face_tangents(FaceData(surface).table, np.array([0]))
    view = np.array([[0.99], [0.0], [np.sqrt(1 - 0.99 ** 2)]], np.float32)
    got = skin_detail.bumped_normals(np.array([[0.0], [0.0], [1.0]], np.float32), pu, pv,
                                     np.array([[300.0], [0.0]]), view, 1.0)
    assert (got[:, 0] @ view[:, 0]) >= 1e-3 - 1e-6


def test_the_compiled_bump_is_the_numpy_definition(hand):
    """detail_normals (one compiled pass) against face_tangents and bumped_normals (numpy), on random hits of the
    hand's faces with random slopes, strong enough that some normals are bent back toward the viewer."""
    rng = np.random.default_rng(5)
    surface = Surface("hand", np.asarray(hand.v_template, np.float32), np.asarray(hand.faces, np.int32),
                      np.zeros((len(hand.v_template), 3), np.float32), skin_material(),
                      np.asarray(hand.uvs, np.float32), np.asarray(hand.faces_uv, np.int32))
    table = FaceData(surface).table
    m = 400
    prim = rng.integers(0, len(hand.faces), m)
    n = table[18:21, prim] * np.where(rng.random(m) < 0.5, -1, 1)
    view = n + rng.normal(scale=0.8, size=(3, m))
    view /= np.linalg.norm(view, axis=0)
    slopes = rng.normal(scale=0.05, size=(2, m)).astype(np.float32)
    hits = Hits(np.zeros((3, m), np.float32), n.astype(np.float32), view.astype(np.float32),
                rng.random((2, m)).astype(np.float32), np.full(m, 1e-3, np.float32))
    texture = float_pyramid(np.zeros((1, 1, 3), np.float32))
    cavity = rng.uniform(0.7, 1.0, m).astype(np.float32)

    class Slopes:                                   # a texture whose lookup returns the slopes and cavity given
        def sample(self, uv, lod):
            return np.concatenate([slopes, cavity[None]])

        def lod_of_footprint(self, footprint):
            return texture.lod_of_footprint(footprint)

    got, occlusion = skin_detail.detail_at(hits, table, prim, Slopes(), 1.5)
    want = skin_detail.bumped_normals(hits.normal, *skin_detail.face_tangents(table, prim), slopes, hits.view, 1.5)
    assert np.allclose(got, want, atol=2e-6)
    assert np.allclose(occlusion, np.maximum(1 - 1.5 * (1 - cavity), 0))


# ------------------------------------------------------------------------------------------------ the relief


@pytest.fixture(scope="module")
def small_bake(hand):
    return bake(hand, 256)


def test_the_relief_is_deterministic_and_in_its_depth_range(small_bake, hand):
    h = skin_detail.relief_heights(small_bake)
    assert np.array_equal(h, skin_detail.relief_heights(bake(hand, 256)))
    assert h.min() > -3 * skin_detail.PALM_CREASE_DEPTH and h.max() < 5 * skin_detail.RELIEF_DEPTH
    # creases on the palm side, folds on the back: both places have grooves deeper than the pores
    palmar = small_bake.fields["palmar"]
    deep = h < -3 * skin_detail.PORE_DEPTH
    assert deep[palmar > 0.8].any() and deep[(palmar < 0.2) & (small_bake.fields["wrinkle"] > 0.5)].any()
    a = skin_detail.relief_image(small_bake, h)
    assert np.array_equal(a, skin_detail.relief_image(small_bake, h)) and np.isfinite(a).all()
    cavity = a[..., 2].reshape(-1)[small_bake.texel]
    assert (cavity[h >= 0] == 1).all() and (cavity[h < -skin_detail.PORE_DEPTH] < 1).all()
    assert cavity.min() >= 1 - skin_detail.CAVITY


def test_bumped_normals_are_continuous_across_uv_seams(small_bake, hand):
    """A smooth relief of known shape, h = A sin(2 pi x / L) on the rest surface (L = 2 cm, well resolved by a 256
    atlas), through the slope image, its mip pyramid and each face's own tangent frame: at the midpoint of every UV
    seam edge, the normals bumped from the two islands' uvs (about the same base normal) agree to a fraction of the
    bump's own tilt."""
    amplitude, wavelength = 0.5e-3, 0.02
    h = (amplitude * np.sin(2 * np.pi * small_bake.position[:, 0] / wavelength)).astype(np.float32)
    tex = float_pyramid(skin_detail.slope_image(small_bake, h))
    faces, faces_uv = np.asarray(hand.faces), np.asarray(hand.faces_uv)
    table = FaceData(Surface("hand", np.asarray(hand.v_template, np.float32), faces.astype(np.int32),
                             np.zeros((len(hand.v_template), 3), np.float32), skin_material(),
                             np.asarray(hand.uvs, np.float32), faces_uv.astype(np.int32))).table
    first: dict = {}
    pairs = []
    for f in range(len(faces)):
        for k in range(3):
            a, b = faces[f, k], faces[f, (k + 1) % 3]
            corners = {a: faces_uv[f, k], b: faces_uv[f, (k + 1) % 3]}
            key = (min(a, b), max(a, b))
            if key in first:
                g, other = first[key]
                if not all(np.allclose(hand.uvs[other[v]], hand.uvs[corners[v]]) for v in key):
                    pairs.append((g, other, f, corners, key))
            else:
                first[key] = (f, corners)
    assert len(pairs) > 20
    tilt, gap = [], []
    for g, cg, f, cf, (a, b) in pairs:
        n = table[18:21, g] + table[18:21, f]
        n = (n / np.linalg.norm(n))[:, None].astype(np.float32)
        bumped = []
        for face, corners in ((g, cg), (f, cf)):
            uv = (0.5 * (hand.uvs[corners[a]] + hand.uvs[corners[b]]))[:, None].astype(np.float32)
            pu, pv = skin_detail.face_tangents(table, np.array([face]))
            bumped.append(skin_detail.bumped_normals(n, pu, pv, tex.bilinear(uv, 0), n, 1.0)[:, 0])
        tilt.append(np.arccos(np.clip(bumped[0] @ n[:, 0], -1, 1)))
        gap.append(np.arccos(np.clip(bumped[0] @ bumped[1], -1, 1)))
    tilt, gap = np.degrees(tilt), np.degrees(gap)
    assert np.median(tilt) > 2                           # the relief does tilt the normals there
    assert np.median(gap) < 0.25 * np.median(tilt) and np.percentile(gap, 90) < 0.5 * np.percentile(tilt, 90)


# ------------------------------------------------------------------------------------------------ on the hand


def test_options_default_to_todays_shading_and_check_their_values():
    o = ShadingOptions()
    assert o.skin_specular == "single" and o.skin_detail == 0
    assert set(o.to_json()) == {"ao_rays", "interreflection", "skin"}
    assert ShadingOptions(skin_specular="dual", skin_detail=0.5).to_json()["skin_detail"] == 0.5
    with pytest.raises(InputError, match="skin_specular"):
        ShadingOptions(skin_specular="triple")
    with pytest.raises(InputError, match="skin_detail"):
        ShadingOptions(skin_detail=-1)


def test_labels_mask_and_normals_unchanged_by_skin_options(assets, hand):
    """Both options on change the image (and only the hand's pixels), never the mask, edges, depth, normals or
    labels (beyond the shading options recorded), and the frame is the same on a second render."""
    assets._detail = skin_detail.DetailMap(hand, res=256)
    r = Renderer(assets, threads=1)
    common = dict(camera="three_quarter", width=160, height=160, maps=("depth", "normals", "parts"))
    off = r.render("fist", **common)
    on = r.render("fist", shading={"skin_specular": "dual", "skin_detail": 1.0}, **common)
    again = r.render("fist", shading={"skin_specular": "dual", "skin_detail": 1.0}, **common)
    assert_only_shading_differs(on, off)
    assert on.labels["render"]["shading"]["skin_specular"] == "dual"
    assert not np.array_equal(on.rgba, off.rgba)
    assert np.array_equal(on.rgba[off.alpha == 0], off.rgba[off.alpha == 0])
    assert np.array_equal(on.rgba, again.rgba)


def test_each_option_alone_changes_the_skin_and_not_the_ring(assets, hand, ring):
    assets._detail = skin_detail.DetailMap(hand, res=256)
    r = Renderer(assets, threads=1)
    common = dict(camera="dorsal", width=256, height=256, accessory=ring.id)
    off = r.render("relaxed", **common)
    ring_at = off.geom == 1
    inside = np.zeros_like(ring_at)              # ring pixels whose 4 neighbours are ring: no hand sample in them
    inside[1:-1, 1:-1] = (ring_at[1:-1, 1:-1] & ring_at[:-2, 1:-1] & ring_at[2:, 1:-1] & ring_at[1:-1, :-2]
                          & ring_at[1:-1, 2:])
    assert inside.sum() > 20
    hand_at = (off.geom == 0) & (off.alpha == 1)
    for shading in ({"skin_specular": "dual"}, {"skin_detail": 1.0}):
        on = r.render("relaxed", shading=shading, **common)
        assert not np.array_equal(on.rgba[hand_at], off.rgba[hand_at])
        assert np.array_equal(on.rgba[inside], off.rgba[inside])


def test_a_material_without_relief_is_shaded_as_before(assets):
    """The checker (no relief) renders the same with skin_detail on: the option needs a model's relief."""
    r = Renderer(assets, threads=1)
    common = dict(texture="checker", camera="dorsal", width=96, height=96)
    assert np.array_equal(r.render(None, **common).rgba,
                          r.render(None, shading={"skin_detail": 2.0}, **common).rgba)
    assert dataclasses.replace(skin_material(), name="x").detail is None


@pytest.mark.slow
def test_render_and_render_dataset_take_the_options_and_frames_repeat_to_the_byte(hand, tmp_path, capsys):
    """`darthand render-dataset --skin-specular dual --skin-detail 1`: recorded in dataset.json and each frame's
    labels; two runs write the same bytes (frame i depends on (seed, i) only). `darthand render` takes them too,
    and refuses an out-of-range strength in one line."""
    from darthand.cli import main
    from darthand.model.npz_io import save_npz

    model = tmp_path / "model" / "right.npz"
    save_npz(hand, model)
    common = [str(model), "--count", "2", "--size", "64", "--samples", "4", "--processes", "1", "--seed", "3",
              "--skin-specular", "dual", "--skin-detail", "1"]
    for name in ("a", "b"):
        assert main(["render-dataset", *common, "--out", str(tmp_path / name)]) == 0
    want = {"ao_rays": 16, "interreflection": True, "skin": "subsurface", "skin_specular": "dual", "skin_detail": 1.0,
            "shadows": "vertex"}                       # the dataset default
    doc = json.loads((tmp_path / "a" / "dataset.json").read_text())
    assert doc["shading"] == want
    for path in sorted((tmp_path / "a" / "labels").iterdir()):
        assert json.loads(path.read_text())["render"]["shading"] == want
    images = sorted((tmp_path / "a" / "images").iterdir())
    assert len(images) == 2
    assert all(p.read_bytes() == (tmp_path / "b" / "images" / p.name).read_bytes() for p in images)
    assert main(["render", str(model), "--out", str(tmp_path / "one"), "--size", "48", "--skin-specular", "dual",
                 "--skin-detail", "0.5"]) == 0
    assert json.loads((tmp_path / "one" / "labels.json").read_text())["render"]["shading"]["skin_detail"] == 0.5
    capsys.readouterr()
    assert main(["render", str(model), "--out", str(tmp_path / "two"), "--skin-detail", "9"]) == 2
    err = capsys.readouterr().err
    assert "--skin-detail: 9 is outside [0, 4]" in err and len(err.strip().splitlines()) == 1
