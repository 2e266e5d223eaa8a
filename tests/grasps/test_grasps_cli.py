"""`darthand grasps build` end to end over the objects stage's own catalogue (two of its objects), with the
contact sheets; bad input refused in one line."""

import pytest

from darthand.cli import main
from darthand.fileio import read_json
from darthand.grasps.loader import load_grasp_catalog
from darthand.model.load import open_hand
from darthand.model.npz_io import save_npz
from darthand.schemas import check_schema


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    folder = tmp_path_factory.mktemp("models")
    for side in ("right", "left"):
        save_npz(open_hand(side), folder / f"{side}.npz")
    return folder


def test_grasps_build_over_the_object_catalogue(capsys, tmp_path, models):
    code, _, err = run(capsys, "objects", "build", "--out", tmp_path / "objects", "--ids", "golf_ball_01",
                       "card_01", "--no-sheet")
    assert code == 0, err
    code, out, err = run(capsys, "grasps", "build", models / "right.npz", models / "left.npz", "--objects",
                         tmp_path / "objects" / "catalog.json", "--out", tmp_path / "grasps", "--ids", "golf_ball_01")
    assert code == 0, err
    assert out.startswith("[grasps] ") and "of 1 objects" in out
    doc = read_json(tmp_path / "grasps" / "catalog.json")
    check_schema(doc, "grasp_catalog.schema.json", "catalog.json")
    assert doc["contact_sheets"] == {"ball": "grasps_ball.png"} and (tmp_path / "grasps" / "grasps_ball.png").is_file()
    grasps = load_grasp_catalog(tmp_path / "grasps", side="right")
    assert grasps and {g.object_id for g in grasps} == {"golf_ball_01"}


def test_grasps_build_refuses_a_missing_catalogue_in_one_line(capsys, tmp_path, models):
    code, _, err = run(capsys, "grasps", "build", models / "right.npz", models / "left.npz", "--objects",
                       tmp_path / "nowhere.json", "--out", tmp_path / "grasps")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "nowhere.json" in err
