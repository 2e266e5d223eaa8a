"""Two hands in one frame (render/bodies.py, render/labels.group_labels): each hand's instance pixels against the
hand rendered alone, a keypoint hidden by the other hand, contacts against trimesh's point-to-mesh distance."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from render_scenes import RING_JOINT, ring_around
from scipy import ndimage

from darthand.model.mirror import mirror_model
from darthand.render.api import Renderer
from darthand.render.assets import HandAssets
from darthand.render.contacts import CONTACT_M
from darthand.render.labels import instance_map
from darthand.render.scenes import Scene

SIZE = 128
TURN = np.diag([-1.0, -1.0, 1.0])      # 180 degrees about z: a left hand's fingers toward -X, its palm toward +Y


def placement(rotation, shift) -> list:
    P = np.eye(4)
    P[:3, :3], P[:3, 3] = rotation, shift
    return P.tolist()


# Left hands placed against the right one at the identity (the open hand, flat): palms facing 2 mm apart at the
# closest (found by scanning shifts, no vertex inside the other hand), far apart, and 6 cm in front of the back of
# the right hand (seen from the dorsal view, between the camera and it).
FACING = placement(TURN, (0.0, -0.07, -0.06))
APART = placement(TURN, (0.0, -0.25, 0.0))
IN_FRONT = placement(TURN, (0.0, 0.08, 0.0))


@pytest.fixture(scope="module")
def renderer(hand, texture_files):
    left = mirror_model(hand)
    ring = ring_around(left, RING_JOINT, RING_JOINT + 1)
    right = HandAssets(hand, {texture_files.id: texture_files}, texture_files.id, {}, "open+wrist")
    left_source = HandAssets(left, {texture_files.id: texture_files}, texture_files.id, {ring.id: ring}, "left")
    return Renderer(right, 2, sources={"left": left_source}), ring.id


def render(renderer, bodies, camera="three_quarter"):
    job = {"bodies": [{"kind": "hand", **b} for b in bodies], "camera": camera}
    return renderer.render_scene(Scene.from_job(job), width=SIZE, height=SIZE, samples=4)


def hands(labels: dict) -> list:
    """A frame's hands' labels, either form (as dataset/hands.hands_of reads them)."""
    return labels["hands"] if "hands" in labels else [labels]


def camera_of(frame) -> dict:
    return {"K": frame.labels["K"], "R": frame.labels["camera"]["R"], "t": frame.labels["camera"]["t"],
            "width": SIZE, "height": SIZE}


def test_each_hands_pixels_are_where_it_is_drawn_alone_and_nearer(renderer):
    renderer, ring = renderer
    right = {"side": "right", "pose": "fist"}
    left = {"side": "left", "pose": "flat", "placement": FACING, "accessory": ring}
    both = render(renderer, [right, left], "radial")          # from the thumbs' side: both hands and the ring seen
    camera = camera_of(both)
    alone = [render(renderer, [body], camera) for body in (right, left)]
    instances = instance_map(both.geom, both.subject)
    ids = [h["instance"] for h in both.labels["hands"]]
    assert ids == [{"hand": 1, "accessory": 2}, {"hand": 3, "accessory": 4}]
    assert both.labels["hand_type"] == "interacting"
    assert [h["side"] for h in both.labels["hands"]] == ["right", "left"]
    drawn = [a.geom >= 0 for a in alone]
    depth = [np.where(d, a.depth, np.inf) for a, d in zip(alone, drawn)]
    nearer = np.where(depth[0] <= depth[1], 0, 1)
    expected = np.where(drawn[0] | drawn[1], nearer, -1)
    got = np.select([np.isin(instances, (1, 2)), np.isin(instances, (3, 4))], [0, 1], -1)
    assert (got == expected).mean() > 0.999, np.argwhere(got != expected)[:5]
    for b in (0, 1):
        assert (got == b).sum() > 100                                      # both hands seen
    assert (instances == 4).sum() > 0 and (instances == 2).sum() == 0      # the left's ring, the right wears none
    own_pixels = [(np.isin(instances, (1 + 2 * b, 2 + 2 * b))).sum() for b in (0, 1)]
    coverage = [h["coverage"] for h in both.labels["hands"]]
    assert coverage[0] > 0 and coverage[1] > 0 and abs(sum(coverage) - both.labels["coverage"]) < 0.02
    assert own_pixels[0] > 0 and own_pixels[1] > 0


def test_a_keypoint_behind_the_other_hand_is_not_visible(renderer):
    renderer, _ = renderer
    right = {"side": "right", "pose": "flat"}
    left = {"side": "left", "pose": "flat", "placement": IN_FRONT}
    both = render(renderer, [right, left], "dorsal")
    camera = camera_of(both)
    right_alone, left_alone = (render(renderer, [body], camera) for body in (right, left))
    hidden_by = ndimage.binary_erosion(left_alone.geom >= 0, iterations=3)
    uv = np.floor(np.asarray(both.labels["hands"][0]["keypoints_2d"])).astype(int)
    behind = hidden_by[uv[:, 1], uv[:, 0]]
    clear = ~ndimage.binary_dilation(left_alone.geom >= 0, iterations=3)[uv[:, 1], uv[:, 0]]
    visible = np.asarray(both.labels["hands"][0]["visibility"])
    alone_visible = np.asarray(hands(right_alone.labels)[0]["visibility"])
    assert behind.sum() >= 5 and alone_visible[behind].any()          # seen alone, covered by the left hand
    assert not visible[behind].any()
    assert (visible[clear] == alone_visible[clear]).all()
    # nothing is in front of the left hand: its keypoints are as visible as alone
    assert both.labels["hands"][1]["visibility"] == hands(left_alone.labels)[0]["visibility"]


@pytest.mark.parametrize("where, touching", [(FACING, True), (APART, False)])
def test_contacts_are_the_vertices_near_the_other_hand(renderer, where, touching):
    renderer, _ = renderer
    frame = render(renderer, [{"side": "right", "pose": "flat"}, {"side": "left", "pose": "flat",
                                                                   "placement": where}])
    members = frame.subject.members
    meshes = [trimesh.Trimesh(m.hand.vertices.astype(np.float64), m.hand.faces, process=False) for m in members]
    for b, hand in enumerate(frame.labels["hands"]):
        other = meshes[1 - b]
        _, distance, _ = trimesh.proximity.closest_point_naive(other, members[b].hand_vertices.astype(np.float64))
        expected = np.flatnonzero(distance <= CONTACT_M).tolist()
        assert hand["contacts"] == expected
        assert bool(expected) == touching
