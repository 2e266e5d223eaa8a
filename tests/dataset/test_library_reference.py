"""The pose library as DART's reference set: `--reference library` (and `library:TAG`) plans frames whose poses
walk toward, or jitter about, library poses named in the jobs and labels; it is the default reference set
(PoseOptions.reference), the 12 gestures one value away."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from darthand.cli import main
from darthand.dataset import poses
from darthand.dataset.frames import frame_names
from darthand.dataset.plan import Planner, PoseOptions
from darthand.errors import InputError
from darthand.model.library_fit import model_library
from darthand.model.pose_library import library_poses, select_tags
from darthand.model.rotations import axis_angle_to_quaternion


def test_the_default_reference_is_one_line_from_the_library():
    """Both values the default can take plan frames; the default itself is the one line the lead flips."""
    assert PoseOptions().reference in ("gestures", "library")
    assert PoseOptions(reference="library").reference == poses.LIBRARY


@pytest.mark.parametrize("reference", ["gestures", "library"])
def test_either_default_plans_named_reference_poses(sources, reference):
    planner = Planner({"seed": 4, "poses": {"mode": "jitter", "reference": reference}}, sources[0])
    names = {p.name for p in library_poses()} if reference == "library" else set(sources[0]["right"].gesture_names())
    jobs = list(planner.jobs(0, 12))
    assert all(job["gesture"] in names for job in jobs)
    assert planner.describe()["reference"]["source"] == reference


def test_dart_walks_toward_library_poses_named_in_the_record(sources, hand):
    """A DART group's last frame (t = 1) is the library pose its record names, on the model's library."""
    planner = Planner({"seed": 7, "poses": {"reference": "library", "steps": 4}}, sources[0])
    lib = model_library(hand)
    for job in planner.jobs(0, 12):
        record = job["sample"]["pose"]
        assert record["mode"] == "dart" and record["reference"]["set"] == "library"
        if record["t"] == 1.0 and job["side"] == "right":
            k = lib.names.index(record["reference"]["name"])
            got = axis_angle_to_quaternion(np.asarray(job["pose"]).reshape(16, 3)[1:])
            want = axis_angle_to_quaternion(lib.poses[k].reshape(16, 3)[1:])
            assert np.abs(np.abs((got * want).sum(-1)) - 1).max() < 1e-5


def test_a_tagged_reference_draws_only_from_its_tags(sources, hand):
    alphabet = {p.name for p in select_tags(library_poses(), ["alphabet"])}
    planner = Planner({"seed": 2, "poses": {"mode": "jitter", "reference": "library:alphabet"}}, sources[0])
    drawn = {job["gesture"] for job in planner.jobs(0, 40)}
    assert drawn <= alphabet and len(drawn) > 10
    ref = poses.load_reference("library:alphabet,counting", hand)
    assert len(ref) == 26 + len(select_tags(library_poses(), ["counting"]))
    assert poses.load_reference("library", hand, gestures=["asl_a", "fist"]).names == ("fist", "asl_a")


@pytest.mark.parametrize("spec, message", [("library:nonesuch", "no pose is tagged 'nonesuch'"),
                                           ("library:", "names no tag")])
def test_a_bad_library_reference_is_one_line(hand, spec, message):
    with pytest.raises(InputError, match=message) as e:
        poses.load_reference(spec, hand)
    assert "\n" not in str(e.value)


def test_render_dataset_takes_reference_library_and_labels_name_the_pose(package, tmp_path):
    model, tex, acc = package
    out = tmp_path / "ds"
    assert main(["render-dataset", model, "--textures", tex, "--accessories", acc, "--count", "3", "--seed", "1",
                 "--size", "48", "--processes", "1", "--pose-mode", "jitter", "--reference", "library:counting",
                 "--out", str(out)]) == 0
    names = {p.name for p in select_tags(library_poses(), ["counting"])}
    for i in range(3):
        labels = json.loads((out / frame_names(i)["labels"]).read_text())
        assert labels["gesture"] in names
    dataset = json.loads((out / "dataset.json").read_text())
    assert dataset["plan"]["reference"]["source"] == "library:counting"


def test_the_report_shows_the_library_beside_another_reference_set(small_dataset, tmp_path):
    """A dataset whose plan names the gestures as its reference: the report measures the library's poses against it
    too (the report reads the reference set from dataset.json's plan, so the fixture's copy says 'gestures')."""
    out = tmp_path / "dataset"
    shutil.copytree(small_dataset[0], out)
    doc = json.loads((out / "dataset.json").read_text())
    doc["jobs"]["plan"]["poses"]["reference"] = "gestures"
    (out / "dataset.json").write_text(json.dumps(doc))
    assert main(["dataset", "report", str(out), "--out", str(tmp_path / "report"), "--sheet", "4"]) == 0
    figures = json.loads((tmp_path / "report" / "report.json").read_text())
    lib = figures["library_coverage"]
    assert figures["reference"] == "gestures"
    assert lib["reference_poses"] == len(library_poses()) and lib["dataset_poses"] == 16
    assert len(lib["reference_to_dataset_deg"]) == lib["reference_poses"]
    # the gestures are part of the library: their distances are the gesture coverage's
    gestures = [k for k, p in enumerate(library_poses()) if p.group == "gestures"]
    np.testing.assert_allclose(sorted(np.asarray(lib["reference_to_dataset_deg"])[gestures]),
                               sorted(figures["pose_coverage"]["reference_to_dataset_deg"]), atol=1e-2)


def test_the_plan_reads_the_fit_beside_the_model_file(hand, tmp_path):
    """A package whose model has a library fit beside it (build/poses/right.json for build/model/right.npz, as
    make assets writes it) draws the fitted poses (the package of the tests above has none: the authored ones)."""
    from darthand.dataset.sources import source_specs
    from darthand.model.anatomy import angles_to_axis_angle
    from darthand.model.gestures import joints_to_angles
    from darthand.model.library_fit import FIT_FORMAT, model_digest, write_fit
    from darthand.model.npz_io import save_npz

    save_npz(hand, tmp_path / "model" / "right.npz")
    alphabet = select_tags(library_poses(), ["alphabet"])
    bent = {"index1": {"bend": 33.0}, "thumb1": {"spread": 5.0}}
    write_fit(tmp_path / "poses" / "right.json", {
        "format": FIT_FORMAT, "version": 1, "model": {"side": "right", "digest": model_digest(hand)},
        "poses": {p.name: {"joints": bent} for p in alphabet}})
    specs = source_specs(str(tmp_path / "model" / "right.npz"), ("right",))
    opened = {side: spec.open() for side, spec in specs.items()}
    planner = Planner({"seed": 1, "poses": {"mode": "gestures", "reference": "library:alphabet"}}, opened)
    want = angles_to_axis_angle(hand, joints_to_angles(bent)).reshape(-1)[3:]
    for job in planner.jobs(0, 3):
        assert job["gesture"] in {p.name for p in alphabet}
        np.testing.assert_allclose(np.asarray(job["pose"])[3:], want, atol=1e-6)
