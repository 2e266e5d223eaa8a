"""The shape checks (darthand template shapes): extreme shapes of the open hand at rest and through every named
gesture, their figures, and the command's errors."""

import json

import numpy as np
import pytest

from darthand.cli import main
from darthand.model.load import load_model
from darthand.template import shape_checks


@pytest.fixture(scope="module")
def model():
    return load_model("open")


def test_folded_faces_sees_a_face_turned_over(model):
    v = model.v_template.copy()
    assert not shape_checks.folded_faces(model, v).any()
    a, b, c = model.faces[100]
    v[a] = v[b] + v[c] - v[a]        # reflect one corner through the opposite edge's midpoint: the face flips
    assert shape_checks.folded_faces(model, v)[100]


def test_joint_depths_inside_and_outside(model):
    depth, inside = shape_checks.joint_depths(model, model.v_template)
    assert inside.all() and (depth > 2e-3).all()
    moved = model.v_template + np.array([0.0, 0.3, 0.0])     # the joints come along: still inside
    assert shape_checks.joint_depths(model, moved)[1].all()


def test_extreme_shape_list(model):
    shapes = shape_checks.extreme_shapes(model, 2.5)
    assert shapes[0][0] == "mean" and len(shapes) == 1 + 2 * model.num_betas
    label, betas = shapes[4]
    assert label == "beta2=+2.5" and betas[1] == 2.5 and np.count_nonzero(betas) == 1


def test_size_chart_draws_the_histograms(tmp_path, model):
    sizes = shape_checks.hand_size_sample(model, 300)
    path = tmp_path / "sizes.png"
    shape_checks.write_size_chart(sizes, path)
    import OpenImageIO as oiio
    img = oiio.ImageBuf(str(path)).get_pixels(oiio.UINT8)[..., :3].astype(int)
    bar = np.array([int(shape_checks.SAMPLES_COLOUR[i:i + 2], 16) for i in (1, 3, 5)])
    assert (np.abs(img - bar).max(-1) <= 2).sum() > 2000      # the histograms' bars are drawn


def test_bad_magnitude_is_a_one_line_error(tmp_path, capsys):
    assert main(["template", "shapes", "open", "--out-dir", str(tmp_path), "--magnitude", "-1"]) == 2
    err = capsys.readouterr().err
    assert "--magnitude" in err and len(err.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def extreme_report(tmp_path_factory, model):
    out = tmp_path_factory.mktemp("shapes")
    return out, shape_checks.write_shape_checks(model, out)


@pytest.mark.slow
def test_extreme_shapes_hold_at_rest_and_in_every_gesture(extreme_report, model):
    """|beta_i| = 3 on each direction of the open hand: no fold at rest, joints inside and deep, every named
    gesture finite and without inverted faces; the report and the figures written."""
    out, report = extreme_report
    assert len(report["shapes"]) == 1 + 2 * model.num_betas
    for label, r in report["shapes"].items():
        assert r["folded_faces"] == 0 and not r["joints_outside"] and r["min_joint_depth_ratio"] > 0.5, label
        for name, g in r["gestures"].items():
            assert g["finite"] and g["inverted_faces"] == 0, (label, name)
    assert json.loads((out / "shapes.json").read_text())["shape_dims"] == model.num_betas
    for name in ("shapes.png", "hand_sizes.png", "shape_variance.png", "shape_gestures.png"):
        assert (out / name).stat().st_size > 10_000


@pytest.mark.slow
def test_extreme_shapes_keep_the_digits_apart_in_every_gesture(extreme_report):
    """With the gestures fitted to each shape (as `model build` fits them to the hand it builds), no digit passes
    through another on any extreme shape (it did with the mean hand's authored angles on the largest shapes)."""
    _, report = extreme_report
    assert not any(r["gesture_problems"] for r in report["shapes"].values())
    assert all(g["between_fingers_faces"] == 0 for r in report["shapes"].values() for g in r["gestures"].values())
