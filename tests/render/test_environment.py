"""Image-based lighting (render/environment.py) against independent truth: the direction convention at hand-computed
directions, a uniform white map on a convex white Lambertian surface (its albedo), one bright texel against the
directional light of the same irradiance (shadow included), the backdrop of a map of known quadrant colours, bad maps
(one line each, exit 2 through the CLI), determinism, labels unchanged by the environment."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
import trimesh
from render_scenes import flat_material, quad, render, subject, surface, top_camera

from darthand.errors import InputError
from darthand.model.npz_io import save_npz
from darthand.render import environment as env
from darthand.render.api import Renderer
from darthand.render.camera import Camera, intrinsics
from darthand.render.lights import Light, Lighting, load_lighting
from darthand.render.shade import ShadingOptions
from darthand.render.subject import Material
from darthand.render.texture import constant_texture

REPO = Path(__file__).resolve().parents[2]


def write_exr(path: Path, pixels: np.ndarray) -> Path:
    """Write (H, W, C) float32 pixels as an EXR (OpenImageIO, independent of the reader under test)."""
    pixels = np.ascontiguousarray(pixels, np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), pixels)
    assert buf.write(str(path))
    return path


def texel_direction(row: int, col: int, height: int) -> np.ndarray:
    """The contract's lookup direction of a texel centre, inverted by hand: u = (col + 0.5) / W, v = 1 - (row + 0.5)
    / H; azimuth 2 pi (u - 0.5) = atan2(d_y, -d_x), elevation pi (v - 0.5)."""
    width = 2 * height
    phi = 2 * np.pi * ((col + 0.5) / width - 0.5)
    theta = np.pi * (0.5 - (row + 0.5) / height)
    return np.array([-np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi), np.sin(theta)])


def sphere(radius=1.0, centre=(0.0, 0.0, 0.0), role="hand", material=None, name="ball"):
    ball = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    return surface(ball.vertices + np.asarray(centre), ball.faces, material=material, role=role, name=name)


# ------------------------------------------------------------------------------------------------ directions


def test_direction_convention_at_hand_computed_directions():
    # (world direction, frame, camera R, rotation) -> (u, v) worked out from the contract by hand
    R = np.eye(3)
    cases = [((0, 0, 1), "camera", R, 0, (0.5, 0.5)),          # looking forward: the map's centre
             ((0, -1, 0), "camera", R, 0, (None, 1.0)),        # image up: the map's top
             ((1, 0, 0), "camera", R, 0, (0.75, 0.5)),         # image right: d_E = +y, u = 0.75
             ((-1, 0, 0), "camera", R, 0, (0.25, 0.5)),
             ((0, 0, 1), "camera", R, 90, (0.75, 0.5)),        # Rz(-90) (-1, 0, 0) = (0, 1, 0)
             ((0, 1, 0), "world", R, 0, (None, 1.0)),          # world Y up is the map's up
             ((0, 0, 1), "world", R, 0, (0.25, 0.5)),          # world +Z: d_E = (0, -1, 0)
             ((-1, 0, 0), "world", R, 0, (0.5, 0.5)),          # world -X: the map's centre column
             ((0, 0, 1), "camera", np.diag([-1.0, 1.0, -1.0]), 0, (0.0, 0.5))]   # camera turned 180 about y
    for d, frame, rot, angle, (u_exp, v_exp) in cases:
        u, v = env.direction_uv(env.env_directions(np.array([d], float), frame, rot, angle))
        if u_exp is not None:
            assert min(abs(u[0] - u_exp), abs(abs(u[0] - u_exp) - 1)) < 1e-12, (d, frame, angle, u)
        assert abs(v[0] - v_exp) < 1e-12, (d, frame, angle, v)


def test_texel_directions_and_solid_angles_invert_the_convention():
    h = 16
    dirs = env.texel_directions(h)
    u, v = env.direction_uv(dirs.reshape(-1, 3))
    rows, cols = np.mgrid[0:h, 0:2 * h]
    assert np.allclose(u, ((cols + 0.5) / (2 * h)).ravel()) and np.allclose(v, (1 - (rows + 0.5) / h).ravel())
    assert np.allclose(dirs[3, 5], texel_direction(3, 5, h))
    assert np.isclose(env.texel_solid_angles(h).sum() * 2 * h, 4 * np.pi)


# ------------------------------------------------------------------------------------------------ closed forms


@pytest.mark.parametrize("ao_rays, interreflection", [(16, True), (16, False), (0, True)])
def test_uniform_white_map_renders_the_albedo_of_a_convex_lambert_surface(tmp_path, ao_rays, interreflection):
    """A white Lambertian surface under a uniform map of value L renders L (the contract's units): a convex sphere
    sees the whole hemisphere of every point, so with indirect rays (all escape) or without (the SH irradiance of a
    constant is exact) its albedo a renders a x L."""
    path = write_exr(tmp_path / "white.exr", np.full((32, 64, 3), 2.0, np.float32))
    lighting = load_lighting({"environment": {"map": str(path), "strength": 0.5}})
    ball = sphere(material=flat_material((0.6, 0.4, 0.2)))
    frame = render(subject(ball), top_camera(height=4.0, size=48), lighting, samples=1,
                   shading=ShadingOptions(ao_rays=ao_rays, interreflection=interreflection))
    inside = frame.alpha == 1
    assert inside.sum() > 300
    assert np.abs(frame.colour[inside] - [0.6, 0.4, 0.2]).max() < 2e-3


def test_one_bright_texel_is_the_directional_light_of_the_same_irradiance(tmp_path):
    """A black map but one texel of radiance L is a light from that texel's direction of pi-folded intensity
    L x (its solid angle) / pi: a floor under a ball, with the ball's shadow, renders as under that directional
    light. Tolerance: the renderer keeps a remainder of at most CLAMP_MEAN x the mean (4 L dOmega / (4 pi), 1e-4 of
    the light) in the ambient, and the light's float32 direction may move a shadow-edge pixel's sub-samples."""
    h, row, col, value = 128, 50, 64, 4000.0
    pixels = np.zeros((h, 2 * h, 3), np.float32)
    pixels[row, col] = value
    path = write_exr(tmp_path / "texel.exr", pixels)
    theta_top, theta_bottom = np.pi * (0.5 - row / h), np.pi * (0.5 - (row + 1) / h)
    solid_angle = (np.sin(theta_top) - np.sin(theta_bottom)) * 2 * np.pi / (2 * h)
    d_e = texel_direction(row, col, h)
    toward = np.array([d_e[0], d_e[2], -d_e[1]])           # frame 'world': d_E = (x, -z, y)
    assert toward[2] > 0.9                                  # from above
    light = Lighting(lights=(Light("directional", (1.0, 1.0, 1.0), float(value * solid_angle / np.pi),
                                   direction=tuple(-toward), shadows=True, frame="world"),))
    lit = load_lighting({"environment": {"map": str(path), "frame": "world"}})
    scene = subject(quad((0, 0, -1.0), 4.0), sphere(0.4, (0, 0, -0.2), role="accessory", name="b"))
    camera = top_camera(height=4.0, size=64)
    expected = render(scene, camera, light, samples=4)
    got = render(scene, camera, lit, samples=4)
    assert got.stats["shadow_rays"] > 0 and len(lit.lights) == 0
    diff = np.abs(got.colour - expected.colour).max(axis=-1)
    assert expected.colour.max() > 0.3 and (expected.colour.max(axis=-1) < 0.05).sum() > 50   # lit, with a shadow
    assert np.percentile(diff, 99) < 2e-3 and diff.mean() < 1e-3


def test_a_polished_metal_ball_reflects_what_is_behind_the_camera(tmp_path):
    """At the centre of a mirror-like ball the reflection runs back along the view ray: it shows the map behind the
    camera (blue), not in front (red), scaled by the split-sum's F0 A + B at normal incidence (about F0 for a
    polished metal: F0 = the albedo for metallic 1)."""
    pixels = np.zeros((32, 64, 3), np.float32)
    pixels[:, :16], pixels[:, 48:], pixels[:, 16:48] = (0, 0, 1), (0, 0, 1), (1, 0, 0)
    path = write_exr(tmp_path / "behind.exr", pixels)
    metal = Material("pbr", constant_texture((0.9, 0.9, 0.9)), None, 0.1, None, 1.0, (0.0, 0.0, 0.0), 0.04,
                     "metal")
    camera = top_camera(height=4.0, size=48)
    frame = render(subject(sphere(material=metal)), camera, load_lighting({"environment": {"map": str(path)}}),
                   samples=1)
    centre = frame.colour[22:26, 22:26].reshape(-1, 3)
    assert np.all(centre[:, 2] > 0.75) and np.all(centre[:, 2] < 0.95) and np.all(centre[:, 0] < 0.02)


# ------------------------------------------------------------------------------------------------ backdrop


def test_background_view_shows_the_map_quadrants_where_the_camera_looks(tmp_path):
    colours = {"top_left": (1, 0, 0), "top_right": (0, 1, 0), "bottom_left": (0, 0, 1), "bottom_right": (1, 1, 0)}
    pixels = np.zeros((32, 64, 3), np.float32)
    pixels[:16, :32], pixels[:16, 32:] = colours["top_left"], colours["top_right"]
    pixels[16:, :32], pixels[16:, 32:] = colours["bottom_left"], colours["bottom_right"]
    path = write_exr(tmp_path / "quadrants.exr", pixels)
    camera = Camera(intrinsics(40, 40, fov_deg=60), np.eye(3), np.zeros(3), 40, 40)
    view = env.background_view(env.Environment(str(path)), camera)
    assert view.shape == (40, 40, 3) and view.dtype == np.float32
    # the camera looks at the map's centre, its up the map's up: each image quadrant (off the seams) is the map's
    for name, (rows, cols) in {"top_left": (slice(0, 16), slice(0, 16)), "top_right": (slice(0, 16), slice(24, 40)),
                               "bottom_left": (slice(24, 40), slice(0, 16)),
                               "bottom_right": (slice(24, 40), slice(24, 40))}.items():
        assert np.allclose(view[rows, cols], colours[name], atol=1e-6), name
    # turned by 90 degrees the centre looks at u = 0.75, well inside the right half; blurred, the seams soften
    turned = env.background_view(env.Environment(str(path), rotation=90), camera)
    assert np.allclose(turned[4:16, 4:36], colours["top_right"], atol=1e-6)
    blurred = env.background_view(env.Environment(str(path)), camera, blur_deg=30)
    assert 0.05 < blurred[19, 19, 0] < 0.95


def test_backdrop_grid_is_the_blurred_map_along_the_grid_pixels_rays(tmp_path):
    rng = np.random.default_rng(8)
    path = write_exr(tmp_path / "noise.exr", rng.uniform(0, 2, (64, 128, 3)).astype(np.float32))
    environment = env.Environment(str(path), rotation=20, strength=1.5, white_balance=(1.0, 0.8, 1.2))
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R *= np.sign(np.linalg.det(R))
    camera = Camera(intrinsics(61, 47, fov_deg=50), R, np.zeros(3), 61, 47)
    levels = env.map_lighting(str(path)).full
    for blur in (0.0, 9.0, 17.0):
        backdrop = env.backdrop_grid(environment, camera, blur)
        step = backdrop.step
        h, w = backdrop.grid.shape[:2]
        assert (h, w) == (-(-47 // step), -(-61 // step)) and (step > 1) == (blur > 0)
        # grid sample (i, j): the ray of the frame's point (step (j + 0.5), step (i + 0.5)) in the map's frame
        i, j = np.mgrid[:h, :w]
        p = np.stack([step * (j.ravel() + 0.5), step * (i.ravel() + 0.5), np.ones(h * w)])
        d = (env.frame_matrix("camera", R, 20) @ R.T @ np.linalg.inv(camera.K) @ p).T
        lod = float(env.level_of_detail(levels, np.array([blur]))[0])
        k, frac = int(lod), lod - int(lod)
        want = (1 - frac) * env.bilinear(levels[k], d)
        if k + 1 < len(levels):
            want += frac * env.bilinear(levels[k + 1], d)
        want = want * environment.scale
        np.testing.assert_allclose(backdrop.grid.reshape(-1, 3), want, rtol=1e-5, atol=1e-6)
        assert np.array_equal(backdrop.pixels(), env.background_view(environment, camera, blur))


# ------------------------------------------------------------------------------------------------ bad input


def bad_maps(folder: Path) -> dict:
    nan = np.ones((8, 16, 3), np.float32)
    nan[2, 3, 1] = np.nan
    negative = np.ones((8, 16, 3), np.float32)
    negative[4, 4] = -1
    garbage = folder / "garbage.exr"
    garbage.write_bytes(b"\x76\x2f\x31\x01" + os.urandom(64))
    text = folder / "map.png"
    text.write_bytes(b"not an image")
    return {garbage: "cannot read", write_exr(folder / "square.exr", np.ones((8, 8, 3))): "not 2:1",
            write_exr(folder / "nan.exr", nan): "NaN or Inf", write_exr(folder / "negative.exr", negative): "negative",
            text: ".exr or .hdr", folder / "missing.exr": "neither a built-in"}


def test_bad_maps_are_one_line_errors_naming_the_file(tmp_path):
    for path, fault in bad_maps(tmp_path).items():
        with pytest.raises(InputError) as err:
            env.read_map(path)
        text = str(err.value)
        assert "\n" not in text and path.name in text and fault in text, text
    with pytest.raises(InputError, match="environment.frame"):
        load_lighting({"environment": {"map": "studio", "frame": "sideways"}})


def test_a_bad_map_on_the_command_line_is_one_line_and_exit_2(tmp_path, hand):
    model = tmp_path / "right.npz"
    save_npz(hand, model)
    square = write_exr(tmp_path / "square.exr", np.ones((8, 8, 3)))
    run = subprocess.run([sys.executable, "-m", "darthand.cli", "render", str(model), "--environment", str(square),
                          "--out", str(tmp_path / "out"), "--size", "32"], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": f"{REPO / 'tools'}{os.pathsep}{REPO}"})
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "square.exr" in lines[0] and "not 2:1" in lines[0], run.stderr


# ------------------------------------------------------------------------------------------------ frames


def test_a_lights_file_names_its_map_relative_to_its_folder(tmp_path):
    (tmp_path / "maps").mkdir()
    write_exr(tmp_path / "maps" / "grey.exr", np.full((8, 16, 3), 0.5, np.float32))
    (tmp_path / "lights.json").write_text(json.dumps({"environment": {"map": "maps/grey.exr"}}))
    lighting = load_lighting(tmp_path / "lights.json")
    assert lighting.environment is not None and Path(lighting.environment.map) == tmp_path / "maps" / "grey.exr"
    assert load_lighting({"environment": {"map": "studio"}}).environment == env.Environment("studio")


def test_builtin_maps_are_listed_and_read():
    names = env.list_builtin()
    assert names == ["city", "courtyard", "forest", "interior", "night", "studio", "sunrise", "sunset"]
    pixels = env.read_map("studio")
    assert pixels.shape == (512, 1024, 3) and pixels.min() >= 0


def test_environment_frames_are_deterministic_and_keep_the_labels(assets):
    lights = {"environment": {"map": "sunrise", "rotation": 40, "strength": 1.5, "white_balance": [1, 0.9, 0.8]}}
    options = {"width": 64, "height": 64, "camera": "three_quarter"}
    plain = Renderer(assets, threads=1).render(None, **options)
    first = Renderer(assets, threads=1).render(None, lights=lights, background="environment", **options)
    again = Renderer(assets, threads=2).render(None, lights=lights, background="environment", **options)
    assert first.rgba.tobytes() == again.rgba.tobytes()
    assert first.rgba[..., 3].min() == 255 and first.labels["render"]["background"] == "environment"
    assert json.dumps(first.labels["render"]["lights"]["environment"]) == json.dumps(
        {"map": "sunrise", "rotation": 40.0, "strength": 1.5, "white_balance": [1.0, 0.9, 0.8], "frame": "camera"})
    for key in ("keypoints_2d", "keypoints_3d", "visibility", "coverage"):
        if key in plain.labels:
            assert plain.labels[key] == first.labels[key], key
    assert "visibility" in plain.labels
    assert not np.array_equal(plain.colour, first.colour)


def test_environment_background_without_an_environment_is_refused(assets):
    with pytest.raises(InputError, match="needs lights with an environment"):
        Renderer(assets, threads=1).render(None, width=32, height=32, background="environment")


# ------------------------------------------------------------------------------------------------ exposure's key


def test_key_white_of_a_uniform_map_is_its_radiance_times_the_strongest_channel(tmp_path):
    """Under a uniform map of radiance L a white Lambertian card renders L whichever way it faces (the closed form
    the renderer's units are defined by), so the key is L x strength x the largest white-balance gain."""
    path = write_exr(tmp_path / "grey.exr", np.full((32, 64, 3), 0.3, np.float32))
    doc = env.Environment(str(path), rotation=40.0, strength=2.0, white_balance=(0.9, 1.0, 1.1))
    assert env.key_white(doc) == pytest.approx(0.3 * 2.0 * 1.1, rel=2e-3)


@pytest.mark.parametrize("behind_hand", [True, False])
def test_key_white_of_one_bright_texel_is_its_light_on_the_best_facing_card(tmp_path, behind_hand):
    """One bright texel is a directional light of pi-folded intensity L dOmega / pi (the test above), toward-light
    direction t in camera axes. A card facing the camera (normal n, n_z <= 0) renders at most intensity x max n.t:
    1 for a light on the camera's side (t_z <= 0), sqrt(1 - t_z^2) at the rim for one behind the hand (t_z > 0).
    Frame 'camera', rotation 0: the map's centre column is where the camera looks, its edge behind the camera."""
    h, value = 64, 4000.0
    row, col = h // 2, (h + 11 if behind_hand else 3)          # 33 degrees off the view axis, or behind the camera
    pixels = np.zeros((h, 2 * h, 3), np.float32)
    pixels[row, col] = value
    path = write_exr(tmp_path / "sun.exr", pixels)
    theta_top, theta_bottom = np.pi * (0.5 - row / h), np.pi * (0.5 - (row + 1) / h)
    intensity = value * (np.sin(theta_top) - np.sin(theta_bottom)) * 2 * np.pi / (2 * h) / np.pi
    d_e = texel_direction(row, col, h)
    t = np.array([d_e[1], -d_e[2], -d_e[0]])                  # frame 'camera': d_E = (-z, x, -y)
    assert (t[2] > 0.8) == behind_hand and (t[2] < -0.9) != behind_hand
    best = np.sqrt(1.0 - t[2] ** 2) if t[2] > 0 else 1.0
    assert env.key_white(env.Environment(str(path))) == pytest.approx(intensity * best, rel=0.01)
