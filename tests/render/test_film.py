"""render/film.py, a camera's image: the tone curve against Hable's published formula, the sensor noise's mean and
variance against its physical model, blur kernels' energy and spread against closed forms, the JPEG round trip,
exposure that keeps skin tones (light, medium, dark catalogue tones under one light keep their order and their
clean render's sRGB), 'none' exact, labels unchanged by any film, determinism from the seed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from render_scenes import write_image

from darthand.errors import InputError
from darthand.render import film as F
from darthand.render.api import Renderer
from darthand.render.assets import HandAssets
from darthand.render.lights import default_lighting
from darthand.textures.color import hex_to_srgb, luminance, tone_color
from darthand.textures.loader import TextureSet

CATALOGUE = Path(__file__).resolve().parents[2] / "assets_src" / "textures" / "catalog.json"
TONES = {"light": 2, "medium": 5, "dark": 9}         # Monk Skin Tone steps of the texture catalogue's scale


def hable_published(x):
    """Hable's filmic curve as published (filmicworlds.com, 'Filmic Tonemapping Operators'), typed from the post."""
    A, B, C, D, E, F_ = 0.15, 0.50, 0.10, 0.20, 0.02, 0.30
    return ((x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F_)) - E / F_


def test_tone_curve_is_hables_normalised_by_its_white_point_and_monotonic():
    x = np.linspace(0, 11.2, 2001)
    for white in (F.HABLE_WHITE, 4.0, 2.0):
        y = F.tone_curve(x, white)
        expected = np.minimum(hable_published(x) / hable_published(white), 1)
        assert np.allclose(y, expected, atol=1e-12, rtol=0)
        assert (np.diff(y) >= 0).all() and y[0] == 0 and float(F.tone_curve(white, white)) == 1.0
        for target in (0.01, 0.18, 0.5, 0.99):
            assert float(F.tone_curve(F.inverse_tone_curve(target, white), white)) == pytest.approx(target, abs=1e-9)
    # Hable's own exposure bias 2 on linear 1 with W = 11.2: the post's mid-grey lands near 0.47 display-linear.
    assert float(F.tone_curve(2.0, F.HABLE_WHITE)) == pytest.approx(hable_published(2.0) / hable_published(11.2))


def test_sensor_noise_keeps_the_mean_and_follows_shot_plus_read_noise():
    """A flat grey of exposed signal s: electrons n = s c with c = FULL_WELL_E / W x 100 / ISO; the variance in
    signal units is (n + read^2) / c^2 (Poisson shot noise plus Gaussian read noise)."""
    for iso, read, s in ((800.0, 3.0, 0.3), (3200.0, 6.0, 0.05), (100.0, 1.0, 2.0)):
        film = F.Film(iso=iso, read_noise=read, white_point=4.0)
        flat = np.full((400, 400, 3), s, np.float32)
        noisy = F.sensor_noise(flat, film, np.random.default_rng(5))
        c = 10000.0 / 4.0 * 100.0 / iso
        variance = (s * c + read ** 2) / c ** 2
        n = noisy.size
        assert abs(noisy.mean() - s) < 5 * np.sqrt(variance / n)
        assert noisy.var() == pytest.approx(variance, rel=0.02)
    assert F.sensor_noise(flat, F.Film(), np.random.default_rng(0)) is flat


def test_blur_kernels_keep_energy_and_have_their_closed_form_spread():
    for length, angle in ((1.0, 0.0), (7.0, 30.0), (12.5, 100.0)):
        k = F.line_kernel(length, angle).astype(np.float64)
        assert k.sum() == pytest.approx(1.0, abs=1e-6) and (k >= 0).all()
        R = k.shape[0] // 2
        y, x = np.mgrid[-R:R + 1, -R:R + 1]
        a = np.deg2rad(angle)
        along = x * np.cos(a) - y * np.sin(a)            # image y is down: counter-clockwise means -y
        across = x * np.sin(a) + y * np.cos(a)
        assert (k * along).sum() == pytest.approx(0, abs=1e-6) and (k * across).sum() == pytest.approx(0, abs=1e-6)
        # a uniform segment of length L has variance L^2 / 12; bilinear splatting adds at most 1/4 per axis
        assert (k * along ** 2).sum() == pytest.approx(length ** 2 / 12, abs=0.25)
    for radius in (0.0, 1.0, 3.0, 8.0):
        k = F.disc_kernel(radius).astype(np.float64)
        assert k.sum() == pytest.approx(1.0, abs=1e-6)
        R = k.shape[0] // 2
        y, x = np.mgrid[-R:R + 1, -R:R + 1]
        if radius >= 3:                                  # a uniform disc: variance r^2 / 4 per axis
            assert (k * x ** 2).sum() == pytest.approx(radius ** 2 / 4, rel=0.08)
    spot = np.zeros((64, 64, 3), np.float32)
    spot[30:34, 28:31] = [1.0, 2.0, 3.0]
    for kernel in (F.line_kernel(9, 45), F.disc_kernel(5)):
        blurred = F.convolve(spot, kernel)
        assert np.allclose(blurred.sum(axis=(0, 1)), spot.sum(axis=(0, 1)), rtol=1e-5)


def test_jpeg_round_trip_keeps_the_size_is_deterministic_and_close():
    rng = np.random.default_rng(3)
    y, x = np.mgrid[0:96, 0:80]
    rgb = np.stack([x * 3, y * 2, (x + y) % 256], axis=2).astype(np.uint8)
    rgb[40:50, 10:60] = rng.integers(0, 256, (10, 50, 3))
    a, b = F.jpeg_round_trip(rgb, 75), F.jpeg_round_trip(rgb, 75)
    assert a.shape == rgb.shape and a.dtype == np.uint8 and np.array_equal(a, b)
    smooth = np.s_[:30]                                  # away from the noise block
    assert np.abs(a[smooth].astype(int) - rgb[smooth]).mean() < 3
    assert not np.array_equal(F.jpeg_round_trip(rgb, 20), a)


def test_film_settings_refuse_unknown_and_out_of_range_fields_in_one_line():
    with pytest.raises(InputError, match="unknown film field 'isoo'"):
        F.Film.from_json({"isoo": 100})
    for doc, field in (({"iso": 10}, "iso"), ({"jpeg_quality": 101}, "jpeg_quality"), ({"vignetting": 2}, "vignetting"),
                       ({"white_balance": [1, 1]}, "white_balance"), ({"exposure_ev": "auto"}, "exposure_ev")):
        with pytest.raises(InputError, match=f"'{field}'") as e:
            F.Film.from_json(doc, "f.json")
        assert "\n" not in str(e.value) and str(e.value).startswith("f.json: ")
    film = F.Film(iso=400, defocus_px=2, white_balance=(1.05, 1, 0.95), jpeg_quality=80)
    assert F.Film.from_json(json.loads(json.dumps(film.to_json()))) == film
    assert F.load_film("none") is None and F.load_film(None) is None


def test_random_films_are_valid_and_fixed_by_their_uniforms():
    rng = np.random.default_rng(0)
    for u in [np.zeros(F.RANDOM_UNIFORMS), np.nextafter(np.ones(F.RANDOM_UNIFORMS), 0)] + [
            rng.random(F.RANDOM_UNIFORMS) for _ in range(200)]:
        doc = F.random_film(u)
        assert F.Film.from_json(doc).to_json() == doc and doc["exposure_ev"] is None
        assert F.random_film(u.copy()) == doc
    assert F.load_film("random", 1) == F.load_film("random", 1) != F.load_film("random", 2)


@pytest.fixture(scope="module")
def toned(hand, tmp_path_factory):
    """HandAssets with flat textures at the catalogue scale's light, medium and dark tones."""
    folder = tmp_path_factory.mktemp("tones")
    anchors = [hex_to_srgb(h) for h in json.loads(CATALOGUE.read_text())["tone_scale"]["anchors_srgb"]]
    textures = {}
    for name, mst in TONES.items():
        linear = tone_color(mst, anchors)
        srgb = np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)
        image = np.broadcast_to(np.rint(srgb * 255).astype(np.uint8), (32, 32, 3))
        textures[name] = TextureSet(name, write_image(folder / f"{name}.png", image))
    return lambda: HandAssets(hand, textures, "medium", {}, "open+wrist")


def _hand_median(rgba, alpha) -> float:
    """Median sRGB luma code (Rec. 709 weights on codes) over pixels fully covered by the hand."""
    codes = rgba[..., :3][alpha >= 1].astype(np.float64)
    return float(np.median(codes @ np.array([0.2126, 0.7152, 0.0722])))


def _scaled_lighting(scale: float) -> dict:
    doc = default_lighting().to_json()
    doc["ambient"]["intensity"] *= scale
    for light in doc["lights"]:
        light["intensity"] *= scale
    return doc


def test_exposure_meters_the_light_so_skin_keeps_its_tone_and_order(toned):
    """Light, medium and dark hands under the default light: with the film (automatic exposure, no noise) each
    keeps its order and its clean render's median sRGB within 14 codes, few hand pixels clip; under a light twice
    as strong (or half as strong) the film's medians stay those of the default light (the meter reads the light,
    not the hand) while the clean render's move."""
    renderer = Renderer(toned(), threads=1)
    film = F.Film()
    medians: dict = {}
    for name in TONES:
        for lights in ("default", "bright", "dim"):
            lighting = {"default": None, "bright": _scaled_lighting(2.0), "dim": _scaled_lighting(0.5)}[lights]
            clean = renderer.render("flat", texture=name, camera="dorsal", width=96, height=96, lights=lighting,
                                    labels=False)
            developed = renderer.render("flat", texture=name, camera="dorsal", width=96, height=96,
                                        lights=lighting, labels=False, film=film)
            medians[name, lights] = (_hand_median(clean.rgba, clean.alpha), _hand_median(developed.rgba,
                                                                                         developed.alpha))
            if lights == "default":
                covered = developed.alpha >= 1
                clipped = (developed.rgba[..., :3][covered] == 255).any(axis=1).mean()
                assert clipped < 0.02, (name, clipped)
    for lights in ("default", "bright", "dim"):
        film_order = [medians[name, lights][1] for name in TONES]
        assert film_order[0] > film_order[1] > film_order[2], (lights, film_order)
    for name in TONES:
        clean, developed = medians[name, "default"]
        assert abs(developed - clean) <= 14, (name, clean, developed)
        for lights in ("bright", "dim"):
            assert abs(medians[name, lights][1] - developed) <= 4, (name, lights, medians)
        assert medians[name, "dim"][0] < clean - 15          # the clean render does move with the light


def test_none_is_the_renderer_image_and_films_leave_labels_alone(toned):
    renderer = Renderer(toned(), threads=1)
    options = dict(camera="three_quarter", width=64, height=64, texture="dark")
    clean = renderer.render("fist", **options)
    none = renderer.render("fist", **options, film=F.load_film("none"))
    assert np.array_equal(clean.rgba, none.rgba) and clean.labels == none.labels
    assert "film" not in clean.labels["render"]
    rng = np.random.default_rng(7)
    for k in range(3):
        film = F.Film.from_json(F.random_film(rng.random(F.RANDOM_UNIFORMS)))
        film = F.Film(**{**film.to_json(), "white_balance": film.white_balance, "defocus_px": 2.0,
                         "motion_blur_px": 3.0, "jpeg_quality": 60})
        developed = renderer.render("fist", **options, film=film, film_seed=k)
        again = renderer.render("fist", **options, film=film, film_seed=k)
        assert np.array_equal(developed.rgba, again.rgba)
        assert not np.array_equal(developed.rgba, renderer.render("fist", **options, film=film, film_seed=k + 9).rgba)
        record = developed.labels["render"].pop("film")
        assert developed.labels == clean.labels
        assert record["seed"] == k and record["auto_exposure"] and record["exposure_ev"] is not None
        # the record develops the same image again
        assert np.array_equal(F.develop(developed.colour, developed.alpha, developed.depth,
                                        F.Film.from_json(record), record["seed"], composited=False), developed.rgba)
        assert np.array_equal(developed.rgba[..., 3], clean.rgba[..., 3])   # the image's alpha is the mask


def test_defocus_keeps_the_hand_sharp_and_blurs_the_background(toned):
    """Over a striped background at infinity: the background's stripes lose contrast, the hand's pixels barely
    change."""
    renderer = Renderer(toned(), threads=1)
    stripes = np.zeros((96, 96, 3), np.float32)
    stripes[:, ::4] = 0.8
    options = dict(camera="dorsal", width=96, height=96, texture="medium", background=stripes, labels=False)
    sharp = renderer.render("flat", **options, film=F.Film())
    blurred = renderer.render("flat", **options, film=F.Film(defocus_px=4.0))
    behind = sharp.alpha == 0
    contrast = lambda img: img[..., 1][behind].astype(float).std()
    assert contrast(blurred.rgba) < 0.3 * contrast(sharp.rgba)
    inner = np.zeros_like(behind)
    inner[sharp.alpha >= 1] = True
    for _ in range(4):                                  # away from the silhouette by the blur's radius
        inner[1:-1, 1:-1] &= inner[:-2, 1:-1] & inner[2:, 1:-1] & inner[1:-1, :-2] & inner[1:-1, 2:]
    assert inner.sum() > 100
    assert np.abs(blurred.rgba[inner].astype(int) - sharp.rgba[inner]).mean() < 3


def test_metered_white_is_the_lights_cosine_sum():
    """One directional light and ambient: the meter's dome facing the camera reads ambient + intensity x (1 +
    cos theta) / 2 (a hemisphere's projected area seen from theta off its axis); a point light falls off with the
    square of its distance."""
    from darthand.render.camera import look_at
    from darthand.render.lights import Light, Lighting

    cam = look_at((0, 0, -1), (0, 0, 0), (0, -1, 0))
    for angle, cosine in ((0.0, 1.0), (60.0, 0.75), (90.0, 0.5), (120.0, 0.25), (180.0, 0.0)):
        d = (np.sin(np.deg2rad(angle)), 0.0, np.cos(np.deg2rad(angle)))
        lighting = Lighting((1, 1, 1), 0.1, (Light("directional", (1, 1, 1), 2.0, direction=d, frame="camera"),))
        assert np.allclose(F.metered_white(lighting, cam, (0, 0, 0)), 0.1 + 2.0 * cosine, atol=1e-6)
    point = Lighting((1, 1, 1), 0.0, (Light("point", (1, 1, 1), 1.0, position=(0, 0, -2)),))
    assert np.allclose(F.metered_white(point, cam, (0, 0, 0)), 0.25, atol=1e-6)       # inverse square at 2 m
    assert F.auto_exposure_ev(np.full(3, F.METERED_WHITE / 2)) == pytest.approx(1.0)
    assert F.auto_exposure_ev(np.full(3, F.METERED_WHITE / 100)) == F.AUTO_EV_LIMIT
    assert F.auto_exposure_ev(np.zeros(3)) == F.AUTO_EV_LIMIT
    assert float(luminance(np.ones(3))) == pytest.approx(1.0, abs=1e-6)



@pytest.mark.slow
def test_render_takes_a_film_and_refuses_a_bad_one_in_one_line(tmp_path):
    import subprocess
    import sys

    def darthand(*argv):
        return subprocess.run([sys.executable, "-m", "darthand.cli", "render", "open", "--size", "32", *argv],
                              capture_output=True, text=True, timeout=300)

    (tmp_path / "film.json").write_text(json.dumps({"iso": 400, "jpeg_quality": 70}))
    done = darthand("--film", str(tmp_path / "film.json"), "--film-seed", "4", "--out", str(tmp_path / "a"))
    assert done.returncode == 0, done.stderr
    record = json.loads((tmp_path / "a" / "labels.json").read_text())["render"]["film"]
    assert record["iso"] == 400 and record["jpeg_quality"] == 70 and record["seed"] == 4
    (tmp_path / "bad.json").write_text(json.dumps({"iso": 400, "grain": 2}))
    for film, words in ((str(tmp_path / "bad.json"), "unknown film field 'grain'"),
                        (str(tmp_path / "missing.json"), "no such film settings file")):
        done = darthand("--film", film, "--out", str(tmp_path / "b"))
        assert done.returncode == 2 and done.stderr.count("\n") == 1 and words in done.stderr, done.stderr
