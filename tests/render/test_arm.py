"""An arm that goes on (render/arm.py, render/dress.py): no cap pixels where the cut faced the camera, the seam with
the hand closed in any pose and shape, UVs continuing the wrist band's, the camera kept out of the arm, and the
labels, the camera and the dataset's mesh (the model's MANO-layout vertices) unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.dataset.frames import render_job, write_dataset_frame
from darthand.errors import InputError
from darthand.model.cap import forearm_cap
from darthand.model.wrist import loop_frame
from darthand.render.api import Renderer
from darthand.render.arm import ARM, ARM_END, MIN_LENGTH, forearm_arm, shorten_before

ARM_M = 0.3
FLAT_POSE = np.zeros(48)


def cut_camera(hand, angle_deg: float = 40.0, distance: float = 0.25, side_deg: float = 0.0) -> dict:
    """A camera looking at the rest hand's forearm cut from `distance` metres, `angle_deg` off the forearm's
    axis (beyond the cut), so the cap faces it."""
    loop = forearm_cap(hand).loop
    centre, axis, _ = loop_frame(hand, loop)
    across = np.cross(axis, [0.0, 1.0, 0.0])
    across /= np.linalg.norm(across)
    a = np.radians(angle_deg)
    eye = centre + distance * (np.cos(a) * axis + np.sin(a) * across)
    return {"fov_deg": 40, "look_at": {"eye": eye.tolist(), "target": centre.tolist(), "up": [0.0, 1.0, 0.0]}}


def cap_pixels(frame) -> int:
    caps = [i for i, s in enumerate(frame.subject.surfaces) if s.role == "cap"]
    return int(np.isin(frame.geom, caps).sum())


def test_the_arm_hides_the_cap(hand, assets):
    renderer = Renderer(assets, threads=1)
    camera = cut_camera(hand)
    plain = renderer.render(FLAT_POSE, camera=camera, width=96, height=96)
    arm = renderer.render(FLAT_POSE, camera=camera, width=96, height=96, arm=ARM_M)
    assert cap_pixels(plain) > 100
    assert cap_pixels(arm) == 0
    roles = [s.role for s in arm.subject.surfaces]
    assert roles == ["hand", "arm", "cap"] and arm.labels["render"]["geometry"] == {"arm": ARM_M}


def test_the_camera_and_labels_stay(hand, assets):
    renderer = Renderer(assets, threads=1)
    plain = renderer.render("fist", camera="three_quarter", width=96, height=96, accessory="ring_test")
    arm = renderer.render("fist", camera="three_quarter", width=96, height=96, accessory="ring_test", arm=ARM_M,
                          subdivision=1)
    a, b = plain.labels, arm.labels
    for key in ("K", "camera", "keypoints_2d", "keypoints_3d", "joints_3d", "mano_pose", "accessory"):
        assert a[key] == b[key], key
    # The mask (and its bbox, coverage) is the hand's and the accessory's: the arm is drawn in the image's alpha.
    assert np.abs(np.array(b["bbox"]) - np.array(a["bbox"])).max() <= 2
    assert abs(b["coverage"] - a["coverage"]) < 0.1 * a["coverage"]
    assert arm.rgba[..., 3].astype(float).sum() > 1.05 * 255 * arm.alpha.sum()
    # The arm can only hide keypoints (a real occluder), never reveal one.
    assert not (np.array(b["visibility"]) & ~np.array(a["visibility"])).any()
    assert np.array_equal(arm.subject.hand_vertices, plain.subject.hand.vertices)


@pytest.mark.parametrize("betas", [None, np.array([1.5, -1.0, 0.5])])
def test_the_seam_stays_closed(hand, assets, betas):
    pose = np.random.default_rng(3).normal(0, 0.3, 48)
    subject = assets.subject(pose, betas=betas, arm=ARM_M)
    tube = next(s for s in subject.surfaces if s.name == ARM)
    end = next(s for s in subject.surfaces if s.name == ARM_END)
    loop = forearm_cap(hand).loop
    assert np.abs(tube.vertices[:len(loop)] - subject.hand.vertices[loop]).max() < 1e-6
    assert np.array_equal(end.vertices[:len(loop)], tube.vertices[-len(loop):])     # the far end closes the tube
    # The arm reaches its length from the cut, and widens away from the wrist.
    centre = tube.vertices[:len(loop)].mean(0)
    assert abs(np.linalg.norm(end.vertices[-1] - centre) - ARM_M) < 0.01
    radius = lambda ring: np.linalg.norm(ring - ring.mean(0), axis=1).mean()
    assert radius(tube.vertices[-len(loop):]) > 1.2 * radius(tube.vertices[:len(loop)])


def test_the_arm_keeps_its_rest_arrays_across_frames(hand, assets):
    """Each frame's arm surfaces carry the same rest arrays (the skin's curvature is kept per rest array, not worked
    out again each frame), equal to the arm's own rest mesh."""
    rng = np.random.default_rng(5)
    first, second = (assets.subject(rng.normal(0, 0.3, 48), betas=rng.normal(0, 1, 3), arm=ARM_M) for _ in range(2))
    arm = forearm_arm(hand, ARM_M)
    for name, rest in ((ARM, arm.skin.vertices[:arm.tube_vertices]),
                       (ARM_END, arm.skin.vertices[arm.tube_vertices - arm.ring_size:])):
        a, b = (next(s for s in subject.surfaces if s.name == name) for subject in (first, second))
        assert a.rest is b.rest and np.array_equal(a.rest, rest)


def test_the_uvs_continue_the_wrist_band(hand):
    arm = forearm_arm(hand, ARM_M)
    cap = forearm_cap(hand)
    L = len(cap.loop)
    ring0 = arm.skin.uvs[:2 * L]
    assert np.array_equal(ring0, cap.uvs[:2 * L])                  # the rim's UVs, edge by edge (seams kept)
    band = hand.uvs[hand.faces_uv[hand.meta["wrist"]["base_faces"]:].reshape(-1)]
    v = arm.skin.uvs[:, 1]
    assert band[:, 1].min() - 1e-9 <= v.min() and v.max() <= band[:, 1].max() + 1e-9
    # Along the arm V runs at the band's own density: V per metre equals the band's height over the rings' length.
    tube = arm.skin.vertices[:arm.tube_vertices]
    axis = loop_frame(hand, cap.loop)[1]
    first = (tube[L:2 * L].mean(0) - tube[:L].mean(0)) @ axis
    v_step = abs(arm.skin.uvs[2 * L, 1] - arm.skin.uvs[0, 1])
    band_density = np.ptp(band[:, 1]) / hand.meta["wrist"]["length_m"]
    assert v_step / first == pytest.approx(band_density, rel=1e-6)


@pytest.mark.parametrize("distance", [0.15, 0.6])
def test_a_camera_looking_along_the_arm_sees_the_cut(hand, assets, distance):
    """On the forearm's axis (inside a 0.3 m arm, or beyond its end) any arm would hide the hand: it is cut back
    to the shortest, and the frame is the one without the option, the cut moved by at most MIN_LENGTH."""
    renderer = Renderer(assets, threads=1)
    camera = cut_camera(hand, angle_deg=0.0, distance=distance)
    frame = renderer.render(FLAT_POSE, camera=camera, width=64, height=64, arm=ARM_M)
    plain = renderer.render(FLAT_POSE, camera=camera, width=64, height=64)
    tube = next(s for s in frame.subject.surfaces if s.name == ARM)
    centre, axis, _ = loop_frame(hand, forearm_cap(hand).loop)
    assert ((tube.vertices - centre) @ axis).max() < MIN_LENGTH + 1e-3
    assert np.abs(frame.rgba[..., 3] / 255 - plain.alpha).mean() < 0.05


def test_shorten_before_leaves_a_clear_arm_alone():
    rim = np.array([[0.02, 0.0, 0.0], [0.0, 0.02, 0.0], [-0.02, 0.0, 0.0], [0.0, -0.02, 0.0]])
    v = np.concatenate([rim, 1.5 * rim + [0, 0, 0.3], [[0.0, 0.0, 0.3]]])        # two rings and a far centre
    z = np.array([0.0, 0.0, 1.0])
    assert shorten_before(v, np.zeros(3), z, np.array([0.5, 0.0, 0.1]), 0.05, 0.3, rim) is v    # beside the arm
    assert shorten_before(v, np.zeros(3), z, np.array([0.0, 0.0, -0.2]), 0.05, 0.3, rim) is v   # behind the cut
    moved = shorten_before(v, np.zeros(3), z, np.array([0.0, 0.01, 0.2]), 0.05, 0.3, rim)
    assert np.allclose(moved[:4], rim) and np.allclose(moved[4:8], rim + [0, 0, MIN_LENGTH])
    assert np.allclose(moved[8], [0, 0, MIN_LENGTH])


def test_arm_refuses_bad_lengths(assets):
    with pytest.raises(InputError, match="arm"):
        Renderer(assets, threads=1).render(FLAT_POSE, width=32, height=32, arm=5.0)


def test_dataset_mesh_and_labels_stay_the_models(hand, assets, tmp_path):
    """A dataset frame with the arm and subdivision writes the model's own posed vertices (its MANO layout) and the
    same labels as without them, but for the render record (and visibility, which the arm may hide)."""
    renderer = Renderer(assets, threads=1)
    job = {"index": 0, "side": "right", "pose": "point", "camera": "dorsal", "texture": "skin_test",
           "accessory": "none", "skin_tone_offset": 0.0}
    files = {}
    for name, geometry in (("plain", {}), ("dressed", {"subdivision": 1, "arm": ARM_M})):
        settings = {"size": 64, "samples": 4, "aa_shading": "triangle", "geometry": geometry}
        frame, _ = render_job(renderer, job, settings)
        write_dataset_frame(frame, job, "digest", tmp_path / name, assets, None)
        files[name] = frame
    plain, dressed = (np.load(tmp_path / n / "meshes" / "000000.npy") for n in ("plain", "dressed"))
    assert plain.shape == (hand.num_vertices, 3) and np.array_equal(plain, dressed)
    a, b = files["plain"].labels, files["dressed"].labels
    assert a["mesh"] == b["mesh"] and a["mano"] == b["mano"]
    differ = {k for k in a if a[k] != b[k]}
    assert differ <= {"render", "visibility", "bbox", "coverage"}, differ
