"""Dataset plans: determinism and frame independence, the options' distributions, DART's grid-and-slerp poses
(against scipy's rotations), equal-area views (closed forms), real light colours (CIE's illuminant A), reference
sets (FreiHAND's training_mano.json), splits, backgrounds (a truncated image is skipped)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers_dataset import TEXTURES
from scipy.spatial.transform import Rotation

from darthand.dataset import backgrounds, lighting, plan, poses, views
from darthand.errors import InputError
from darthand.model.anatomy import axis_angle_to_angles, within_limits
from darthand.model.mirror import mirror_pose
from darthand.schemas import check_schema


def test_a_frame_depends_only_on_seed_and_index(planner, sources):
    jobs = list(planner.jobs(0, 20))
    assert jobs == list(planner.jobs(0, 20))
    assert list(planner.jobs(5, 12)) == jobs[5:12] and planner.job(17) == jobs[17]
    other = plan.Planner({"seed": 4, "accessory_share": 0.5}, sources[0])
    assert sum(a["camera"] != b["camera"] for a, b in zip(jobs, other.jobs(0, 20))) >= 18
    narrowed = plan.Planner({"seed": 3, "accessory_share": 0.5, "textures": [TEXTURES[1]]}, sources[0])
    assert [j["camera"] for j in narrowed.jobs(0, 20)] == [j["camera"] for j in jobs]   # one option, not another's
    assert planner.job(10**11)["index"] == 10**11                                        # no list: any index at once


def test_planned_jobs_follow_the_defaults_and_the_schema(planner, sources):
    jobs = list(plan.Planner({"seed": 1}, sources[0]).jobs(0, 400))
    check_schema({"frames": jobs}, "dataset_jobs.schema.json", "plan")
    json.loads(json.dumps(jobs))
    assert {j["texture"] for j in jobs} == set(TEXTURES)
    tones = np.array([j["skin_tone_offset"] for j in jobs])
    assert tones.min() >= -0.15 and tones.max() <= 0.15 and abs(tones.mean()) < 0.02
    assert 0.19 < np.mean([j["accessory"] != "none" for j in jobs]) < 0.31              # DART's 25 %
    assert 0.4 < np.mean([j["side"] == "left" for j in jobs]) < 0.6
    for j in jobs:              # the defaults: an environment per frame, seen behind the hand
        assert set(j["lights"]) == {"environment"} and j["background"]["environment"] is True
        assert 30 <= j["camera"]["fov_deg"] <= 60 and -45 <= j["camera"]["roll_deg"] <= 45
        check_schema(j["lights"], "lights.schema.json", "lights")
    assert len({j["lights"]["environment"]["map"] for j in jobs}) == 8                  # the built-in set
    for j in plan.Planner({"seed": 1, "lights": "random", "backgrounds": "builtin"}, sources[0]).jobs(0, 50):
        assert j["lights"]["lights"][0]["shadows"] and j["background"]["builtin"] < backgrounds.BUILTIN_COUNT
        check_schema(j["lights"], "lights.schema.json", "lights")
    # splits: by pose group (the 8 frames of a slerp path share one), about 0.8 / 0.1 / 0.1
    assert all(len({j["split"] for j in jobs[g:g + 8]}) == 1 for g in range(0, 400, 8))
    many = [plan.split_of(g, 1, (0.8, 0.1, 0.1)) for g in range(3000)]
    assert abs(many.count("train") / 3000 - 0.8) < 0.03 and abs(many.count("test") / 3000 - 0.1) < 0.02


def test_left_frames_take_the_mirror_image_of_the_planned_pose(planner):
    for i in range(40):
        job = planner.job(i)
        right, _ = planner.poses.sample(planner.seed, i)
        expected = mirror_pose(right) if job["side"] == "left" else right
        assert np.allclose(job["pose"], expected, atol=0)


def test_grid_slerp_walks_from_a_grid_pose_to_the_most_different_reference(planner):
    sampler = planner.poses
    assert isinstance(sampler, poses.GridSlerp) and sampler.steps == 8 and sampler.draws == 2000
    ref = sampler.reference
    for g in range(3):
        group = sampler.group(planner.seed, g)
        base_pose = np.zeros(48)
        base_pose[3:] = Rotation.from_quat(group["base"][:, [1, 2, 3, 0]]).as_rotvec().reshape(-1)
        assert within_limits(axis_angle_to_angles(planner.model, base_pose), tol=1e-6).all()   # a legal grid pose
        # the kept reference is the most different of the draws (recomputed with scipy's rotations)
        rng = np.random.default_rng([planner.seed, poses.POSE_STREAM, g])
        {f: rng.integers(sampler.cells[f]) for f in sampler.cells}
        drawn = rng.integers(len(ref), size=sampler.draws)
        base_rot = Rotation.from_quat(group["base"][:, [1, 2, 3, 0]])
        dist = [sum((base_rot[j].inv() * Rotation.from_quat(ref.quats[k, j, [1, 2, 3, 0]])).magnitude()
                    for j in range(15)) for k in np.unique(drawn)]
        assert group["distance"] == pytest.approx(max(dist), abs=1e-5)
        frames = [sampler.sample(planner.seed, 8 * g + k)[0] for k in range(8)]
        total = (base_rot.inv() * Rotation.from_quat(ref.quats[group["reference"]][:, [1, 2, 3, 0]])).magnitude()
        for k, pose in enumerate(frames):                       # slerp: a fraction k/7 of each joint's arc
            rot = Rotation.from_rotvec(pose[3:].reshape(15, 3))
            assert np.allclose((base_rot.inv() * rot).magnitude(), total * k / 7, atol=1e-6)
        assert np.allclose(frames[-1], ref.pose(group["reference"]), atol=1e-6)


def test_equal_area_cells_stratify_the_views():
    n = views.cell_count()
    cells = [views.frame_cell(5, i, n) for i in range(3 * n)]
    for k in range(3):
        assert sorted(cells[k * n:(k + 1) * n]) == list(range(n))          # every n frames visit every cell once
    u = np.random.default_rng(0).random((20000, 3))
    dirs = np.array([views.cell_direction(int(a * n), b, c) for a, b, c in u])
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1, atol=1e-5) and dirs[:, 0].max() <= views.WRIST_CONE_COS
    # uniform on the zone x in [-1, c]: x uniform (Archimedes), so its mean is the midpoint and E[y^2] = E[1 - x^2]/2
    c = views.WRIST_CONE_COS
    assert dirs[:, 0].mean() == pytest.approx((c - 1) / 2, abs=0.01)
    assert np.mean(dirs[:, 1] ** 2) == pytest.approx((1 - ((c ** 3 + 1) / 3) / (c + 1)) / 2, abs=0.01)


def test_light_colours_are_on_the_planckian_locus():
    x, y = lighting.planckian_xy(2856)                     # CIE standard illuminant A: (0.44757, 0.40745)
    assert (x, y) == pytest.approx((0.44757, 0.40745), abs=1e-3)
    x, y = lighting.planckian_xy(6504)                     # D65's temperature, on the locus (D65 lies 0.003 above)
    assert (x, y) == pytest.approx((0.3135, 0.3237), abs=2e-3)
    assert np.allclose(lighting.kelvin_to_rgb(6504), 1, atol=0.08)
    rgb = np.array([lighting.PALETTE[n] for n in lighting.PALETTE])
    blue_over_red = rgb[:, 2] / rgb[:, 0]
    assert (np.diff(blue_over_red) > 0).all() and rgb.max() == 1 and rgb.min() >= 0     # ordered by temperature
    doc, record = lighting.random_rig(np.full(lighting.UNIFORMS, 0.3))
    check_schema(doc, "lights.schema.json", "rig")
    assert doc["lights"][0]["direction"][2] >= -lighting.KEY_MAX_Z and record["second"].startswith("point")


def test_freihand_training_mano_is_a_reference_set(hand, tmp_path):
    rng = np.random.default_rng(1)
    finger = rng.normal(scale=0.3, size=(5, 45))
    rows = [[[*rng.normal(size=3), *(f - hand.hands_mean), *rng.normal(size=10), 112.0, 98.0, 800.0]]
            for f in finger]                                                   # FreiHAND: [[61 values]] per sample
    path = tmp_path / "training_mano.json"
    path.write_text(json.dumps(rows))
    ref = poses.load_reference(str(path), hand)
    assert len(ref) == 5 and ref.source == "freihand:training_mano.json"
    expected = Rotation.from_rotvec(finger.reshape(-1, 3)).as_quat()[:, [3, 0, 1, 2]].reshape(5, 15, 4)
    got = ref.quats.astype(float)
    assert np.allclose(np.abs((got * expected).sum(-1)), 1, atol=1e-6)        # the same rotations (q or -q)
    path.write_text(json.dumps([[[0.0] * 60]]))
    with pytest.raises(InputError, match=r"row 0 has 60 values, a training_mano.json row has 61"):
        poses.load_reference(str(path), hand)
    path.write_text(json.dumps([[0.1] * 61] * 50))
    with pytest.raises(InputError, match=r"over the reference-file budget .*--max-reference-mb"):
        poses.load_reference(str(path), hand, max_mb=0.01)


def test_bad_plan_options_are_one_line_errors(sources):
    for options, expected in [({"split": [0.8, 0.2, 0.1]}, "sums to 1.1, more than 1"),
                              ({"skin_tone_range": [float("nan"), 0.1]}, "must be finite"),
                              ({"accessory_share": 2}, "outside 0..1"),
                              ({"textures": ["nope_00"]}, "'nope_00' is not one of"),
                              ({"poses": {"mode": "wave"}}, "not auto, dart, jitter or gestures"),
                              ({"poses": {"reference": "gestures", "gestures": ["wave"]}},
                               "'wave' is not a gesture"),
                              ({"poses": {"gestures": ["wave"]}}, "'wave' is not a pose of the pose library"),
                              ({"backgrounds": "/nonexistent"}, "neither 'builtin'"),
                              ({"views": ["top"]}, "views: 'top'")]:
        with pytest.raises(InputError, match=expected):
            plan.Planner(options, sources[0])


def test_a_truncated_background_is_skipped_and_recorded(tmp_path):
    from darthand.render.image import write_png

    folder = tmp_path / "bg"
    folder.mkdir()
    ramp = np.tile(np.arange(64, dtype=np.uint8)[None, :, None] * 4, (48, 1, 3))
    write_png(folder / "b.png", ramp)
    data = (folder / "b.png").read_bytes()
    (folder / "a.png").write_bytes(data[:len(data) // 2])                    # truncated: decodes partly, then fails
    sampler = backgrounds.BackgroundSampler(str(folder))
    assert sampler.files == ["a.png", "b.png"]
    spec = sampler.sample(np.array([0.0, 0.0, 0.5, 0.5, 0.9]))
    assert spec["files"] == ["a.png", "b.png"] and spec["zoom"] == 1.0
    pixels, info = backgrounds.background_pixels(spec, 32, 24)
    assert info == {"used": "b.png", "skipped": ["a.png"]} and pixels.shape == (24, 32, 3)
    # the crop (zoom 1, centred, aspect 4:3 of a 64 x 48 image: all of it) resamples the ramp: linear in x
    from darthand.textures.color import srgb_to_linear

    expected = srgb_to_linear(np.clip((np.arange(32) * 2 + 0.5) * 4 / 255, 0, 1))
    assert np.allclose(pixels[10, :, 0], expected, atol=0.01)
    spec["files"] = ["a.png"]
    assert backgrounds.background_pixels(spec, 16, 16)[1]["used"].startswith("builtin:")
    assert np.array_equal(backgrounds.builtin_background(3, 64), backgrounds.builtin_background(3, 64))
