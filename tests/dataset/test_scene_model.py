"""The scene model (render/scenes.py) and the sources' declared interface (render/source.py): jobs are a scene's
serialised form, both sources satisfy FrameSource, and a scene this renderer cannot draw is one line."""

from __future__ import annotations

import numpy as np
import pytest

from darthand.errors import InputError
from darthand.render.api import Renderer, open_source
from darthand.render.scenes import HandBody, Scene
from darthand.render.source import FrameSource

HAND_JOBS = [
    {},
    {"index": 3},
    {"index": 0, "pose": None, "camera": None, "lights": None, "background": None},
    {"index": 1, "pose": "fist", "texture": "plain", "skin_tone_offset": -0.1, "accessory": "none", "split": "val"},
    {"index": 2, "pose": "poses.json", "pose_index": 4, "side": "left", "camera": {"view": "palmar"},
     "betas": [0.5, -1.0], "sample": {"pose": {"mode": "dart"}}, "gesture": None},
    {"index": 4, "pose": 2, "background": {"folder": "bg", "file": "a.png", "crop": [0, 0, 1, 1]}},
    {"index": 5, "pose": [0.1] * 48, "lights": {"ambient": [0.1, 0.1, 0.1]}},
]


@pytest.mark.parametrize("job", HAND_JOBS)
def test_a_job_is_its_scenes_serialised_form(job):
    scene = Scene.from_job(job)
    assert scene.to_job() == job
    assert len(scene.hands) == 1 and scene.single_hand().kind == "hand"


def test_a_job_field_lands_in_its_body_or_scene():
    scene = Scene.from_job(HAND_JOBS[4])
    hand = scene.single_hand()
    assert (hand.side, hand.pose, hand.pose_index, hand.betas) == ("left", "poses.json", 4, (0.5, -1.0))
    assert scene.camera == {"view": "palmar"} and scene.record == {"index": 2, "sample": {"pose": {"mode": "dart"}},
                                                                    "gesture": None}
    vector = Scene.from_job(HAND_JOBS[6]).single_hand().pose_value()
    assert vector.dtype == np.float64 and vector.shape == (48,)


def test_every_planned_job_round_trips(planner):
    for job in planner.jobs(0, 40):
        assert Scene.from_job(job).to_job() == job


def test_a_scene_of_several_bodies_is_refused_in_one_line_where_one_hand_is_needed():
    scene = Scene((HandBody(side="right"), HandBody(side="left")))
    assert len(scene.hands) == 2
    with pytest.raises(InputError, match=r"^scene: one hand per frame here; this one holds hand, hand$"):
        scene.single_hand()
    with pytest.raises(InputError, match="holds nothing"):
        Scene(()).single_hand()


def test_both_sources_declare_the_interface(package, small_build):
    model_source = open_source(package[0], textures=package[1], accessories=package[2])
    usd = open_source(small_build / "usd" / "right")
    for source in (model_source, usd):
        assert isinstance(source, FrameSource)
        assert source.side == "right" and source.texture_ids() and "none" in source.accessory_ids()
    assert model_source.kind == "model" and model_source.pose_model() is model_source.model
    assert usd.kind == "usd" and usd.pose_model() is None
    assert "fist" in model_source.gesture_names() and "fist" in usd.gesture_names()
    assert model_source.accessory_type("ring_test") == "ring" and usd.accessory_type("ring_01_court_gold") is None
    assert usd.describe() == {"source": "usd", "format": "usd"}
    assert model_source.describe()["vertices"] == model_source.model.num_vertices


def test_render_scene_is_render_with_the_scenes_fields(package):
    renderer = Renderer(open_source(package[0], textures=package[1], accessories=package[2]), threads=1)
    job = {"pose": "fist", "texture": "light_moles_00", "skin_tone_offset": 0.05, "accessory": "ring_test",
           "camera": "dorsal", "betas": [0.8, -0.4]}
    frame = renderer.render_scene(Scene.from_job(job), width=48, height=48, samples=4)
    direct = renderer.render("fist", texture="light_moles_00", skin_tone_offset=0.05, accessory="ring_test",
                             camera="dorsal", width=48, height=48, samples=4, betas=[0.8, -0.4])
    assert np.array_equal(frame.rgba, direct.rgba) and frame.labels == direct.labels
