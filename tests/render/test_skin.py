"""The subsurface skin model (render/skin.py): energy conservation (a white-furnace check: under light from every
direction the blurred response averages what Lambert's does), Lambert's cosine on flat skin, a table entry against
a brute-force Monte Carlo integral over the sphere, curvature radii of a sphere and a cylinder, darker tones
scattering less far, and on the hand: nails and accessories unchanged by the skin model."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.render import skin


def test_white_furnace_the_response_averages_to_lamberts_on_every_sphere():
    """Lit from every direction alike, a sphere reflects what a Lambert sphere does: the mean of D(cos theta, r/d)
    over cos theta uniform in [-1, 1] (directions uniform on the sphere) is the mean of max(0, cos) = 1/4."""
    table = skin.sphere_table()
    cos = np.linspace(-1, 1, skin.COS_STEPS)
    for row in table:
        assert abs(np.trapezoid(row, cos) / 2 - 0.25) < 2e-4
    assert (table >= 0).all() and (table <= 1 + 1e-6).all()


def test_flat_skin_is_lambert_and_small_spheres_spread_light_past_the_terminator():
    table = skin.sphere_table()
    cos = np.linspace(-1, 1, skin.COS_STEPS)
    assert np.allclose(table[-1], np.maximum(cos, 0), atol=2e-3)
    ratios = np.linspace(skin.LOG_LO, skin.LOG_HI, skin.RATIO_STEPS)
    at_terminator = table[:, skin.COS_STEPS // 2]                       # cos theta = 0
    assert np.all(np.diff(at_terminator) < 1e-6)                         # bigger sphere: less light past it
    assert at_terminator[np.searchsorted(ratios, 2.0)] > 0.1


def test_a_table_entry_against_monte_carlo_over_the_sphere():
    """D at r / d = 4 and cos theta = 0.2, by uniform random points on the sphere weighted by Burley's profile."""
    rng = np.random.default_rng(0)
    rho, c = 4.0, 0.2
    q = rng.normal(size=(1_000_000, 3))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    p = np.array([np.sqrt(1 - c * c), 0.0, c])                           # light along +z
    x = rho * np.linalg.norm(q - p, axis=1)
    w = (np.exp(-x) + np.exp(-x / 3)) / np.maximum(x, 1e-9)
    want = (w * np.maximum(q[:, 2], 0)).sum() / w.sum()
    got = skin.subsurface_diffuse(np.array([c], np.float32), np.array([rho * 1e-3], np.float32),
                                  np.full(3, 1e-3, np.float32))
    assert np.allclose(got[:, 0], want, atol=0.01)


def test_curvature_radius_of_a_sphere_and_of_a_plane():
    import trimesh

    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.01)
    r = skin.curvature_radius(ball.vertices, ball.faces)
    assert abs(np.median(r) - 0.01) < 1e-4 and np.allclose(r, 0.01, rtol=0.15)
    assert (skin.curvature_radius(*_grid()) == skin.FLAT_RADIUS).all()


def _grid():
    xs = np.linspace(0, 1, 6)
    v = np.array([[x, y, 0.0] for y in xs for x in xs])
    f = []
    for j in range(5):
        for i in range(5):
            a = j * 6 + i
            f += [[a, a + 1, a + 7], [a, a + 7, a + 6]]
    return v, np.array(f)


def test_cylinder_mean_curvature():
    """An open tube (no caps) of radius 8 mm: the sphere of its mean curvature has radius 16 mm."""
    phi = np.linspace(0, 2 * np.pi, 96, endpoint=False)
    zs = np.linspace(-0.05, 0.05, 41)
    v = np.array([[0.008 * np.cos(a), 0.008 * np.sin(a), z] for z in zs for a in phi])
    f = []
    for j in range(len(zs) - 1):
        for i in range(96):
            a, b = j * 96 + i, j * 96 + (i + 1) % 96
            f += [[a, b, b + 96], [a, b + 96, a + 96]]
    r = skin.curvature_radius(v, np.array(f))
    inner = slice(96, -96)                                               # boundary rings count as flat
    assert np.allclose(r[inner], 0.016, rtol=0.01)
    assert (r[:96] == skin.FLAT_RADIUS).all()


def test_darker_skin_scatters_less_far():
    """Christensen and Burley's searchlight fit: s(0.8) = 1.05, so d = l / 1.05; a dark tone's profile is narrower."""
    mfp = np.array([1e-3, 1e-3, 1e-3])
    light = skin.profile_width(np.full((3, 1), 0.8), mfp)[:, 0]
    dark = skin.profile_width(np.full((3, 1), 0.15), mfp)[:, 0]
    assert np.allclose(light, 1e-3 / 1.05, rtol=1e-5)
    assert (dark < 0.6 * light).all()


@pytest.fixture(scope="module")
def hand_frames(hand, texture_files, ring):
    """The hand with a rigid ring, rendered with each skin model (indirect light off, so that only the skin model
    differs), and the surface and face hit at each pixel centre."""
    from darthand.render.api import Renderer
    from darthand.render.assets import HandAssets
    from darthand.render.trace import Context, intersect_samples, pixel_centres
    assets = HandAssets(hand, {texture_files.id: texture_files}, texture_files.id, {ring.id: ring})
    renderer = Renderer(assets, threads=1)
    frames = {m: renderer.render("flat", accessory=ring.id, camera="dorsal", width=320, height=320,
                                 shading={"ao_rays": 0, "skin": m}) for m in ("lambert", "subsurface", "wrap")}
    f = frames["lambert"]
    from darthand.render.scene import Scene

    ctx = Context(Scene(f.subject), f.camera, [], np.zeros(3, np.float32))
    hits = intersect_samples(ctx, pixel_centres(0, 320, 0, 320))
    return frames, hits.geom.reshape(320, 320), hits.prim.reshape(320, 320), f.subject


def test_nails_and_accessories_are_unchanged_by_the_skin_model(hand_frames):
    from darthand.model.layout import FACE_LABEL_IDS

    frames, geom, prim, subj = hand_frames
    labels = subj.hand.face_labels
    assert labels is not None
    inside = frames["lambert"].alpha == 1
    nail = _interior(inside & (geom == 0) & (labels[np.maximum(prim, 0)] == FACE_LABEL_IDS["nail"]))
    accessory = _interior(inside & (geom == 1))        # (edge pixels mix in the hand's sub-samples)
    skin_px = inside & (geom == 0) & ~nail
    assert nail.sum() > 20 and accessory.sum() > 10
    for model in ("subsurface", "wrap"):
        assert np.array_equal(frames[model].colour[accessory], frames["lambert"].colour[accessory])
    assert np.array_equal(frames["subsurface"].colour[nail], frames["lambert"].colour[nail])
    # ... while the skin itself does change (past the terminators), and the subsurface model moves light rather
    # than adding it: its skin is not brighter overall than Lambert's by more than wrap lighting makes it.
    diff = np.abs(frames["subsurface"].colour[skin_px] - frames["lambert"].colour[skin_px]).max(1)
    assert (diff > 1e-3).sum() > 20
    lambert = frames["lambert"].colour[skin_px].sum()
    gain = {m: frames[m].colour[skin_px].sum() / lambert for m in ("subsurface", "wrap")}
    assert gain["subsurface"] < gain["wrap"]


def _interior(mask: np.ndarray) -> np.ndarray:
    """The pixels of a mask whose four neighbours are in it too."""
    out = mask.copy()
    out[1:] &= mask[:-1]
    out[:-1] &= mask[1:]
    out[:, 1:] &= mask[:, :-1]
    out[:, :-1] &= mask[:, 1:]
    return out


def test_the_skin_width_memo_lets_go_of_its_textures():
    """skin_width remembers a width per texture, but must not keep the texture alive once the pyramid cache drops it:
    holding 2048^2 pyramids here grew a dataset worker by one texture (about 20 MB) per frame."""
    import gc
    import weakref

    from darthand.render.subject import skin_material
    from darthand.render.texture import MipTexture

    rng = np.random.default_rng(0)
    maps = MipTexture([rng.random((64, 64, 3), dtype=np.float32)])
    width = skin.skin_width(skin_material(maps))
    assert width.shape == (3,) and np.all(width > 0)
    alive = weakref.ref(maps.flat)
    del maps
    gc.collect()
    assert alive() is None
