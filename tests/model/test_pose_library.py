"""The pose library (assets_src/poses/library): its files read back as written, every pose named once and within
the joint limits, tagged subsets, bad files refused in one line, and the library on a model (authored or fitted)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from darthand.errors import InputError
from darthand.model.anatomy import LIMITS, angles_to_axis_angle, within_limits
from darthand.model.layout import JOINT_NAMES
from darthand.model.library_fit import FIT_FORMAT, fit_beside, model_digest, model_library, write_fit
from darthand.model.load import open_hand
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.model.pose_library import LIBRARY_DIR, library_poses, select_tags

AXES = ("twist", "spread", "bend")


def group_files() -> list[Path]:
    return sorted(LIBRARY_DIR.glob("*.json"))


def test_every_group_file_is_cc0_and_read_back_angle_by_angle():
    """The loader's angles are the files' degrees, read here with json alone, joint by joint and axis by axis."""
    poses = {p.name: p for p in library_poses()}
    for path in group_files():
        doc = json.loads(path.read_text())
        assert doc["licence"] == "CC0-1.0", path
        for entry in doc["poses"]:
            want = np.zeros((16, 3))
            for joint, values in entry["joints"].items():
                for axis, deg in values.items():
                    want[JOINT_NAMES.index(joint), AXES.index(axis)] = deg * np.pi / 180
            got = poses[entry["name"]]
            assert got.group == doc["group"] and list(got.tags) == entry.get("tags", [])
            np.testing.assert_allclose(got.angles, want, atol=1e-12)


def test_the_library_has_150_unique_named_tagged_poses_within_the_limits():
    poses = library_poses()
    names = [p.name for p in poses]
    assert len(names) == len(set(names))
    grasps = [p for p in poses if p.grasp is not None]
    assert len(poses) - len(grasps) >= 130 + 12, "130 authored poses and the 12 gestures, before the grasps"
    assert all(p.tags for p in poses)
    assert within_limits(np.stack([p.angles for p in poses])).all()
    for p in poses:                              # the limits table itself, in degrees (not the loader's radians)
        deg = np.rad2deg(p.angles)
        for j, joint in enumerate(JOINT_NAMES):
            for a in range(3):
                lo, hi = LIMITS[joint][a]
                assert lo - 1e-9 <= deg[j, a] <= hi + 1e-9, (p.name, joint, AXES[a])


def test_the_library_covers_the_alphabet_counting_gestures_and_rest():
    poses = library_poses()
    letters = {t for p in poses for t in p.tags if t.startswith("letter_")}
    assert letters == {f"letter_{c}" for c in "abcdefghijklmnopqrstuvwxyz"}
    numbers = {t for p in select_tags(poses, ["asl"]) for t in p.tags if t.startswith("number_")}
    assert numbers == {f"number_{n}" for n in range(11)}
    assert {"gestures", "alphabet", "counting", "everyday", "rest", "grips"} <= {p.group for p in poses}
    for tag, least in (("rest", 15), ("gesture", 40), ("grip", 10)):
        assert len(select_tags(poses, [tag])) >= least, tag


def test_tags_select_a_subset_and_an_unknown_tag_is_named():
    poses = library_poses()
    alphabet = select_tags(poses, ["alphabet"])
    assert len(alphabet) == 26 and all(p.group == "alphabet" for p in alphabet)
    both = select_tags(poses, ["alphabet", "counting"])
    assert len(both) == 26 + len(select_tags(poses, ["counting"]))
    with pytest.raises(InputError, match="no pose is tagged 'nonesuch'"):
        select_tags(poses, ["nonesuch"])


def write_group(folder: Path, poses: list[dict], name: str = "g") -> Path:
    path = folder / f"{name}.json"
    path.write_text(json.dumps({"group": name, "description": "", "licence": "CC0-1.0", "poses": poses}))
    return path


@pytest.mark.parametrize("poses, message", [
    ([{"name": "a", "tags": [], "joints": {"index4": {"bend": 10}}}], "unknown joint 'index4'"),
    ([{"name": "a", "tags": [], "joints": {"index1": {"bend": 120}}}],
     r"'joints.index1.bend' is 120 deg, outside the joint limit -15..90"),
    ([{"name": "a", "tags": [], "joints": {"index1": {"roll": 1}}}], "'joints.index1.roll' is not an axis"),
    ([{"name": "a", "tags": [], "joints": {}}, {"name": "a", "tags": [], "joints": {}}], "'a' appears twice"),
    ([{"name": "A b", "tags": [], "joints": {}}], "expected lower_snake_case"),
    ([{"name": "a", "tags": [], "joints": {}, "contacts": [["thumb", "thumb"]]}], "field 'contacts'"),
])
def test_a_bad_library_file_is_refused_in_one_line(tmp_path, poses, message):
    path = write_group(tmp_path, poses)
    with pytest.raises(InputError, match=message) as e:
        library_poses(tmp_path)
    assert str(path) in str(e.value) and "\n" not in str(e.value)


def test_a_name_in_two_files_is_refused_naming_both(tmp_path):
    write_group(tmp_path, [{"name": "same", "tags": [], "joints": {}}], "one")
    write_group(tmp_path, [{"name": "same", "tags": [], "joints": {}}], "two")
    with pytest.raises(InputError, match=r"two.json: pose 'same' is also in .*one.json"):
        library_poses(tmp_path)
    with pytest.raises(InputError, match="'flat' is also in"):   # a gesture's name is taken too
        write_group(tmp_path, [{"name": "flat", "tags": [], "joints": {}}], "three")
        library_poses(tmp_path, gestures=True)


def test_the_library_on_a_model_without_a_fit_is_the_authored_angles(tmp_path):
    model = open_hand("right")
    poses = library_poses()[:20]
    lib = model_library(model, poses=poses)
    assert not lib.fitted and lib.names == tuple(p.name for p in poses)
    want = angles_to_axis_angle(model, np.stack([p.angles for p in poses])).reshape(len(poses), 48)
    np.testing.assert_allclose(lib.poses, want, atol=1e-12)


def test_the_fit_beside_a_model_file_is_used_when_it_is_that_models(tmp_path):
    """make assets writes build/poses/right.json beside build/model/<side>.npz: read for that model (and its
    mirror), passed over for another."""
    model = open_hand("right")
    poses = library_poses()[:2]
    bent = {p.name: {"joints": {"index1": {"bend": 33.0}}} for p in poses}
    beside = tmp_path / "model" / "left.npz"
    assert fit_beside(beside) == tmp_path / "poses" / "right.json"
    write_fit(tmp_path / "poses" / "right.json", {"format": FIT_FORMAT, "version": 1, "poses": bent,
                                                   "model": {"side": "right", "digest": "another model"}})
    assert not model_library(model, poses=poses, beside=beside).fitted
    write_fit(tmp_path / "poses" / "right.json", {"format": FIT_FORMAT, "version": 1, "poses": bent,
                                                   "model": {"side": "right", "digest": model_digest(model)}})
    assert model_library(model, poses=poses, beside=beside).fitted
    assert model_library(mirror_model(model), poses=poses, beside=beside).fitted


def test_a_fit_record_is_read_for_its_model_and_its_mirror_only(tmp_path):
    """A record written for the right hand poses the right hand with its angles and the left (its mirror) with the
    mirrored pose; another model's record is refused by name."""
    right = open_hand("right")
    poses = library_poses()[:3]
    bent = {p.name: {"joints": {"index1": {"bend": 33.0}}, "status": "fitted"} for p in poses}
    record = {"format": FIT_FORMAT, "version": 1, "model": {"side": "right", "digest": model_digest(right)},
              "poses": bent}
    write_fit(tmp_path / "right.json", record)
    lib = model_library(right, fit=tmp_path / "right.json", poses=poses)
    assert lib.fitted
    np.testing.assert_allclose(np.rad2deg(lib.angles[:, JOINT_NAMES.index("index1"), 2]), 33.0)
    left = model_library(mirror_model(right), fit=tmp_path / "right.json", poses=poses)
    np.testing.assert_allclose(left.poses, mirror_pose(lib.poses), atol=1e-9)
    other = dict(record, model={"side": "right", "digest": "0" * 16})
    write_fit(tmp_path / "other.json", other)
    with pytest.raises(InputError, match="fitted to another model"):
        model_library(right, fit=tmp_path / "other.json", poses=poses)


def test_every_group_file_follows_its_schema():
    from darthand.schemas import check_schema

    for path in group_files():
        check_schema(json.loads(path.read_text()), "pose_library.schema.json", str(path))
    with pytest.raises(InputError):
        check_schema({"group": "g", "licence": "CC0-1.0", "poses": [{"name": "a", "joints": {"index4": {}}}]},
                     "pose_library.schema.json", "bad.json")
