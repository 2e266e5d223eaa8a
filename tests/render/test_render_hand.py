"""Rendering the hand: labels exact and consistent with the image, visibility, accessories, determinism, left hands,
written files valid against schemas/labels.schema.json."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest
from darthand.errors import InputError
from darthand.render.api import Renderer, write_frame
from darthand.render.camera import look_at
from darthand.render.image import read_png
from darthand.render.lights import Lighting
from darthand.render.scene import Scene
from darthand.render.subject import Subject
from darthand.schemas import load_schema
from render_scenes import RING_JOINT, quad

SIZE = 160


@pytest.fixture
def renderer(assets):
    return Renderer(assets, threads=2)


def test_labels_are_exact_projections(renderer):
    frame = renderer.render("point", camera="three_quarter", width=SIZE, height=SIZE, accessory="ring_test")
    lab = frame.labels
    jsonschema.Draft202012Validator(load_schema("labels.schema.json")).validate(lab)
    K, R, t = (np.array(lab[k]) if k == "K" else np.array(lab["camera"][k]) for k in ("K", "R", "t"))
    X = np.array(lab["keypoints_3d_world"])
    cam = R @ X.T + t[:, None]
    assert np.allclose(np.array(lab["keypoints_3d"]).T, cam, atol=1e-12)
    p = K @ cam
    assert np.allclose(np.array(lab["keypoints_2d"]), (p[:2] / p[2]).T, atol=1e-9)
    # Keypoints are the forward pass's, in openpose order: the wrist first, the thumb tip fifth.
    assert lab["keypoint_names"][0] == "wrist" and lab["keypoint_names"][4] == "thumb4"
    assert np.allclose(X[0], np.array(lab["joints_3d_world"])[0])
    assert lab["gesture"] == "point" and lab["accessory"] == {"id": "ring_test", "parent_joint": RING_JOINT,
                                                              "kind": "rigid"}


def test_keypoints_fall_on_or_next_to_the_mask(renderer):
    frame = renderer.render("relaxed", camera="palmar", width=SIZE, height=SIZE)
    kp = np.array(frame.labels["keypoints_2d"])
    assert all(frame.labels["in_image"])
    mask = frame.alpha > 0
    for u, v in kp:
        r, c = int(v), int(u)
        window = mask[max(r - 2, 0):r + 3, max(c - 2, 0):c + 3]
        assert window.any(), (u, v)
    x0, y0, x1, y1 = frame.labels["bbox"]
    rows, cols = np.nonzero(mask)
    assert (x0, y0, x1, y1) == (cols.min(), rows.min(), cols.max() + 1, rows.max() + 1)
    assert 0.05 < frame.labels["coverage"] < 0.6


def test_visibility_false_behind_an_occluder(renderer, assets):
    frame = renderer.render("flat", camera="dorsal", width=SIZE, height=SIZE)
    vis = np.array(frame.labels["visibility"])
    assert vis.sum() >= 15                      # the back of a flat hand shows nearly every joint
    # A wall between the camera and the hand hides every keypoint.
    cam = frame.camera
    subj = frame.subject
    centre = subj.keypoints.mean(0)
    toward = cam.centre - centre
    wall_at = centre + 0.5 * toward
    axis = int(np.argmax(np.abs(toward)))
    wall = quad(centre=wall_at, size=1.0, normal_axis=axis, role="accessory", name="wall")
    walled = Subject(subj.surfaces + (wall,), subj.joints, subj.keypoints, subj.side, subj.pose, subj.keypoint_order,
                     subj.info)
    from darthand.render.labels import keypoint_thickness, own_parts, visibility

    thick = keypoint_thickness(subj.keypoints, subj.hand.vertices, "openpose")
    assert not visibility(Scene(walled), cam, subj.keypoints, thick, own_parts("openpose")).any()
    assert np.array_equal(visibility(Scene(subj), cam, subj.keypoints, thick, own_parts("openpose")), vis)


def test_fingertips_behind_the_hand_are_not_visible(renderer):
    """Seen from the palm, a fist hides the fingertips curled into it; the dorsal view of the flat hand shows them."""
    fist = renderer.render("fist", camera="dorsal", width=SIZE, height=SIZE)
    names = fist.labels["keypoint_names"]
    vis = dict(zip(names, fist.labels["visibility"]))
    assert not any(vis[f"{f}4"] for f in ("index", "middle", "ring", "pinky"))
    flat = renderer.render("flat", camera="dorsal", width=SIZE, height=SIZE)
    vis = dict(zip(names, flat.labels["visibility"]))
    assert all(vis[f"{f}4"] for f in ("index", "middle", "ring", "pinky"))


def test_accessory_is_visible_next_to_its_bone(renderer):
    frame = renderer.render("flat", camera="dorsal", width=SIZE, height=SIZE, accessory="ring_test")
    ring_px = np.argwhere(frame.geom == 1)
    assert len(ring_px) > 20
    joints_2d, _ = frame.camera.project(frame.subject.joints)
    mid = 0.5 * (joints_2d[RING_JOINT] + joints_2d[RING_JOINT + 1])
    centre = ring_px.mean(0)[::-1] + 0.5
    bone = np.linalg.norm(joints_2d[RING_JOINT + 1] - joints_2d[RING_JOINT])
    assert np.linalg.norm(centre - mid) < 0.5 * bone
    # The ring is gold: red over blue where it is seen.
    c = frame.colour[frame.geom == 1]
    assert (c[:, 0] > c[:, 2]).mean() > 0.9


def test_no_nan_and_determinism(renderer, assets, tmp_path):
    a = renderer.render("ok", camera="three_quarter", width=SIZE, height=SIZE, accessory="ring_test")
    paths = write_frame(a, tmp_path / "a", depth=True)
    b = Renderer(assets, threads=1).render("ok", camera="three_quarter", width=SIZE, height=SIZE,
                                           accessory="ring_test")
    write_frame(b, tmp_path / "b", depth=True)
    assert np.isfinite(a.colour).all() and np.isfinite(a.depth).all()
    for name in ("image.png", "mask.png", "labels.json", "depth.exr"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    img, mask = read_png(paths["image"]), read_png(paths["mask"])
    assert img.shape == (SIZE, SIZE, 4) and mask.shape == (SIZE, SIZE, 1)
    assert np.array_equal(img[..., 3], mask[..., 0])
    labels = json.loads(paths["labels"].read_text())
    assert labels["files"] == {"image": "image.png", "mask": "mask.png", "depth": "depth.exr"}
    # Depth at a covered pixel centre is the camera z of the surface point its ray reaches.
    r, c = np.argwhere(a.geom == 0)[len(np.argwhere(a.geom == 0)) // 2]
    X = a.camera.centre + a.depth[r, c] * a.camera.directions(np.array([[c + 0.5, r + 0.5]]))[0]
    assert np.isclose(a.camera.to_camera(X[None])[0, 2], a.depth[r, c])


def test_left_hand_is_the_mirror_image(hand, texture_files):
    """Mirroring the world (x -> -x) and the camera gives the left hand's image as the right one's, flipped
    left-right (lights move with the camera, their x mirrored too)."""
    from darthand.model.mirror import mirror_model
    from darthand.render.assets import HandAssets
    from darthand.render.lights import Light

    right = HandAssets(hand, {texture_files.id: texture_files}, texture_files.id)
    left = HandAssets(mirror_model(hand), {texture_files.id: texture_files}, texture_files.id)
    cam = look_at((0.05, 0.35, 0.25), (-0.06, 0.0, 0.0), (-1, 0, 0), width=96, height=96, fov_deg=35)
    F = np.diag([-1.0, 1.0, 1.0])
    mirrored = type(cam)(cam.K, F @ cam.R @ F, cam.t * [-1, 1, 1], 96, 96)
    light = lambda x: Lighting((1, 1, 1), 0.2, (Light("directional", (1, 1, 1), 2.0, direction=(x, 0.5, 0.7),
                                                      frame="camera"),))
    a = Renderer(right, threads=1).render("pinch", camera=cam, lights=light(0.4), samples=8)
    b = Renderer(left, threads=1).render("pinch", camera=mirrored, lights=light(-0.4), samples=8)
    # Geometry is mirrored exactly; edge pixels differ a little since the sub-sample pattern is not symmetric.
    diff = np.abs(b.alpha - a.alpha[:, ::-1])
    assert diff.max() <= 0.3 and diff.mean() < 2e-3
    assert abs(b.alpha.sum() - a.alpha.sum()) / a.alpha.sum() < 2e-3
    both = (a.alpha[:, ::-1] == 1) & (b.alpha == 1)
    assert np.abs(b.colour[both] - a.colour[:, ::-1][both]).mean() < 2e-3
    assert np.allclose(np.array(b.labels["keypoints_2d"])[:, 0], 96 - np.array(a.labels["keypoints_2d"])[:, 0])
    assert b.labels["visibility"] == a.labels["visibility"]


def test_background_and_skin_tone_offset(renderer, tmp_path):
    from render_scenes import write_image

    bg = write_image(tmp_path / "bg.png", np.tile(np.array([30, 90, 160], np.uint8), (40, 60, 1)))
    frame = renderer.render("flat", camera="palmar", width=SIZE, height=SIZE, background=bg)
    assert (frame.rgba[..., 3] == 255).all()
    assert np.array_equal(frame.rgba[0, 0, :3], [30, 90, 160])
    darker = renderer.render("flat", camera="palmar", width=SIZE, height=SIZE, skin_tone_offset=-0.15)
    lighter = renderer.render("flat", camera="palmar", width=SIZE, height=SIZE, skin_tone_offset=0.0)
    covered = (darker.alpha == 1) & (lighter.alpha == 1)
    assert darker.colour[covered].mean() < 0.8 * lighter.colour[covered].mean()
    assert darker.labels["texture"] == {"id": "skin_test", "skin_tone_offset": -0.15, "tone_srgb": None}


@pytest.mark.parametrize("kw, match", [
    ({"texture": "nope"}, "texture"), ({"accessory": "nope"}, "accessory"), ({"pose": "wave"}, "pose"),
    ({"pose": np.zeros(47)}, "pose"), ({"samples": 3}, "samples"), ({"aa_shading": "pixel"}, "aa_shading"),
    ({"camera": "aerial"}, "aerial"),
])
def test_bad_arguments_are_input_errors(renderer, kw, match):
    pose = kw.pop("pose", None)
    with pytest.raises(InputError, match=match):
        renderer.render(pose, width=32, height=32, **kw)


def test_triangle_shading_of_edges_is_close_to_per_sample_shading(renderer):
    """Anti-aliasing shaded once per pixel per triangle keeps the coverage of per-sample shading exactly, shades a
    fraction of the sub-samples, and changes the image less than going from 8 to 16 sub-samples does (it differs
    where a shadow, texture or highlight varies across a triangle inside an edge pixel)."""
    options = dict(camera="three_quarter", width=SIZE, height=SIZE, accessory="ring_test")
    tri = renderer.render("ok", aa_shading="triangle", **options)
    per_sample = renderer.render("ok", aa_shading="sample", **options)
    finer = renderer.render("ok", aa_shading="sample", samples=16, **options)
    assert np.array_equal(tri.alpha, per_sample.alpha)
    assert tri.stats["aa_shaded"] < 0.3 * per_sample.stats["aa_shaded"]
    approximation = np.abs(tri.colour - per_sample.colour).mean()
    sampling = np.abs(finer.colour - per_sample.colour).mean()
    assert 0 < approximation < sampling
    assert tri.labels["render"]["aa_shading"] == "triangle"


def test_render_many_matches_frame_by_frame(assets):
    """The pipelined loop (next frame prepared on a helper thread) gives the frames `render` gives one by one,
    including a repeated pose whose scene is reused while the frame before it is still being traced."""
    poses = ["point", "ok", "ok", "flat"]
    options = dict(camera="three_quarter", width=SIZE, height=SIZE, accessory="ring_test")
    many = list(Renderer(assets, threads=2).render_many(poses, **options))
    single = Renderer(assets, threads=2)
    assert len(many) == len(poses)
    for pose, frame in zip(poses, many):
        ref = single.render(pose, **options)
        assert np.array_equal(frame.rgba, ref.rgba), pose
        assert frame.labels == ref.labels, pose
    assert list(Renderer(assets).render_many([], **options)) == []
