"""The pose library fitted to a model: the fitted poses do not pass through themselves by the self-crossing check
(model/self_crossing: signed distances between digits and MeshLab's face intersections), stay within the joint
limits, a fit record round-trips through its file and the CLI, and the left model reads the right one's fit."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from darthand.cli import main
from darthand.model.anatomy import angles_to_axis_angle, within_limits
from darthand.model.gestures import joints_to_angles
from darthand.model.library_fit import fit_library, fitted_poses, model_library, pose_key, read_fit, write_fit
from darthand.model.load import load_model
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.model.pose_library import library_poses
from darthand.model.regions import ensure_face_labels
from darthand.model.self_crossing import SelfCrossing
from darthand.model.wrist import add_wrist

# Poses whose authored angles put one digit into another on the open hand (a pinch, a half-closed hand's thumb on
# the index, fingers crossed as far as the limits allow), each fitted in a few seconds.
CLOSE = ("asl_r", "grip_tip_pinch_small", "rest_half_open_4")


@pytest.fixture(scope="module")
def model():
    return ensure_face_labels(add_wrist(load_model("open")))


def crossing_names(model, lib) -> list[str]:
    found = SelfCrossing(model).crossing_poses(lib.poses)
    return [f"{n}: {c}" for n, c in zip(lib.names, found) if c is not None]


def test_fitted_close_poses_do_not_cross_and_round_trip(model, tmp_path):
    poses = [p for p in library_poses() if p.name in CLOSE]
    authored = angles_to_axis_angle(model, np.stack([p.angles for p in poses])).reshape(len(poses), -1)
    assert all(SelfCrossing(model).crossing_poses(authored)), "each pose crosses itself as authored"
    record = fit_library(model, poses, jobs=2)          # in two processes, as `make assets` fits
    assert set(record["poses"]) == set(CLOSE) and record["reused"] == 0
    write_fit(tmp_path / "right.json", record)
    assert read_fit(tmp_path / "right.json") == json.loads(json.dumps(record))
    lib = model_library(model, fit=tmp_path / "right.json", poses=poses)
    assert lib.fitted and within_limits(lib.angles, tol=1e-6).all()
    assert crossing_names(model, lib) == []
    left = model_library(mirror_model(model), fit=tmp_path / "right.json", poses=poses)
    np.testing.assert_allclose(left.poses, mirror_pose(lib.poses), atol=1e-9)


def test_fit_library_command_writes_a_record_the_sheet_command_reads(model, tmp_path, capsys, monkeypatch):
    import darthand.model.library_fit as library_fit
    from darthand.model.npz_io import save_npz

    small = [p for p in library_poses() if p.name in ("asl_b", "asl_l")]
    monkeypatch.setattr(library_fit, "library_poses", lambda: small)
    save_npz(model, tmp_path / "right.npz")
    assert main(["model", "fit-library", str(tmp_path / "right.npz"), "--out", str(tmp_path / "fit.json")]) == 0
    assert "2 library poses fitted" in capsys.readouterr().out
    assert main(["model", "library-sheet", str(tmp_path / "right.npz"), "--fit", str(tmp_path / "fit.json"),
                 "--out-dir", str(tmp_path / "sheets")]) == 0
    assert sorted(p.name for p in (tmp_path / "sheets").iterdir()) == ["library_alphabet.png"]


def test_a_pose_whose_fit_inputs_are_unchanged_keeps_its_earlier_fit(model):
    """An earlier record's entry is taken when its key is the pose's (same model, same authored pose); a pose
    edited since, or a record of another model, is fitted again."""
    pose = next(p for p in library_poses() if p.name == "asl_b")
    marker = {"joints": {"index1": {"bend": 1.0}}, "status": "kept", "changed_deg": {}, "max_change_deg": 0.0,
              "crossing": {}, "seconds": 0.0}
    earlier = {"poses": {"asl_b": marker | {"key": pose_key(model, pose)}}}
    record = fit_library(model, [pose], previous=earlier)
    assert record["reused"] == 1 and record["poses"]["asl_b"]["joints"] == marker["joints"]

    edited = replace(pose, angles=pose.angles + np.deg2rad(1.0) * (np.arange(16)[:, None] == 2))
    assert pose_key(model, edited) != pose_key(model, pose)
    assert pose_key(mirror_model(model), pose) == pose_key(model, pose)     # one fit serves both sides
    record = fit_library(model, [edited], previous=earlier)
    assert record["reused"] == 0 and record["poses"]["asl_b"]["joints"] != marker["joints"]
    assert record["poses"]["asl_b"]["key"] == pose_key(model, edited)


def test_a_fit_of_part_of_the_library_draws_its_own_poses(model, tmp_path, capsys):
    """`make assets LIBRARY_POSES=...` fits some poses: the sheet command draws those, a dataset asking for all
    is told to refit."""
    from darthand.errors import InputError

    poses = [p for p in library_poses() if p.name in ("asl_b", "asl_l")]
    write_fit(tmp_path / "fit.json", fit_library(model, poses))
    assert [p.name for p in fitted_poses(model, fit=tmp_path / "fit.json")] == ["asl_b", "asl_l"]
    with pytest.raises(InputError, match="refit the library"):
        model_library(model, fit=tmp_path / "fit.json")
    from darthand.model.npz_io import save_npz

    save_npz(model, tmp_path / "right.npz")
    assert main(["model", "fit-library", str(tmp_path / "right.npz"), "--out", str(tmp_path / "x.json"),
                 "--poses", "no_such_pose"]) == 2
    assert "--poses: no library pose 'no_such_pose'" in capsys.readouterr().err


@pytest.mark.slow
def test_the_whole_fitted_library_is_collision_free(model):
    """Every library pose fitted to the open hand: no digit through another (minutes: the `make assets` step)."""
    poses = library_poses()
    record = fit_library(model, poses)
    angles = np.stack([joints_to_angles(record["poses"][p.name]["joints"]) for p in poses])
    assert within_limits(angles, tol=1e-6).all()
    fitted = angles_to_axis_angle(model, angles).reshape(len(poses), -1)
    found = SelfCrossing(model).crossing_poses(fitted)
    assert [f"{p.name}: {c}" for p, c in zip(poses, found) if c is not None] == []
