"""Rings worn per pose (accessories/wear) against independent truth: the depth estimate against a closed-form
cylinder; the worn ring's contact with the hand by ray parity and the brute-force distance (test_sweep's helpers) in
poses where a rigid ring cuts millimetres into the palm's fold or a neighbouring finger; the room-making step's
linearisation against finite differences; a hand without a ring, or with a ring it does not touch, left exactly as
posed; a frame's labels taken from the pose it shows."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from darthand.accessories import catalog as cat
from darthand.accessories.attach import apply, to_local
from darthand.accessories.collide import Solid
from darthand.accessories.item import generate
from darthand.accessories.loader import Accessory
from darthand.accessories.sweep import probes
from darthand.accessories.wear import (CLEARANCE, MAX_CHANGE_DEG, SLIDES, RingWear, _signed_depths, sample_points,
                                       slide_matrix, wear_ring)
from darthand.model.anatomy import angles_to_axis_angle, axis_angle_to_angles, within_limits
from darthand.model.forward import forward
from darthand.model.layout import FINGER_JOINTS
from scipy.spatial import cKDTree
from test_sweep import closed, overlap, open_hand

SEED = int(cat.load_spec()["seed"])


@pytest.fixture(scope="module")
def hand():
    return open_hand()


def ring_on(model, ring_id: str, t: float = 0.5, clearance: float = 0.5e-3):
    """The catalogue ring `ring_id` fitted at `t` on the model, as a sweep probe (local mesh, joint, rest)."""
    entry = cat.entries(cat.load_spec(), [ring_id])[0]
    built = generate(model, {**entry, "t": t}, SEED, clearance=clearance)
    return built, probes([built])[0]


def pose_of(model, **angles_deg) -> np.ndarray:
    """(48,) axis-angle of anatomical angles given as joint=(twist, spread, bend) degrees (others zero)."""
    from darthand.model.layout import JOINT_NAMES

    a = np.zeros((16, 3))
    for name, value in angles_deg.items():
        a[JOINT_NAMES.index(name)] = np.deg2rad(value)
    return angles_to_axis_angle(model, a).reshape(48)


def contact(model, item, pose: np.ndarray, slide: float) -> float:
    """Independent contact depth (m) of a ring slid by `slide` on its bone at `pose`: ring vertices inside the
    whole hand closed by fans and hand vertices inside the ring, by ray parity and brute-force distances."""
    posed = forward(model, pose[None])
    placed = posed.transforms[0, item.joint] @ item.rest @ slide_matrix(slide)
    ring = trimesh.Trimesh(item.vertices, item.faces, process=False)
    hand = posed.vertices[0]
    return overlap(ring, apply(placed, item.vertices), closed(hand, model.faces), to_local(placed, hand))


def test_depth_estimate_matches_a_sphere_in_closed_form():
    """Points at distance r from the centre of a sphere of radius R (icosphere, 10242 vertices): the estimate is
    R - r inside and -(r - R) outside, to 0.01 mm."""
    R = 0.01
    ball = trimesh.creation.icosphere(subdivisions=5, radius=R)
    v, normals = np.asarray(ball.vertices), np.asarray(ball.vertex_normals)
    radii = np.array([0.2, 0.5, 0.8, 0.95, 0.99, 1.02, 1.05, 1.1]) * R
    rng = np.random.default_rng(1)
    u = rng.standard_normal((len(radii), 3))
    pts = radii[:, None] * u / np.linalg.norm(u, axis=1, keepdims=True)
    signed, _ = _signed_depths(Solid(v, ball.faces), cKDTree(v), v, normals, pts)
    assert signed == pytest.approx(R - radii, abs=1e-5)


def test_sample_points_are_spread_capped_and_survive_a_round_trip():
    """Samples are mesh vertices (to 0.1 um), at most the cap, one per cell; a mesh carried to a rest frame and
    back (as a catalogue file stores it) gives the same samples, bit for bit."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    v = rng.uniform(-0.01, 0.01, (20000, 3))
    s = sample_points(v, 0.001, most=700)
    assert 0 < len(s) <= 700
    assert cKDTree(v).query(s)[0].max() < 1e-7
    assert len(np.unique(np.round(s, 9), axis=0)) == len(s)
    rest = np.eye(4)
    rest[:3, :3] = Rotation.from_rotvec([0.3, -1.1, 0.7]).as_matrix()
    rest[:3, 3] = [0.05, -0.01, 0.02]
    assert np.array_equal(sample_points(to_local(rest, apply(rest, v)), 0.001, most=700), s)


@pytest.mark.parametrize("ring_id, angles, part", [
    # the index flexed to 88 deg at its knuckle: the palm's skin folds over a ring at its usual place
    ("ring_02_flat_silver", dict(index1=(0, 0, 88), index2=(0, 0, 40)), "palm"),
    # the pinky pressed against the ring finger (spread -18 deg) and bent: it cuts into the ring finger's band
    ("ring_01_court_gold", dict(ring1=(0, 4, 45), pinky1=(0, -18, 50), pinky2=(0, 0, 60)), "pinky"),
])
def test_worn_ring_clears_the_hand_where_a_rigid_ring_cuts_into_it(hand, ring_id, angles, part):
    """Rigid on its bone the ring cuts more than 1.5 mm into the hand (independent measure); worn, at most
    CLEARANCE + 0.6 mm (the estimate samples the ring at about 1 mm), with only the knuckles' spread turned, by at
    most MAX_CHANGE_DEG and within the joint limits, every other angle exactly as given, the slide within SLIDES."""
    _, item = ring_on(hand, ring_id)
    pose = pose_of(hand, **angles)
    assert contact(hand, item, pose, 0.0) > 1.5e-3
    w = RingWear(hand, item.joint, item.rest, item.vertices).worn(pose)
    assert contact(hand, item, w.pose, w.slide) <= CLEARANCE + 0.6e-3
    assert SLIDES[0] <= w.slide <= SLIDES[-1]
    moved = [j for j in range(16) if not np.array_equal(w.pose.reshape(16, 3)[j], pose.reshape(16, 3)[j])]
    assert sorted(moved) == sorted(w.changed)
    roots = {chain[0] for chain in FINGER_JOINTS.values()}
    assert set(moved) <= roots
    before, after = (axis_angle_to_angles(hand, p.reshape(16, 3)) for p in (pose, w.pose))
    turned = np.rad2deg(after - before)
    for j in moved:
        assert turned[j, 0] == pytest.approx(0, abs=1e-6) and turned[j, 2] == pytest.approx(0, abs=1e-6)
        assert abs(turned[j, 1]) <= MAX_CHANGE_DEG["finger"] + 1e-6
        assert turned[j, 1] == pytest.approx(w.changed[j][1], abs=1e-6)
    assert within_limits(after, tol=1e-6).all()


def test_a_ring_with_room_leaves_the_pose_alone_and_is_deterministic(hand):
    """The flat hand: the ring does not touch it, so the pose is returned bit for bit, unslid; the same pose gives
    the same result from a fresh RingWear."""
    _, item = ring_on(hand, "ring_02_flat_silver")
    pose = pose_of(hand, index1=(0, 0, 20))
    w = RingWear(hand, item.joint, item.rest, item.vertices).worn(pose)
    assert np.array_equal(w.pose, pose) and w.slide == 0.0 and w.changed == {}
    hard = pose_of(hand, ring1=(0, 4, 45), pinky1=(0, -18, 50), pinky2=(0, 0, 60))
    _, item1 = ring_on(hand, "ring_01_court_gold")
    a, b = (RingWear(hand, item1.joint, item1.rest, item1.vertices).worn(hard) for _ in range(2))
    assert np.array_equal(a.pose, b.pose) and a.slide == b.slide and a.changed.keys() == b.changed.keys()
    assert all(np.array_equal(a.changed[j], b.changed[j]) for j in a.changed)


def test_room_making_step_follows_finite_differences(hand):
    """The step's linearised depths (RingWear._depth_gradient, what each round solves with): turning the pinky's
    knuckle spread by 0.5 deg changes the signed depth of each sample point the pinky carries (same nearest vertex)
    as the gradient predicts, to 25 % (it leaves out the turn of the tangent plane and the correctives, as the
    gesture fit's does; the step is measured again after each round), and points on the ring's own finger not at
    all; sliding the ring 0.5 mm changes every point's depth as its slide column says."""
    _, item = ring_on(hand, "ring_01_court_gold")
    wear = RingWear(hand, item.joint, item.rest, item.vertices)
    pose = pose_of(hand, ring1=(0, 4, 45), pinky1=(0, -18, 50), pinky2=(0, 0, 60))
    angles = axis_angle_to_angles(hand, pose.reshape(16, 3))
    posed, hand_state = wear._posed(pose)
    depth, (pts, signed, nearest) = wear._contact(hand_state, 0.0)
    pinky = FINGER_JOINTS["pinky"][0]
    free = np.array([3 * pinky + 1])
    gradients = wear._depth_gradient(angles, posed, pts, nearest, free, np.eye(1))
    grad, per_slide = gradients[:, 0], gradients[:, 1]
    from darthand.model.topology import vertex_normals

    v = posed.vertices[0].astype(np.float64)
    y, n = v[nearest], vertex_normals(v, hand.faces)[nearest]
    slid = wear._contact(hand_state, 0.5e-3)[1][0]                 # the same sample points, slid 0.5 mm
    assert np.allclose(np.einsum("kd,kd->k", y - slid, n) - np.einsum("kd,kd->k", y - pts, n), 0.5e-3 * per_slide,
                       atol=1e-9)
    step = np.deg2rad(0.5)
    moved = angles.copy()
    moved[pinky, 1] += step
    posed2 = forward(hand, angles_to_axis_angle(hand, moved).reshape(1, 48))
    v2 = posed2.vertices[0]
    n2 = vertex_normals(v2, hand.faces)[nearest]
    near = signed > -1.5e-3
    numeric = (np.einsum("kd,kd->k", v2[nearest] - pts, n2) - np.einsum("kd,kd->k", y - pts, n))[near] / step
    grad = grad[near]
    carried = np.abs(numeric) > 1e-3                                # m per radian: the pinky's points
    assert carried.sum() > 20
    assert np.abs(grad[carried] - numeric[carried]).max() <= 0.25 * np.abs(numeric[carried]).max()
    assert (np.abs(grad[carried] - numeric[carried]) <= 0.25 * np.abs(numeric[carried]) + 5e-4).all()
    assert np.abs(grad[~carried]).max() < 2e-3


def test_frames_with_a_worn_ring_are_labelled_with_the_pose_they_show(hand):
    """A model source wearing rings (as dataset sources do): the subject's pose and keypoints are the worn pose's
    (the ordinary forward pass), the ring's vertices are its rest mesh slid along its bone and carried by its
    joint; without worn rings (packages, plain renders) the same call poses the hand as given and the ring rigid."""
    from darthand.render.assets import HandAssets

    built, item = ring_on(hand, "ring_01_court_gold")
    acc = Accessory(built.id, built.world_vertices, built.mesh.faces, parent_joint=item.joint, kind="ring",
                    rest_transform=item.rest)
    pose = pose_of(hand, ring1=(0, 4, 45), pinky1=(0, -18, 50), pinky2=(0, 0, 60))
    worn = HandAssets(hand, accessories={acc.id: acc}, worn_rings=True)
    rigid = HandAssets(hand, accessories={acc.id: acc})
    w = RingWear(hand, item.joint, item.rest, item.vertices).worn(pose)
    assert w.changed
    s = worn.subject(pose, accessory=acc.id)
    assert np.array_equal(s.pose, w.pose)
    truth = forward(hand, w.pose[None], keypoint_order="openpose")
    assert np.abs(s.keypoints - truth.keypoints[0]).max() < 1e-5
    ring = apply(truth.transforms[0, item.joint] @ item.rest @ slide_matrix(w.slide), item.vertices)
    assert np.abs(s.surfaces[1].vertices - ring).max() < 1e-5
    assert s.info["ring_worn"]["slide_mm"] == pytest.approx(w.slide * 1000, abs=1e-3)
    r = rigid.subject(pose, accessory=acc.id)
    assert np.array_equal(r.pose, pose) and "ring_worn" not in r.info
    assert np.abs(r.surfaces[1].vertices - apply(forward(hand, pose[None]).transforms[0, item.joint] @ item.rest,
                                                   item.vertices)).max() < 1e-5
    p2, none = wear_ring(hand, acc, acc.id, pose_of(hand), None)
    assert none is not None and none.record["turned_deg"] == {} and np.array_equal(p2, pose_of(hand))


def test_sweep_measures_worn_rings_together_as_alone(hand):
    """The sweep measures the rings whose pose was not turned against one shared hand and each turned one against
    its own: the figures are those of each ring measured alone, bit for bit, and a turned pose is recorded."""
    from darthand.accessories.sweep import measure

    spec = cat.load_spec()
    built = [generate(hand, {**e, "t": 0.5}, SEED) for e in cat.entries(spec, ["ring_01_court_gold",
                                                                            "ring_02_flat_silver",
                                                                            "watch_01_round_leather"])]
    poses = np.stack([pose_of(hand), pose_of(hand, ring1=(0, 4, 45), pinky1=(0, -18, 50), pinky2=(0, 0, 60)),
                      pose_of(hand, index1=(0, 0, 88), index2=(0, 0, 40))])
    together = measure(hand, built, poses)
    assert together["ring_01_court_gold"]["turned"][1] > 0 and together["ring_02_flat_silver"]["slide"][2] > 0
    for b in built:
        alone = measure(hand, [b], poses)[b.id]
        for key, value in alone.items():
            assert np.array_equal(together[b.id][key], value), (b.id, key)
