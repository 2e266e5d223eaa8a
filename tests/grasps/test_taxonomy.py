"""The grasp taxonomy file: the pose library's format (contract section 2), Feix's numbering, the catalogue's
categories covered, pre-shapes within the joint limits, contact parts found on the hand."""

import json

import numpy as np
import pytest

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.grasps.parts import contact_patches
from darthand.grasps.taxonomy import GRASPS_FILE, load_taxonomy
from darthand.model.anatomy import within_limits
from darthand.model.load import open_hand

CATEGORIES = {"mug", "bottle", "phone", "pen", "box", "ball", "tool", "card"}


def test_grasps_file_is_a_pose_library_group_of_feix_types():
    doc = read_json(GRASPS_FILE)
    assert doc["group"] == "grasps" and doc["licence"] == "CC0-1.0"
    feix = [p["grasp"]["feix"] for p in doc["poses"]]
    assert len(feix) >= 12 and len(set(feix)) == len(feix) and all(1 <= f <= 33 for f in feix)
    assert all("grasp" in p["tags"] and p["name"] for p in doc["poses"])
    assert len({p["name"] for p in doc["poses"]}) == len(doc["poses"])


def test_every_category_has_grasps_and_preshapes_keep_the_limits():
    taxonomy = load_taxonomy()
    assert CATEGORIES <= {c for t in taxonomy.values() for c in t.categories}
    for t in taxonomy.values():
        assert within_limits(t.angles).all(), t.name
        assert t.contacts and np.abs(t.angles).max() > 0


@pytest.mark.parametrize("side", ["right", "left"])
def test_contact_parts_are_found_on_the_hand(side):
    model = open_hand(side)
    parts = sorted({p for t in load_taxonomy().values() for p in t.contacts})
    patches = contact_patches(model, parts)
    assert all(len(ids) >= 3 for ids in patches.values())
    tips = model.v_template[model.tip_ids]
    assert np.linalg.norm(model.v_template[patches["index_tip"]] - tips[1], axis=1).max() < 0.008


def test_a_preshape_outside_its_joint_limit_is_refused(tmp_path):
    doc = read_json(GRASPS_FILE)
    doc["poses"][0]["joints"]["index2"] = {"bend": 150}
    path = tmp_path / "grasps.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError, match="index2.bend is 150 deg"):
        load_taxonomy(path)
