"""A small grasp catalogue built end to end (test objects in the catalogue's format, the open hand both sides),
checked by independent tools: penetration and contacts by exact brute-force signed distances (tests/grasps/
truth.py), no digit through another by MeshLab's face intersections, joint limits, the schema, the loader's round
trip, left grasps the mirror image of right ones, dropped fits counted with why, refit to other shapes."""

import dataclasses

import numpy as np
import pytest

from darthand.errors import InputError
from darthand.fileio import read_json
from darthand.grasps.build import build_grasps, object_reflection
from darthand.grasps.field import ObjectField
from darthand.grasps.loader import load_grasp_catalog
from darthand.grasps.refit import object_field, refit_grasp
from darthand.model.anatomy import within_limits
from darthand.model.forward import forward
from darthand.model.intersections import between_digits, face_parts, part_intersections
from darthand.model.load import open_hand
from darthand.model.npz_io import save_npz
from darthand.schemas import check_schema
from grasps.objects_fixture import box, crumb, cylinder, lump, sphere
from grasps.truth import signed_distances



@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("grasps")
    models = {s: open_hand(s) for s in ("right", "left")}
    paths = {}
    for side, model in models.items():
        paths[side] = str(out / f"{side}.npz")
        save_npz(model, paths[side])
    items = [sphere(), cylinder(), box(), lump(), crumb()]
    doc = build_grasps(items, paths, out / "catalog", approaches=2, sheet=False)
    return doc, out / "catalog", {it.id: it for it in items}, models


def hand_in_object_frame(model, pose, placement):
    v = np.asarray(forward(model, np.asarray(pose)[None]).vertices[0], np.float64)
    M = np.linalg.inv(placement)
    return v @ M[:3, :3].T + M[:3, 3]


def near_truth(item, v):
    """Exact signed distances of the vertices within 6 mm of the object's box (the others are farther out)."""
    lo, hi = item.vertices.min(0) - 0.006, item.vertices.max(0) + 0.006
    near = ((v >= lo) & (v <= hi)).all(1)
    d = np.full(len(v), np.inf)
    d[near] = signed_distances(item.vertices, item.faces, v[near])
    return d


def test_catalogue_validates_and_counts_its_drops(built):
    doc, folder, _, _ = built
    check_schema(read_json(folder / "catalog.json"), "grasp_catalog.schema.json", "catalog.json")
    assert doc["counts"]["fitted"] == len(doc["grasps"]) >= 10
    whys = {(d["object"], d["type"]): d["why"] for d in doc["dropped"]}
    assert whys[("crumb_test", "no_such_grasp")] == "no such grasp type"
    assert "contact" in whys[("crumb_test", "power_sphere")]
    assert doc["counts"]["dropped"] == len(doc["dropped"])


def test_every_grasp_keeps_out_touches_and_keeps_its_limits(built):
    _, folder, items, models = built
    grasps = load_grasp_catalog(folder)
    assert {g.side for g in grasps} == {"right", "left"}
    for g in grasps:
        v = hand_in_object_frame(models[g.side], g.pose, g.placement)
        d = near_truth(items[g.object_id], v)
        assert -d.min() <= 2e-3, g.id                                   # penetration by the independent measure
        assert np.abs(d[g.contact_vertices]).max() <= 5e-3, g.id         # contacts within tolerance
        assert abs(-min(d.min(), 0) * 1e3 - g.figures["penetration_max_mm"]) < 0.05
        assert within_limits(g.angles, tol=1e-6).all(), g.id
        posed = np.asarray(forward(models[g.side], g.pose[None]).vertices[0], np.float64)
        crossing = part_intersections(posed, models[g.side].faces, face_parts(models[g.side]))["between"]
        assert between_digits(crossing) == 0, (g.id, crossing)


def test_left_grasps_are_the_mirror_of_right_ones(built):
    _, folder, items, models = built
    right = {g.id: g for g in load_grasp_catalog(folder, side="right")}
    left = load_grasp_catalog(folder, side="left")
    assert {g.figures.get("mirrored", False) for g in left} == {True, False}    # exact mirrors and refits
    for g in left:
        if g.id not in right:
            continue
        item = items[g.object_id]
        S, asymmetry = object_reflection(ObjectField(item.vertices, item.faces))
        mirrored = hand_in_object_frame(models["right"], right[g.id].pose, right[g.id].placement) @ S
        hand = hand_in_object_frame(models["left"], g.pose, g.placement)
        moved = np.linalg.norm(hand - mirrored, axis=1)
        if g.figures.get("mirrored"):
            assert moved.max() < 1e-6 and np.array_equal(g.angles, right[g.id].angles), g.id
        else:
            assert np.median(moved) < 3e-3 + asymmetry, g.id   # the refit moves it as far as the object differs


def test_loader_round_trip_and_filters(built):
    doc, folder, _, _ = built
    every = load_grasp_catalog(folder)
    assert [g.id for g in every] == [r["id"] for r in doc["grasps"]]
    only = load_grasp_catalog(folder, side="left", objects=["ball_test"])
    assert only and all(g.side == "left" and g.object_id == "ball_test" for g in only)
    g = every[0]
    assert g.angles.shape == (16, 3) and g.pose.shape == (48,) and g.placement.shape == (4, 4)
    assert np.allclose(g.placement[3], [0, 0, 0, 1])
    assert np.allclose(g.placement[:3, :3] @ g.placement[:3, :3].T, np.eye(3), atol=1e-9)


def test_refit_to_other_shapes_keeps_the_grasp(built):
    _, folder, items, models = built
    rng = np.random.default_rng(7)
    for g in load_grasp_catalog(folder, side="right")[::3]:
        item = items[g.object_id]
        field = object_field(item)
        shaped = models["right"].shaped(rng.uniform(-2, 2, models["right"].num_betas))
        fitted = refit_grasp(shaped, item, g, field)
        v = hand_in_object_frame(shaped, fitted.pose, fitted.placement)
        d = near_truth(item, v)
        assert fitted.ok, (g.id, fitted.figures)
        assert -d.min() <= 2e-3 and np.abs(d[fitted.contact_vertices]).max() <= 5e-3, g.id


def test_refit_refuses_another_side_or_mesh_in_one_line(built):
    _, folder, items, models = built
    g = load_grasp_catalog(folder, side="right")[0]
    with pytest.raises(InputError, match="built for a right hand"):
        refit_grasp(models["left"], items[g.object_id], g)
    other_mesh = dataclasses.replace(g, contact_vertices=g.contact_vertices + models["right"].num_vertices)
    with pytest.raises(InputError, match="built on another model"):
        refit_grasp(models["right"], items[g.object_id], other_mesh)


def test_catalogue_is_the_same_bytes_on_every_build(tmp_path):
    paths = {}
    for side in ("right", "left"):
        paths[side] = str(tmp_path / f"{side}.npz")
        save_npz(open_hand(side), paths[side])
    docs = []
    for k in range(2):
        build_grasps([sphere(grasps=("tripod",))], paths, tmp_path / f"run{k}", approaches=1, sheet=False)
        docs.append(((tmp_path / f"run{k}" / "catalog.json").read_bytes(),
                     dict(np.load(tmp_path / f"run{k}" / "grasps.npz"))))
    assert docs[0][0] == docs[1][0]
    assert all(np.array_equal(docs[0][1][k], docs[1][1][k]) for k in docs[0][1])
