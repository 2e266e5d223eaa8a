"""The object catalogue built from its real spec: every object closed and outward (trimesh), at real sizes, the
catalogue valid against its schema, builds byte-reproducible, the loader's round trip and its drawn parts."""

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import trimesh

from darthand.errors import InputError
from darthand.objects import catalog as cat
from darthand.objects.build import build_objects
from darthand.objects.loader import load_object_catalog, object_ids

REPO = Path(__file__).resolve().parents[2]

# Real sizes (cm) per category, from the objects themselves (not from the generators): the sorted bounding-box
# extents (smallest, middle, largest) must lie in these ranges.
REAL_CM = {
    "mug": ((6.0, 10.0), (6.0, 13.0), (7.0, 13.0)),           # cups 6-9 cm across, mugs 8 cm + a handle
    "bottle": ((4.5, 9.0), (4.5, 9.0), (8.0, 32.0)),          # cans 6.6 x 12.2, bottles up to 1 l
    "phone": ((0.6, 1.2), (6.0, 8.0), (12.0, 17.0)),
    "pen": ((0.5, 2.0), (0.5, 2.0), (10.0, 20.0)),
    "box": ((1.0, 20.0), (3.0, 25.0), (4.0, 40.0)),
    "ball": ((3.5, 8.5), (3.5, 8.5), (4.0, 9.0)),            # golf ball 4.3 .. apples 8
    "tool": ((0.4, 4.0), (1.0, 13.0), (10.0, 35.0)),
    "card": ((0.02, 0.1), (5.0, 6.5), (8.0, 9.5)),
}


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("objects")
    build_objects(cat.load_spec(), out, cat.DEFAULT_SPEC.parent)
    return out


def test_at_least_fifty_objects_in_the_eight_categories(built):
    data = json.loads((built / "catalog.json").read_text())
    counts = {c: sum(o["category"] == c for o in data["objects"]) for c in cat.CATEGORIES}
    assert len(data["objects"]) >= 50 and all(n >= 3 for n in counts.values()), counts
    assert data["skipped"] == []
    assert {o["source"] for o in data["objects"]} == {"procedural", "robosuite-1.5.2"}


def test_the_catalogue_validates_against_its_schema(built):
    schema = json.loads((REPO / "schemas" / "object_catalog.schema.json").read_text())
    jsonschema.Draft202012Validator(schema).validate(json.loads((built / "catalog.json").read_text()))


def test_every_object_is_closed_outward_and_centred(built):
    for item in load_object_catalog(built):
        mesh = trimesh.Trimesh(item.vertices, item.faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent, item.id
        assert mesh.volume > 0, item.id
        assert np.allclose(mesh.bounds.sum(axis=0), 0, atol=1e-9), item.id      # bounding box centred
        assert np.allclose(mesh.extents, item.size_m, atol=2e-6), item.id


def test_sizes_are_real(built):
    for item in load_object_catalog(built):
        extents = np.sort(np.asarray(item.size_m)) * 100
        for (lo, hi), e in zip(REAL_CM[item.category], extents):
            assert lo <= e <= hi, (item.id, extents)


def test_named_objects_have_their_standard_sizes(built):
    items = {i.id: i for i in load_object_catalog(built)}
    assert np.allclose(sorted(items["card_01"].size_m), [0.00076, 0.05398, 0.0856], atol=2e-5)   # ISO/IEC 7810 ID-1
    assert 0.0654 <= items["tennis_ball_01"].size_m[0] <= 0.0686                                  # ITF
    assert items["golf_ball_01"].size_m[0] >= 0.04267                                           # R&A minimum
    can = items["can_01"].size_m
    assert abs(can[0] - 0.066) < 0.001 and abs(can[2] - 0.122) < 0.002
    mug = items["mug_01"].size_m
    assert 0.077 <= mug[1] <= 0.085 and 0.09 <= mug[2] <= 0.1         # 8 cm across (y: no handle), 9.5 cm tall
    phone = sorted(items["phone_01"].size_m)
    assert phone[0] < 0.009 and 0.068 < phone[1] < 0.074 and 0.14 < phone[2] < 0.155


def test_vendored_meshes_come_out_at_robosuites_sizes(built):
    # robosuite's XML: bread scaled 0.8, lemon 1.5 along x; their sites put the can's half height near 4 cm
    items = {i.id: i for i in load_object_catalog(built)}
    assert np.allclose(items["rs_can"].size_m, [0.05, 0.05, 0.08], atol=1e-3)
    assert np.allclose(items["rs_lemon"].size_m, [0.0675, 0.04, 0.04], atol=1e-3)
    assert np.allclose(items["rs_bread"].size_m, [0.048, 0.04, 0.048], atol=1e-3)
    data = json.loads((built / "catalog.json").read_text())
    entries = {o["id"]: o for o in data["objects"]}
    assert entries["rs_can"]["repairs"] and entries["rs_bottle"]["repairs"]
    assert entries["rs_can"]["licence"] == "MIT" and (built / entries["rs_can"]["licence_file"]).is_file()
    assert "MIT License" in (built / entries["rs_can"]["licence_file"]).read_text()


def test_loader_round_trip(built):
    data = json.loads((built / "catalog.json").read_text())
    ids = object_ids(built / "catalog.json")
    assert ids == [o["id"] for o in data["objects"]]
    (item,) = load_object_catalog(built, ids=["rs_cereal"])
    with np.load(built / "rs_cereal.npz") as z:
        assert np.array_equal(item.vertices, z["vertices"]) and np.array_equal(item.faces, z["faces"])
        assert z["vertices"].dtype == np.float64 and z["faces"].dtype == np.int32 and z["face_part"].dtype == np.int16
        assert z["uvs"].dtype == np.float32 and z["faces_uv"].shape == z["faces"].shape
    assert item.base_color_png is not None and item.base_color_png.is_file()
    assert item.parts[0]["name"] == "body" and item.grasps and item.licence == "MIT"
    with pytest.raises(InputError, match="no object with id 'nope'"):
        load_object_catalog(built, ids=["nope"])


def test_drawn_parts_split_creases_and_face_outward(built):
    ids = ["box_01", "card_01", "tennis_ball_01", "bottle_01", "rs_can"]
    items = {i.id: i for i in load_object_catalog(built, ids=ids)}
    (card,) = items["card_01"].drawn_parts()
    assert len(card.vertices) == 2 * len(items["card_01"].vertices)      # each rim corner: a face and a side normal
    on_face = np.abs(card.normals[:, 2]) > 0.5
    assert np.allclose(np.abs(card.normals[on_face, 2]), 1) and np.allclose(card.normals[~on_face, 2], 0)
    (board,) = items["box_01"].drawn_parts()                            # rounded edges, flat lid
    lid = board.vertices[:, 2] > board.vertices[:, 2].max() - 1e-7
    assert lid.sum() >= 4 and (board.normals[lid, 2] > np.cos(np.radians(1.0))).all()
    (skin,) = items["tennis_ball_01"].drawn_parts()
    radial = skin.vertices / np.linalg.norm(skin.vertices, axis=1, keepdims=True)
    assert len(skin.vertices) == len(items["tennis_ball_01"].vertices)   # smooth: no vertex split
    assert np.einsum("ij,ij->i", skin.normals, radial).min() > 0.99
    for item in items.values():
        parts = item.drawn_parts()
        assert sum(len(p.faces) for p in parts) == len(item.faces)
        for p in parts:
            assert np.allclose(np.linalg.norm(p.normals, axis=1), 1, atol=1e-5)
            tri = p.vertices[p.faces].astype(float)
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            big = np.linalg.norm(n, axis=1) > 1e-12
            agree = np.einsum("ij,ij->i", n[big], p.normals[p.faces].mean(axis=1)[big])
            assert (agree > 0).mean() > 0.99, (item.id, p.name)
    (can,) = items["rs_can"].drawn_parts()
    assert can.uvs is not None and can.faces_uv is not None and can.base_color_png is not None


def test_two_builds_are_byte_equal_and_jobs_change_nothing(tmp_path):
    ids = ["mug_02", "bottle_03", "pencil_01", "card_04", "hammer_01", "rs_can", "rs_lemon"]
    a, b = tmp_path / "a", tmp_path / "b"
    build_objects(cat.load_spec(), a, cat.DEFAULT_SPEC.parent, ids=ids, jobs=1)
    build_objects(cat.load_spec(), b, cat.DEFAULT_SPEC.parent, ids=ids, jobs=2)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    assert "contact_sheet.png" in {f.name for f in files}
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f
