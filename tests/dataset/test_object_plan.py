"""Planning object frames (`render-dataset --objects SHARE`, dataset/objects.py): off by default and then invisible
in the plan; on, a share of the frames holds an object in a grasp refitted to the frame's shape, the jobs round-trip,
pass the jobs' checks (no hand through its object), are the same from any planner, and the other frames are the
frames of the plan without objects."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "render"))
from object_catalog import toy_items, write_catalog  # noqa: E402

from darthand.dataset.jobs import check_jobs, validate_jobs  # noqa: E402
from darthand.dataset.plan import DEFAULTS, Planner, PlanOptions, plan_spec  # noqa: E402
from darthand.errors import InputError  # noqa: E402
from darthand.render.objects import ObjectLibrary  # noqa: E402
from darthand.render.scenes import Scene  # noqa: E402

FRAMES = 16


def test_objects_are_off_by_default_and_then_out_of_the_plan():
    assert PlanOptions().objects == 0
    assert "objects" not in DEFAULTS and "objects" not in PlanOptions().spec()
    assert plan_spec(objects=0, object_categories=["mug"]) == plan_spec()
    with pytest.raises(InputError, match=r"^objects: 1\.5 is not a share within 0\.\.1$"):
        plan_spec(objects=1.5)
    with pytest.raises(InputError, match=r"sum to more than all of them$"):
        plan_spec(objects=0.6, two_hands=0.6)


@pytest.fixture(scope="module")
def catalogues(package, tmp_path_factory):
    """(objects catalogue, grasp catalogue): the toy ball's grasps fitted on the test model's right hand."""
    from darthand.grasps.build import build_grasps

    root = tmp_path_factory.mktemp("object_plan")
    catalog = write_catalog(root / "objects", [i for i in toy_items() if i.id == "ball_01"])
    build_grasps([i for i in toy_items() if i.id == "ball_01"], {"right": package[0]}, root / "grasps", sheet=False)
    return str(catalog), str(root / "grasps")


@pytest.mark.slow
def test_object_frames_are_planned_refitted_and_checked(sources, catalogues):
    opened, _ = sources
    right = {"right": opened["right"]}
    spec = {"seed": 3, "sides": ["right"], "objects": 0.5, "accessory_share": 1.0}       # every hand a ring
    planner = Planner(spec, right, {"objects": catalogues[0], "grasps": catalogues[1]})
    plain = Planner({"seed": 3, "sides": ["right"], "accessory_share": 1.0}, right)
    jobs = list(planner.jobs(0, FRAMES))
    held = [j for j in jobs if "bodies" in j]
    assert 3 <= len(held) <= FRAMES - 3
    for job in jobs:
        assert Scene.from_job(job).to_job() == job
        if "bodies" not in job:
            assert job == plain.job(job["index"])             # a frame without an object draws as before
            assert job["accessory"] == "ring_test"
            continue
        hand, obj = job["bodies"]
        assert obj["object"] == "ball_01" and hand["side"] == "right" and job["grasp"]["id"].startswith("ball_01/")
        assert job["sample"]["object"]["category"] == "ball"
        assert job["sample"]["pose"] == {"mode": "grasp", "grasp": job["grasp"]["id"]}   # the pose drawn is the grasp's
        assert hand["accessory"] == "none" and job["sample"]["accessory"] == "none"     # a ring is left off
        assert job["sample"]["object"]["accessory_left_off"] == "ring"
        assert hand["pose"] != plain.job(job["index"])["pose"]
        assert np.asarray(obj["placement"]).shape == (4, 4)
    again = Planner(spec, right, {"objects": catalogues[0], "grasps": catalogues[1]})
    assert [again.job(j["index"]) for j in held[::-1]] == held[::-1]      # frame i depends on (seed, i) only
    validate_jobs(right, check_jobs(held), objects=ObjectLibrary.load(catalogues[0]))
    with pytest.raises(InputError, match=r"^object categories: 'mug' is not a category of the catalogue \(ball\)$"):
        Planner({**spec, "object_categories": ["mug"]}, right, {"objects": catalogues[0], "grasps": catalogues[1]})
