"""Grasps aimed at a mug's handle and side contacts: the handle found where the mug generator put it (its own
parameters), a handle grasp whose holding contacts lie on the handle (beyond the body's radius) without entering the mug
(exact brute-force signed distances), no finger's bone through its wall (winding numbers), and a lateral
pinch whose index contact lands on the index's radial side."""

import numpy as np
import pytest

from darthand.grasps.aims import HANDLE_HOLD, handle_aim
from darthand.grasps.field import ObjectField
from darthand.grasps.fit import HandRig, fit_grasp
from darthand.grasps.parts import part_vertices
from darthand.grasps.taxonomy import load_taxonomy
from darthand.model.anatomy import rest_joints
from darthand.model.forward import forward
from darthand.model.layout import FINGER_JOINTS
from darthand.model.load import open_hand
from darthand.model.topology import vertex_normals
from darthand.objects.generators import mug
from grasps.objects_fixture import box
from grasps.truth import signed_distances, winding_numbers

MUG = {"diameter": 0.08, "height": 0.095, "wall": 0.004, "floor": 0.006, "handle_radius": 0.005,
       "handle_reach": 0.027, "handle_span": 0.056, "handle_height": 0.53, "color": [0.8, 0.8, 0.78],
       "roughness": 0.2}


@pytest.fixture(scope="module")
def model():
    return open_hand("right")


def placed_vertices(model, fit):
    v = np.asarray(forward(model, fit.pose[None]).vertices[0], np.float64)
    M = np.linalg.inv(fit.placement)
    return v @ M[:3, :3].T + M[:3, 3]


def test_the_handle_is_found_where_the_generator_put_it():
    shape = mug(MUG, np.random.default_rng(0))
    aim = handle_aim(shape.vertices, "mug")
    assert aim is not None
    bar_x = MUG["diameter"] / 2 + MUG["handle_reach"]          # the handle tube's outermost centreline
    assert abs(aim.target[0] - bar_x) < MUG["handle_radius"] + 0.004
    assert abs(aim.target[1]) < 1e-3
    assert abs(aim.target[2] - MUG["height"] * MUG["handle_height"]) < 0.004
    assert np.allclose(aim.approach, [1.0, 0, 0])
    assert handle_aim(shape.vertices, "bottle") is None


def test_a_handle_grasp_holds_the_handle_with_no_finger_through_the_wall(model):
    shape = mug(MUG, np.random.default_rng(0))
    aim = handle_aim(shape.vertices, "mug")
    g = load_taxonomy()["medium_wrap"]
    rig = HandRig.of(model, aim.contacts)
    fit = fit_grasp(rig, ObjectField(shape.vertices, shape.faces), aim.contacts, g.angles, aim.approach, aim.across,
                    aim.target)
    assert fit.dropped is None, fit.dropped
    posed = forward(model, fit.pose[None])
    start, end = rig.capsules.segments(posed.transforms[0])
    t = np.linspace(0, 1, 6)[None, :, None]
    bones = (start[:, None] + t * (end - start)[:, None]).reshape(-1, 3)
    M = np.linalg.inv(fit.placement)
    assert winding_numbers(shape.vertices, shape.faces, bones @ M[:3, :3].T + M[:3, 3]).max() < 0.5   # no finger in
    v = placed_vertices(model, fit)
    touching = v[fit.contact_vertices]
    gaps = signed_distances(shape.vertices, shape.faces, touching)
    assert np.abs(gaps).max() < 5e-3
    holding = [aim.contacts.index(p) for p in HANDLE_HOLD]
    radial = np.linalg.norm(touching[holding, :2], axis=1)
    assert (radial > MUG["diameter"] / 2 + 0.002).all()          # palm, phalanges and thumb on the handle
    near = np.linalg.norm(v - aim.target, axis=1) < 0.08
    assert -signed_distances(shape.vertices, shape.faces, v[near]).min() < 2e-3


def test_a_lateral_pinch_presses_on_the_index_side(model):
    card = box((0.054, 0.086, 0.0008), ("lateral",))
    g = load_taxonomy()["lateral"]
    assert "index_middle_radial" in g.contacts
    rig = HandRig.of(model, g.contacts)
    fit = fit_grasp(rig, ObjectField(card.vertices, card.faces), g.contacts, g.angles, np.array([0, 0, 1.0]),
                    np.array([0, 1.0, 0]))
    assert fit.dropped is None, fit.dropped
    k = g.contacts.index("index_middle_radial")
    vid = fit.contact_vertices[k]
    assert vid in part_vertices(model, "index_middle_radial")
    joints = rest_joints(model)
    toward_thumb = joints[FINGER_JOINTS["index"][0]] - joints[FINGER_JOINTS["pinky"][0]]
    normal = vertex_normals(model.v_template, model.faces)[vid]
    assert normal @ toward_thumb / np.linalg.norm(toward_thumb) > 0.5     # a side vertex, not the pad
    gap = signed_distances(card.vertices, card.faces, placed_vertices(model, fit)[[vid]])[0]
    assert abs(gap) < 1.5e-3
