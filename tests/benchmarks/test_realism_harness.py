"""The realism benchmark's harness maths (benchmarks/realism.py) on synthetic detections: closed-form cases, no
MediaPipe and no rendering."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks import realism
from darthand.render.labels import keypoint_names


def hand(width: float = 120.0, height: float = 50.0, seed: int = 0) -> np.ndarray:
    """(21, 2) pixel keypoints spanning exactly a width x height box from (30, 40): size hypot(width, height)."""
    rng = np.random.default_rng(seed)
    kp = rng.uniform(0, 1, (21, 2))
    kp[0], kp[1] = (0, 0), (1, 1)                      # two corners fix the bounding box
    return kp * [width, height] + [30, 40]


def labels(kp: np.ndarray, side: str = "right", visible: int = 21, accessory: str = "none") -> dict:
    """A frame's labels as render-dataset writes them (the fields the harness reads), keypoints in 'openpose' order."""
    return {"keypoints_2d": kp.tolist(), "visibility": [k < visible for k in range(21)], "side": side,
            "keypoint_order": "openpose", "accessory": {"id": accessory}}


def detection(points: np.ndarray | None, label: str = "Left") -> dict:
    if points is None:
        return {"found": False, "landmarks": [], "handedness": None, "score": None}
    return {"found": True, "landmarks": points.tolist(), "handedness": label, "score": 0.9}


def test_hand_size_is_the_bounding_box_diagonal():
    assert realism.hand_size(hand(120, 50)) == pytest.approx(130.0)       # a 5-12-13 triangle, times 10


def test_a_detection_equal_to_the_labels_has_pck_one():
    kp = hand()
    f = realism.figures([realism.frame_record(labels(kp), detection(kp))])
    assert f["detection_rate"] == 1 and f["pck_0.1"] == 1 and f["pck_0.2"] == 1 and f["mean_error"] == 0
    assert f["median_error_per_keypoint"] == [0.0] * 21


@pytest.mark.parametrize("direction", [(1, 0), (0, -1), (0.6, 0.8)])
def test_a_shift_of_015_of_the_size_counts_at_02_and_not_at_01(direction):
    kp = hand()
    shifted = kp + 0.15 * 130.0 * np.asarray(direction)
    f = realism.figures([realism.frame_record(labels(kp), detection(shifted))])
    assert f["pck_0.2"] == 1 and f["pck_0.1"] == 0
    assert f["mean_error"] == pytest.approx(0.15)


def test_pck_pools_keypoints_over_found_frames_only():
    kp = hand()
    half = kp.copy()
    half[:7] += 0.15 * 130.0                            # 7 of 21 landmarks off by 0.15 x size (diagonally)
    records = [realism.frame_record(labels(kp), detection(kp)), realism.frame_record(labels(kp), detection(half)),
               realism.frame_record(labels(kp), detection(None))]
    f = realism.figures(records)
    assert f["detection_rate"] == pytest.approx(2 / 3)
    assert f["pck_0.1"] == pytest.approx(35 / 42)       # 7 of the 42 found landmarks are off by more than 0.1
    assert f["pck_0.2"] == pytest.approx(1 - 7 / 42)    # off by 0.15 x sqrt(2) = 0.21 > 0.2


def test_nothing_to_count_is_none_not_nan():
    f = realism.figures([realism.frame_record(labels(hand()), detection(None))])
    assert f["detection_rate"] == 0 and f["pck_0.2"] is None and f["handedness"] is None
    assert realism.figures([])["detection_rate"] is None and realism.wilson(0, 0) == [None, None]


def test_mediapipe_left_is_a_right_hand_in_an_unmirrored_frame():
    assert realism.side_of("Left") == "right" and realism.side_of("Right") == "left"
    assert realism.side_of(None) is None
    kp = hand()
    right_as_left = realism.frame_record(labels(kp, "right"), detection(kp, "Left"))
    right_as_right = realism.frame_record(labels(kp, "right"), detection(kp, "Right"))
    left_as_right = realism.frame_record(labels(kp, "left"), detection(kp, "Right"))
    assert realism.figures([right_as_left, left_as_right])["handedness"] == 1
    assert realism.figures([right_as_right])["handedness"] == 0


def test_subsets_keep_frames_with_enough_visible_keypoints_and_split_accessories():
    kp = hand()
    records = [realism.frame_record(labels(kp, visible=15), detection(kp)),
               realism.frame_record(labels(kp, visible=14), detection(kp)),             # too few visible: left out
               realism.frame_record(labels(kp, accessory="ring_01"), detection(None))]
    s = realism.subsets(records)
    assert (s["bare"]["frames"], s["accessory"]["frames"], s["any"]["frames"]) == (1, 1, 2)
    assert (s["bare"]["detection_rate"], s["accessory"]["detection_rate"]) == (1, 0)


def test_visible_pck_counts_the_labels_visible_keypoints_only():
    kp = hand()
    det = kp.copy()
    det[20] += 0.5 * 130.0                              # the one hidden keypoint (index 20) badly off
    f = realism.figures([realism.frame_record(labels(kp, visible=20), detection(det))])
    assert f["pck_visible_0.1"] == 1 and f["pck_0.1"] == pytest.approx(20 / 21)


def test_labels_in_manos_order_are_compared_by_name():
    kp = hand()
    mano, openpose = keypoint_names("mano"), keypoint_names("openpose")
    in_mano = np.array([kp[openpose.index(name)] for name in mano])
    doc = {**labels(kp), "keypoints_2d": in_mano.tolist(), "keypoint_order": "mano"}
    assert realism.frame_record(doc, detection(kp))["errors"].max() == 0


def test_order_check_finds_the_identity_and_a_swap():
    frames = {i: labels(hand(seed=i)) for i in range(5)}
    same = {i: detection(np.asarray(frames[i]["keypoints_2d"])) for i in frames}
    swapped = {i: detection(np.asarray(frames[i]["keypoints_2d"])[[0, 4, 2, 3, 1, *range(5, 21)]]) for i in frames}
    for dets, agrees in ((same, 21), (swapped, 19)):
        records = [{"index": i, **realism.frame_record(frames[i], dets[i])} for i in frames]
        check = realism.order_check(records, frames, dets)
        assert check["agrees"] == agrees and check["frames"] == 5
    assert check["nearest"][1] == 4 and check["nearest"][4] == 1
    assert realism.order_check([], frames, same) == {"frames": 0, "agrees": None, "nearest": None}


def test_wilson_interval_matches_the_closed_form():
    lo, hi = realism.wilson(50, 100)                    # p = 0.5: centre 0.5, half-width z sqrt(1/400 + z^2/40000)
    z = 1.96
    half = z * np.sqrt(0.25 / 100 + z * z / 40000) / (1 + z * z / 100)
    assert (lo, hi) == pytest.approx((0.5 - half, 0.5 + half))
    assert realism.wilson(0, 10)[0] == pytest.approx(0, abs=1e-12)


def test_the_settings_table_starts_with_todays_default():
    names = list(realism.SETTINGS)
    assert names[:2] == ["default", "before"] and realism.SETTINGS["default"] == []
    assert list(realism.chosen_settings("random-film,default")) == ["default", "random-film"]
    with pytest.raises(SystemExit, match="unknown settings nope"):
        realism.chosen_settings("nope")


def test_make_bench_runs_the_harness_and_not_the_detector_script():
    from benchmarks.__main__ import available

    assert "realism" in available() and not any("detect" in name for name in available())


def test_summary_says_why_it_skipped_and_which_setting_failed():
    assert realism.summary({"skipped": "no hand detector"}) == "Skipped: no hand detector"
    kp = hand()
    ok = {**realism.subsets([realism.frame_record(labels(kp), detection(kp))]), "cpu_s_per_frame": 0.2,
          "cpu_ms_per_image": 150.0}
    res = {"detection_rate_default": 1.0, "min_visible": 15, "seed": 11, "frames": 1, "order": ["default", "env"],
           "settings": {"env": {"error": "unrecognized arguments: --environments", "command": "render-dataset ..."},
                        "default": ok}}
    lines = realism.summary(res).splitlines()
    assert lines[0].startswith("Headline: MediaPipe finds the hand in 100 % of the default frames")
    assert lines[4].startswith("| default | 1 | 100 %") and "| 150, 200 |" in lines[4]
    assert lines[5].startswith("| env | failed: unrecognized arguments")


def test_without_the_detector_the_benchmark_reports_itself_skipped(monkeypatch, tmp_path):
    monkeypatch.setattr(realism, "DETECTOR_PYTHON", tmp_path / "no-venv" / "bin" / "python")
    res = realism.run(out=tmp_path, frames=2)
    assert res == {"skipped": res["skipped"]} and "make detector" in res["skipped"]
    assert not list(tmp_path.iterdir())                 # nothing rendered, no sheet


def test_clipped_share_counts_the_hands_inner_pixels_at_255(tmp_path):
    """A 6 x 6 hand in a 12 x 12 frame: its inner 4 x 4 (eroded by one) is what counts. Four of those 16 at 255 in
    one channel: 0.25; a clipped pixel on the hand's edge or in the backdrop does not count."""
    from darthand.dataset.frames import frame_names
    from darthand.render.image import write_png

    names = frame_names(7)
    image = np.full((12, 12, 3), 120, np.uint8)
    mask = np.zeros((12, 12), np.uint8)
    mask[3:9, 3:9] = 255
    image[4:6, 4:6, 0] = 255                          # inner pixels (rows and columns 4..7 are inner)
    image[3, 5] = 255                                 # the hand's edge
    image[0, 0] = 255                                 # the backdrop
    for key, pixels in (("image", image), ("mask", mask)):
        (tmp_path / names[key]).parent.mkdir(parents=True, exist_ok=True)
        write_png(tmp_path / names[key], pixels)
    assert realism.clipped_share(realism.inner_hand(tmp_path, 7)) == pytest.approx(4 / 16)
    figures = realism.washed_out([0.0, 0.06, 0.25, 0.01])
    assert figures == {"frames": 4, "over_5": 2, "over_20": 1, "mean": pytest.approx(0.08)}


def test_tone_agreement_ranks_the_labels_tone_against_the_images_hand(tmp_path):
    """Four frames whose hands are painted at grey levels in the labels' tone order: Spearman 1; reversed: -1. The
    backdrop (white) and the hand's edge (black) do not count, nor a frame whose labels have no tone or
    that has no inner hand pixels."""
    from darthand.dataset.frames import frame_names
    from darthand.render.image import write_png

    greys = {0: 60, 1: 200, 2: 110, 3: 150}
    labels = {}
    for i, grey in greys.items():
        names = frame_names(i)
        image = np.full((12, 12, 3), 255, np.uint8)
        image[3:9, 3:9] = 0
        image[4:8, 4:8] = grey
        mask = np.zeros((12, 12), np.uint8)
        mask[3:9, 3:9] = 255
        for key, pixels in (("image", image), ("mask", mask)):
            (tmp_path / names[key]).parent.mkdir(parents=True, exist_ok=True)
            write_png(tmp_path / names[key], pixels)
        labels[i] = {"texture": {"tone_srgb": [grey / 255 * 0.9 + 0.05] * 3}}
    labels[4] = {"texture": {"tone_srgb": None}}
    hands = {i: realism.inner_hand(tmp_path, i) for i in greys}
    assert realism.tone_agreement({**hands, 4: hands[0]}, labels) == {"frames": 4, "spearman": 1.0}
    assert realism.tone_agreement({**hands, 5: hands[0][:0]}, {**labels, 5: labels[0]}) == \
        {"frames": 4, "spearman": 1.0}
    reversed_labels = {i: {"texture": {"tone_srgb": [1 - grey / 255] * 3}} for i, grey in greys.items()}
    assert realism.tone_agreement(hands, reversed_labels) == {"frames": 4, "spearman": -1.0}
    assert realism.tone_agreement({i: hands[i] for i in (0, 1)}, labels) == {"frames": 2, "spearman": None}
