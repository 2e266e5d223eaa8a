"""model/hand_pair.py: penetration between two posed surfaces against closed forms (two spheres overlapping by a
known depth, apart by a known gap) and trimesh's inside test; the rigid resolution on spheres and on two hands."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from darthand.model import hand_pair as hp
from darthand.model.load import load_model
from darthand.model.topology import close_loops, vertex_normals
from darthand.render.contacts import CONTACT_M, contact_vertices

R = 0.02                       # m: sphere radius
TESSELLATION = 0.2e-3          # m: an icosphere of 4 subdivisions of radius R lies within this of the true sphere


def sphere(centre) -> hp.PosedHand:
    m = trimesh.creation.icosphere(subdivisions=4, radius=R)
    v = np.asarray(m.vertices) + centre
    f = np.asarray(m.faces)
    return hp.PosedHand(v, f, vertex_normals(v, f), np.zeros(len(v), np.int64), np.zeros(len(f), np.int64))


def inside_trimesh(a: hp.PosedHand, b: hp.PosedHand) -> int:
    """Vertices of a inside b and of b inside a, by trimesh's ray test on the closed meshes (independent)."""
    n = 0
    for p, q in ((a, b), (b, a)):
        mesh = trimesh.Trimesh(*close_loops(q.vertices, q.faces), process=False)   # the wrist capped
        assert mesh.is_watertight
        n += int(mesh.contains(p.vertices).sum())
    return n


@pytest.mark.parametrize("depth", [1e-3, 4e-3, 8e-3])
def test_spheres_overlapping_by_a_known_depth(depth):
    a, b = sphere([0, 0, 0]), sphere([2 * R - depth, 0, 0])
    pen = hp.penetration(a, b)
    assert pen.max_m == pytest.approx(depth, abs=TESSELLATION)
    assert pen.inside > 0 and pen.crossing_faces > 0


@pytest.mark.parametrize("gap", [0.5e-3, 5e-3, 50e-3])
def test_spheres_apart_by_a_known_gap(gap):
    a, b = sphere([0, 0, 0]), sphere([2 * R + gap, 0, 0])
    pen = hp.penetration(a, b)
    assert pen.clear and pen.max_m == 0
    assert inside_trimesh(a, b) == 0
    assert hp.first_contact_shift(a, b, np.array([-1.0, 0, 0])) == pytest.approx(gap, abs=2 * TESSELLATION)
    assert (len(contact_vertices(a.vertices, b.vertices, b.faces)) > 0) == (gap < CONTACT_M)


def test_resolving_two_overlapping_spheres_moves_one_off_by_the_depth():
    depth = 5e-3
    a, b = sphere([0, 0, 0]), sphere([2 * R - depth, 0, 0])
    res = hp.resolve(a, b)
    moved = b.moved(res.T)
    assert res.resolved and res.after.clear and inside_trimesh(a, moved) == 0
    gap = np.linalg.norm(moved.vertices.mean(0)) - 2 * R
    assert hp.CLEARANCE - TESSELLATION <= gap <= hp.CLEARANCE + 2 * hp.STEP + TESSELLATION


def test_a_contact_asked_for_ends_touching():
    a, b = sphere([0, 0, 0]), sphere([2 * R + 0.01, 0.003, 0])
    res = hp.resolve(a, b, touch=[(None, None)])
    moved = b.moved(res.T)
    assert res.resolved and inside_trimesh(a, moved) == 0
    assert res.contacts[0] == pytest.approx(hp.CONTACT_GAP, abs=0.3e-3)
    assert len(contact_vertices(moved.vertices, a.vertices, a.faces)) > 0


@pytest.fixture(scope="module")
def hands():
    return load_model("open"), load_model("open-left")


def test_a_hand_pushed_into_another_is_found_and_resolved(hands):
    right, left = hands
    a = hp.pose_hand(right, np.zeros(48))
    T = np.diag([-1.0, -1.0, 1.0, 1.0])                      # palms facing
    b = hp.pose_hand(left, np.zeros(48), T=T)
    shift = hp.first_contact_shift(a, b, np.array([0.0, 1.0, 0.0]))
    T[1, 3] = shift + 3e-3                                    # 3 mm past first contact: into the other palm
    b = hp.pose_hand(left, np.zeros(48), T=T)
    pen = hp.penetration(a, b)
    assert pen.crossing_faces > 0 and inside_trimesh(a, b) > 0
    assert 1e-3 < pen.max_m < 4e-3
    res = hp.resolve(a, b, touch=[((0,), (0,))])
    moved = b.moved(res.T)
    assert res.resolved and hp.penetration(a, moved).clear and inside_trimesh(a, moved) == 0
    assert res.contacts[0] == pytest.approx(hp.CONTACT_GAP, abs=0.5e-3)


def test_nearest_point_kernel_matches_trimesh():
    """pair_kernels.nearest_on_candidates (the compiled inner step of Surface) against trimesh's exact closest point,
    every triangle a candidate, on points near, on and far from a random soup (vertex, edge and face regions)."""
    from trimesh.proximity import closest_point_naive

    from darthand.model.pair_kernels import nearest_on_candidates

    rng = np.random.default_rng(3)
    tris = rng.normal(size=(40, 3, 3)) * 0.01
    points = rng.normal(size=(300, 3)) * 0.02
    cand = np.tile(np.arange(len(tris)), (len(points), 1))
    best, bary, dist = nearest_on_candidates(tris, cand, points)
    mesh = trimesh.Trimesh(tris.reshape(-1, 3), np.arange(len(tris) * 3).reshape(-1, 3), process=False)
    closest, exact, _ = closest_point_naive(mesh, points)
    np.testing.assert_allclose(dist, exact, atol=1e-12)
    on = np.einsum("pk,pkd->pd", bary, tris[cand[np.arange(len(points)), best]])
    np.testing.assert_allclose(on, closest, atol=1e-9)
    assert (bary >= -1e-12).all() and np.allclose(bary.sum(1), 1)


# ------------------------------------------------------------------------------------------------ the digits fitted


def bent(model, degrees: dict) -> np.ndarray:
    """(48,) pose of `model`: each finger's (MCP, PIP, DIP) bends (degrees) from `degrees` {finger: (3,)}."""
    from darthand.model.anatomy import angles_to_axis_angle
    from darthand.model.layout import FINGER_JOINTS

    angles = np.zeros((16, 3))
    for finger, bends in degrees.items():
        angles[list(FINGER_JOINTS[finger]), 2] = np.deg2rad(bends)
    return angles_to_axis_angle(model, angles).reshape(-1)


def test_a_bent_finger_in_a_large_sphere_is_fitted_out_by_its_depth_and_the_clearance(hands):
    """Closed form: the index fingertip 2 mm inside a sphere of radius 0.2 m (distance |p - c| - r, exact but for
    the icosphere's few micrometres of sag); after the fit no vertex is nearer the surface than the clearance
    (less the tessellation) nor much farther, the index's angles moved, trimesh finds nothing inside."""
    from darthand.model.pair_digits import DigitHand

    right, _ = hands
    pose = bent(right, {"index": (30, 30, 20), "middle": (5, 5, 5), "ring": (5, 5, 5), "pinky": (5, 5, 5)})
    hand = hp.pose_hand(right, pose)
    tip = hand.vertices[hand.vertex_joint == 3]
    radius, depth = 0.2, 2e-3
    centre = tip[np.argmin(tip[:, 1])] - [0, radius - depth, 0]
    m = trimesh.creation.icosphere(subdivisions=5, radius=radius)
    v, f = np.asarray(m.vertices) + centre, np.asarray(m.faces)
    ball = hp.PosedHand(v, f, vertex_normals(v, f), np.zeros(len(v), np.int64), np.zeros(len(f), np.int64))
    res = hp.resolve(ball, hand, digits=(None, DigitHand(right, pose)))
    fitted = hp.pose_hand(right, res.poses[1], T=res.T)
    gap = (np.linalg.norm(fitted.vertices - centre, axis=1) - radius).min()
    assert res.resolved and res.poses[0] is None
    assert hp.CLEARANCE - 0.05e-3 <= gap <= hp.CLEARANCE + 0.3e-3
    assert res.digits_max_deg > 0.1 and res.figures()["digits_max_deg"] == round(res.digits_max_deg, 3)
    closed = trimesh.Trimesh(v, f, process=False)
    assert not closed.contains(fitted.vertices).any()


def pressed_palms(hands, bend=40.0, past=2e-3):
    """Two hands with every finger bent by `bend` (degrees), palms facing, the left pushed `past` (m) beyond
    first contact: (a, b, (right's, left's) DigitHand)."""
    from darthand.model.pair_digits import DigitHand

    right, left = hands
    bends = {f: (bend, bend, 0.7 * bend) for f in ("index", "middle", "ring", "pinky")}
    pa, pb = bent(right, bends), bent(left, bends)
    a = hp.pose_hand(right, pa)
    T = np.diag([-1.0, -1.0, 1.0, 1.0])
    b = hp.pose_hand(left, pb, T=T)
    T[1, 3] = hp.first_contact_shift(a, b, np.array([0.0, 1.0, 0.0])) + past
    return a, hp.pose_hand(left, pb, T=T), (DigitHand(right, pa), DigitHand(left, pb, T=T))


def test_the_digit_jacobian_matches_finite_differences(hands):
    """DigitPairProblem's analytic Jacobian (rigid and angle columns) against central differences of its own
    residuals, on the rows active on both sides of the step."""
    a, b, digits = pressed_palms(hands)
    problem = hp.DigitPairProblem(a, b, digits, [], hp.CLEARANCE, b.vertices.mean(0))
    y = np.zeros(6 + sum(len(h.free) for h in digits))
    problem.select(y)
    r0, J = problem.evaluate(y)
    active = r0 > 0
    active[:len(y)] = False
    assert active.sum() > 5
    checked = 0
    for k in range(len(y)):
        step = np.zeros(len(y))
        step[k] = 1e-6
        rp, rm = problem.evaluate(y + step)[0], problem.evaluate(y - step)[0]
        ok = active & (rp > 0) & (rm > 0)
        fd = (rp - rm)[ok] / 2e-6
        if np.linalg.norm(fd) > 1.0:
            assert np.linalg.norm(J[ok, k] - fd) <= 0.05 * np.linalg.norm(fd), k
            checked += 1
    assert checked >= 10          # the rigid part and angles of both hands


def test_the_digit_fit_keeps_joint_limits_and_the_maximum_change_and_is_deterministic(hands):
    from darthand.model.anatomy import axis_angle_to_angles, within_limits
    from darthand.model.gesture_fit import MAX_CHANGE_DEG

    right, left = hands
    a, b, digits = pressed_palms(hands, bend=85.0, past=4e-3)     # near the bend limits, deep in
    res = hp.resolve(a, b, digits=digits)
    again = hp.resolve(a, b, digits=digits)
    assert res.resolved and res.digits_max_deg > 0
    for model, pose, digit in zip((right, left), res.poses, digits):
        angles = axis_angle_to_angles(model, pose)
        assert within_limits(angles, tol=1e-6).all()
        assert np.rad2deg(np.abs(angles - digit.angles)).max() <= MAX_CHANGE_DEG + 1e-6
    assert res.digits_max_deg <= MAX_CHANGE_DEG + 1e-6
    assert all(np.array_equal(p, q) for p, q in zip(res.poses, again.poses)) and np.array_equal(res.T, again.T)
    moved = (hp.pose_hand(right, res.poses[0]), hp.pose_hand(left, res.poses[1], T=res.T @ digits[1].place))
    assert hp.penetration(*moved).clear and inside_trimesh(*moved) == 0


def test_only_the_digits_near_the_other_hand_are_freed(hands):
    """A point 5 mm off the index fingertip frees the index's angles only (its MCP's three, the PIP's and DIP's
    bends: gesture_fit.freedom of a bent finger); a point far from every digit frees none."""
    from darthand.model.layout import FINGER_JOINTS
    from darthand.model.pair_digits import DigitHand, near_digits

    right, _ = hands
    pose = bent(right, {f: (20, 20, 14) for f in ("index", "middle", "ring", "pinky")})
    hand = hp.pose_hand(right, pose)
    index = list(FINGER_JOINTS["index"])
    tip = hand.vertices[hand.vertex_joint == index[-1]].mean(0)
    near = near_digits(hand.vertex_joint, hand.vertices, tip[None] + [0, -0.005, 0], 0.01)
    assert near == index
    freed = DigitHand(right, pose).only(near)
    assert sorted(set((freed.free // 3).tolist())) == index and len(freed.free) == 5
    assert near_digits(hand.vertex_joint, hand.vertices, np.array([[1.0, 1.0, 1.0]]), 0.01) == []
    assert DigitHand(right, pose).only([]) is None
