"""Cameras: projection and rays against closed-form pinhole geometry, look-at, framing, camera files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from darthand.errors import InputError
from darthand.render import camera
from darthand.render.camera import Camera, frame_points, intrinsics, load_camera, look_at


def test_known_point_projects_to_known_pixel():
    # Camera at (0, 0, 2) looking at the origin with +Y up: world x -> image right, world y -> image up.
    cam = look_at((0, 0, 2), (0, 0, 0), (0, 1, 0), width=640, height=480, focal_px=500)
    assert np.allclose(cam.K, [[500, 0, 320], [0, 500, 240], [0, 0, 1]])
    uv, z = cam.project([[0.0, 0.0, 0.0], [0.1, 0.2, 0.0], [0.0, 0.0, 1.0]])
    assert np.allclose(z, [2.0, 2.0, 1.0])
    # u = fx X / Z + cx, v = fy Y / Z + cy with camera Y pointing down (world -y).
    assert np.allclose(uv, [[320, 240], [320 + 500 * 0.1 / 2, 240 - 500 * 0.2 / 2], [320, 240]])


def test_projection_equals_K_R_t_and_rays_go_through_their_pixels():
    rng = np.random.default_rng(0)
    cam = look_at((0.3, -0.2, 0.6), (0.01, 0.02, -0.03), (0.2, 1, 0.1), width=300, height=200, fov_deg=35)
    X = rng.normal(scale=0.05, size=(20, 3))
    uv, z = cam.project(X)
    p = cam.K @ (cam.R @ X.T + cam.t[:, None])
    assert np.allclose(uv, (p[:2] / p[2]).T, atol=1e-12)
    assert np.allclose(z, p[2])
    # The ray through a point's pixel reaches the point at parameter t = z (camera z of the direction is 1).
    d = cam.directions(uv)
    assert np.allclose(cam.centre + z[:, None] * d, X, atol=1e-12)
    assert np.allclose(cam.R @ cam.centre + cam.t, 0)
    assert np.allclose(cam.extrinsics @ np.append(X[0], 1), np.append(cam.to_camera(X[:1])[0], 1))


def test_look_at_axes_are_opencv():
    cam = look_at((0, 0, 5), (0, 0, 0), (0, 1, 0))
    assert np.allclose(cam.R, [[1, 0, 0], [0, -1, 0], [0, 0, -1]])   # x right, y down, z forward (toward -Z)
    with pytest.raises(InputError):
        look_at((0, 0, 1), (0, 0, 0), (0, 0, 1))                        # up parallel to the view direction


def test_intrinsics_field_of_view():
    K = intrinsics(400, 200, fov_deg=60)
    # 60 degrees across the smaller side (200 px): f = 100 / tan(30 deg).
    assert np.isclose(K[0, 0], 100 / np.tan(np.deg2rad(30)))
    assert np.allclose(K[:2, 2], [200, 100])


def test_framing_fits_points_with_margin():
    rng = np.random.default_rng(1)
    pts = rng.uniform(-0.1, 0.1, size=(500, 3)) * [1, 0.3, 0.5] + [0.05, 0.0, 0.02]
    for view in ("three_quarter", "dorsal", "palmar", "radial"):
        cam = frame_points(pts, view, width=256, height=192, margin=0.1)
        uv, z = cam.project(pts)
        assert (z > 0).all()
        lo, hi = uv.min(0), uv.max(0)
        assert (lo >= 0).all() and (hi[0] <= 256) and (hi[1] <= 192)
        # Fills the frame to the margin on the tighter axis (within 3%), centred.
        fill = max((hi - lo)[0] / 256, (hi - lo)[1] / 192)
        assert abs(fill - 0.8) < 0.03
        assert np.allclose(0.5 * (lo + hi), [128, 96], atol=4)


def test_dorsal_view_looks_at_the_back_of_a_right_hand_fingers_up():
    # MANO frame: fingers toward -X, palm facing -Y: the dorsal camera sits at +Y, fingers point up in the image.
    pts = np.array([[0.0, 0, 0], [-0.1, 0, 0], [0, 0, 0.05]])
    cam = frame_points(pts, "dorsal")
    assert cam.centre[1] > 0.05
    uv, _ = cam.project(pts)
    assert uv[1, 1] < uv[0, 1]                      # the fingertip end is higher in the image
    left = frame_points(pts * [-1, 1, 1], "dorsal", side="left")
    assert left.centre[1] > 0.05
    uv_left, _ = left.project(pts * [-1, 1, 1])
    assert uv_left[1, 1] < uv_left[0, 1]            # a left hand's fingers point up too
    # The left hand's view is the mirror image of the right one's.
    assert np.allclose(uv_left[:, 0], left.width - uv[:, 0]) and np.allclose(uv_left[:, 1], uv[:, 1])


def test_camera_files(tmp_path):
    pts = np.random.default_rng(2).normal(scale=0.05, size=(50, 3))
    spec = {"width": 100, "height": 80, "fov_deg": 40, "look_at": {"eye": [0, 0, 1], "target": [0, 0, 0]}}
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(spec))
    cam = load_camera(path)
    assert (cam.width, cam.height) == (100, 80)
    assert np.allclose(cam.centre, [0, 0, 1])
    explicit = load_camera({"K": cam.K.tolist(), "R": cam.R.tolist(), "t": cam.t.tolist(), "width": 100,
                            "height": 80})
    assert np.allclose(explicit.R, cam.R) and np.allclose(explicit.K, cam.K)
    framed = load_camera({"view": [0, 1, 0], "margin": 0.2}, pts)
    assert framed.width == 512
    assert isinstance(load_camera("palmar", pts), Camera)


@pytest.mark.parametrize("spec, field", [
    ({"R": [[1, 0, 0], [0, 1, 0]], "t": [0, 0, 0]}, "R"),
    ({"look_at": {"eye": [0, 0, 1]}}, "look_at"),
    ({"view": "sideways"}, "view"),
    ({"view": "dorsal", "look_at": {"eye": [0, 0, 1], "target": [0, 0, 0]}}, "cam.json"),
    ({"view": "dorsal", "fov_deg": -3}, "fov_deg"),
])
def test_bad_camera_specs_name_the_field(spec, field):
    with pytest.raises(InputError, match=field):
        load_camera(spec, np.zeros((3, 3)), source="cam.json")


def test_bad_camera_values():
    with pytest.raises(InputError, match="rotation"):
        Camera(np.eye(3), np.diag([1.0, 1.0, -1.0]), np.zeros(3), 10, 10)
    with pytest.raises(InputError, match="no such camera file"):
        load_camera("no/such/file.json")


def test_middle_rows_give_np_median_of_every_shifted_copy():
    """frame_points' medians: np.mean(z[middle_rows(r)]) equals np.median(z) bit for bit for z = r + t (any t), with
    ties, odd and even counts; NaN or no values leave it to np.median."""
    rng = np.random.default_rng(3)
    for n in (1, 2, 3, 4, 5, 64, 5006, 5007):
        r = rng.normal(0.3, 0.05, n)
        r[rng.integers(0, n, n // 3)] = r[0]                          # ties
        middle = camera.middle_rows(r)
        for t in rng.normal(0, 1, 20).tolist() + [0.0, -0.3, 1e-300, 1e6]:
            z = r + t
            assert np.mean(z[middle]).tobytes() == np.median(z).tobytes(), (n, t)
    assert camera.middle_rows(np.array([0.1, np.nan, 0.2])) is None and camera.middle_rows(np.zeros(0)) is None
