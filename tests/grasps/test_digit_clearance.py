"""The digits' capsule clearances (grasps/digit_clearance): segment distances against a brute-force search, the
Jacobian against central differences, and a pen's wrap whose thumb crosses the index without the term closing without
it (MeshLab's test through model/self_crossing as the independent judge)."""

import numpy as np
import pytest

from darthand.grasps.digit_clearance import Capsules, segment_distances
from darthand.grasps.field import ObjectField
from darthand.grasps.fit import GraspProblem, HandRig, fit_grasp
from darthand.grasps.taxonomy import load_taxonomy
from darthand.model.anatomy import angles_to_axis_angle, joint_frames
from darthand.model.forward import forward
from darthand.model.load import open_hand
from darthand.model.pair_digits import turn_axes
from darthand.model.self_crossing import SelfCrossing
from grasps.objects_fixture import cylinder


@pytest.fixture(scope="module")
def model():
    return open_hand("right")


def crossing_angles() -> np.ndarray:
    """(16, 3) radians: the thumb folded over the index, the ring spread into the pinky."""
    a = np.zeros((16, 3))
    a[13] = np.deg2rad([-40, 20, 50])       # thumb1 twist, spread, bend
    a[14, 2], a[15, 2] = np.deg2rad(40), np.deg2rad(40)
    a[1, 2], a[2, 2] = np.deg2rad(30), np.deg2rad(30)
    a[10, 1] = np.deg2rad(15)
    a[7, 1] = np.deg2rad(-20)
    return a


def test_segment_distances_match_a_brute_force_search():
    rng = np.random.default_rng(3)
    a0, a1, b0, b1 = (rng.normal(size=(50, 3)) * 0.02 for _ in range(4))
    a1[:5] = a0[:5] + 0.01 * (b1[:5] - b0[:5])          # some parallel pairs
    d = segment_distances(a0, a1, b0, b1)[0]
    s = np.linspace(0, 1, 401)
    pa = a0[:, None] + s[None, :, None] * (a1 - a0)[:, None]
    pb = b0[:, None] + s[None, :, None] * (b1 - b0)[:, None]
    brute = np.linalg.norm(pa[:, :, None] - pb[:, None, :], axis=3).min(axis=(1, 2))
    assert np.all(d <= brute + 1e-12)
    assert np.allclose(d, brute, atol=2e-4 * 0.04)


def test_clearance_jacobian_matches_central_differences(model):
    caps = Capsules.of(model)
    frames = joint_frames(model)
    angles = crossing_angles()
    free = np.flatnonzero(np.ones(48, bool))[3:]

    def clearance(a):
        posed = forward(model, angles_to_axis_angle(model, a, frames).reshape(1, -1))
        return caps.clearances(posed.transforms[0]), posed

    (clear, u, pa, pb), posed = clearance(angles)
    assert (clear < 0).any()                            # the pose does cross: the rows are tested where they act
    omega = turn_axes(frames, angles, posed.world_rotations[0], model.parents, free)
    rows = caps.rows(u, pa, pb, free, omega, posed.joints[0, free // 3])
    h = 1e-6
    numeric = np.zeros_like(rows)
    for n, k in enumerate(free):
        up, down = angles.copy(), angles.copy()
        up.flat[k] += h
        down.flat[k] -= h
        numeric[:, n] = (clearance(up)[0][0] - clearance(down)[0][0]) / (2 * h)
    near = np.abs(clear) < 0.01                         # where closest points are not jumping between ends
    assert np.allclose(rows[near], numeric[near], atol=2e-5), np.abs(rows - numeric)[near].max()


def test_a_small_diameter_wrap_of_a_pen_keeps_the_thumb_off_the_index(model):
    g = load_taxonomy()["small_diameter"]
    judge = SelfCrossing(model)

    def wrap(radius, clearance):
        pen = cylinder(radius, 0.14)
        rig = HandRig.of(model, g.contacts, clearance=clearance)
        fit = fit_grasp(rig, ObjectField(pen.vertices, pen.faces), g.contacts, g.angles, np.array([1.0, 0, 0]),
                        np.array([0, 0, 1.0]))
        return fit, forward(model, fit.pose[None]), rig

    fit, posed, _ = wrap(0.004, False)                  # the fault: without the term the thumb closes through
    assert judge.crossing(np.asarray(posed.vertices[0], np.float64)) == "thumb-index"
    fit, posed, rig = wrap(0.006, True)
    assert fit.dropped is None, fit.dropped
    assert judge.crossing(np.asarray(posed.vertices[0], np.float64)) is None
    assert rig.capsules is not None
    assert rig.capsules.clearances(posed.transforms[0])[0].min() > -0.5e-3


def test_problem_jacobian_with_digit_terms_matches_central_differences(model):
    taxonomy = load_taxonomy()
    g = taxonomy["small_diameter"]
    rig = HandRig.of(model, g.contacts)
    can = cylinder(0.012, 0.14)
    field_ = ObjectField(can.vertices, can.faces)
    start = np.eye(4)
    start[:3, 3] = [0.0, -0.08, 0.0]
    problem = GraspProblem(rig, field_, g.contacts, crossing_angles(), crossing_angles(), start)
    y = np.zeros(6 + len(problem.free))
    posed = rig.pose(problem.angles(y))
    omega = turn_axes(rig.frames, problem.angles(y), posed.world_rotations[0], model.parents, problem.free)
    res, jac = problem.digit_terms(posed, omega)
    assert (res > 0).any()
    numeric = central_differences(lambda x: problem.digit_terms(rig.pose(problem.angles(x)), omega)[0], y, 1e-6)
    act = res > 0.5
    assert np.allclose(jac[act], numeric[act], atol=2e-2 * np.abs(numeric[act]).max())


def test_bone_terms_jacobian_matches_central_differences(model):
    g = load_taxonomy()["small_diameter"]
    rig = HandRig.of(model, g.contacts)
    rod = cylinder(0.006, 0.3)                           # a rod through the curled fingers' bones
    problem = GraspProblem(rig, ObjectField(rod.vertices, rod.faces), g.contacts, g.angles, g.angles, np.eye(4))
    posed = rig.pose(g.angles)
    bones = problem.bone_points(posed)
    start = np.eye(4)
    start[:3, 3] = -bones[len(bones) // 2 + 2] + np.array([0.0, 0.0, 0.001])
    problem = GraspProblem(rig, problem.field, g.contacts, g.angles, g.angles, start)

    def terms(y):
        angles = problem.angles(y)
        posed = rig.pose(angles)
        M = problem.transform(y)
        omega = turn_axes(rig.frames, angles, posed.world_rotations[0], model.parents, problem.free)
        pivot = posed.joints[0, problem.free // 3] @ M[:3, :3].T + M[:3, 3]
        return problem.bone_terms(posed, M, y, omega @ M[:3, :3].T, pivot)

    y = np.full(6 + len(problem.free), 1e-3)
    res, jac = terms(y)
    act = res > 1.0
    assert act.sum() >= 3
    numeric = central_differences(lambda x: terms(x)[0], y, 1e-7)
    assert np.allclose(jac[act], numeric[act], atol=2e-2 * np.abs(numeric[act]).max())


def central_differences(f, y: np.ndarray, h: float) -> np.ndarray:
    """(R, N) the central-difference Jacobian of f: (N,) -> (R,) at y with step h."""
    columns = []
    for n in range(len(y)):
        up, down = y.copy(), y.copy()
        up[n] += h
        down[n] -= h
        columns.append((f(up) - f(down)) / (2 * h))
    return np.stack(columns, axis=1)
