"""Named gestures: schema, limits, loading, pose files, the gesture checks and the contact sheet."""

import json
from pathlib import Path

import jsonschema
import numpy as np
import OpenImageIO as oiio
import pytest
from darthand.errors import InputError
from darthand.model import anatomy
from darthand.model.forward import forward
from darthand.model.layout import JOINT_NAMES
from darthand.model.mirror import mirror_model, mirror_pose
from darthand.model.npz_io import load_npz
from darthand.model.poses import POSES_DIR, gesture_angles, list_gestures, load_gesture, load_pose_file
from darthand.model.preview import render_mesh
from darthand.schemas import load_schema
from darthand.model.intersections import face_parts, part_intersections, self_intersecting
from darthand.template.gesture_checks import gesture_report, inverted_faces, write_gesture_checks, write_gesture_sheet
from darthand.template.gesture_problems import gesture_problems
from synthetic import tube_hand, tube_mesh

REQUIRED = {"flat", "relaxed", "fist", "point", "pinch", "ok", "spread", "thumbs_up"}
OPEN_TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template" / "open_right.npz"
SCHEMA = load_schema("pose.schema.json")
TUBE = tube_hand(0)


def test_the_required_gestures_exist():
    names = list_gestures()
    assert REQUIRED <= set(names) and len(names) >= 8


@pytest.mark.parametrize("name", list_gestures())
def test_gesture_file_matches_the_schema_and_the_limits(name):
    doc = json.loads((POSES_DIR / f"{name}.json").read_text())
    jsonschema.validate(doc, SCHEMA)
    assert doc["name"] == name
    lim = anatomy.LIMITS
    for joint, values in doc["joints"].items():
        for axis, deg in values.items():
            lo, hi = lim[joint][anatomy.AXES.index(axis)]
            assert lo <= deg <= hi, (joint, axis, deg)


@pytest.mark.parametrize("name", list_gestures())
def test_gesture_loads_to_the_angles_written_in_its_file(name):
    doc = json.loads((POSES_DIR / f"{name}.json").read_text())
    pose = load_gesture(name, TUBE)
    assert pose.shape == (48,) and np.isfinite(pose).all()
    angles = anatomy.axis_angle_to_angles(TUBE, pose)
    expected = np.zeros((16, 3))
    for joint, values in doc["joints"].items():
        for axis, deg in values.items():
            expected[JOINT_NAMES.index(joint), anatomy.AXES.index(axis)] = np.deg2rad(deg)
    np.testing.assert_allclose(angles, expected, atol=1e-10)


def test_left_hand_gesture_is_the_mirror_image():
    left = mirror_model(TUBE)
    np.testing.assert_allclose(load_gesture("fist", left), mirror_pose(load_gesture("fist", TUBE)), atol=1e-12)


def write(tmp_path, name, obj):
    path = tmp_path / name
    path.write_text(obj if isinstance(obj, str) else json.dumps(obj))
    return path


def test_gesture_errors_name_the_file_and_field(tmp_path):
    write(tmp_path, "bad.json", {"name": "bad", "joints": {"index2": {"bend": 150}}})
    with pytest.raises(InputError, match=r"bad.json: field 'joints.index2.bend' is 150 deg, outside"):
        gesture_angles("bad", tmp_path)
    write(tmp_path, "typo.json", {"name": "typo", "joints": {"index1": {"bnd": 10}}})
    with pytest.raises(InputError, match=r"typo.json: field 'joints.index1.bnd' is not an allowed field"):
        gesture_angles("typo", tmp_path)
    write(tmp_path, "joint.json", {"name": "joint", "joints": {"index4": {"bend": 10}}})
    with pytest.raises(InputError, match=r"joint.json: field 'joints' has an unknown joint name"):
        gesture_angles("joint", tmp_path)
    write(tmp_path, "other.json", {"name": "another", "joints": {}})
    with pytest.raises(InputError, match=r"other.json: field 'name' is 'another'"):
        gesture_angles("other", tmp_path)
    with pytest.raises(InputError, match=r"missing.json: no such gesture"):
        gesture_angles("missing", tmp_path)


def test_pose_file_round_trip_and_schema(tmp_path):
    poses = np.random.default_rng(0).normal(0, 0.3, (3, 48))
    doc = {"pose": poses.tolist(), "betas": [0.5, -1.0], "flat_hand_mean": False}
    jsonschema.validate(doc, SCHEMA)
    pose, betas, flat = load_pose_file(write(tmp_path, "p.json", doc))
    np.testing.assert_array_equal(pose, poses)
    np.testing.assert_array_equal(betas, [0.5, -1.0])
    assert flat is False
    single = {"pose": poses[0].tolist()}
    jsonschema.validate(single, SCHEMA)
    pose, betas, flat = load_pose_file(write(tmp_path, "one.json", single))
    assert pose.shape == (1, 48) and betas is None and flat is True


@pytest.mark.parametrize("doc, message", [
    ({"pose": [0.0] * 47}, r"field 'pose' has 47 values, expected 48"),
    ({"pose": [[0.0] * 48, [0.0] * 49]}, r"field 'pose\[1\]' has 49 values, expected 48"),
    ({"pose": [0.0] * 48, "flat_hand_mean": 1}, r"field 'flat_hand_mean' is int 1, expected boolean"),
    ({"pose": [0.0] * 48, "betas": ["a"]}, r"field 'betas\[0\]' is str a, expected number"),
    ({"pose": [[0.0] * 48] * 2, "betas": [[0.0]] * 3}, r"field 'betas' has 3 rows for 2 poses"),
    ({"poses": [0.0] * 48}, r"field 'pose' is missing"),
    ({"pose": [0.0] * 48, "extra": 1}, r"field 'extra' is not an allowed field"),
    ('{"pose": [' + "0," * 47 + "NaN]}", r"field 'pose.47' is nan, not a finite number"),
    ('{"pose": [[' + "0," * 47 + "Infinity]]}", r"field 'pose.0.47' is inf, not a finite number"),
    ('{"pose": [0, 0', r"not valid JSON \(line 1"),
])
def test_bad_pose_files_give_one_line_errors(tmp_path, doc, message):
    path = write(tmp_path, "bad.json", doc)
    with pytest.raises(InputError, match=r"bad.json: " + message) as info:
        load_pose_file(path)
    assert "\n" not in str(info.value)
    if not isinstance(doc, str):  # the schema rejects the same documents (except cross-field rules)
        if "rows for" not in message:
            with pytest.raises(jsonschema.ValidationError):
                jsonschema.validate(doc, SCHEMA)


def test_inverted_faces_are_found_and_rigid_motion_flips_none():
    m = TUBE
    pose = np.zeros((1, 48))
    pose[0, :3] = [0.4, -2.0, 1.0]
    posed = forward(m, pose)
    inv, deg = inverted_faces(m, posed.vertices, posed.world_rotations)
    assert not inv.any() and not deg.any()
    flipped = m.v_template.copy()
    f = m.faces[10]
    flipped[f[0]] = flipped[f[1]] + flipped[f[2]] - flipped[f[0]]  # reflect a corner across the opposite edge
    inv, _ = inverted_faces(m, flipped[None], np.broadcast_to(np.eye(3), (1, 16, 3, 3)))
    assert inv[0, 10]


def test_part_intersections_find_crossing_parts_only():
    """Two tubes crossing each other: every intersecting face is between the two parts."""
    v, f = tube_mesh(12)
    v2 = v[:, [2, 1, 0]] - [0.09, 0, 0]
    vertices, faces = np.concatenate([v, v2]), np.concatenate([f, f + len(v)])
    parts = np.repeat([1, 2], len(f))
    out = part_intersections(vertices, faces, parts)
    assert out["faces"] > 0 and out["within"] == {}
    assert out["between"] == {"thumb-index": out["faces"]}
    assert not self_intersecting(v, f).any()


def test_gesture_report_on_the_tube_hand():
    report = gesture_report(TUBE, ["flat", "fist"])
    assert set(report) == {"flat", "fist"}
    assert report["flat"]["finite"] and report["flat"]["inverted_faces"] == 0
    # (MeshLab flags a couple of exactly coplanar, non-touching triangles of the tube's flat strips, so the
    # total is not asserted; parts cannot cross at rest.)
    assert report["flat"]["between_fingers_faces"] == 0 and report["flat"]["finger_palm_faces"] == 0
    assert report["fist"]["finite"]
    assert len(face_parts(TUBE)) == TUBE.num_faces
    bad = {"a": dict(report["flat"], inverted_faces=3), "b": dict(report["flat"], between_fingers_faces=11,
                                                                    between={"thumb-index": 11}),
           "c": dict(report["flat"], finite=False)}
    assert gesture_problems({"flat": report["flat"]}) == []
    remedy = ("the gestures are not fitted to this model: build it with `darthand model build` (make assets) or "
              "change assets_src/poses/{}.json")
    assert gesture_problems(bad) == ["gesture 'a': 3 inverted triangles; " + remedy.format("a"),
                                     "gesture 'b': 11 faces where digits intersect (thumb-index 11), more than 0; "
                                     + remedy.format("b"),
                                     "gesture 'c': non-finite vertices"]
    assert gesture_problems(bad, max_between_fingers=11)[1:] == ["gesture 'c': non-finite vertices"]


def test_preview_render_sees_the_mesh(tmp_path):
    img = render_mesh(TUBE.v_template, TUBE.faces, view="dorsal", size=64)
    assert img.shape == (64, 64, 3) and np.isfinite(img).all()
    covered = (img.max(-1) > 0.05).mean()
    # the tube seen from above fills a 6 cm x ~19.5 cm rectangle framed in a square 1.12 x 19.5 cm wide
    assert 0.2 < covered < 0.4
    out = tmp_path / "sheet.png"
    write_gesture_sheet(TUBE, out, names=["flat", "fist"], size=64)
    spec = oiio.ImageInput.open(str(out)).spec()
    assert spec.nchannels == 3 and spec.width > 64 * 2 and spec.format == oiio.UINT8


def test_left_hand_preview_is_the_mirror_image_of_the_right():
    left = mirror_model(TUBE)
    right_img = render_mesh(TUBE.v_template, TUBE.faces, view="three_quarter", size=48)
    left_img = render_mesh(left.v_template, left.faces, view="three_quarter", size=48, side="left")
    assert np.abs(left_img - right_img[:, ::-1]).mean() < 1e-3


@pytest.mark.slow
@pytest.mark.skipif(not OPEN_TEMPLATE.is_file(), reason="open hand template not built yet")
def test_open_hand_gestures_are_clean(tmp_path):
    """Every gesture on the open hand, and on its left mirror: finite, no inverted triangle, at most a few faces
    where two digits intersect (contacts such as the pinch are meant to touch, not to pass through)."""
    model = load_npz(OPEN_TEMPLATE)
    report = write_gesture_checks(model, tmp_path)
    assert set(report) == set(list_gestures())
    assert (tmp_path / "gestures.png").is_file() and (tmp_path / "gestures.json").is_file()
    left = gesture_report(mirror_model(model), ["fist", "ok"])
    assert gesture_problems(report) == [] and gesture_problems(left) == []


def test_failures_of_fitted_gestures_name_what_to_change():
    entry = {"finite": True, "inverted_faces": 0, "between_fingers_faces": 7, "between": {"thumb-index": 7},
             "fit": {"status": "unresolved", "changed_deg": {}, "at_bound": ["thumb1.bend"], "clearance_mm": 1.0}}
    assert gesture_problems({"ok": entry}) == [
        "gesture 'ok': 7 faces where digits intersect (thumb-index 7), more than 0; after fitting to this model "
        "(unresolved, stopped at the bound of thumb1.bend): change the index and thumb angles or the contacts in "
        "assets_src/poses/ok.json"]
    mirror = {"finite": True, "inverted_faces": 2, "between_fingers_faces": 0, "finger_palm_faces": 0,
              "between": {}}
    clean = dict(entry, between_fingers_faces=0, between={}, finger_palm_faces=0)
    assert gesture_problems({"ok": dict(clean, mirror=mirror)}) == [
        "gesture 'ok' (mirror): 2 inverted triangles; after fitting to this model (unresolved, stopped at the bound "
        "of thumb1.bend): change the digit angles or the contacts in assets_src/poses/ok.json"]
